"""``record``, ``replay`` and ``validate``: bags in and out of the ROS graph, and offline validation."""

from __future__ import annotations

import argparse
import glob
import logging
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import (
    Subcommands,
    _number,
    add_json_flag,
    add_msg_option,
    emit,
    print_json,
    ros_topic,
)
from skidsteer_power.drive.prediction_modes import CMD, VALIDATE_KINEMATICS
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import (
    BAG_TIME_S,
    CLOCK_HZ,
    LOCAL_WORKERS,
    RECORD_DURATION_S,
    REPLAY_RATE,
    SUBSCRIBER_WAIT_S,
)

if TYPE_CHECKING:
    from skidsteer_power.bag_io.reader import BagReader
    from skidsteer_power.bag_io.record import Recorder
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.validation.validate import ValidateOptions


def _add_bag_reading(parser: argparse.ArgumentParser) -> None:
    add_msg_option(parser)
    parser.add_argument(
        '--salvage',
        action='store_true',
        help='read every intact message of a damaged bag instead of failing (exit 0; the JSON says '
        'messages_expected, messages_read, complete, messages_unverified); an MCAP file of at most 4 GiB',
    )
    parser.add_argument(
        '--include-unverified',
        action='store_true',
        help='with --salvage: also use the messages of chunks whose CRC failed or could not be checked '
        '(read record by record; their payload may be altered; left out by default; never complete)',
    )


def _open(args: argparse.Namespace) -> BagReader:
    """The bag after one full counting pass: without ``--salvage`` a damaged bag is one line and
    exit 2; with it the pass measures what is there (``messages_read``), so nothing unread is
    called complete."""
    from skidsteer_power.bag_io.reader import BagDamageError, load_msg_definitions, open_bag

    try:
        if args.include_unverified and not args.salvage:
            raise InputError('--include-unverified needs --salvage')
        bag = open_bag(
            args.bag,
            extra_types=load_msg_definitions(args.msg),
            salvage=args.salvage,
            include_unverified=args.include_unverified,
        )
        try:
            bag.count_all()  # reads every message once; raises (not salvage) saying what is missing
        except BaseException:
            bag.close()
            raise
    except BagDamageError as err:
        raise BagDamageError(f'{err}; --salvage recovers every intact message') from err
    return bag


def _integrity(bag: BagReader, undecodable: dict[str, int]) -> JsonObject:
    """The bag's integrity keys, with ``undecodable`` (skipped messages per topic) merged in."""
    out = bag.integrity()
    for topic, count in undecodable.items():
        out['undecodable'][topic] = out['undecodable'].get(topic, 0) + count
    out['complete'] = out['complete'] and not out['undecodable']
    return out


def _log_to_stderr() -> None:
    logging.basicConfig(level=logging.WARNING, format='%(levelname)s: %(message)s', stream=sys.stderr)


def _cmd_record(args: argparse.Namespace) -> int:
    from skidsteer_power.bag_io.record import record
    from skidsteer_power.stop_signals import StopFlag, stop_on_signals

    _log_to_stderr()
    stop = StopFlag()
    if args.all and args.topics:
        raise InputError('record: -a/--all records every topic: name topics or give -a, not both')
    if args.output is None:  # rosbag2's default name (local time), a rosbag2 directory
        args.output = time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')

    def ready(recorder: Recorder) -> None:
        what = ', '.join(recorder.recorded) or 'none yet'
        print(f'recording to {args.output} (topics: {what}); Ctrl-C to stop', file=sys.stderr, flush=True)

    with stop_on_signals(stop):
        result = record(args.output, args.topics, stop=stop, duration_s=args.duration, on_ready=ready)
    emit(
        {
            'bag': str(result.path),
            'message_count': sum(result.counts.values()),
            'counts': result.counts,
            'skipped': result.skipped,
            'stopped_by': result.stopped_by,
        },
        args.json,
    )
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from skidsteer_power.bag_io.replay import ReplayOptions, replay
    from skidsteer_power.stop_signals import StopFlag, stop_on_signals

    _log_to_stderr()
    options = ReplayOptions(
        rate=args.rate,
        loop=args.loop,
        topics=args.topics,
        start_s=args.start,
        duration_s=args.duration,
        clock=args.clock,
        clock_hz=args.clock_hz,
        wait_for_subscribers_s=args.wait_for_subscribers,
    )
    stop = StopFlag()
    with _open(args) as bag, stop_on_signals(stop):
        result = replay(bag, options, stop=stop)
    emit(
        {
            'message_count': result.message_count,
            'counts': result.counts,
            'skipped': result.skipped,
            'passes': result.passes,
            'wall_time_s': result.wall_s,
            'max_late_s': result.max_late_s,
            'stopped_by': stop.signal_name or 'end',
            **_integrity(bag, result.undecodable),
        },
        args.json,
    )
    return 0


