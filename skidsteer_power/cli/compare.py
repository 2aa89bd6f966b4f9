"""``skidsteer-power compare BAG... --vehicle V --terrain T [--holdout BAG...]``: FESS against the
simple models a user would fit (issue 27; :mod:`skidsteer_power.apps.compare`).

JSON keys: vehicle, terrain, kinematics (what FESS predicted from: validate's default, 'cmd' = the
commands' wheel speed set points), train_bags, train_envelope {max_speed_m_s, max_yaw_rate_rad_s},
holdout [{bag, split, outside_envelope_share, max_speed_m_s, max_yaw_rate_rad_s}], transfer,
calibration (with fit_at: what calibrate solved the segments at), baselines, splits {same_range |
extrapolation | transfer: {bags, models {linear, gazebo_cmd_vel, icr_rls_online, fess, fess_online,
fess_calibrated, fess_calibrated_online: {energy_error_pct, power_rmse_W,
median_abs_segment_error_pct, energy_predicted_J, energy_measured_J, segments, error (a model that
failed: its reason, the figures NaN)}}}}, goal {split:
{best_baseline, ..., met}}, plot.
"""

from __future__ import annotations

import argparse
import sys

from skidsteer_power.cli.common import Subcommands, add_json_flag, add_msg_option, emit, finite_float


def register(subparsers: Subcommands) -> None:
    from skidsteer_power.apps.compare import MAX_BAG_S, MAX_BAGS

    parser = subparsers.add_parser(
        'compare',
        help='FESS vs the models a user would fit (linear, gazebo_ros_battery, on-line ICR + RLS)',
        description='Fit the baselines on the training BAGs, calibrate FESS on them, and score every model '
        'on the hold-out bags (same range or extrapolation, detected from the command envelope) and on '
        f'transfer bags. At most {MAX_BAGS} bags per list, each at most {MAX_BAG_S:.0f} s long.',
    )
    parser.add_argument('bags', nargs='+', metavar='BAG', help=f'training bags (at most {MAX_BAGS})')
    parser.add_argument('--vehicle', required=True, help='vehicle name in config/vehicles/ or YAML file')
    parser.add_argument('--terrain', required=True, help='terrain the robot drives on: preset or YAML file')
    parser.add_argument(
        '--holdout',
        nargs='+',
        default=[],
        metavar='BAG',
        help=f'hold-out bags (at most {MAX_BAGS}; default: the last BAG when two or more are given)',
    )
    parser.add_argument(
        '--transfer',
        nargs='+',
        default=[],
        metavar='BAG',
        help=f'bags on another terrain or payload (at most {MAX_BAGS})',
    )
    parser.add_argument('--transfer-terrain', help='terrain of the --transfer bags (preset or YAML file)')
    parser.add_argument(
        '--transfer-payload-kg',
        type=finite_float,
        help='mass added for the --transfer bags [kg], in [-50, 500]',
    )
    parser.add_argument('--work-dir', help='folder for the calibrated terrain (default: a temporary one)')
    parser.add_argument('--map-cache', help="power map cache folder (default: the estimator's)")
    parser.add_argument('--plot', metavar='DIR', help='write DIR/compare.png')
    add_msg_option(parser)
    add_json_flag(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from skidsteer_power.apps.compare import CompareOptions, compare, plot, table
    from skidsteer_power.bag_io.reader import load_msg_definitions

    train, holdout = list(args.bags), list(args.holdout)
    if not holdout and len(train) >= 2 and not args.transfer:
        holdout = [train.pop()]
    options = CompareOptions(
        vehicle=args.vehicle,
        terrain=args.terrain,
        train=tuple(train),
        holdout=tuple(holdout),
        transfer=tuple(args.transfer),
        transfer_terrain=args.transfer_terrain,
        transfer_payload_kg=args.transfer_payload_kg,
        work_dir=args.work_dir,
        map_cache_dir=args.map_cache,
        extra_types=load_msg_definitions(args.msg),
    )
    result = compare(options, progress=lambda message: print(message, file=sys.stderr, flush=True))
    result['plot'] = str(plot(result, args.plot)) if args.plot else None
    if args.json:
        emit(result, True)
    else:
        print(table(result))
    return 0
