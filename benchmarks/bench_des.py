"""DES 70/10 link: achieved poll rate of two amplifiers against the byte-time limit of the line.

The simulators run in their own process (``skidsteer-power des-sim``), as real amplifiers are other
hardware, and emulate the wire: every byte costs 10 bit times (8N1) at the chosen baud rate. Each
side is polled by its own :class:`~skidsteer_power.des.poller.AmplifierPoller` thread as fast as it
can (the node's cycle: mean velocity, mean current, encoder counter; status word every 5th cycle).
The byte-time limit is the baud rate / 10 divided by the bytes one cycle puts on the line (both
directions, handshakes included, no turnaround time): the ratio shows what the handshaking
protocol, the pty and Python leave of the line. A run without wire emulation gives the software's
own ceiling.

Fail safe (issue 13): the time from a fault (an exception in a poller, an unplugged port, a silent
amplifier) to the zero set point arriving at each amplifier, read from the simulator's own command
log (arrival times), over several trials at a random phase of the poll cycle; here the simulators
run in the benchmark's process, because the faults are injected into them.
"""

from __future__ import annotations

import functools
import json
import math
import random
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from benchmarks.harness import Report
from skidsteer_power.des.poller import AmplifierPoller, DriveCommand
from skidsteer_power.des.protocol import DesConfig, OpCode, command_bytes
from skidsteer_power.des.transport import LinkTiming

if TYPE_CHECKING:
    from skidsteer_power.des.simulator import SimulatedDes, SimulatedPair

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
    assert proc.stdout is not None  # stdout=PIPE
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
    run_fail_safe(report)
    run_issue34(report)
    run_signals(report)
    run_guardian(report)
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


# -- fail safe: time from a fault to zero speed at the amplifier -----------------------------------

FAULT_TRIALS = 7
DRIVE_RPM = 1000


def _wait(predicate: Callable[..., bool], timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.002)
    return predicate()