def _is_fleet(args: argparse.Namespace) -> bool:
    """Fleet mode: several bags, a folder of bags, a glob, --jobs, --scheduler or --manifest."""
    from skidsteer_power.apps.fleet import is_bag

    specs = args.bag
    return (
        len(specs) > 1
        or args.jobs is not None
        or args.scheduler is not None
        or args.manifest is not None
        or glob.has_magic(specs[0])
        or (Path(specs[0]).is_dir() and not is_bag(Path(specs[0])))
    )


def _check_manifest(path: str | None, manifest: dict[str, tuple[str, str]] | None) -> None:
    """Every vehicle and terrain a manifest names exists (before any bag is read): one line naming
    the manifest, not a failed row per bag (issue 34)."""
    from skidsteer_power.errors import SkidsteerError
    from skidsteer_power.estimator import factory
    from skidsteer_power.vehicle import load_vehicle

    for bag, (vehicle, terrain) in sorted((manifest or {}).items()):
        try:
            load_vehicle(vehicle)
            factory.check_terrain(terrain)
        except SkidsteerError as err:
            raise InputError(f'manifest {path}, bag {bag}: {err}') from err


def _run_fleet(args: argparse.Namespace, shared: ValidateOptions) -> int:
    """``validate`` in fleet mode (:mod:`skidsteer_power.apps.fleet`): ``shared`` holds the single-bag
    ValidateOptions."""
    from skidsteer_power.apps.fleet import expand, fmt, plan_jobs, read_manifest, validate_fleet
    from skidsteer_power.distributed.engine import Engine

    if args.msg:
        raise InputError('--msg is not supported with several bags yet')
    manifest = read_manifest(args.manifest) if args.manifest else None
    _check_manifest(args.manifest, manifest)
    jobs = plan_jobs(expand(args.bag), shared, manifest, salvage=args.salvage)
    with Engine(args.scheduler, None if args.scheduler else args.jobs) as engine:
        summary = validate_fleet(engine, jobs, args.report, plots=not args.no_plots)
    if args.json:
        print_json(summary.as_json())
    else:
        print(
            f'{summary.bags} bags: {summary.ok} validated ({summary.incomplete} of them '
            f'incomplete), {summary.failed} failed ({summary.engine})'
        )
        for g in summary.groups:
            print(
                f'  {g.vehicle} on {g.terrain}: {g.bags} bags, {g.distance_m:.1f} m, '
                f'{fmt(g.energy_per_m_J_m)} J/m, '
                f'mean energy error {fmt(g.energy_error_pct_mean, "+.1f")} %'
            )
        for r in summary.rows:
            if not r.ok:
                print(f'  FAILED {r.bag}: {r.error}')
        print(f'fleet summary: {summary.files["markdown"]}')
    return 0 if summary.failed == 0 else 1


def _cmd_validate(args: argparse.Namespace) -> int:
    from skidsteer_power.validation.report import one_screen
    from skidsteer_power.validation.validate import ValidateOptions, console_warnings, validate

    options = ValidateOptions(
        vehicle=args.vehicle,
        terrain=args.terrain,
        report_dir=args.report,
        cmd_vel_topic=args.cmd_vel,
        joint_states_topic=args.joint_states,
        odom_topic=args.odom,
        map_cache_dir=args.map_cache,
        plots=not args.no_plots,
        cmd_hold_s=args.cmd_hold,
        left_joints=args.left_joints,
        right_joints=args.right_joints,
        effort_is=args.effort,
        joints_at=args.joints_at,
        kinematics=args.kinematics,
    )
    if _is_fleet(args):  # several bags: skidsteer_power.apps.fleet (Dask), each with these options
        return _run_fleet(args, options)
    args.bag = args.bag[0]
    _log_to_stderr()
    with _open(args) as bag:
        summary = validate(bag, options)
        integrity = bag.integrity()
    note = summary.motor_data_note or ''
    if (args.left_joints or args.right_joints) and 'never holds all of' in note:
        raise InputError(f'{args.bag}: --left-joints/--right-joints: {note}')
    for line in console_warnings(summary):  # dropped readings, missing measured power (issue 35)
        print(f'warning: {line}', file=sys.stderr)
    if args.json:
        print_json({**summary.as_json(), **integrity})
    else:
        print(one_screen(summary))
        motion = summary.motion_prediction
        if motion and not summary.has_motor_data:  # nothing to compare with: say what it predicts
            energy = motion.metrics.energy_predicted_J
            print(f'predicted from the measured motion ({motion.kinematics}): energy {energy:.4g} J')
        elif motion:  # ch. 7.3 validated FESS with the measured motion: show that prediction too
            m = motion.metrics
            print(
                f'predicted from the measured motion ({motion.kinematics}): energy error '
                f'{m.energy_error_pct:+.1f} %, torque MAE left/right {m.torque_left.mae:.3f} / '
                f'{m.torque_right.mae:.3f} N m'
            )
    return 0


