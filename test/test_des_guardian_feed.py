"""The guardian's hardware-watchdog feed (``guardian_feed``; docs/RELIABILITY.md, "The hardware line of
defence"): a modem-control line of the amplifier ports that changes level every 50 ms while the way
is clear and holds still on a stale command, a fault, a lost link, a trip or the guardian's end.

A pseudo-terminal carries no modem lines (the first test shows it on the simulated DES 70/10's pty:
every TIOCMGET / TIOCMBIS / TIOCMBIC is ENOTTY, on both ends), so no test here can see the line
itself. The feed is tested as far as it goes on the real serial objects: pyserial's ``dtr`` / ``rts``
attribute (set before the ioctl the kernel refuses), the kernel's refusal (ENOTTY, recorded), the
ports' termios (HUPCL cleared, read back from the pty), and the guardian process's own account of
each change of state (its log lines, stamped on the system-wide monotonic clock). The time from the
heartbeat stopping to the feed holding is a benchmark (``bench_des.run_guardian``), not asserted here.
"""

from __future__ import annotations

import errno
import fcntl
import re
import struct
import termios
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
from des_harness import Harness

from skidsteer_power.des.guardian import GuardianClient, GuardianError, WatchdogFeed
from skidsteer_power.des.simulator import SimulatedPair


@pytest.fixture
def pair() -> Iterator[SimulatedPair]:
    with SimulatedPair(38400) as sims:
        yield sims


