"""DES 70/10 link: achieved poll rate of two amplifiers against the byte-time limit of the line.

The simulators run in their own process (``skidsteer-power des-sim``), as real amplifiers are other
hardware, and emulate the wire: every byte costs 10 bit times (8N1) at the chosen baud rate. Each
side is polled by its own :class:`~skidsteer_power.des.poller.AmplifierPoller` thread as fast as it
can (the node's cycle: mean velocity, mean current, encoder counter; status word every 5th cycle).
The byte-time limit is the baud rate / 10 divided by the bytes one cycle puts on the line (both
directions, handshakes included, no turnaround time): the ratio shows what the handshaking
protocol, the pty and Python leave of the line. A run without wire emulation gives the software's
own ceiling.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

from benchmarks.harness import Report
from skidsteer_power.des.poller import AmplifierPoller, DriveCommand
from skidsteer_power.des.protocol import DesConfig, OpCode, command_bytes
from skidsteer_power.des.transport import LinkTiming

STATUS_EVERY = 5
NODE_RATE_HZ = 50.0
MEASURE_S = 4.0


def cycle_bytes() -> float:
    """Bytes on the line per poll cycle of one side (mean over the status-word period)."""
    per_cycle = (
        command_bytes(OpCode.READ_VELOCITY_IS_MUST, 1, 2)
        + command_bytes(OpCode.READ_TEMP_PARAM, 2, 1)  # current, status variable 130
        + command_bytes(OpCode.READ_TEMP_PARAM, 2, 1)  # encoder counter, status variable 143
    )
    return per_cycle + command_bytes(OpCode.READ_SYS_STATUS, 1, 1) / STATUS_EVERY


def measure(baud: int, emulate: bool) -> tuple[float, float, int]:
    """(left Hz, right Hz, link failures) of free-running pollers on a ``des-sim`` subprocess."""
    argv = [sys.executable, '-m', 'skidsteer_power.cli.main', 'des-sim', '--baud', str(baud), '--json']
    proc = subprocess.Popen(
        [*argv, *([] if emulate else ['--no-baud-emulation'])], stdout=subprocess.PIPE, text=True
    )
    try:
        lines: list[str] = []
        while not lines or lines[-1] != '}\n':
            lines.append(proc.stdout.readline())
        ports = json.loads(''.join(lines))
        command = DriveCommand(timeout_s=1e6)
        command.set({'left': 1000.0, 'right': -1000.0})
        pollers = [
            AmplifierPoller(
                side, ports[side], command, config=DesConfig(baudrate=baud), timing=LinkTiming(),
                poll_period_s=0.0, status_every=STATUS_EVERY,
            ).start()
            for side in ('left', 'right')
        ]  # fmt: skip
        time.sleep(1.0)  # connect, enable, spin up
        start = [p.sample.sequence for p in pollers]
        time.sleep(MEASURE_S)
        rates = [(p.sample.sequence - s) / MEASURE_S for p, s in zip(pollers, start, strict=True)]
        failures = sum(int(p.sample.link.get('failures', 0)) for p in pollers)
        for p in pollers:
            p.request_stop()
        for p in pollers:
            p.stop()
        return rates[0], rates[1], failures
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def run(report: Report) -> None:
    nbytes = cycle_bytes()
    report.figure('bytes on the line per poll cycle (one side)', nbytes, 'B')
    for baud in (38400, 115200):
        limit = baud / 10.0 / nbytes
        left, right, failures = measure(baud, emulate=True)
        report.figure(f'{baud} baud: byte-time limit per side', limit, 'Hz')
        rate = min(left, right)
        report.figure(
            f'{baud} baud: achieved poll rate, slower side (two amplifiers)',
            rate,
            'Hz',
            goal=f'>= {NODE_RATE_HZ:g} Hz (node default)',
            met=rate >= NODE_RATE_HZ,
            note=f'left {left:.1f}, right {right:.1f}, link failures {failures}',
        )
        report.ratio(
            f'{baud} baud: achieved / byte-time limit', rate, limit, goal='> 0.5', met=rate / limit > 0.5
        )
    left, right, failures = measure(115200, emulate=False)
    report.figure(
        'no wire emulation: software ceiling per side',
        min(left, right),
        'Hz',
        note=f'left {left:.1f}, right {right:.1f}, link failures {failures}',
    )
