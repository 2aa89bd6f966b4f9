"""``des probe`` (read one DES 70/10 amplifier) and ``des-sim`` (run virtual amplifiers on ptys)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit
from skidsteer_power.des.client import DesAmplifier
from skidsteer_power.des.protocol import BAUD_CODES
from skidsteer_power.des.transport import LinkTiming
from skidsteer_power.stop_signals import StopFlag, stop_on_signals
from skidsteer_power.terramechanics.ranges import Range

PROBE_TIMEOUT_S = Range('timeout', 0.0, 10.0, 's', positive=True)
"""Wait per acknowledge or reply of ``des probe`` [s]: the DES answers within ms; 1e9 hung the probe."""


def _baud(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value not in BAUD_CODES:
        raise argparse.ArgumentTypeError(f'{value} is not a DES baud rate {sorted(BAUD_CODES)}')
    return value


def register(subparsers: Subcommands) -> None:
    des = subparsers.add_parser('des', help='talk to a maxon DES 70/10 amplifier over RS232')
    des_sub = des.add_subparsers(dest='des_command', metavar='ACTION', parser_class=type(des))
    probe = des_sub.add_parser(
        'probe', help='read version, status, errors, speed and current of one amplifier'
    )
    probe.add_argument('--port', required=True, help='serial port path or pyserial URL')
    probe.add_argument('--baud', type=_baud, default=38400, help='link speed [bit/s] (default 38400)')
    probe.add_argument(
        '--timeout',
        type=range_arg(PROBE_TIMEOUT_S),
        default=0.1,
        help=range_help(PROBE_TIMEOUT_S, 'wait per acknowledge/reply (default 0.1)'),
    )
    add_json_flag(probe)
    probe.set_defaults(func=run_probe)
    des.set_defaults(func=_usage(des))

    sim = subparsers.add_parser('des-sim', help='run virtual DES 70/10 amplifiers on ptys until Ctrl-C')
    sim.add_argument('--count', type=int, choices=(1, 2), default=2, help='number of amplifiers (default 2)')
    sim.add_argument('--baud', type=_baud, default=38400, help='emulated link speed [bit/s] (default 38400)')
    sim.add_argument('--no-baud-emulation', action='store_true', help='answer at pty speed, not wire speed')
    add_json_flag(sim)
    sim.set_defaults(func=run_sim)


def _usage(parser: argparse.ArgumentParser) -> Callable[[argparse.Namespace], int]:
    def show(args: argparse.Namespace) -> int:
        parser.print_help(sys.stderr)
        return 2

    return show


def probe_amplifier(port: str, baud: int = 38400, timeout_s: float = 0.1) -> dict[str, object]:
    """Read one amplifier: the ``des probe`` payload (speeds in rpm, current in mA)."""
    timing = LinkTiming(ack_timeout_s=timeout_s, reply_timeout_s=timeout_s)
    with DesAmplifier.open(port, baud, timing=timing) as amp:
        version = amp.read_version()
        status = amp.read_status()
        errors = amp.read_errors()
        velocity = amp.read_velocity()
        current = amp.read_current()
    return {
        'port': port,
        'baud': baud,
        'software_version': version.software,
        'hardware_version': version.hardware,
        'status': int(status),
        'status_flags': status.describe(),
        'errors': int(errors),
        'error_flags': errors.describe(),
        'velocity_rpm': velocity.actual_rpm,
        'velocity_setpoint_rpm': velocity.setpoint_rpm,
        'current_ma': current,
    }


def run_probe(args: argparse.Namespace) -> int:
    emit(probe_amplifier(args.port, args.baud, args.timeout), args.json)
    return 0


def run_sim(args: argparse.Namespace) -> int:
    """Run until SIGINT or SIGTERM, also as a background job that inherited SIGINT as ignored."""
    with stop_on_signals(StopFlag()) as stop:
        return _serve_sims(args, stop)


def _serve_sims(args: argparse.Namespace, stop: StopFlag) -> int:
    from skidsteer_power.des.simulator import SimulatedDes

    names = ['des_left', 'des_right'][: args.count]
    sims = [SimulatedDes(args.baud, name=n, emulate_baud=not args.no_baud_emulation) for n in names]
    try:
        for sim in sims:
            sim.start()
        ports = {
            n.removeprefix('des_') if args.count == 2 else 'port': s.port
            for n, s in zip(names, sims, strict=True)
        }
        if args.json:
            emit({**ports, 'baud': args.baud}, True)
        else:
            for sim in sims:
                print(sim.port)
        sys.stdout.flush()
        while not stop.wait(1.0):
            pass
    finally:
        for sim in sims:
            sim.stop()
    return 0
