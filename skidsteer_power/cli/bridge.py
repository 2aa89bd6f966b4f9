"""``skidsteer-power bridge``: a Foxglove WebSocket server forwarding the suite's topics.

    skidsteer-power bridge [--host 127.0.0.1] [--port 8765] [--topics T ...] [--allow-origin URL ...]
                           [--allow-publish cmd_vel] [--duration S] [--json]

For robots without ``foxglove_bridge``: the Foxglove app connects to ``ws://HOST:8765`` and gets
every topic (or only ``--topics``) as ros2msg schemas with CDR payloads
(:mod:`skidsteer_power.nodes.foxglove_bridge`). It listens on 127.0.0.1 (reach it through an SSH
tunnel, docs/ROS.md); ``--host 0.0.0.0`` serves every network the robot is on, with a warning: there is
no authentication. Web pages are refused unless served from localhost or named by
``--allow-origin``. ``--allow-publish cmd_vel`` lets clients publish there (Foxglove's Teleop
panel); des_driver's checks apply to it as to any cmd_vel. Open ``config/foxglove/operator_layout.json`` in
the app for the operator's view. Prints ``serving ws://HOST:PORT`` when ready; runs until SIGINT /
SIGTERM (or ``--duration``), then prints what it forwarded (``--json``: url, topics: {topic:
messages}, skipped: {topic: reason}).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, ros_topic, web_origin
from skidsteer_power.errors import InputError
from skidsteer_power.stop_signals import StopFlag, stop_on_signals
from skidsteer_power.terramechanics.ranges import RECORD_DURATION_S


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a port number: {text!r}') from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f'port must be 0..65535 (0 = any free port), got {value}')
    return value


def _loopback(host: str) -> bool:
    import ipaddress

    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def register(subparsers: Subcommands) -> None:
    from skidsteer_power.nodes.foxglove_bridge import DEFAULT_PORT

    parser = subparsers.add_parser(
        'bridge', help='Foxglove WebSocket server forwarding ROS topics (ros2msg schemas, CDR)'
    )
    parser.add_argument(
        '--host',
        default='127.0.0.1',
        help='address to listen on (default 127.0.0.1; 0.0.0.0: every network, no authentication)',
    )
    parser.add_argument('--port', type=_port, default=DEFAULT_PORT, help='TCP port (0 = any free one)')
    parser.add_argument(
        '--topics', nargs='+', type=ros_topic, default=[], help='only these topics (default: all)'
    )
    parser.add_argument(
        '--allow-origin',
        nargs='+',
        type=web_origin,
        default=[],
        metavar='URL',
        help='web origins accepted besides localhost, e.g. https://app.foxglove.dev (default: none)',
    )
    parser.add_argument(
        '--allow-publish',
        nargs='+',
        type=ros_topic,
        default=[],
        metavar='TOPIC',
        help='topics clients may publish to, e.g. cmd_vel for the Teleop panel (default: none)',
    )
    parser.add_argument(
        '--duration',
        type=range_arg(RECORD_DURATION_S),
        help=range_help(RECORD_DURATION_S, 'stop after this many seconds (default: until a signal)'),
    )
    add_json_flag(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import rclpy
    import rclpy.utilities
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    try:
        import foxglove  # noqa: F401
    except ImportError as err:
        raise InputError(f'the Foxglove bridge needs the foxglove-sdk package ({err})') from err
    if not _loopback(args.host):
        print(
            f'warning: serving Foxglove on {args.host}: no authentication, anyone who can reach port '
            f'{args.port} reads every bridged topic'
            + (f' and publishes to {", ".join(args.allow_publish)}' if args.allow_publish else '')
            + '; prefer --host 127.0.0.1 and an SSH tunnel (docs/ROS.md, "Watching the robot in Foxglove")',
            file=sys.stderr,
            flush=True,
        )
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('foxglove_bridge', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    bridge = None
    try:
        bridge = FoxgloveBridge(
            node,
            host=args.host,
            port=args.port,
            topics=args.topics,
            allowed_origins=args.allow_origin,
            allow_publish=args.allow_publish,
        )
        url = f'ws://{args.host}:{bridge.port}'
        print(f'serving {url}', file=sys.stderr if args.json else sys.stdout, flush=True)
        duration = args.duration if args.duration is not None else math.inf
        started = time.monotonic()
        with stop_on_signals(StopFlag()) as stop:
            while not stop.is_set() and time.monotonic() - started < duration:
                executor.spin_once(timeout_sec=0.1)
        topics = {t: f.messages for t, f in sorted(bridge.forwarded.items())}
        skipped = dict(bridge.skipped)
        published = dict(bridge.client_publish.published) if bridge.client_publish else {}
        refused = {'origins': bridge.front.refused}
    finally:
        if bridge is not None:
            bridge.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.utilities.try_shutdown(context=context)
    summary = {'url': url, 'topics': topics, 'skipped': skipped, 'published': published, 'refused': refused}
    emit(summary, args.json)
    return 0