def wait_for(predicate: Callable[[], object], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return bool(predicate())


def test_a_pty_carries_no_modem_lines(pair: SimulatedPair) -> None:
    """The evidence: the simulated amplifier's pty refuses every modem-line ioctl on both ends
    (Linux's pty driver has no tiocmget / tiocmset), and pyserial, asked to lower DTR, raises the
    kernel's ENOTTY after keeping the level it was given: as far as a pty lets the feed go."""
    sim = pair.left
    ser = serial.Serial(sim.port, 38400, timeout=0)
    try:
        bits = struct.pack('I', termios.TIOCM_DTR)
        ends = {'slave (the driver side)': ser.fileno(), 'master (the amplifier side)': sim._master}
        for end, fd in ends.items():
            assert fd is not None
            for request in (termios.TIOCMGET, termios.TIOCMBIS, termios.TIOCMBIC):
                with pytest.raises(OSError) as err:
                    fcntl.ioctl(fd, request, bits)
                assert err.value.errno == errno.ENOTTY, (end, request)
        with pytest.raises(OSError) as err:
            ser.dtr = False
        assert err.value.errno == errno.ENOTTY
        assert ser.dtr is False  # pyserial's own state: the level the feed asked for
    finally:
        ser.close()


def _serials(pair: SimulatedPair) -> dict[str, serial.Serial]:
    sims = (('left', pair.left), ('right', pair.right))
    return {side: serial.Serial(sim.port, 38400, timeout=0) for side, sim in sims}


def test_feed_changes_the_line_at_a_fixed_rate_and_holds_it(pair: SimulatedPair) -> None:
    """:class:`WatchdogFeed` on the real serial objects of both simulated ports, in the time of a
    stepped clock (binary fractions of a second, so the arithmetic is exact): while clear, the line
    changes at once and then every period, on both ports alike; held, it does not move; clear again,
    it changes at once; a late turn gives one change, not a burst; RTS is left alone with DTR fed."""
    period, step = 0.0625, 0.015625  # 4 turns per period
    log: list[str] = []
    feed = WatchdogFeed('dtr', period_s=period, log=log.append)
    serials = _serials(pair)
    try:
        for name, ser in serials.items():
            feed.probe(name, ser)
        assert set(feed.refused) == {'left', 'right'} and 'Errno 25' in feed.refused['left']  # ENOTTY
        levels: list[tuple[float, bool]] = []  # (time, level) at each change seen on pyserial's state
        now = 100.0

        def turn(hold: str = '') -> None:
            feed.step(now, dict(serials), hold)
            level = serials['left'].dtr
            assert serials['right'].dtr == level  # both ports alike
            if not levels or levels[-1][1] != level:
                levels.append((now, level))

        for _ in range(16):  # 0.25 s clear: changes at 0, 1, 2, 3 periods
            turn()
            now += step
        assert [t - 100.0 for t, _ in levels] == [0.0, 0.0625, 0.125, 0.1875]
        assert [lv for _, lv in levels] == [False, True, False, True]  # open raised DTR: first change low
        assert feed.changes == 4 and feed.last_change_s == 100.1875
        assert bool(feed.running)
        held_at = now
        for _ in range(40):  # 0.625 s held: nothing moves
            turn('no fresh command')
            now += step
        assert len(levels) == 4 and feed.held_s == held_at
        assert not feed.running
        assert 'held (no fresh command)' in log[-1] and 'last change at t=100.187500 s' in log[-1]
        resumed = now
        turn()
        assert levels[-1] == (resumed, False) and bool(feed.running)  # at once
        now += 3.5 * period  # a late turn (a loaded machine): one change, the next a period later
        turn()
        assert levels[-1] == (now, True)
        late = now
        now += step
        turn()
        assert levels[-1][0] == late  # no catching up
        now = late + period
        turn()
        assert levels[-1] == (now, False)
        assert all(ser.rts for ser in serials.values())  # the other line: as the port opened it
        assert sum('refuses DTR' in line for line in log) == 2  # each port named once, not per change
    finally:
        for ser in serials.values():
            ser.close()


def test_feed_rts_and_unknown_line() -> None:
    with pytest.raises(GuardianError, match='feed must be one of none, dtr, rts'):
        WatchdogFeed('dsr', log=print)
    with pytest.raises(GuardianError, match='feed must be one of'):
        GuardianClient({'left': '/dev/null'}, feed='DTR!')


# -- the guardian process ----------------------------------------------------------------------------

_HELD = re.compile(
    r'DTR held \((?P<why>.*?)\) at t=(?P<at>[0-9.]+) s; last change at t=(?P<last>[0-9.inf-]+)'
)


def _held(text: str) -> list[tuple[str, float, float]]:
    return [(m['why'], float(m['at']), float(m['last'])) for m in _HELD.finditer(text)]


def _set_hupcl(pair: SimulatedPair) -> None:
    """Set HUPCL on both simulated ports, as on a real serial device (the kernel's default there; the
    simulator's raw pty has it off)."""
    for sim in (pair.left, pair.right):
        assert sim._slave is not None
        attrs = termios.tcgetattr(sim._slave)
        attrs[2] |= termios.HUPCL
        termios.tcsetattr(sim._slave, termios.TCSANOW, attrs)


def _hupcl(pair: SimulatedPair) -> dict[str, bool]:
    """Whether HUPCL is set on each simulated port (read from the pty the guardian configured)."""
    out = {}
    for side, sim in (('left', pair.left), ('right', pair.right)):
        assert sim._slave is not None
        out[side] = bool(termios.tcgetattr(sim._slave)[2] & termios.HUPCL)
    return out


def test_guardian_feeds_only_while_the_way_is_clear(pair: SimulatedPair, tmp_path: Path) -> None:
    """A guardian process with ``--feed dtr`` and a stand-in driver (this test) whose heartbeat says
    whether a fresh command is in force: no feeding before the first 'h'; feeding while 'h'; held on
    'i' (a stale command), fed again on 'h'; held when the heartbeat stops without an EOF (a frozen
    driver: the trip), and held for good once the driver is gone (EOF), also through the guardian's
    exit, with HUPCL cleared so that the last close leaves the line alone."""
    log_path = tmp_path / 'guardian.log'
    clear = threading.Event()
    ports = {'left': pair.left.port, 'right': pair.right.port}
    _set_hupcl(pair)
    with open(log_path, 'w') as log:
        client = GuardianClient(ports, stderr=log.fileno(), feed='dtr', driving=clear.is_set)
        client.start()
    try:
        assert set(client.feed_refused) == {'left', 'right'}  # ptys: ENOTTY, reported at start
        assert _hupcl(pair) == {'left': False, 'right': False}
        time.sleep(0.3)  # heartbeats 'i': nothing to feed yet
        assert 'changing' not in log_path.read_text()
        clear.set()
        assert wait_for(lambda: log_path.read_text().count('DTR changing') == 1, 5.0), log_path.read_text()
        clear.clear()
        assert wait_for(lambda: len(_held(log_path.read_text())) == 1, 5.0), log_path.read_text()
        why, at, last = _held(log_path.read_text())[0]
        assert why.startswith('the driver has no fresh command') and last <= at
        clear.set()
        assert wait_for(lambda: log_path.read_text().count('DTR changing') == 2, 5.0)
        # the heartbeat stops, the socket stays open (SIGSTOP, a frozen driver): the trip holds it
        client._closing.set()
        assert client._thread is not None
        client._thread.join()
        stopped_beating = time.monotonic()
        assert wait_for(lambda: len(_held(log_path.read_text())) == 2, 5.0), log_path.read_text()
        why, at, last = _held(log_path.read_text())[1]
        assert why.startswith('tripped: no heartbeat for') and at > stopped_beating and last <= at
        assert client.sock is not None
        client.sock.close()  # now the driver is gone: EOF; the guardian stops, ends
        client.sock = None
        assert client.proc is not None and client.proc.wait(10) == 0
        text = log_path.read_text()
        assert text.count('DTR changing') == 2 and len(_held(text)) == 2  # nothing moved it after
        assert _hupcl(pair) == {'left': False, 'right': False}  # also after its last close
    finally:
        client.close()


def test_no_feed_is_the_default_and_changes_nothing(pair: SimulatedPair, tmp_path: Path) -> None:
    """Without ``--feed`` (guardian_feed none, the default): no feed line, HUPCL as it was, and the
    heartbeat never asks the driver (``driving`` is not called)."""
    asked: list[int] = []

    def driving() -> bool:
        asked.append(1)
        return True

    log_path = tmp_path / 'guardian.log'
    _set_hupcl(pair)
    with open(log_path, 'w') as log:
        client = GuardianClient(
            {'left': pair.left.port, 'right': pair.right.port},
            stderr=log.fileno(),
            driving=driving,
        )
        client.start()
    try:
        assert '--feed' not in client.command(3)
        time.sleep(0.3)
        assert _hupcl(pair) == {'left': True, 'right': True} and client.feed_refused == {}
    finally:
        client.close()
    assert asked == [] and 'watchdog feed' not in log_path.read_text()


# -- des_driver ----------------------------------------------------------------------------------------


@pytest.mark.ros
def test_driver_feeds_while_driving_and_holds_on_a_stale_command(
    ros_context: Any, pair: SimulatedPair, capfd: pytest.CaptureFixture[str]
) -> None:
    """des_driver with ``guardian_feed:=dtr`` on the simulated pair: the guardian feeds while cmd_vel
    drives, holds once the command goes stale (the driver's watchdog, cmd_timeout_s), and the
    diagnostics say that the ptys refuse the line."""
    h = Harness(ros_context, pair, guardian_feed='dtr', cmd_timeout_s=0.5)
    text = ''

    def seen(what: str) -> bool:
        nonlocal text
        text += capfd.readouterr().err
        return what in text

    try:
        assert h.spin_until(lambda: 'feed' in h.diag('des_driver: command')[1].get('guardian', ''))
        status = h.diag('des_driver: command')[1]
        assert 'feed DTR REFUSED by left, right' in status['guardian'], status
        assert not seen('DTR changing')  # no command yet
        h.twist = (0.2, 0.0)
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and seen('DTR changing'))
        h.twist = None  # the teleop stops: the watchdog's zero, then the feed holds
        assert h.spin_until(lambda: seen('DTR held (the driver has no fresh command'), 5.0), text
        assert pair.left.speed_setpoint_rpm == 0 and pair.right.speed_setpoint_rpm == 0
    finally:
        h.close()


@pytest.mark.ros
@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        ({'guardian_feed': 'dsr'}, 'guardian_feed must be one of none, dtr, rts'),
        ({'guardian_feed': 'rts', 'guardian': False}, 'guardian_feed rts needs guardian:=true'),
    ],
)
def test_driver_refuses_a_bad_feed(
    ros_context: Any, pair: SimulatedPair, overrides: dict[str, Any], message: str
) -> None:
    h = Harness(ros_context, pair, activate=False, **overrides)
    try:
        from rclpy.lifecycle import TransitionCallbackReturn

        assert h.driver.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert message in h.driver.configure_error
        assert h.driver.guardian.client is None  # no guardian was started
    finally:
        h.close()