def _driving(pair: SimulatedPair) -> bool:
    return (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (DRIVE_RPM, -DRIVE_RPM)


def _zeroed_at(sim: SimulatedDes, after: float) -> float:
    """Arrival time of the first zero set point at ``sim`` at or after ``after`` (NaN: none)."""
    return sim.arrival_s(OpCode.SET_VELOCITY, (0,), after)


def fault_to_zero(kind: str, trials: int = FAULT_TRIALS) -> tuple[list[float], list[float]]:
    """Per trial: (seconds until the faulted side's amplifier holds zero, until the other side's).

    ``kind``: 'poller' (an exception inside the left poller's cycle), 'silent' (the left amplifier
    stops answering) or 'unplug' (the left port disappears). Two pollers at the node's 50 Hz and
    default timing drive simulated amplifiers (wire byte time emulated, 38400 baud) at +-1000 rpm.
    A faulted side that cannot be reached (silent, unplugged) is NaN: only the other side can be
    stopped, which is what ``stop_both_on_link_loss`` is for.
    """
    from skidsteer_power.des.simulator import Fault, SimulatedPair

    own, other = [], []
    with SimulatedPair(38400) as pair:
        command = DriveCommand(timeout_s=1e6)
        command.set({'left': DRIVE_RPM, 'right': -DRIVE_RPM})
        pollers = {
            side: AmplifierPoller(
                side, sim.port, command, config=DesConfig(baudrate=38400), timing=LinkTiming(),
                poll_period_s=1.0 / NODE_RATE_HZ, status_every=STATUS_EVERY, reconnect_period_s=0.1,
                log_error=lambda text: None,
            ).start()
            for side, sim in (('left', pair.left), ('right', pair.right))
        }  # fmt: skip
        try:
            for _ in range(trials):
                assert _wait(lambda: _driving(pair)), 'the motors never reached the set point'
                time.sleep(0.05 + 0.02 * random.random())  # a random phase of the poll cycle
                amp = pollers['left'].amp
                if kind == 'poller':
                    real = amp.read_current
                    started: list[float] = []

                    def broken(
                        *args: Any,
                        _real: Callable[..., Any] = real,
                        _started: list[float] = started,
                        **kwargs: Any,
                    ) -> Any:
                        if not _started:
                            _started.append(time.monotonic())
                            raise ZeroDivisionError('injected')
                        return _real(*args, **kwargs)

                    amp.read_current = broken  # type: ignore[method-assign]  # deliberate fault injection
                    _wait(lambda _s=started: bool(_s))
                    t0 = started[0]
                elif kind == 'silent':
                    t0 = time.monotonic()
                    pair.left.inject(Fault.SILENT, -1)
                else:
                    t0 = time.monotonic()
                    pair.left.close_port()
                _wait(lambda _t=t0: not math.isnan(_zeroed_at(pair.right, _t)))
                own.append(_zeroed_at(pair.left, t0) - t0)
                other.append(_zeroed_at(pair.right, t0) - t0)
                if kind == 'poller':
                    del amp.read_current
                pair.left.clear_faults()
                pair.left.reopen_port()
        finally:
            for poller in pollers.values():
                poller.stop()
    return own, other


SIGNAL_TRIALS = 3
SIGNALS = ('SIGINT', 'SIGTERM', 'SIGHUP', 'SIGQUIT', 'SIGUSR1', 'SIGALRM')  # issue 28: not only INT/TERM
STOP_SIGNALS = ('SIGTSTP', 'SIGTTIN', 'SIGTTOU')  # issue 34: the process stops; zero and disable first


def process_stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (state T in /proc/PID/stat)."""
    with open(f'/proc/{pid}/stat') as stat:
        return stat.read().rsplit(')', 1)[1].split()[0] in ('T', 't')


def signal_to_zero(signame: str, trials: int = SIGNAL_TRIALS) -> tuple[list[float], list[float]]:
    """Per trial: (seconds from sending ``signame`` to a ``des_driver`` process until the left
    amplifier holds zero, until the right one does). A real process per trial (``python -m
    skidsteer_power.nodes.des_driver``, autostart, default timing) drives the simulated pair at
    0.2 m/s from cmd_vel published over DDS; arrival times from the simulator's command log. A trial
    whose process did not exit 0 or left an amplifier enabled is NaN."""
    import os
    import signal
    import uuid

    import rclpy
    import rclpy.utilities
    from geometry_msgs.msg import Twist
    from rclpy.context import Context

    from skidsteer_power.des.simulator import SimulatedPair
    from skidsteer_power.nodes.spin import node_command

    left, right = [], []
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('bench_des_signal', context=context)
        for _ in range(trials):
            with SimulatedPair(38400) as pair:
                ns = f'/b{uuid.uuid4().hex[:8]}'
                params = {'left_port': pair.left.port, 'right_port': pair.right.port, 'autostart': 'true'}
                proc = subprocess.Popen(  # its own process group: not orphaned, so a stop signal stops it
                    node_command('skidsteer_power.nodes.des_driver', ns, params),
                    env=os.environ.copy(),
                    process_group=0,
                )
                publisher = node.create_publisher(Twist, f'{ns}/cmd_vel', 10)
                msg = Twist()
                msg.linear.x = 0.2
                try:
                    deadline = time.monotonic() + 30
                    while not (pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0):
                        if time.monotonic() > deadline:
                            raise RuntimeError('des_driver never drove both sides')
                        publisher.publish(msg)
                        time.sleep(0.02)
                    time.sleep(0.2 + 0.02 * random.random())  # driving, at a random phase
                    t0 = time.monotonic()
                    proc.send_signal(getattr(signal, signame))
                    if signame in STOP_SIGNALS:
                        _wait(functools.partial(process_stopped, proc.pid), 10.0)
                        clean = process_stopped(proc.pid) and not (pair.left.enabled or pair.right.enabled)
                        proc.send_signal(signal.SIGCONT)
                        proc.send_signal(signal.SIGTERM)
                        clean = proc.wait(timeout=15) == 0 and clean
                    else:
                        clean = proc.wait(timeout=15) == 0 and not (pair.left.enabled or pair.right.enabled)
                finally:
                    proc.kill()
                    proc.wait()
                    node.destroy_publisher(publisher)
                left.append(_zeroed_at(pair.left, t0) - t0 if clean else math.nan)
                right.append(_zeroed_at(pair.right, t0) - t0 if clean else math.nan)
    finally:
        rclpy.utilities.try_shutdown(context=context)
    return left, right


def run_signals(report: Report) -> None:
    goal_s = 0.5  # as for the faults: not slower than the command timeout
    for signame in (*SIGNALS, *STOP_SIGNALS):
        left, right = signal_to_zero(signame)
        for side, values in (('left', left), ('right', right)):
            p50, worst = _p50_max(values)
            failed = sum(math.isnan(v) for v in values)
            report.figure(
                f'{signame} -> zero speed and disabled, {side} amplifier: max of {len(values)}',
                worst if not failed else math.nan,
                's',
                goal=f'< {goal_s:g} s, every trial',
                met=not failed and worst < goal_s,
                note=f'p50 {1000 * p50:.0f} ms' + (f'; {failed} trial(s) not zeroed' if failed else ''),
            )


def _p50_max(values: list[float]) -> tuple[float, float]:
    finite = sorted(v for v in values if not math.isnan(v))
    if not finite:
        return math.nan, math.nan
    return statistics.median(finite), finite[-1]


def run_fail_safe(report: Report) -> None:
    goal_s = 0.5  # the node's default cmd_timeout_s: a detected fault must not stop slower than silence
    for kind, what in (
        ('poller', 'poller exception'),
        ('unplug', 'port unplugged'),
        ('silent', 'amplifier silent'),
    ):
        own, other = fault_to_zero(kind)
        for side, values in (('faulted side', own), ('other side', other)):
            p50, worst = _p50_max(values)
            if math.isnan(p50):
                report.figure(
                    f'{what} -> zero speed, {side}', math.nan, 's', note='unreachable: keeps its set point'
                )
                continue
            report.figure(
                f'{what} -> zero speed, {side}: max of {len(values)}',
                worst,
                's',
                goal=f'< {goal_s:g} s (cmd_timeout_s)',
                met=worst < goal_s,
                note=f'p50 {1000 * p50:.0f} ms',
            )


# -- the guardian (issue 34, item 6): the ends of the driver no handler sees -------------------------

GUARDIAN_SIGNALS = ('SIGKILL', 'SIGSTOP', 'SIGSEGV', 'SIGBUS', 'SIGILL', 'SIGFPE', 'SIGSYS')
GUARDIAN_TRIALS = 3
GUARDIAN_GOAL_S = 0.6  # issue 34: a motor turning more than 0.6 s after a fault is critical


def guardian_signal_to_zero(
    signame: str, trials: int = GUARDIAN_TRIALS, feed: str = 'none'
) -> list[tuple[float, ...]]:
    """Per trial: (seconds from sending ``signame`` to a ``des_driver`` process (autostart, default
    timing, guardian on, cmd_timeout_s 5 s so that its own watchdog cannot be what stops them) until
    both amplifiers hold zero speed, until both are disabled). NaN: not within 5 s. Arrival times from
    the simulator's command log; the driver drives the simulated pair at 0.2 m/s from cmd_vel. With
    ``feed`` (``guardian_feed`` dtr or rts) two more: seconds from the signal until the guardian held
    the watchdog feed, and until its last change (negative: before the signal), from its log lines
    (stamped on the system-wide monotonic clock; NaN: no such line)."""
    import os
    import resource
    import signal
    import tempfile
    import uuid

    import rclpy
    import rclpy.utilities
    from geometry_msgs.msg import Twist
    from rclpy.context import Context

    from skidsteer_power.des.simulator import SimulatedPair
    from skidsteer_power.nodes.spin import node_command

    resource.setrlimit(resource.RLIMIT_CORE, (0, resource.getrlimit(resource.RLIMIT_CORE)[1]))  # no cores
    results = []
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('bench_des_guardian', context=context)
        for _ in range(trials):
            with SimulatedPair(38400) as pair:
                sims = (pair.left, pair.right)
                ns = f'/b{uuid.uuid4().hex[:8]}'
                params: dict[str, object] = {
                    'left_port': pair.left.port,
                    'right_port': pair.right.port,
                    'autostart': 'true',
                    'cmd_timeout_s': 5.0,
                }
                if feed != 'none':
                    params['guardian_feed'] = feed
                log = tempfile.TemporaryFile()  # noqa: SIM115  # closed below, read for the feed's lines
                proc = subprocess.Popen(
                    node_command('skidsteer_power.nodes.des_driver', ns, params),
                    env=os.environ.copy(),
                    stderr=log,
                )
                publisher = node.create_publisher(Twist, f'{ns}/cmd_vel', 10)
                msg = Twist()
                msg.linear.x = 0.2
                try:
                    deadline = time.monotonic() + 40
                    while not (
                        pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0
                    ) or not (pair.left.enabled and pair.right.enabled):
                        if time.monotonic() > deadline:
                            raise RuntimeError('des_driver never drove both sides')
                        publisher.publish(msg)
                        time.sleep(0.02)
                    time.sleep(0.3 + 0.05 * random.random())  # driving, at a random phase
                    t0 = time.monotonic()
                    os.kill(proc.pid, getattr(signal, signame))
                    _wait(lambda _s=sims: all(not s.enabled and s.speed_setpoint_rpm == 0 for s in _s), 5.0)
                finally:
                    proc.kill()
                    proc.wait()
                    node.destroy_publisher(publisher)
                zero = max(_zeroed_at(sim, t0) for sim in sims) - t0
                off = max(_disabled_at(sim, t0) for sim in sims) - t0
                time.sleep(0.5)  # the guardian sees the EOF of the killed process and ends
                log.seek(0)
                held = _feed_held_after(log.read().decode(errors='replace'), t0) if feed != 'none' else ()
                log.close()
                results.append((zero, off, *held))
    finally:
        rclpy.utilities.try_shutdown(context=context)
    return results


def _feed_held_after(text: str, t0: float) -> tuple[float, float]:
    """(held - t0, last change - t0) [s] of the guardian's first 'held' line at or after ``t0`` in
    ``text`` (its log; ``WatchdogFeed.step``), NaN for both if there is none."""
    import re

    pattern = r'held \(.*?\) at t=([0-9.]+) s; last change at t=([-0-9.inf]+) s'
    for at, last in re.findall(pattern, text):
        if float(at) >= t0:
            return float(at) - t0, float(last) - t0
    return math.nan, math.nan


def _disabled_at(sim: SimulatedDes, after: float) -> float:
    """Arrival time of the first Enable 0 at ``sim`` at or after ``after`` (NaN: none)."""
    return sim.arrival_s(OpCode.ENABLE, (0,), after)


def guardian_poll_rate(seconds: float = 2.0, rounds: int = 3) -> tuple[float, float]:
    """(direct, through the guardian): free-running poll rate of the slower side [Hz], simulated pair
    at 38400 baud with the wire's byte time; ``rounds`` alternations of the two, the median of each
    (the shared machine's load changes from one second to the next)."""
    from skidsteer_power.des.guardian import GuardianClient
    from skidsteer_power.des.simulator import SimulatedPair

    rates: dict[bool, list[float]] = {False: [], True: []}
    for through in (False, True) * rounds:
        with SimulatedPair(38400) as pair:
            ports = {'left': pair.left.port, 'right': pair.right.port}
            client = GuardianClient(ports) if through else None
            if client is not None:
                ports = client.start()
            command = DriveCommand(timeout_s=1e6)
            command.set({'left': 1000.0, 'right': -1000.0})
            pollers = [
                AmplifierPoller(
                    side, ports[side], command, config=DesConfig(baudrate=38400), timing=LinkTiming(),
                    poll_period_s=0.0, status_every=STATUS_EVERY,
                ).start()
                for side in ('left', 'right')
            ]  # fmt: skip
            time.sleep(1.0)
            start = [p.sample.sequence for p in pollers]
            time.sleep(seconds)
            sequences = zip(pollers, start, strict=True)
            rates[through].append(min((p.sample.sequence - s) / seconds for p, s in sequences))
            for p in pollers:
                p.request_stop()
            for p in pollers:
                p.stop()
            if client is not None:
                client.close()
    return statistics.median(rates[False]), statistics.median(rates[True])


def run_guardian(report: Report) -> None:
    """Worst time from the driver's unhandled end to zero at both amplifiers (goal <= 0.6 s), and what
    the proxy costs the poll rate."""
    for signame in GUARDIAN_SIGNALS:
        trials = guardian_signal_to_zero(signame)
        zeros = [t[0] for t in trials]
        offs = [t[1] for t in trials]
        failed = sum(math.isnan(v) for v in zeros + offs)
        worst = max(zeros) if not failed else math.nan
        report.figure(
            f'guardian: {signame} of des_driver -> zero at both amplifiers: max of {len(trials)}',
            worst,
            's',
            goal=f'<= {GUARDIAN_GOAL_S:g} s, every trial',
            met=not failed and worst <= GUARDIAN_GOAL_S,
            note=f'p50 {1000 * _p50_max(zeros)[0]:.0f} ms; both disabled: max {1000 * _p50_max(offs)[1]:.0f} '
            'ms' + (f'; {failed} trial(s) not stopped within 5 s' if failed else ''),
        )
    run_guardian_feed(report)
    direct, through = guardian_poll_rate()
    report.figure(
        'guardian: free-running poll rate through its proxy, slower side (38400 baud), median of 3',
        through,
        'Hz',
        note=f'direct, alternating with it: {direct:.1f} Hz (ratio {through / direct:.2f})',
    )


FEED_WATCHDOG_PERIOD_S = 0.2  # docs/RELIABILITY.md: the hardware watchdog's period, about 0.2 s (ASSUMED)
FEED_GOAL_S = GUARDIAN_GOAL_S - FEED_WATCHDOG_PERIOD_S  # held by then: the enable drops within 0.6 s
FEED_SIGNALS = ('SIGSTOP', 'SIGKILL')  # the heartbeat stops without an EOF / with one


def run_guardian_feed(report: Report) -> None:
    """Worst time from the driver's heartbeat stopping (SIGSTOP: no EOF, the guardian's timeout;
    SIGKILL: the EOF) to the guardian holding the watchdog feed (``guardian_feed`` dtr on the
    simulated ptys, which refuse the line: the guardian's own account of when it stopped changing it).
    Goal: held within 0.6 s less the watchdog's period, so that the enable drops within 0.6 s."""
    for signame in FEED_SIGNALS:
        trials = guardian_signal_to_zero(signame, feed='dtr')
        held = [t[2] for t in trials]
        last = [t[3] for t in trials]
        failed = sum(math.isnan(v) for v in held)
        worst = max(held) if not failed else math.nan
        report.figure(
            f'guardian feed (DTR): {signame} of des_driver -> feed held: max of {len(trials)}',
            worst,
            's',
            goal=f'<= {FEED_GOAL_S:g} s (0.6 s less a {FEED_WATCHDOG_PERIOD_S:g} s watchdog period)',
            met=not failed and worst <= FEED_GOAL_S,
            note=f'p50 {1000 * _p50_max(held)[0]:.0f} ms; last change {1000 * max(last):+.0f} ms worst; '
            f'zero at both amplifiers max {1000 * max(t[0] for t in trials):.0f} ms'
            + (f'; {failed} trial(s) never held' if failed else ''),
        )


def guardian_main(argv: list[str]) -> int:
    """``python -m benchmarks.bench_des guardian``: the guardian's figures alone (exit 1 on a miss)."""
    report = Report(section='des')
    run_guardian(report)
    return 1 if any(f.met is False for f in report.figures) else 0


# -- issue 34: slow links, CRC storms, slow polling, a self-reset, job-control stops ---------------

WATCHDOG_S = 0.5  # the node's default cmd_timeout_s, unchanged
STOP_GOAL_S = 0.6  # issue 34: a motor turning > 0.6 s after its command went stale or a fault
ISSUE34_TRIALS = 5


class _Rig:
    """Two pollers (real time, the node's default timing) on a simulated pair with a slow link, a
    late amplifier or slow polling: what des_driver runs, without ROS."""

    def __init__(self, *, latency_s: float = 0.0, delay_s: float = 0.0, poll_hz: float = NODE_RATE_HZ):
        from skidsteer_power.des.simulator import Fault, SimulatedPair

        self.pair = SimulatedPair(38400, latency_s=latency_s).start()
        if delay_s:
            for sim in (self.pair.left, self.pair.right):
                sim.inject(Fault.DELAY, -1, delay_s=delay_s)
        self.command = DriveCommand(
            timeout_s=WATCHDOG_S, stall_timeout_s=max(1.0, 5.0 / poll_hz)
        )  # as the node
        timing = LinkTiming(exchange_timeout_s=max(0.25, 8 * (latency_s + delay_s)))
        self.pollers = {
            side: AmplifierPoller(
                side, sim.port, self.command, config=DesConfig(baudrate=38400), timing=timing,
                poll_period_s=1.0 / poll_hz, status_every=STATUS_EVERY, reconnect_period_s=0.1,
                log_error=lambda text: None,
            ).start()
            for side, sim in (('left', self.pair.left), ('right', self.pair.right))
        }  # fmt: skip

    def drive(self) -> float:
        """Command +-DRIVE_RPM until both amplifiers hold it; the last command's time [s]."""
        deadline = time.monotonic() + 30
        while not _driving(self.pair):
            if time.monotonic() > deadline:
                raise RuntimeError('the motors never reached the set point')
            self.command.set({'left': DRIVE_RPM, 'right': -DRIVE_RPM})
            time.sleep(0.02)
        for _ in range(int(random.random() * 10)):  # a random phase of the poll cycle
            self.command.set({'left': DRIVE_RPM, 'right': -DRIVE_RPM})
            time.sleep(0.013)
        self.command.set({'left': DRIVE_RPM, 'right': -DRIVE_RPM})
        return time.monotonic()

    def both_zeroed_after(self, t0: float, timeout_s: float = 5.0) -> float:
        """Seconds from ``t0`` until both amplifiers got a zero set point (NaN: not within timeout)."""
        sims = (self.pair.left, self.pair.right)
        _wait(lambda: all(not math.isnan(_zeroed_at(s, t0)) for s in sims), timeout_s)
        return max(_zeroed_at(s, t0) for s in sims) - t0

    def close(self) -> None:
        for poller in self.pollers.values():
            poller.request_stop()
        for poller in self.pollers.values():
            poller.stop()
        self.pair.stop()


def issue34_case(kind: str, trials: int = ISSUE34_TRIALS) -> list[float]:
    """Per trial, seconds until both amplifiers hold zero: from the last command (watchdog cases:
    'latency16', 'late45', 'poll1', 'poll0.1'), or from the fault ('crc' storm on the left, 'reset':
    the left amplifier resets itself, 'deactivate' at 1 Hz polling)."""
    from skidsteer_power.des.simulator import Fault

    rig = _Rig(
        latency_s=0.016 if kind == 'latency16' else 0.0,
        delay_s=0.045 if kind == 'late45' else 0.0,
        poll_hz={'poll1': 1.0, 'poll0.1': 0.1, 'deactivate': 1.0}.get(kind, NODE_RATE_HZ),
    )
    times = []
    try:
        for _ in range(2 if kind == 'poll0.1' else trials):  # a set point waits for a poll: 10 s
            last = rig.drive()
            if kind == 'crc':
                t0 = time.monotonic()
                rig.pair.left.inject(Fault.CORRUPT_CRC, -1)
            elif kind == 'reset':
                t0 = time.monotonic()
                rig.pair.left.self_reset()
            elif kind == 'deactivate':
                t0 = time.monotonic()
                rig.command.active = False
            else:
                t0 = last  # the command goes stale WATCHDOG_S later: the stop counts from here
            if kind in ('crc', 'reset', 'deactivate'):
                while time.monotonic() < t0 + 2.0 and math.isnan(rig.both_zeroed_after(t0, 0.01)):
                    rig.command.set({'left': DRIVE_RPM, 'right': -DRIVE_RPM})  # a teleop keeps sending
                    time.sleep(0.02)
            times.append(rig.both_zeroed_after(t0))
            rig.pair.left.clear_faults()
            rig.command.active = True
            rig.command.request_clear(['left', 'right'])
            _wait(lambda: not rig.command.halted_by, 5.0)
    finally:
        rig.close()
    return times


ISSUE34_CASES = (
    ('latency16', 'FTDI 16 ms latency: last command -> both zero (watchdog 0.5 s)'),
    ('late45', 'amplifier answering 45 ms late: last command -> both zero (watchdog 0.5 s)'),
    ('poll1', 'poll_rate_hz 1: last command -> both zero (watchdog 0.5 s)'),
    ('poll0.1', 'poll_rate_hz 0.1: last command -> both zero (watchdog 0.5 s)'),
    ('deactivate', 'poll_rate_hz 1: deactivate -> both zero'),
    ('crc', 'CRC storm on the left: fault -> both zero'),
    ('reset', 'left amplifier resets itself: fault -> both zero'),
)


def run_issue34(report: Report, cases: tuple[str, ...] = ()) -> None:
    for kind, what in ISSUE34_CASES:
        if cases and kind not in cases:
            continue
        times = issue34_case(kind)
        failed = sum(math.isnan(v) for v in times)
        p50, worst = _p50_max(times)
        report.figure(
            f'{what}: max of {len(times)}',
            worst if not failed else math.nan,
            's',
            goal=f'<= {STOP_GOAL_S:g} s, every trial',
            met=not failed and worst <= STOP_GOAL_S,
            note=f'p50 {1000 * p50:.0f} ms' + (f'; {failed} trial(s) never zeroed' if failed else ''),
        )


def main(argv: list[str]) -> int:
    """``python -m benchmarks.bench_des CASE...``: only the issue-34 cases named (exit 1 on a missed
    goal); the planted-fault script runs the slow-link case this way. ``guardian``: the guardian's
    figures (signals of des_driver, the watchdog feed, the proxy's poll rate)."""
    if argv == ['guardian']:
        return guardian_main(argv)
    report = Report(section='des')
    run_issue34(report, tuple(argv))
    return 1 if any(f.met is False for f in report.figures) else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
