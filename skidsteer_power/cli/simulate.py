"""``skidsteer-power simulate``: run the digital twin offline and write its sensors to a bag."""

from __future__ import annotations

import argparse
from pathlib import Path

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import FORWARD_SPEED_M_S, LEAD_IN_S, SEED, SIM_DURATION_S


def register(subparsers: Subcommands) -> None:
    p = subparsers.add_parser(
        'simulate',
        help='run the digital twin (its own terrain, not the estimator) and record a bag',
        description='Drive the dynamic twin (skidsteer_power/twin, docs/TWIN.md) through commands '
        'and write /cmd_vel, /joint_states, /odom, /ground_truth/odom and /battery/measured to an '
        'MCAP bag. The twin never uses FESS or the maps. A command CSV has columns t_s, speed_m_s, '
        'yaw_rate_rad_s (each row held until the next; the last row ends the run). '
        f'The lead-in and the commands together are at most {SIM_DURATION_S.high:g} s of twin time '
        '(about 0.5 s of CPU per simulated second); a progress bar shows on a terminal.',
    )
    p.add_argument('--vehicle', required=True, help='vehicle YAML file or shipped name')
    p.add_argument('--terrain', required=True, help="the twin's (true) terrain: preset or YAML file")
    p.add_argument('--patches', metavar='FILE.yaml', help='polygons of other terrains (see docs/TWIN.md)')
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument('--commands', metavar='BAG|CSV', help='cmd_vel of a bag, or a command CSV')
    source.add_argument('--route', help='patrol | search-retrieve | FILE.csv (a mission route)')
    p.add_argument(
        '--speed',
        type=range_arg(FORWARD_SPEED_M_S),
        help=range_help(FORWARD_SPEED_M_S, "route speed (default: the route's)"),
    )
    p.add_argument('--contact', choices=('classic', 'extended'), default='extended',
                   help="the twin's contact laws: classic (the chapter 2-4 laws only) or extended (plus "
                   'slip-sinkage and bulldozing; docs/TWIN.md). Default extended')  # fmt: skip
    p.add_argument(
        '--seed', type=range_arg(SEED), default=0, help=range_help(SEED, 'sensor noise seed (default 0)')
    )
    p.add_argument(
        '--lead-in',
        type=range_arg(LEAD_IN_S),
        default=1.0,
        help=range_help(LEAD_IN_S, 'rest before the commands (default 1)'),
    )
    p.add_argument('-o', '--output', required=True, help='output bag (OUT.mcap)')
    add_json_flag(p)
    p.set_defaults(func=run_simulate_cmd)


def run_simulate_cmd(args: argparse.Namespace) -> int:
    from skidsteer_power.progress import progress_bar
    from skidsteer_power.terramechanics import load_terrain
    from skidsteer_power.twin import Segment, Twin, load_patches, run_commands, sensors, write_bag
    from skidsteer_power.vehicle import load_vehicle

    output = Path(args.output)
    if output.exists():
        raise InputError(f'output exists already, not overwriting: {output}')
    if args.speed is not None and args.route is None:
        raise InputError('--speed applies to --route only')
    vehicle = load_vehicle(args.vehicle)
    terrain = load_terrain(args.terrain)
    patches = load_patches(args.patches) if args.patches else None
    if args.commands:
        path = Path(args.commands)
        if not path.exists():
            raise InputError(f'command file not found: {path}')
        commands = (
            sensors.commands_from_csv(path)
            if path.suffix.lower() == '.csv'
            else sensors.commands_from_bag(path)
        )
    else:
        from skidsteer_power.missions.routes import resolve_route

        commands = sensors.commands_from_route(resolve_route(args.route, args.speed))
    twin = Twin(vehicle, terrain, patches=patches, seed=args.seed, contact=args.contact)
    lead_in = [Segment(0.0, 0.0, args.lead_in)] if args.lead_in > 0 else []
    commands = [*lead_in, *commands]
    total_s = SIM_DURATION_S.check(sum(c.duration_s for c in commands))
    with progress_bar(None, 'simulating [s of twin time]', total_s) as advance:
        trace = run_commands(twin, commands, progress=advance)
    write_bag(trace, output)
    payload = trace.summary(vehicle.tread_m)
    emit(payload if args.json else {**payload, 'output': str(output)}, args.json)
    return 0
