"""``skidsteer-power calibrate BAG [BAG ...]``: fit terrain (and internal resistance) to recordings.

JSON keys: parameters (name -> {value, ci95: [lo, hi] | null, unit, fitted, identifiable, start,
sensitivity_Nm}), correlations_warnings, segments_fit, segments_holdout, torque_rmse_before_Nm,
torque_rmse_after_Nm (hold-out segments; the fit segments when there is no hold-out),
holdout_energy_error_before, holdout_energy_error_after (signed fractions: predicted / measured - 1
of the hold-out segments' motor terminal energy), seconds, residual_rms_Nm, correlation,
segments_dropped, optimizer_converged (the optimizer's own stop; see at_bound),
at_bound (fitted parameters pinned at a fit bound: status 'at_bound (lower|upper)', no interval, a
warning), converged_inside_bounds, fit_at ('cmd' | 'motion', what the segments were solved
at), from_cmd (the fitted terrain predicting each segment from its command, at the wheel speed set
points), fit_to ('torque' | 'motion' | 'both'), not_identifiable (name -> why: its interval left the
physical range), left_fixed (name -> why it was not fitted), kept_start (why the start was kept, or
null), motion (hold-out V and yaw-rate MAE before / after), suggest (with --suggest), out_terrain,
out_powertrain, out_vehicle. Method:
:mod:`skidsteer_power.calibration.fit`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, add_msg_option, emit, nonnegative_float
from skidsteer_power.drive.prediction_modes import CMD, FIT_AT, prediction_mode
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import SEED

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

FIT_TO = ('torque', 'motion', 'both')  # = calibration.fit.FIT_TO (not imported: --help stays light)
SETTLE_TOL, SETTLE_ABS_RAD_S, CMD_TOL, GAP_S = 0.1, 2.0, 0.01, 1.0  # = SegmentOptions()'s defaults


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'calibrate',
        help='fit terrain parameters (and internal resistance) to recorded drives; write a terrain YAML',
        description='Find the steady segments of the bags (constant command, settled motion), solve FESS at '
        'the wheel speed set points of their commands (as the estimator predicts; --fit-at motion: at their '
        'measured speed and yaw rate), and fit the identifiable terrain parameters to the measured '
        'motor torque by robust least squares, with 95 %% confidence intervals and a hold-out check.',
    )
    parser.add_argument('bags', nargs='+', metavar='BAG', help='rosbag2 bags (MCAP or sqlite3)')
    parser.add_argument('--vehicle', required=True, help='vehicle name in config/vehicles/ or YAML file')
    parser.add_argument('--terrain', required=True, help='starting terrain T0: preset name or YAML file')
    _add_fit_options(parser)
    _add_output_options(parser)
    _add_segment_options(parser)
    parser.add_argument('--plot', help='PNG: measured vs predicted torque per segment, before and after')
    add_msg_option(parser)
    parser.add_argument(
        '--suggest',
        action='store_true',
        help='name the 2-4 (V, yaw rate) holds that would most shrink the widest interval '
        "(experiment design from the fit's Fisher information; a 7 x 7 grid over the command envelope)",
    )
    add_json_flag(parser)
    parser.set_defaults(func=run)


def _add_fit_options(parser: argparse.ArgumentParser) -> None:
    """What is fitted, to what, at which speeds, and the hold-out split."""
    parser.add_argument(
        '--fit',
        default='kphi,n,c,phi,K',
        help='comma-separated parameters to fit (kphi, kc, n, c, phi, K, '
        'internal = per-side internal resistance b, c (sides_b, sides_c: one b, c for both sides, what '
        'a whole-robot battery total sees); idle = idle power, copper = copper-loss '
        'coefficient k_cu [W/(N m)^2], both seen only in battery-side V x I), or auto: what the recordings '
        "identify (the ground's parameters; the internal resistance where a torque or current is recorded; "
        'idle and copper where battery-side power is), fitted to '
        'the torque and the measured motion together where both are recorded; default kphi,n,c,phi,K',
    )
    parser.add_argument(
        '--fit-to',
        choices=FIT_TO,
        help='what the residuals compare: motor torque, the measured body motion (V, yaw rate at the set '
        'points), or both (default: torque; with --fit auto what the recordings carry)',
    )
    parser.add_argument(
        '--fit-at',
        type=_fit_at,
        default=CMD,
        metavar='{' + ','.join(FIT_AT) + '}',
        help='solve the segments at the wheel speed set points of their commands (cmd, the default: '
        'what power_estimator and validate predict from; the old spelling setpoints still works) or '
        'at the measured motion (needs a pose topic)',
    )
    parser.add_argument(
        '--holdout', type=nonnegative_float, default=0.3, help='fraction of segments held out'
    )
    parser.add_argument(
        '--seed', type=range_arg(SEED), default=0, help=range_help(SEED, 'seed of the hold-out split')
    )


def _fit_at(text: str) -> str:
    """``--fit-at``'s value by its name (:mod:`skidsteer_power.drive.prediction_modes`); an earlier
    spelling works with a one-line note on stderr."""
    try:
        name, note = prediction_mode(text, '--fit-at', FIT_AT)
    except InputError as err:
        raise argparse.ArgumentTypeError(str(err)) from err
    if note:
        print(f'note: {note}', file=sys.stderr)
    return name


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    """The calibrated files written."""
    parser.add_argument('--out-terrain', required=True, help='calibrated terrain YAML to write')
    parser.add_argument(
        '--out-powertrain', help='calibrated powertrain YAML to write (with --fit ...,internal or auto)'
    )
    parser.add_argument(
        '--out-vehicle',
        help='vehicle YAML to write: the --vehicle file with its identified powertrain inline',
    )
    parser.add_argument('--name', help='name of the calibrated terrain (default: the output file stem)')


def _add_segment_options(parser: argparse.ArgumentParser) -> None:
    """The topics read and how the bags are cut into steady segments (calibration.segments)."""
    parser.add_argument(
        '--settle-s', type=nonnegative_float, default=1.5, help='start of each segment dropped [s]'
    )
    parser.add_argument(
        '--min-segment-s', type=nonnegative_float, default=1.0, help='shortest segment kept [s]'
    )
    parser.add_argument('--cmd-vel-topic', default='/cmd_vel')
    parser.add_argument('--joint-states-topic', default='/joint_states')
    parser.add_argument(
        '--settle-tol',
        type=nonnegative_float,
        default=SETTLE_TOL,
        help='allowed drift of the mean motor speed between the two halves of a window, relative '
        f'(default {SETTLE_TOL:g}; the larger of this and --settle-abs applies)',
    )
    parser.add_argument(
        '--settle-abs',
        type=nonnegative_float,
        default=SETTLE_ABS_RAD_S,
        help=f'the same drift always allowed, at the motor [rad/s] (default {SETTLE_ABS_RAD_S:g})',
    )
    parser.add_argument(
        '--cmd-tol',
        type=nonnegative_float,
        default=CMD_TOL,
        help=f'commands closer than this [m/s, rad/s] are one hold (default {CMD_TOL:g})',
    )
    parser.add_argument(
        '--gap-s',
        type=nonnegative_float,
        default=GAP_S,
        help=f'a pause in commands longer than this ends a hold [s] (default {GAP_S:g})',
    )
    parser.add_argument(
        '--motion-topic',
        '--odom-topic',
        dest='odom_topic',
        default='',
        help='topic with the true body motion: nav_msgs/Odometry (lidar/ICP, mocap, fused), a pose, or '
        'sensor_msgs/Imu (yaw rate only); default ground_truth/odom where the bag has it, else odom. '
        'Wheel odometry from the same encoders shows no slip: it is no evidence of the ground',
    )


def run(args: argparse.Namespace) -> int:
    from skidsteer_power.bag_io.reader import load_msg_definitions
    from skidsteer_power.calibration import calibrate_bags, io
    from skidsteer_power.calibration.segments import SegmentOptions

    started = time.perf_counter()
    for bag in args.bags:
        if not Path(bag).exists():
            raise InputError(f'{bag}: no such file or directory')
    out = Path(args.out_terrain)
    if out.suffix.lower() not in ('.yaml', '.yml'):
        raise InputError(f'--out-terrain must be a .yaml file, not {out}')
    if args.out_powertrain and 'internal' not in args.fit and args.fit.strip() != 'auto':
        raise InputError('--out-powertrain needs internal (or auto) in --fit')
    for option, path in (('--out-powertrain', args.out_powertrain), ('--out-vehicle', args.out_vehicle)):
        if path and Path(path).suffix.lower() not in ('.yaml', '.yml'):
            raise InputError(f'{option} must be a .yaml file, not {path}')
    options = SegmentOptions(
        settle_s=args.settle_s,
        min_s=args.min_segment_s,
        gap_s=args.gap_s,
        cmd_tol=args.cmd_tol,
        settle_tol=args.settle_tol,
        settle_abs_rad_s=args.settle_abs,
        cmd_vel_topic=args.cmd_vel_topic,
        joint_states_topic=args.joint_states_topic,
        odom_topic=args.odom_topic,
        extra_types=load_msg_definitions(args.msg),
    )
    result, segments = calibrate_bags(
        args.bags,
        args.vehicle,
        args.terrain,
        fit=args.fit,
        holdout=args.holdout,
        seed=args.seed,
        settle_s=args.settle_s,
        min_segment_s=args.min_segment_s,
        fit_at=args.fit_at,
        options=options,
        fit_to=args.fit_to,
    )
    result.seconds = time.perf_counter() - started
    name = args.name or out.stem
    io.write_terrain(out, result, args.bags, str(args.terrain), name)
    payload: JsonObject = result.as_json()
    payload['out_terrain'] = str(out)
    payload['out_powertrain'] = None
    if args.out_powertrain:
        payload['out_powertrain'] = str(io.write_powertrain(args.out_powertrain, result, args.bags))
    payload['out_vehicle'] = None
    if args.out_vehicle:
        payload['out_vehicle'] = str(
            io.write_vehicle(args.out_vehicle, args.vehicle, result, args.bags, str(out))
        )
    payload['suggest'] = None
    if args.suggest:
        from skidsteer_power.calibration.design import suggest_holds
        from skidsteer_power.vehicle import load_vehicle

        payload['suggest'] = suggest_holds(load_vehicle(args.vehicle), result)
    if args.plot:
        from skidsteer_power.calibration.plots import plot_segments

        plot_segments(args.plot, result, segments)
    if args.json:
        emit(payload, True)
    else:
        _print_human(payload)
    return 0


def _fmt(value: object) -> str:
    return f'{value:.4g}' if isinstance(value, float) else str(value)


def _print_torque_line(payload: JsonObject) -> None:
    """The hold-out torque and energy line, each part only where it was measured."""

    def finite(*values: object) -> bool:
        return all(isinstance(v, float) and math.isfinite(v) for v in values)

    torque = payload['torque_rmse_before_Nm'], payload['torque_rmse_after_Nm']
    energy = payload['holdout_energy_error_before'], payload['holdout_energy_error_after']
    parts = []
    if finite(*torque):
        parts.append(f'hold-out torque RMSE: {torque[0]:.4g} -> {torque[1]:.4g} N m')
    if finite(*energy):
        parts.append(
            f'{"energy" if parts else "hold-out energy"} error: {energy[0]:+.1%} -> {energy[1]:+.1%}'
        )
    print(
        '; '.join(parts) or 'hold-out torque and energy: none measured (no torque, current or power recorded)'
    )


def _print_human(payload: JsonObject) -> None:
    print(f'{"parameter":<17}{"value":>12}  {"95 % CI":<26}{"unit":<12}status')
    for name, p in payload['parameters'].items():
        ci = f'[{_fmt(p["ci95"][0])}, {_fmt(p["ci95"][1])}]' if p['ci95'] else '-'
        status = p['status']
        print(f'{name:<17}{_fmt(p["value"]):>12}  {ci:<26}{p["unit"]:<12}{status}')
    for warning in payload['correlations_warnings']:
        print(f'warning: {warning}')
    for name, why in payload['left_fixed'].items():
        if why and why != 'not in --fit':
            print(f'left fixed: {name}: {why}')
    if payload['at_bound']:
        print(f'warning: the optimizer stopped with {", ".join(payload["at_bound"])} at a fit bound')
    at = 'the set points of their commands' if payload['fit_at'] == CMD else 'the measured motion'
    print(f'segments: {payload["segments_fit"]} fit, {payload["segments_holdout"]} hold-out, solved at {at}')
    _print_torque_line(payload)
    motion = payload['motion']
    if payload['fit_to'] != 'torque' and motion:
        print(
            f'hold-out motion MAE: V {motion["speed_mae_before_m_s"]:.3g} -> '
            f'{motion["speed_mae_after_m_s"]:.3g} m/s, yaw rate {motion["yaw_mae_before_rad_s"]:.3g} -> '
            f'{motion["yaw_mae_after_rad_s"]:.3g} rad/s'
        )
    drive = payload.get('drive_controller')
    if drive is None and payload['fit_to'] != 'torque':
        print('drive controller: not identified (--fit auto identifies it from commands and wheel speeds)')
    for name, item in (drive or {}).get('values', {}).items():
        shown = f'{_fmt(item["value"])} {item["unit"]}' if item['reached'] else item['note']
        print(f'drive controller: {name}: {shown}')
    written = [p for p in (payload['out_terrain'], payload['out_powertrain'], payload['out_vehicle']) if p]
    print('wrote ' + ', '.join(written))
    suggest = payload.get('suggest')
    if suggest and suggest['holds']:
        name, unit = suggest['widest_parameter'], suggest['unit']
        print(f'widest interval: {name} {_ci(suggest["ci95_now"])} {unit}; drive next (steady holds):')
        for hold in suggest['holds']:
            after = _ci(hold[f'{name}_ci95_after'])
            speed, yaw = hold['speed_m_s'], hold['yaw_rate_rad_s']
            print(f'  V {speed:.3g} m/s, yaw rate {yaw:.3g} rad/s -> {name} {after}')
    print(f'{payload["seconds"]:.1f} s')


def _ci(interval: list[float]) -> str:
    return f'[{_fmt(interval[0])}, {_fmt(interval[1])}]' if interval else '-'
