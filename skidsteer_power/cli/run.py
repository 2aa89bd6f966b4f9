"""``skidsteer-power run``: start the on-board suite (power_estimator + des_driver) without ROS launch.

    skidsteer-power run [--simulate] [--vehicle V] [--terrain T] [--duration S] [--speed V --yaw-rate R]

With ``--simulate`` the amplifiers are simulated on pseudo-terminals and loaded by the digital twin
(``skidsteer_power.twin``) on ``--terrain-truth`` (alias ``--sim-terrain``, default ``--terrain``)
and ``--patches``. ``--speed``/``--yaw-rate`` publish a
constant cmd_vel at 10 Hz (a quick drive without a teleop). A status line is printed every
``--status-every`` s; at the end a summary (``--json``: duration_s, joint_states_received,
predicted_received, soc_start, soc_end, remaining_wh_start, remaining_wh_end, energy_used_J,
energy_source, rejected_inputs).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from typing import TYPE_CHECKING, TypedDict

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli import _ros_names
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, positive_float
from skidsteer_power.errors import InputError
from skidsteer_power.stop_signals import StopFlag, stop_on_signals
from skidsteer_power.terramechanics.ranges import COMMAND_YAW_RATE_RAD_S, RECORD_DURATION_S, SPEED_M_S

if TYPE_CHECKING:
    from rclpy.node import Node

    from skidsteer_power.nodes.param_spec import ParamValue
    from skidsteer_power.nodes.suite import Suite

HARDWARE_PORTS = ('/dev/ttyUSB0', '/dev/ttyUSB1')
"""Default serial ports of the left and right amplifiers."""
EXIT_FAILURE = 1
"""Exit code when a thread or process of the suite died (2 is bad input, 0 a clean stop)."""


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'run', help='start power_estimator and des_driver (optionally against simulated amplifiers)'
    )
    parser.add_argument('--simulate', action='store_true', help='simulated DES 70/10 amplifiers on ptys')
    parser.add_argument('--vehicle', default='test_robot_track', help='vehicle name or YAML file')
    parser.add_argument('--terrain', default='dry_sand', help="the estimator's terrain (preset or YAML)")
    parser.add_argument(
        '--terrain-truth',
        '--sim-terrain',
        dest='sim_terrain',
        default='',
        help="--simulate: the digital twin's (true) terrain (default --terrain)",
    )
    parser.add_argument('--patches', default='', help='--simulate: YAML polygons of other truth terrains')
    parser.add_argument(
        '--duration',
        type=range_arg(RECORD_DURATION_S),
        help=range_help(RECORD_DURATION_S, 'stop after this many seconds (default: until a signal)'),
    )
    parser.add_argument(
        '--speed',
        type=range_arg(SPEED_M_S),
        help=range_help(SPEED_M_S, 'publish cmd_vel with this forward speed'),
    )
    parser.add_argument(
        '--yaw-rate',
        type=range_arg(COMMAND_YAW_RATE_RAD_S),
        default=0.0,
        help=range_help(COMMAND_YAW_RATE_RAD_S, '... and this yaw rate'),
    )
    parser.add_argument(
        '--left-port',
        help=f'left amplifier port (hardware; default {HARDWARE_PORTS[0]}; not with --simulate)',
    )
    parser.add_argument(
        '--right-port',
        help=f'right amplifier port (hardware; default {HARDWARE_PORTS[1]}; not with --simulate)',
    )
    parser.add_argument('--map-cache', default='', help='map cache directory')
    parser.add_argument(
        '--state-file',
        default='',
        help='energy state file (default: per namespace and vehicle; with --simulate none: starts fresh)',
    )
    parser.add_argument(
        '--resume-energy',
        action='store_true',
        help='--simulate: restore and save the default energy state file (default: start fresh)',
    )
    parser.add_argument(
        '--namespace', type=_ros_names.namespace, default='', help='ROS namespace of the suite (e.g. robot1)'
    )
    parser.add_argument(
        '--cmd-vel-type',
        choices=('auto', 'twist', 'twist_stamped'),
        default='auto',
        help="cmd_vel's type: auto (follow the publishers), twist or twist_stamped (ROS 2 Jazzy's default)",
    )
    parser.add_argument('--status-every', type=positive_float, default=1.0, help='status line period [s]')
    parser.add_argument('--quiet', action='store_true', help='no status lines')
    add_json_flag(parser)
    parser.set_defaults(func=run)


class _Snapshot(TypedDict):
    """The estimator's battery and energy at one moment (SI units, energy in W h and J)."""

    soc: float
    remaining_wh: float
    energy_source: str
    energy_used_J: float
    battery_W: float
    rejected_inputs: int


def _snapshot(suite: Suite) -> _Snapshot:
    estimator = suite.estimator
    now = estimator.now_s()
    with estimator._lock:
        core = estimator.core
        core.tick(now)
        return {
            'soc': core.battery.soc,
            'remaining_wh': core.battery.remaining_wh,
            'energy_source': core.energy.source(now),
            'energy_used_J': sum(core.energy.energy_J.values()),
            'battery_W': core.energy.power_W(now),
            'rejected_inputs': sum(core.rejects.counts.values()),
        }


