"""``mission``, ``sensitivity`` and ``design-study`` (chapter 8; DESIGN.md command-line contract).

mission --json keys: energy_J, energy_internal_J, energy_terrain_J, power_straight_W, power_turning_W,
max_sinkage_m, max_drawbar_pull_N (+ drawbar_pull_ratio, energy_battery_J, internal_fraction,
battery_end_soc, battery_remaining_wh, legs, ...). design-study --json: best: {track, 4-wheel, 6-wheel}
each with mass_kg, width_m, radius_m, length_or_wheelbase_m, tread_m (+ powers, mobility, merit),
candidates: [...], criterion. sensitivity --json: results: {vehicle: {baseline, changes_percent}}.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, positive_float
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import (
    FORWARD_SPEED_M_S,
    LOCAL_WORKERS,
    PAYLOAD_KG,
    SAMPLES,
    SEED,
)

if TYPE_CHECKING:
    from skidsteer_power.distributed.engine import Engine
    from skidsteer_power.missions.energy import MissionResult
    from skidsteer_power.missions.routes import Route
    from skidsteer_power.powertrain.power_flow import Powertrain
    from skidsteer_power.studies.uncertainty import ParameterSpread
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

PACKBOTS = ('packbot_track', 'packbot_4wheel', 'packbot_6wheel')
MODEL_CHOICES = ('fess', 'wong', 'steeds', 'icr', 'fast')


def register(subparsers: Subcommands) -> None:
    _register_mission(subparsers)
    _register_sensitivity(subparsers)
    _register_design(subparsers)


def _register_mission(subparsers: Subcommands) -> None:
    p = subparsers.add_parser(
        'mission',
        help='power and energy along a route (ch. 8.1, 8.2)',
        description='Energy of a vehicle driving a route: built-in patrol (ch. 8.1), search-retrieve '
        '(ch. 8.2, synthetic smooth path) or a CSV of segments (length_m or duration_s, speed_m_s, '
        'turn_radius_m, payload_kg). Energy = terrain + internal (eqs. 7.1-7.4); battery energy adds '
        'motor and amplifier losses.',
    )
    p.add_argument('--vehicle', required=True, help='vehicle YAML file or shipped name')
    p.add_argument('--terrain', required=True, help='terrain preset or YAML file')
    p.add_argument('--route', required=True, help='patrol | search-retrieve | FILE.csv')
    p.add_argument(
        '--speed',
        type=range_arg(FORWARD_SPEED_M_S),
        help=range_help(
            FORWARD_SPEED_M_S, 'forward speed (default: 0.2 patrol, 0.5 search-retrieve; CSV rows)'
        )
        + "; with the power map (default), above the map's speed envelope is an error",
    )
    p.add_argument(
        '--payload-kg',
        type=range_arg(PAYLOAD_KG),
        help=range_help(
            PAYLOAD_KG, 'search-retrieve: payload brought back (default 10); other routes: carried'
        ),
    )
    _add_source_args(p)
    p.add_argument(
        '--cache-dir', default=None, help='map cache folder (default $SKIDSTEER_POWER_CACHE or ~/.cache)'
    )
    p.add_argument(
        '--no-cache', action='store_true', help='build maps in memory; do not read or write the cache'
    )
    p.add_argument('--plot', metavar='PNG', help='write power and energy along the route to this PNG')
    _add_uncertainty_args(p, calibration=True)
    _add_workers(p, 'with --samples: local processes (default: all cores)')
    add_json_flag(p)
    p.set_defaults(func=run_mission_cmd)


def _register_sensitivity(subparsers: Subcommands) -> None:
    p = subparsers.add_parser(
        'sensitivity',
        help='soil-parameter sensitivity of a mission (ch. 8.2)',
        description='Change each soil parameter (n, kc, kphi, c, phi, K) by +-delta and all at once; '
        'relative change of mission energy, max drawbar pull / weight and max sinkage per vehicle.',
    )
    p.add_argument(
        '--vehicle', action='append', help='vehicle (repeatable; default: the three chapter 8 Packbots)'
    )
    p.add_argument(
        '--terrain', default='sandy_soil', help='terrain preset or YAML (default sandy_soil, Table 8.2)'
    )
    p.add_argument('--route', default='search-retrieve', help='patrol | search-retrieve | FILE.csv')
    p.add_argument(
        '--speed',
        type=range_arg(FORWARD_SPEED_M_S),
        help=range_help(FORWARD_SPEED_M_S, "forward speed (default: the route's)"),
    )
    p.add_argument('--delta', type=positive_float, default=0.01, help='relative change (default 0.01 = 1 %%)')
    _add_source_args(p)
    _add_workers(p, 'processes (default: all cores)')
    p.add_argument('--plot', metavar='PNG', help='write a bar chart of the changes to this PNG')
    p.add_argument(
        '--method',
        choices=('oat', 'sobol'),
        default='oat',
        help='oat: the one-at-a-time table (default); sobol: also first-order and total Sobol indices '
        "over the parameters' spread (--samples N base samples, default 64; N (D+2) missions per vehicle)",
    )
    _add_uncertainty_args(p, calibration=False)
    add_json_flag(p)
    p.set_defaults(func=run_sensitivity_cmd)


def _register_design(subparsers: Subcommands) -> None:
    from skidsteer_power.missions.design import CONFIGURATIONS, CRITERIA

    p = subparsers.add_parser(
        'design-study',
        help='the 729-candidate design study of ch. 8.3 (Table 8.4)',
        description='Straight at 0.2 m/s and R = 2 m at 0.2 m/s for every Table 8.4 candidate; best design '
        'per configuration by --criterion (merit: max drawbar pull / weight per watt of mean power).',
    )
    p.add_argument(
        '--terrain', default='sandy_soil', help='terrain preset or YAML (default sandy_soil, Table 8.2)'
    )
    p.add_argument('--model', default='fess', choices=MODEL_CHOICES)
    p.add_argument('--criterion', default='merit', choices=CRITERIA)
    p.add_argument(
        '--configuration',
        action='append',
        choices=CONFIGURATIONS,
        help='study only this configuration (repeatable; default: all three)',
    )
    _add_workers(p, 'processes (default: 2 or the cores there are)')
    p.add_argument('--plot', metavar='PNG', help='write the power vs mobility scatter to this PNG')
    _add_uncertainty_args(p, calibration=False)
    add_json_flag(p)
    p.set_defaults(func=run_design_cmd)


def _add_workers(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        '--workers', type=range_arg(LOCAL_WORKERS), default=None, help=range_help(LOCAL_WORKERS, what)
    )


def _add_source_args(p: argparse.ArgumentParser) -> None:
    p.add_argument('--model', default='fess', choices=MODEL_CHOICES, help='skid-steer model (default fess)')
    p.add_argument(
        '--direct',
        action='store_true',
        help='solve the model at every route state instead of querying the FESS power map '
        '(implied by a model other than fess; fails where the model cannot solve a tight turn)',
    )


def _add_uncertainty_args(p: argparse.ArgumentParser, calibration: bool) -> None:
    from skidsteer_power.distributed.engine import add_engine_args

    g = p.add_argument_group('uncertainty (Monte Carlo over terrain and powertrain; docs/STUDIES.md)')
    g.add_argument(
        '--samples',
        type=range_arg(SAMPLES),
        default=0,
        metavar='N',
        help=range_help(SAMPLES, 'samples (default 0: nominal only)'),
    )
    g.add_argument(
        '--seed', type=range_arg(SEED), default=0, help=range_help(SEED, 'sampling seed (default 0)')
    )
    g.add_argument(
        '--sampling', choices=('sobol', 'random'), default='sobol', help='scrambled Sobol (default) or random'
    )
    spread = g.add_mutually_exclusive_group()
    spread.add_argument('--uncertainty', metavar='FILE.yaml', help='sigmas of terrain/powertrain parameters')
    if calibration:
        spread.add_argument(
            '--from-calibration', metavar='F.yaml', help="a calibrated terrain file's covariance (calibrate)"
        )
    add_engine_args(g)


def _spread(args: argparse.Namespace, terrain: Terrain, powertrain: Powertrain) -> ParameterSpread:
    from skidsteer_power.studies import uncertainty

    if args.samples < 0:
        raise InputError(f'--samples must be >= 0, not {args.samples}')
    if getattr(args, 'from_calibration', None):
        return uncertainty.spread_from_calibration(args.from_calibration)
    if args.uncertainty:
        return uncertainty.spread_from_yaml(args.uncertainty, terrain, powertrain)
    return uncertainty.default_spread(terrain, powertrain)


def _engine(args: argparse.Namespace) -> Engine:
    from skidsteer_power.distributed.engine import Engine

    return Engine(args.scheduler, None if args.scheduler else _workers(args.workers))


def _source(args: argparse.Namespace) -> str:
    return 'direct' if args.direct or args.model != 'fess' else 'map'


def _load(vehicle: str, terrain: str) -> tuple[Vehicle, Terrain]:
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    return load_vehicle(vehicle), load_terrain(terrain)


def _route(spec: str, speed: float | None, payload: float | None) -> Route:
    import dataclasses

    from skidsteer_power.missions.routes import resolve_route, search_retrieve

    if spec == 'search-retrieve':
        kwargs: dict[str, float] = {}
        if speed is not None:
            kwargs['speed_m_s'] = speed
        if payload is not None:
            kwargs['payload_kg'] = payload
        return search_retrieve(**kwargs)
    route = resolve_route(spec, speed)
    if payload:
        segments = tuple(dataclasses.replace(s, payload_kg=s.payload_kg + payload) for s in route.segments)
        route = dataclasses.replace(route, segments=segments)
    return route


def _workers(value: int | None) -> int | None:
    if value is not None and value < 1:
        raise InputError(f'--workers must be >= 1, not {value}')
    return value


def run_mission_cmd(args: argparse.Namespace) -> int:
    from skidsteer_power.missions.energy import run_mission
    from skidsteer_power.powertrain import Battery, Powertrain

    png = _png(args.plot) if args.plot else None  # checked before the work
    vehicle, terrain = _load(args.vehicle, args.terrain)
    route = _route(args.route, args.speed, args.payload_kg)
    powertrain = Powertrain.for_vehicle(vehicle)
    cache_dir = None if args.no_cache else (args.cache_dir or _default_cache())
    result = run_mission(
        vehicle,
        terrain,
        route,
        source=_source(args),
        model=args.model,
        powertrain=powertrain,
        cache_dir=cache_dir,
    )
    payload = result.summary()
    if payload['slowed_segments']:
        print(f'warning: {_slowed_warning(result)}', file=sys.stderr)
    battery = Battery.from_config(powertrain.battery)
    battery.run_profile(result.power_battery_W, result.duration_s)
    payload['battery_end_soc'] = battery.soc
    payload['battery_remaining_wh'] = battery.remaining_wh
    if args.samples or args.uncertainty or getattr(args, 'from_calibration', None) or args.scheduler:
        from skidsteer_power.studies.montecarlo import mission_uncertainty

        spread = _spread(args, terrain, powertrain)
        if not args.samples:
            raise InputError('--uncertainty, --from-calibration and --scheduler need --samples N (N >= 1)')
        with _engine(args) as engine:
            payload |= mission_uncertainty(
                engine, vehicle, terrain, route, powertrain, spread, samples=args.samples, seed=args.seed,
                method=args.sampling, source=_source(args), model=args.model,
            )  # fmt: skip
    if png is not None:
        from skidsteer_power.missions.plots import plot_missions

        plot_missions([result], png)
        payload['plot'] = str(png)
    emit(
        payload if args.json else {k: v for k, v in payload.items() if k not in ('legs', 'commands')},
        args.json,
    )
    return 0


def _slowed_warning(result: MissionResult) -> str:
    """The console line of a mission the drive controller slowed (issue 36: never a silent change)."""
    slowed = result.slowed
    fastest = max(abs(s.speed_m_s) for s, k in zip(result.route.segments, slowed, strict=True) if k)
    return (
        f'{int(slowed.sum())} of {slowed.size} route segments are faster than the drive controller '
        f'carries out (velocity limits, wheel speed ceiling): driven on the same path, slower (at most '
        f'{fastest:.3g} m/s there; slowed_segments, duration_s as driven)'
    )


def _png(text: str) -> Path:
    """The file a ``--plot`` writes: a PNG path ('.png' added when missing, as matplotlib would add
    it), so the reported name is the file's; an existing directory is an InputError."""
    path = Path(text)
    if path.is_dir():
        raise InputError(f'--plot {text}: is a directory; give a file name such as {path / "plot.png"}')
    return path if path.suffix.lower() == '.png' else path.with_name(path.name + '.png')