def _hold_float(text: str) -> float:
    """argparse type: a command hold > 0 s, or inf."""
    value = _number(text, allow_inf=True)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be > 0 (or inf): {text!r}')
    return value


def register(subparsers: Subcommands) -> None:
    _register_record(subparsers)
    _register_replay(subparsers)
    _register_validate(subparsers)


def _register_record(subparsers: Subcommands) -> None:
    rec = subparsers.add_parser(
        'record',
        help='record topics into a rosbag2 MCAP bag (Ctrl-C/SIGTERM stop cleanly)',
        description='Record topics (all but /rosout and /parameter_events if none named) into a '
        'rosbag2-compatible MCAP with message definitions. OUT.mcap gives one file; another name a '
        'rosbag2 directory. SIGINT/SIGTERM stop cleanly without losing a received message.',
    )
    rec.add_argument(
        '-o',
        '--output',
        default=None,
        metavar='OUT.mcap',
        help='bag to write (new); default: a rosbag2 directory rosbag2_YYYY_MM_DD-HH_MM_SS (as rosbag2)',
    )
    rec.add_argument('-a', '--all', action='store_true', help='record every topic (as ros2 bag record -a)')
    rec.add_argument(
        'topics', nargs='*', type=ros_topic, metavar='TOPIC', help='topics to record (default: all)'
    )
    rec.add_argument(
        '--duration',
        type=range_arg(RECORD_DURATION_S),
        metavar='S',
        help=range_help(RECORD_DURATION_S, 'stop after S s'),
    )
    add_json_flag(rec)
    rec.set_defaults(func=_cmd_record)


def _register_replay(subparsers: Subcommands) -> None:
    rep = subparsers.add_parser(
        'replay',
        help='publish a bag (MCAP or sqlite3) with its original timing',
        description='Publish the stored CDR bytes of a bag with the original timing. Topics whose '
        'message type is not installed for Python are skipped with a warning.',
    )
    rep.add_argument('bag', metavar='BAG', help='bag file (.mcap/.db3) or rosbag2 directory')
    rep.add_argument(
        '--rate',
        type=range_arg(REPLAY_RATE),
        default=1.0,
        metavar='R',
        help=range_help(REPLAY_RATE, 'speed factor (default 1)'),
    )
    rep.add_argument('--loop', action='store_true', help='start over at the end until stopped')
    rep.add_argument(
        '--topics', nargs='+', type=ros_topic, default=None, metavar='TOPIC', help='only these topics'
    )
    rep.add_argument(
        '--start',
        type=range_arg(BAG_TIME_S),
        default=0.0,
        metavar='S',
        help=range_help(BAG_TIME_S, 'skip the first S s'),
    )
    rep.add_argument(
        '--duration',
        type=range_arg(RECORD_DURATION_S),
        metavar='D',
        help=range_help(RECORD_DURATION_S, 'only D s of bag time'),
    )
    rep.add_argument('--clock', action='store_true', help='publish the bag time on /clock')
    rep.add_argument(
        '--clock-hz',
        type=range_arg(CLOCK_HZ),
        default=40.0,
        metavar='HZ',
        help=range_help(CLOCK_HZ, '/clock rate (40)'),
    )
    rep.add_argument(
        '--wait-for-subscribers',
        type=range_arg(SUBSCRIBER_WAIT_S),
        default=0.0,
        metavar='S',
        help=range_help(
            SUBSCRIBER_WAIT_S, 'wait up to S s for every topic to have a subscriber before starting'
        ),
    )
    _add_bag_reading(rep)
    add_json_flag(rep)
    rep.set_defaults(func=_cmd_replay)


