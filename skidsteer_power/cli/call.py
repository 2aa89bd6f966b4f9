"""``skidsteer-power call SERVICE``: the suite's std_srvs/Trigger services without a ROS install
(``ros2 service call`` needs ros2cli, which is not on PyPI; issue 37 item 7).

    skidsteer-power call reset_energy [--namespace NS] [--timeout S] [--json]

SERVICE is ``reset_energy`` or ``reset_odometry`` (power_estimator) or ``clear_faults``
(des_driver), or a full service name (``/robot1/power_estimator/reset_energy``). The answer's
``success`` and ``message`` are printed (``--json``: ``service``, ``success``, ``message``); exit 0 on
success, 1 when the service answered ``success: false``, 2 when no such service answered within
``--timeout``.
"""

from __future__ import annotations

import argparse
import sys

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli import _ros_names
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import Range

SERVICES = {
    'reset_energy': 'power_estimator/reset_energy',
    'reset_odometry': 'power_estimator/reset_odometry',
    'clear_faults': 'des_driver/clear_faults',
}
"""Short names -> the service under the namespace (every one std_srvs/srv/Trigger)."""
CALL_TIMEOUT_S = Range('timeout', 0.0, 60.0, 's', positive=True)


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'call',
        help='call a suite service (std_srvs/Trigger): reset_energy, reset_odometry, clear_faults',
        description="Call one of the suite's std_srvs/Trigger services, as `ros2 service call NAME "
        'std_srvs/srv/Trigger` does on a ROS install.',
    )
    parser.add_argument(
        'service', metavar='SERVICE', help=f'{", ".join(SERVICES)}, or a full service name (/ns/node/srv)'
    )
    parser.add_argument(
        '--namespace',
        type=_ros_names.namespace,
        default='',
        help='namespace of the suite (as run --namespace)',
    )
    parser.add_argument(
        '--timeout',
        type=range_arg(CALL_TIMEOUT_S),
        default=5.0,
        help=range_help(CALL_TIMEOUT_S, 'wait for the answer'),
    )
    add_json_flag(parser)
    parser.set_defaults(func=_cmd_call)


def service_name(service: str, namespace: str) -> str:
    """The full service name of ``service`` under ``namespace`` (InputError for an unknown one)."""
    if service.startswith('/'):
        try:
            return _ros_names.full_service_name(service)
        except ValueError as err:
            raise InputError(f'invalid service name {err}') from None
    if service not in SERVICES:
        raise InputError(f'unknown service {service!r}: {", ".join(SERVICES)} or a full name (/ns/node/srv)')
    ns = namespace.strip('/')
    return f'/{ns}/{SERVICES[service]}' if ns else f'/{SERVICES[service]}'


def _cmd_call(args: argparse.Namespace) -> int:
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    name = service_name(args.service, args.namespace)
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('skidsteer_power_call', context=context)
        client = node.create_client(Trigger, name)
        deadline = time.monotonic() + args.timeout
        if not client.wait_for_service(timeout_sec=args.timeout):
            raise InputError(f'no service {name} answered within {args.timeout:g} s (is the suite running?)')
        future = client.call_async(Trigger.Request())
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        while not future.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if not future.done():
            raise InputError(f'{name} did not answer within {args.timeout:g} s')
        response = future.result()
    finally:
        rclpy.try_shutdown(context=context)
    result = {'service': name, 'success': bool(response.success), 'message': str(response.message)}
    emit(result, args.json)
    if not result['success']:
        print(f'skidsteer-power call: {name} answered success: false: {result["message"]}', file=sys.stderr)
        return 1
    return 0