def _default_cache() -> Path:
    from skidsteer_power.maps import default_cache_dir

    return default_cache_dir()


def run_sensitivity_cmd(args: argparse.Namespace) -> int:
    from skidsteer_power.missions.sensitivity import sensitivity

    png = _png(args.plot) if args.plot else None  # checked before the work
    names = args.vehicle or list(PACKBOTS)
    loaded = [_load(name, args.terrain) for name in names]
    vehicles, terrain = [v for v, _ in loaded], loaded[0][1]
    route = _route(args.route, args.speed, None)
    table = sensitivity(
        vehicles,
        terrain,
        route,
        delta=args.delta,
        source=_source(args),
        model=args.model,
        workers=_workers(args.workers),
    )
    if args.method == 'sobol':
        from skidsteer_power.powertrain import Powertrain
        from skidsteer_power.studies.sobol import sobol_indices

        spread = _spread(args, terrain, Powertrain.for_vehicle(vehicles[0]))
        with _engine(args) as engine:
            table['sobol'] = sobol_indices(
                engine, vehicles, terrain, route, spread, samples=args.samples or 64, seed=args.seed,
                source=_source(args), model=args.model,
            )  # fmt: skip
    elif args.samples or args.uncertainty or args.scheduler:
        raise InputError('--samples, --uncertainty and --scheduler go with --method sobol')
    if png is not None:
        from skidsteer_power.missions.plots import plot_sensitivity

        plot_sensitivity(table, png)
        table['plot'] = str(png)
    if args.json:
        emit(table, True)
    else:
        for name, res in table['results'].items():
            if res['baseline'] is None:
                print(f'{name}: baseline did not converge')
                continue
            print(f'{name}: baseline ' + ', '.join(f'{k} {v:.4g}' for k, v in res['baseline'].items()))
            print('  d(metric)/d(parameter) [% per %], central differences of converged direct solves:')
            for group, per_metric in res['derivatives'].items():
                parts = (
                    f'{k} {d["derivative"]:+.3f}' if d['status'] == 'ok' else f'{k} {d["status"].upper()}'
                    for k, d in per_metric.items()
                )
                print(f'  {group:<5} ' + '  '.join(parts))
            for metric, indices in table.get('sobol', {}).get('indices', {}).get(name, {}).items():
                cells = '  '.join(f'{p} {i["S1"]:.2f}/{i["ST"]:.2f}' for p, i in indices.items())
                print(f'  Sobol S1/ST of {metric}: {cells}')
    return 0