class _Counters:
    def __init__(self) -> None:
        self.joint_states = 0
        self.predicted = 0


def run(args: argparse.Namespace) -> int:
    import rclpy
    import rclpy.utilities
    from rclpy.context import Context
    from sensor_msgs.msg import JointState

    from skidsteer_power.nodes.suite import Suite, SuiteOptions

    if args.simulate and (args.left_port or args.right_port):
        raise InputError('--left-port/--right-port name hardware ports; --simulate makes its own amplifiers')
    args.left_port = args.left_port or HARDWARE_PORTS[0]
    args.right_port = args.right_port or HARDWARE_PORTS[1]
    options = SuiteOptions(
        vehicle=args.vehicle, terrain=args.terrain, sim_terrain=args.sim_terrain, simulate=args.simulate,
        patches=args.patches, map_cache_dir=args.map_cache, state_file=args.state_file,
        left_port=args.left_port, right_port=args.right_port, namespace=args.namespace,
        estimator_params=_estimator_params(args), driver_params={'cmd_vel_type': args.cmd_vel_type},
    )  # fmt: skip
    signals = contextlib.ExitStack()  # from here on, also during start-up: SIGINT/SIGTERM end cleanly
    stop = signals.enter_context(stop_on_signals(StopFlag()))
    context = Context()
    rclpy.init(context=context)
    suite = None
    counters = _Counters()
    try:
        suite = Suite(options, context=context, stop=stop)
        helper = rclpy.create_node('run_cli', context=context, namespace=args.namespace)
        suite.add_node(helper)
        helper.create_subscription(JointState, 'joint_states', lambda m: _count(counters, 'joint_states'), 50)
        helper.create_subscription(JointState, 'power/predicted', lambda m: _count(counters, 'predicted'), 50)
        if args.speed is not None:
            _drive(helper, args)
        start = _snapshot(suite)
        started = time.monotonic()
        suite.start()
        _wait(suite, args, started, counters, stop)
        end = _snapshot(suite)
    except KeyboardInterrupt:
        return 130
    finally:
        if suite is not None:
            suite.shutdown()
        rclpy.utilities.try_shutdown(context=context)
        signals.close()
    if suite.failure:  # a thread of the suite died: the motors are stopped, the run is not a result
        print(f'skidsteer-power run: error: {suite.failure}; the suite stopped', file=sys.stderr)
        return EXIT_FAILURE
    emit(
        {
            'duration_s': time.monotonic() - started,
            'joint_states_received': counters.joint_states,
            'predicted_received': counters.predicted,
            'soc_start': start['soc'],
            'soc_end': end['soc'],
            'remaining_wh_start': start['remaining_wh'],
            'remaining_wh_end': end['remaining_wh'],
            'energy_used_J': end['energy_used_J'] - start['energy_used_J'],
            'energy_source': end['energy_source'],
            'rejected_inputs': end['rejected_inputs'],
        },
        args.json,
    )
    return 0


def _estimator_params(args: argparse.Namespace) -> dict[str, ParamValue]:
    params: dict[str, ParamValue] = {'cmd_vel_type': args.cmd_vel_type}
    if args.simulate and not args.state_file and not args.resume_energy:
        params['persist'] = False  # a simulation starts with a full battery and leaves no state behind
    return params


def _drive(helper: Node, args: argparse.Namespace) -> None:
    """Publish --speed / --yaw-rate at 10 Hz, as the type the suite takes (TwistStamped stamped now
    with --cmd-vel-type twist_stamped, else Twist)."""
    from geometry_msgs.msg import Twist, TwistStamped

    stamped = args.cmd_vel_type == 'twist_stamped'
    publisher = helper.create_publisher(TwistStamped if stamped else Twist, 'cmd_vel', 10)

    def publish() -> None:
        msg = TwistStamped() if stamped else Twist()
        twist = msg.twist if stamped else msg
        twist.linear.x, twist.angular.z = args.speed, args.yaw_rate
        if stamped:
            msg.header.stamp = helper.get_clock().now().to_msg()
        publisher.publish(msg)

    helper.create_timer(0.1, publish)


def _count(counters: _Counters, name: str) -> None:
    setattr(counters, name, getattr(counters, name) + 1)


def _wait(
    suite: Suite, args: argparse.Namespace, started: float, counters: _Counters, stop: StopFlag
) -> None:
    """Print status lines until ``--duration`` has passed, a signal arrived or a thread died."""
    duration = args.duration if args.duration is not None else math.inf
    next_status = started + args.status_every
    while time.monotonic() - started < duration and not stop.is_set():
        time.sleep(min(0.05, max(0.0, started + duration - time.monotonic())))
        if not args.quiet and not args.json and time.monotonic() >= next_status:
            next_status += args.status_every
            s = _snapshot(suite)
            print(
                f'{time.monotonic() - started:7.1f} s  battery {100 * s["soc"]:6.2f} %  '
                f'{s["remaining_wh"]:7.2f} Wh  drive {s["battery_W"]:7.1f} W ({s["energy_source"]})  '
                f'joint_states {counters.joint_states}',
                flush=True,
            )