def _register_validate(subparsers: Subcommands) -> None:
    val = subparsers.add_parser(
        'validate',
        help='run the estimator offline over a bag; compare with measured torque/power; report',
        description="Offline (no ROS graph): predict per-side torque and power from the bag's cmd_vel "
        'and compare with joint_states; trace analysis (eqs. 7.8-7.10) from odometry; CSV, PNG plots, '
        'a Markdown report and a JSON summary in DIR.',
    )
    val.add_argument(
        'bag',
        nargs='+',
        metavar='BAG',
        help='bag file (.mcap/.db3) or rosbag2 directory; several, a folder of bags or a glob: fleet '
        'validation (one report per bag in DIR/<bag>/, fleet.csv, summary.md, plots; apps/fleet.py)',
    )
    val.add_argument('--vehicle', required=True, metavar='FILE', help='vehicle YAML or config name')
    val.add_argument('--terrain', required=True, metavar='T', help='terrain preset or YAML file')
    val.add_argument('--report', required=True, metavar='DIR', help='folder for the report (created)')
    val.add_argument('--cmd-vel', default='/cmd_vel', metavar='TOPIC', help='command topic (/cmd_vel)')
    val.add_argument('--joint-states', default='/joint_states', metavar='TOPIC', help='(/joint_states)')
    val.add_argument('--odom', default='/odom', metavar='TOPIC', help='odometry topic for the trace (/odom)')
    val.add_argument('--map-cache', default=None, metavar='DIR', help='power map cache (estimator default)')
    val.add_argument('--no-plots', action='store_true', help='skip the PNG plots')
    _add_validate_fleet_options(val)
    _add_validate_kinematics_options(val)
    _add_validate_joint_options(val)
    _add_bag_reading(val)
    add_json_flag(val)
    val.set_defaults(func=_cmd_validate)


def _add_validate_fleet_options(parser: argparse.ArgumentParser) -> None:
    """Options of a validation over several bags (apps/fleet.py)."""
    parser.add_argument(
        '--jobs',
        type=range_arg(LOCAL_WORKERS),
        default=None,
        metavar='N',
        help=range_help(
            LOCAL_WORKERS, 'fleet: local worker processes (default: the cores; more: --scheduler)'
        ),
    )
    parser.add_argument(
        '--scheduler', default=None, metavar='ADDR', help='fleet: existing Dask cluster tcp://HOST:8786'
    )
    parser.add_argument(
        '--manifest',
        default=None,
        metavar='CSV',
        help='fleet: per-bag vehicle, terrain (bag,vehicle,terrain)',
    )


def _add_validate_kinematics_options(parser: argparse.ArgumentParser) -> None:
    """What the prediction is made from, and how long each command holds."""
    parser.add_argument(
        '--kinematics',
        choices=VALIDATE_KINEMATICS,
        default=CMD,
        help='predict from the command at its wheel speed set points (default), from the command taken '
        'as the motion (twist), the --odom twist, or /ground_truth/odom; with cmd or twist, a bag with '
        'odometry also gets the prediction from the measured motion',
    )
    parser.add_argument(
        '--cmd-hold',
        type=_hold_float,
        default=None,
        metavar='S',
        help='hold each command at most S s ("inf": until the next one); default: inferred from the '
        'bag (stream: its longest ordinary pause; on-change: until the next command or odometry rest)',
    )


def _add_validate_joint_options(parser: argparse.ArgumentParser) -> None:
    """Which joints are each side's and what their values are (default: the vehicle file's drivetrain)."""
    parser.add_argument(
        '--left-joints', default='', metavar='A,B', help='left joints (default: vehicle file)'
    )
    parser.add_argument(
        '--right-joints', default='', metavar='C,D', help='right joints (default: vehicle file)'
    )
    parser.add_argument(
        '--effort',
        default='',
        choices=('torque', 'current'),
        help='joint_states effort is torque [N m] or current [A] (default: vehicle file)',
    )
    parser.add_argument(
        '--joints-at',
        default='',
        choices=('motor', 'wheel'),
        help='joint values are at the motor shaft or the wheel (default: vehicle file)',
    )