def run_design_cmd(args: argparse.Namespace) -> int:
    from skidsteer_power.missions.design import CONFIGURATIONS, design_study, grid
    from skidsteer_power.terramechanics.terrain import load_terrain

    png = _png(args.plot) if args.plot else None  # checked before the work
    terrain = load_terrain(args.terrain)
    configs = tuple(args.configuration or CONFIGURATIONS)
    if not (args.samples or args.uncertainty or args.scheduler):
        study = design_study(
            terrain, model=args.model, criterion=args.criterion, workers=_workers(args.workers)
        )
    else:
        from skidsteer_power.powertrain import Powertrain
        from skidsteer_power.studies.montecarlo import design_uncertainty

        spread = _spread(args, terrain, Powertrain.default_test_robot())
        if args.criterion != 'merit' and args.samples:
            raise InputError('--samples ranks candidates by merit: use --criterion merit')
        if args.uncertainty and not args.samples:
            raise InputError('--uncertainty needs --samples N (N >= 1)')
        with _engine(args) as engine:
            study = design_study(
                terrain, model=args.model, criterion=args.criterion, engine=engine, configurations=configs
            )
            if args.samples:
                rows = [c for c in grid() if c['configuration'] in configs]
                extra = design_uncertainty(
                    engine, terrain, spread, samples=args.samples, seed=args.seed, method=args.sampling,
                    model=args.model, rows=rows,
                )  # fmt: skip
                stats = extra.pop('candidate_stats')
                for c in study['candidates']:
                    c |= stats[c['index']]
                study |= extra
    if png is not None:
        from skidsteer_power.missions.plots import plot_design_study

        plot_design_study(study['candidates'], study['best'], png)
        study['plot'] = str(png)
    if args.json:
        emit(study, True)
    else:
        converged = f'{study["n_converged"]} of {study["n_candidates"]} candidates converged'
        print(f'{converged}; criterion: {study["criterion_text"]}')
        for config, best in study['best'].items():
            print(f'best {config:<8} {_design_line(best)}')
        for config, ranked in study.get('best_probability', {}).items():
            top = ', '.join(f'#{c["index"]} {100 * c["p_best"]:.0f} %' for c in ranked[:3])
            print(f'  {config:<8} P(best) under uncertainty: {top}')
    return 0


def _design_line(best: Mapping[str, object]) -> str:
    shape = (
        f'm {best["mass_kg"]:g} kg, width {best["width_m"]:g} m, radius {best["radius_m"]:g} m, '
        f'length/wheelbase {best["length_or_wheelbase_m"]:g} m, tread {best["tread_m"]:g} m'
    )
    power = f'P {best["power_straight_W"]:.3g} / {best["power_turning_W"]:.3g} W'
    return f'{shape}: {power}, DP/W {best["drawbar_pull_ratio"]:.3g}'
