"""The guardian: a small process between ``des_driver`` and the DES 70/10 amplifiers that stops them
when the driver ends or freezes in a way no handler of the driver can see (issue 34, item 6).

SIGKILL, SIGSTOP and the hardware-fault signals (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGSYS) end or
freeze the driver without running a line of its code, and the DES 70/10 has no communication
timeout (``../shared/des-protocol.md``: none among its commands or parameters; parameter 43 "error
procedure" acts on amplifier errors, not on a silent host): an amplifier keeps its last set point for
good. The guardian owns the serial ports and hands the driver a pseudo-terminal per amplifier
(a stable symlink, like the simulator's), forwarding every byte both ways (option (a) of the issue,
a proxy; docs/RELIABILITY.md "The guardian" says why not (b), a second writer on the same device).
Beside the data, a socketpair carries the control channel:

- driver -> guardian: ``h`` heartbeat (every :data:`HEARTBEAT_PERIOD_S`; ``i`` instead: alive, but no
  fresh command in force, a link down or a fault, which holds the watchdog feed), ``A`` re-arm,
  ``Q`` quit;
- guardian -> driver: one JSON line at start (``{"ports": {side: path}}`` or ``{"error": text}``),
  then ``T`` when it tripped.

It trips when the socket reaches EOF (the kernel closes a dead process's descriptors at once: SIGKILL
and every fatal signal), when no heartbeat came for ``timeout_s`` (SIGSTOP, a driver frozen with the
GIL held), on ``Q`` and on its own SIGTERM / SIGINT / SIGHUP. Tripping stops forwarding the driver's
bytes, finishes the exchange in flight on each line (it saw every byte of it, so it knows what the
amplifier waits for: the rest of a frame, sent with a CRC that cannot match and bytes that are no op
code, or an acknowledge), then sends SetVelocity 0 and Enable 0 to both amplifiers in lock step,
each handshake bounded, retried until :data:`STOP_DEADLINE_S`. After a trip the stop is **latched**:
the driver's bytes are dropped (it sees silent amplifiers) until it sends ``A``, which it does once it
runs again (``nodes/driver_guardian.py``: the held command is forgotten and the links reopened first,
so only a cmd_vel received after the re-arm moves the motors). On EOF, ``Q`` or a signal the guardian
exits after the stop.

With ``--feed dtr`` or ``--feed rts`` it also feeds a hardware watchdog on the amplifiers' enable input
(:class:`WatchdogFeed`, docs/RELIABILITY.md "The hardware line of defence"): that modem-control line of
every amplifier port changes level every :data:`FEED_PERIOD_S` while the guardian is armed, its
heartbeat fresh, the driver's heartbeat says ``h`` and every port is open; otherwise, and from a trip,
its own signal or its end on, the line is left as it is. The ports' HUPCL is cleared, so that not even
the kernel's hang-up on the last close (its SIGKILL) changes the line.

Nothing in it blocks: every descriptor is non-blocking, every wait is a ``select`` with a deadline, a
write that cannot complete in time is dropped (forwarding) or retried within the stop's deadline, and
an interval timer (:data:`SELF_WATCHDOG_S`, re-armed every turn of the loop) ends the process with
SIGALRM's default action if the loop ever stalls; the hardware line (the amplifiers' enable input
behind a watchdog, docs/RELIABILITY.md) covers the guardian's own end. Pure Python, no ROS: it starts
in about 0.1 s (its imports: pyserial and the protocol module). It is started in a session of its
own, so a Ctrl-C or Ctrl-Z at the terminal reaches the driver, not it.

    python -m skidsteer_power.des.guardian --control-fd N --port left=/dev/ttyUSB0 \\
        --port right=/dev/ttyUSB1 [--baud 38400] [--timeout 0.3] [--feed none|dtr|rts]
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import math
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, field

from skidsteer_power.des.protocol import (
    ACK_FAIL,
    ACK_OK,
    BAUD_CODES,
    MAX_WORDS,
    REPLY_OPCODE,
    OpCode,
    body_length,
    encode_body,
    frame_crc,
)

HEARTBEAT, IDLE, ARM, QUIT, TRIPPED = b'h', b'i', b'A', b'Q', b'T'
"""Control bytes (see the module docstring)."""
FEED_LINES = ('none', 'dtr', 'rts')
"""The watchdog feed's choices: no feed, or the pyserial modem-control line it toggles."""
FEED_PERIOD_S = 0.05
"""The feed's line changes level this often while the way is clear [s] (a 10 Hz square wave; the
watchdog's period of about 0.2 s is 4 changes, docs/RELIABILITY.md)."""
HEARTBEAT_PERIOD_S = 0.05
"""How often the driver's heartbeat thread writes ``h`` [s]."""
DEFAULT_TIMEOUT_S = 0.3
"""No heartbeat for this long trips the guardian [s] (6 periods; the SIGSTOP case's detection time)."""
STOP_DEADLINE_S = 1.0
"""The stop of one trip gives up after this long [s]; a side not reached is retried while latched."""
RETRY_PERIOD_S = 0.2
"""While latched, a side whose stop failed is tried again this often [s]."""
ACK_TIMEOUT_S = 0.05
"""Wait for each acknowledge of the guardian's own frames [s] (des-protocol.md: about 50 ms)."""
REOPEN_PERIOD_S = 0.2
"""A lost amplifier port is reopened this often [s]."""
SELF_WATCHDOG_S = 5.0
"""A loop turn longer than this (never expected: every wait is bounded) ends the guardian [s]."""
READY_TIMEOUT_S = 20.0
"""The driver waits this long for the guardian's first line [s] (a loaded 2-core machine: ~1 s)."""

_REPLY_OPS = frozenset(
    {
        OpCode.READ_SYS_STATUS,
        OpCode.READ_ERROR,
        OpCode.READ_TEMP_PARAM,
        OpCode.READ_VERSION,
        OpCode.READ_VELOCITY_IS_MUST,
        OpCode.READ_CURRENT_IS_MUST,
    }
)
"""Commands the amplifier answers with a reply frame (des-protocol.md, command table)."""
_OK, _FAIL = bytes((ACK_OK,)), bytes((ACK_FAIL,))


# -- the exchange on one line, seen from both directions ---------------------------------------------


class Exchange:
    """Where the exchange on one line stands, from the bytes the guardian forwards (both ways).

    States: ``idle``; ``op_ack`` (the host sent an op code, the amplifier's 'O'/'F' is due);
    ``host_body`` (the host is sending the body); ``frame_ack`` (the amplifier's 'O'/'F' to the
    body is due); ``reply_op`` (the reply's op code 0x00 is due); ``start_ack`` (the host's 'O' to
    it is due); ``amp_body`` (the amplifier is sending the reply body); ``final_ack`` (the host's
    'O'/'F' to it is due). :meth:`completion` gives the bytes that end the exchange from the host's
    side without executing anything; :attr:`amp_speaks` says when only the amplifier can move it on.
    """

    AMP_SPEAKS = frozenset({'op_ack', 'frame_ack', 'reply_op', 'amp_body'})

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.state = 'idle'
        self.opcode = 0
        self.body = bytearray()  # the host's body so far (host_body) or the reply's (amp_body)

    @property
    def amp_speaks(self) -> bool:
        return self.state in self.AMP_SPEAKS

    def host(self, data: bytes) -> None:
        for byte in data:
            self._host_byte(byte)

    def amp(self, data: bytes) -> None:
        for byte in data:
            self._amp_byte(byte)

    def _host_byte(self, byte: int) -> None:
        state = self.state
        if state == 'host_body':
            self.body.append(byte)
            if len(self.body) == 1 and byte + 1 > MAX_WORDS:
                self.state = 'frame_ack'  # the amplifier refuses an oversized frame at once
            elif len(self.body) >= body_length(self.body[0]):
                self.state = 'frame_ack'
        elif state == 'start_ack':
            self.state, self.body = ('amp_body', bytearray()) if byte == ACK_OK else ('idle', bytearray())
        elif state == 'final_ack':
            self.state = 'reply_op' if byte == ACK_FAIL else 'idle'  # after 'F' the DES may repeat
        else:  # idle, or the host gave up waiting and starts over: an op code
            self.state, self.opcode, self.body = 'op_ack', byte, bytearray()

    def _amp_byte(self, byte: int) -> None:
        state = self.state
        if state == 'op_ack':
            self.state = 'host_body' if byte == ACK_OK else 'idle'
            self.body = bytearray()
        elif state == 'frame_ack':
            self.state = 'reply_op' if byte == ACK_OK and self.opcode in _REPLY_OPS else 'idle'
        elif state == 'reply_op':
            if byte == REPLY_OPCODE:
                self.state = 'start_ack'
        elif state == 'amp_body':
            self.body.append(byte)
            if len(self.body) >= body_length(min(self.body[0], MAX_WORDS)):
                self.state = 'final_ack'
        # other states: line noise or a reset amplifier; nothing to follow

    def completion(self) -> bytes:
        """What the host sends to end the exchange now: the rest of its frame with a CRC that cannot
        match (zeros for missing data, bytes 0x00 / 0x80, none of which is an op code, so an
        amplifier that has already given up on the frame ignores them too), or 'O' to a reply."""
        if self.state == 'start_ack' or self.state == 'final_ack':
            return _OK
        if self.state != 'host_body':
            return b''
        head = bytes(self.body) or b'\x00'  # no len-1 sent yet: one word
        total = body_length(head[0])
        data = bytearray(head[: total - 2])
        data += bytes(total - 2 - len(data))  # missing data: zeros
        words = tuple(int.from_bytes(data[1 + 2 * i : 3 + 2 * i], 'little') for i in range(head[0] + 1))
        right = frame_crc(self.opcode, words).to_bytes(2, 'little')
        crc = bytearray(head[total - 2 : total])  # the CRC byte already sent, if any
        if not crc:
            crc = bytearray(b'\x00\x00' if right != b'\x00\x00' else b'\x80\x80')
        elif len(crc) == 1:
            crc.append(0x00 if crc[0] != right[0] or right[1] != 0x00 else 0x80)
        return bytes(data + crc)[len(self.body) :]


# -- the hardware watchdog's feed ---------------------------------------------------------------------


class WatchdogFeed:
    """The feed of a hardware watchdog on the amplifiers' enable input: one modem-control line
    (pyserial's ``dtr`` or ``rts`` attribute, one ioctl TIOCMBIS / TIOCMBIC per change) of every
    amplifier port, changed every ``period_s`` [s] while :meth:`step` is told the way is clear, left
    as it is otherwise (held: the watchdog then drops the enable after its own period).

    A port that refuses the change (a pseudo-terminal has no modem lines: ENOTTY; an unplugged adapter:
    EIO) is named once in ``log`` and kept in :attr:`refused`; the feed goes on on the others (a line
    that does not move is a held feed: the safe side). Each change of state (changing, held) is one
    line in ``log`` with its time on the system-wide monotonic clock (``time.monotonic``), which is
    how a test or bench in another process reads when the feed stopped.
    """

    def __init__(self, line: str, *, period_s: float = FEED_PERIOD_S, log: Callable[[str], None]) -> None:
        if line not in FEED_LINES[1:]:
            raise GuardianError(f'feed must be one of {", ".join(FEED_LINES)}, not {line!r}')
        self.line = line
        self.period_s = period_s
        self.log = log
        self.running = False
        self.changes = 0
        self.last_change_s = -math.inf  # [s, time.monotonic]
        self.held_s = -math.inf
        self.held_why = 'not started'
        self.refused: dict[str, str] = {}  # port name -> the latest error setting the line
        self._level: bool | None = None  # the level set last ([None]: as the port opened)
        self._next_s = 0.0

    def probe(self, name: str, ser: object) -> None:
        """At open: set the line to the level it has (no change: the kernel and pyserial raise DTR
        and RTS on open), to learn at once whether the port takes it."""
        self._set(name, ser, bool(getattr(ser, self.line)))

    def step(self, now: float, serials: dict[str, object], hold: str) -> None:
        """One turn of the guardian's loop at ``now`` [s]: ``hold`` is why the line must stay as it
        is ('' when the way is clear); ``serials`` the open ports by name."""
        if hold:
            if self.running:
                self.running = False
                self.held_s, self.held_why = now, hold
                self.log(
                    f'watchdog feed: {self.line.upper()} held ({hold}) at t={now:.6f} s; last change at '
                    f't={self.last_change_s:.6f} s, {self.changes} changes'
                )
            return
        if not self.running:
            self.running = True
            self._next_s = now
            self.log(
                f'watchdog feed: {self.line.upper()} changing every {1000 * self.period_s:.0f} ms on '
                f'{", ".join(serials)} from t={now:.6f} s'
            )
        if now < self._next_s:
            return
        level = not (self._level if self._level is not None else self._first_level(serials))
        for name, ser in serials.items():
            self._set(name, ser, level)
        self._level = level
        self.changes += 1
        self.last_change_s = now
        self._next_s += self.period_s  # a fixed rate; a late turn does not bunch the changes up
        if self._next_s <= now:
            self._next_s = now + self.period_s

    def _first_level(self, serials: dict[str, object]) -> bool:
        return any(bool(getattr(ser, self.line)) for ser in serials.values())

    def _set(self, name: str, ser: object, level: bool) -> None:
        try:
            setattr(ser, self.line, level)
        except (OSError, ValueError) as err:  # serial.SerialException is an OSError
            if name not in self.refused:
                self.log(
                    f'watchdog feed: {name} refuses {self.line.upper()} ({err}): '
                    'this port feeds no watchdog (a pseudo-terminal has no modem lines)'
                )
            self.refused[name] = str(err)
        else:
            if self.refused.pop(name, None) is not None:
                self.log(f'watchdog feed: {name} takes {self.line.upper()} again')


# -- one amplifier line ------------------------------------------------------------------------------


@dataclass
class _Side:
    name: str
    device: str  # the amplifier's port (device path)
    link: str  # the stable path the driver opens (a symlink to the proxy pty)
    real: int = -1  # the amplifier port's descriptor, -1 while lost
    master: int = -1  # the proxy pty's master, -1 while the amplifier port is lost
    slave: int = -1  # kept open so the master never reads EIO while the driver reopens its port
    serial: object = None  # the pyserial object that configured ``real`` (kept to keep it open)
    exchange: Exchange = field(default_factory=Exchange)
    stopped: bool = False  # zero and disable acknowledged since the trip
    lost_at: float = -1.0
    forwarded: int = 0
    dropped: int = 0


class GuardianError(Exception):
    """The guardian cannot start (a port cannot be opened)."""


class Guardian:
    """The guardian's state and loop (see the module docstring); ``log`` takes its lines (default:
    :func:`log_line`, stderr without ever blocking)."""

    def __init__(
        self,
        ports: dict[str, str],
        control: socket.socket,
        *,
        baud: int = 38400,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        feed: str = 'none',
        log: Callable[[str], None] | None = None,
    ) -> None:
        if baud not in BAUD_CODES:
            raise GuardianError(f'baud must be one of {sorted(BAUD_CODES)}, not {baud}')
        self.baud = baud
        self.byte_time_s = 10.0 / baud
        self.timeout_s = timeout_s
        self.control = control
        self.log = log or log_line
        self.dir = tempfile.mkdtemp(prefix='des-guardian-')
        self.sides = [_Side(name, device, os.path.join(self.dir, name)) for name, device in ports.items()]
        self.feed = None if feed == 'none' else WatchdogFeed(feed, log=self.log)
        self.driving = False  # the driver's latest heartbeat was 'h' (not 'i'): the feed may run
        self.latched = False
        self.trips = 0
        self.last_beat = time.monotonic()
        self.ending = ''  # why the loop ends after the stop (EOF, quit, signal)
        self.attempts = 0  # of the latest stop: rounds of zero + disable until every side answered
        self._next_retry = 0.0
        try:
            for side in self.sides:
                self._open(side)
        except BaseException:
            self.close()
            raise

    # -- ports --------------------------------------------------------------------------------------

    def _open(self, side: _Side) -> None:
        import serial  # pyserial configures the line (termios); the guardian then uses the descriptor

        try:
            ser = serial.Serial(side.device, baudrate=self.baud, timeout=0, write_timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as err:
            raise GuardianError(f'cannot open DES port {side.device}: {err}') from err
        side.serial, side.real = ser, ser.fileno()
        os.set_blocking(side.real, False)
        if self.feed is not None:
            with contextlib.suppress(termios.error):  # no hang-up on close: the line stays as it is
                attrs = termios.tcgetattr(side.real)
                attrs[2] &= ~termios.HUPCL
                termios.tcsetattr(side.real, termios.TCSANOW, attrs)
            self.feed.probe(side.name, ser)
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        side.master, side.slave = master, slave
        tmp = side.link + '.tmp'
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, side.link)
        side.exchange.reset()
        side.lost_at = -1.0

    def _lose(self, side: _Side, why: str) -> None:
        """The amplifier's port is gone: so is the driver's (its reads fail: 'port lost') until it is back."""
        self.log(f'{side.name}: port {side.device} lost ({why}); reopening every {REOPEN_PERIOD_S:g} s')
        self._close_side(side)
        side.lost_at = time.monotonic()

    def _close_side(self, side: _Side) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(side.link)
        for fd in (side.master, side.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        if side.serial is not None:
            with contextlib.suppress(Exception):
                side.serial.close()  # type: ignore[attr-defined]  # a pyserial Serial
        side.master = side.slave = side.real = -1
        side.serial = None

    def _reopen_lost(self, now: float) -> None:
        for side in self.sides:
            if side.real < 0 and now - side.lost_at >= REOPEN_PERIOD_S:
                try:
                    self._open(side)
                except GuardianError:
                    side.lost_at = now
                    continue
                self.log(f'{side.name}: port {side.device} back')
                side.stopped = False

    def close(self) -> None:
        for side in self.sides:
            self._close_side(side)
        shutil.rmtree(self.dir, ignore_errors=True)

    # -- the loop -----------------------------------------------------------------------------------

    def ready_line(self) -> bytes:
        answer: dict[str, object] = {'ports': {s.name: s.link for s in self.sides}}
        if self.feed is not None:
            answer['feed'] = self.feed.line
            answer['feed_refused'] = dict(self.feed.refused)
        return json.dumps(answer).encode() + b'\n'

    def feed_hold(self, now: float) -> str:
        """Why the watchdog feed must hold its line now ('' when it may change it)."""
        if self.ending:
            return self.ending
        if self.latched:
            return 'tripped: latched until the driver re-arms'
        if now - self.last_beat > self.timeout_s:
            return f'no heartbeat for {now - self.last_beat:.2f} s'
        if not self.driving:
            return 'the driver has no fresh command in force, a link down or a fault'
        lost = [s.name for s in self.sides if s.real < 0]
        return f'port lost: {", ".join(lost)}' if lost else ''

    def _step_feed(self, now: float, hold: str = '') -> None:
        if self.feed is not None:
            serials = {s.name: s.serial for s in self.sides if s.serial is not None and s.real >= 0}
            self.feed.step(now, serials, hold or self.feed_hold(now))

    def run(self) -> int:
        """Forward, watch, stop; returns the exit code (0: every side stopped at the end, 1: not)."""
        self.last_beat = time.monotonic()
        while True:
            signal.setitimer(signal.ITIMER_REAL, SELF_WATCHDOG_S)
            now = time.monotonic()
            if self.ending:
                self.trip(self.ending)
                return 0 if all(s.stopped for s in self.sides) else 1
            if not self.latched and now - self.last_beat > self.timeout_s:
                self._on_control()  # beats that queued while this process was not scheduled count
                if not self.ending and now - self.last_beat > self.timeout_s:
                    self.trip(f'no heartbeat for {now - self.last_beat:.2f} s (driver stopped or frozen)')
            if self.latched and now >= self._next_retry and not all(s.stopped for s in self.sides):
                self._stop(time.monotonic() + STOP_DEADLINE_S, only_unstopped=True)
                self._next_retry = time.monotonic() + RETRY_PERIOD_S
            self._reopen_lost(now)
            self._step_feed(time.monotonic())
            self._turn(now)

    def _turn(self, now: float) -> None:
        fds = [self.control.fileno()]
        for side in self.sides:
            fds += [fd for fd in (side.master, side.real) if fd >= 0]
        wait = 0.01 if self.latched else max(0.0, min(0.01, self.last_beat + self.timeout_s - now))
        try:
            ready, _, _ = select.select(fds, [], [], wait)
        except InterruptedError:
            return
        if self.control.fileno() in ready:
            self._on_control()
        for side in self.sides:
            if side.real >= 0 and side.real in ready:
                self._from_amplifier(side)
            if side.master >= 0 and side.master in ready:
                self._from_driver(side)

    def _on_control(self) -> None:
        try:
            data = self.control.recv(4096)
        except BlockingIOError:
            return
        except OSError as err:
            data = b''
            self.log(f'control channel failed: {err}')
        if not data:
            self.ending = self.ending or 'driver gone (control channel EOF)'
            return
        beat = max(data.rfind(HEARTBEAT), data.rfind(IDLE))
        if beat >= 0:
            self.last_beat = time.monotonic()
            self.driving = data[beat : beat + 1] == HEARTBEAT
        if ARM in data and self.latched:
            self._arm()
        if QUIT in data:
            self.ending = self.ending or 'driver quit'

    def _arm(self) -> None:
        for side in self.sides:
            if side.master >= 0:
                _drain(side.master)  # what the driver sent while latched (an op code it retries)
            if side.real >= 0:
                _drain(side.real)
            side.exchange.reset()
            side.stopped = False
        self.latched = False
        self.driving = False  # the feed waits for the driver's next 'h'
        self.last_beat = time.monotonic()
        self.log('re-armed by the driver: forwarding again')

    def _from_driver(self, side: _Side) -> None:
        try:
            data = os.read(side.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # EIO: the driver has its port closed (reconnecting); the slave we hold keeps it
        if self.latched or not data:
            side.dropped += len(data)
            return
        side.exchange.host(data)
        self._forward(side, side.real, data)

    def _from_amplifier(self, side: _Side) -> None:
        try:
            data = os.read(side.real, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as err:
            self._lose(side, str(err))
            return
        if not data:
            self._lose(side, 'end of file')
            return
        if self.latched:
            return  # an answer to our own frames after their deadline, or noise
        side.exchange.amp(data)
        self._forward(side, side.master, data)

    def _forward(self, side: _Side, fd: int, data: bytes) -> None:
        try:
            written = os.write(fd, data)
        except (BlockingIOError, InterruptedError):
            written = 0
        except OSError as err:
            if fd == side.real and err.errno in (errno.EIO, errno.ENXIO, errno.ENODEV):
                self._lose(side, str(err))
            return
        side.forwarded += written
        side.dropped += len(data) - written  # never wait: the other end is not reading

    # -- the stop -----------------------------------------------------------------------------------

    def trip(self, reason: str) -> None:
        """Stop forwarding, finish each line's exchange, zero then disable both amplifiers; latch."""
        started = time.monotonic()
        first = not self.latched
        self.latched = True
        self._step_feed(started, f'tripped: {reason}')  # held before the stop (up to STOP_DEADLINE_S)
        if first:
            self.trips += 1
        results = self._stop(started + STOP_DEADLINE_S, only_unstopped=not first)
        self._next_retry = time.monotonic() + RETRY_PERIOD_S
        took = 1000 * (time.monotonic() - started)
        text = ', '.join(
            f'{n}: {"zeroed and disabled" if ok else "NOT reached"}' for n, ok in results.items()
        )
        if first or not all(results.values()):
            tries = f'{self.attempts} attempt{"s" if self.attempts != 1 else ""}'
            what = 'final stop' if reason == 'driver quit' else 'tripped'  # quit: the driver stopped first
            self.log(f'{what} ({reason}): {text} in {took:.0f} ms ({tries})')
        if first:
            with contextlib.suppress(OSError):
                self.control.send(TRIPPED)

    def _stop(self, deadline: float, *, only_unstopped: bool) -> dict[str, bool]:
        sides = [s for s in self.sides if s.real >= 0 and not (only_unstopped and s.stopped)]
        self._finish_exchanges(sides, deadline)
        for side in sides:
            _drain(side.real)
        pending = list(sides)
        self.attempts = 0
        while pending and time.monotonic() < deadline:
            self.attempts += 1
            zeroed = self._transact(pending, OpCode.SET_VELOCITY, (0,), deadline)
            disabled = self._transact(zeroed, OpCode.ENABLE, (0,), deadline)
            for side in disabled:
                side.stopped = True
            pending = [s for s in pending if not s.stopped]
            if pending:  # garbled or refused: let the line settle, then try again
                _wait_quiet([s.real for s in pending if s.real >= 0], 2 * ACK_TIMEOUT_S, deadline)
        return {s.name: s.stopped for s in self.sides}

    def _finish_exchanges(self, sides: list[_Side], deadline: float) -> None:
        """End the driver's exchange in flight on every line, all lines at once, so that each
        amplifier waits for an op code again."""
        active = [s for s in sides if s.exchange.state != 'idle']
        body_s = body_length(MAX_WORDS - 1) * self.byte_time_s
        for _ in range(64):  # bytes may come one at a time; bounded by the deadline too
            active = [s for s in active if s.exchange.state != 'idle']
            if not active or time.monotonic() >= deadline:
                break
            for side in active:
                if not side.exchange.amp_speaks:
                    data = side.exchange.completion()
                    if _write_all(side.real, data, deadline):
                        side.exchange.host(data)
                    else:
                        side.exchange.reset()
            listening = {s.real: s for s in active if s.exchange.amp_speaks}
            heard = _read_each(list(listening), min(deadline, time.monotonic() + ACK_TIMEOUT_S + body_s))
            for fd, side in listening.items():
                if heard.get(fd):
                    side.exchange.amp(heard[fd])
                else:
                    side.exchange.reset()  # it said nothing: it gave up on the exchange itself
        for side in sides:
            side.exchange.reset()

    def _transact(
        self, sides: list[_Side], opcode: int, words: tuple[int, ...], deadline: float
    ) -> list[_Side]:
        """One command without a reply on every line at once; the sides that acknowledged both steps."""
        body = encode_body(opcode, words)
        sent = [s for s in sides if _write_all(s.real, bytes((opcode,)), deadline)]
        acked = self._acks(sent, ACK_TIMEOUT_S, deadline)
        sent = [s for s in acked if _write_all(s.real, body, deadline)]
        return self._acks(sent, ACK_TIMEOUT_S + len(body) * self.byte_time_s, deadline)

    def _acks(self, sides: list[_Side], timeout_s: float, deadline: float) -> list[_Side]:
        until = min(deadline, time.monotonic() + timeout_s)
        answers: dict[int, bytes] = {}
        waiting = {s.real: s for s in sides}
        while waiting and (left := until - time.monotonic()) > 0:
            try:
                ready, _, _ = select.select(list(waiting), [], [], left)
            except InterruptedError:
                continue
            for fd in ready:
                try:
                    data = os.read(fd, 1)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:
                    data = b'?'
                answers[fd] = data or b'?'
                waiting.pop(fd)
        return [s for s in sides if answers.get(s.real) == _OK]


# -- bounded I/O on non-blocking descriptors ----------------------------------------------------------


def log_line(text: str) -> None:
    """One line on stderr, or none: never blocks (a pipe nobody reads, a terminal held by Ctrl-S),
    never raises (a closed pipe). stderr is the driver's, shared: it stays blocking for the driver;
    a line shorter than PIPE_BUF is written whole when select says there is room."""
    data = f'des guardian: {text}\n'.encode(errors='replace')[:4000]
    with contextlib.suppress(OSError, ValueError):
        _, writable, _ = select.select([], [2], [], 0)
        if writable:
            os.write(2, data)


def _write_all(fd: int, data: bytes, deadline: float) -> bool:
    """Write ``data`` before ``deadline``; False if that was not possible (the rest is not sent)."""
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view) :]
            continue
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            return False
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        with contextlib.suppress(InterruptedError):
            select.select([], [fd], [], left)
    return True


def _read_each(fds: list[int], deadline: float) -> dict[int, bytes]:
    """What arrives on each of ``fds`` before ``deadline``: returns once every one said something
    (its first chunk), or at the deadline with those that did."""
    heard: dict[int, bytes] = {}
    while (waiting := [fd for fd in fds if fd not in heard]) and (left := deadline - time.monotonic()) > 0:
        try:
            ready, _, _ = select.select(waiting, [], [], left)
        except InterruptedError:
            continue
        for fd in ready:
            try:
                heard[fd] = os.read(fd, 64)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                heard[fd] = b''
    return heard


def _drain(fd: int) -> None:
    """Discard what is waiting on ``fd`` now (input flush, and what is already read in)."""
    with contextlib.suppress(OSError, termios.error):
        termios.tcflush(fd, termios.TCIFLUSH)
    for _ in range(64):
        try:
            if not os.read(fd, 4096):
                return
        except OSError:
            return


def _wait_quiet(fds: list[int], quiet_s: float, deadline: float) -> None:
    """Read and drop bytes until none came for ``quiet_s`` on any of ``fds`` (or the deadline)."""
    until = min(deadline, time.monotonic() + quiet_s)
    while fds and (left := until - time.monotonic()) > 0:
        try:
            ready, _, _ = select.select(fds, [], [], left)
        except InterruptedError:
            continue
        for fd in ready:
            _drain(fd)
        if ready:
            until = min(deadline, time.monotonic() + quiet_s)


# -- the driver's end of it ---------------------------------------------------------------------------


class GuardianClient:
    """Starts a guardian process for ``ports`` ({side: device}), beats its heartbeat and answers its
    trips (from a thread of its own, in the driver's process; no ROS).

    With ``feed`` 'dtr' or 'rts' the guardian feeds a hardware watchdog; ``driving()`` is then asked
    before every heartbeat whether a fresh command is in force on healthy links (``h``; false or an
    exception: ``i``, the feed holds). :attr:`feed_refused` names the ports that refused the line at
    start ({side: error}).

    ``on_trip(reason)`` runs in that thread when the guardian tripped while this process was still
    alive (it was frozen or slow): it must drop the held command and reset the links; the client then
    re-arms the guardian. ``on_lost(reason)`` runs when the guardian ended without being asked (its
    ports are then gone too). :meth:`start` returns the ports the driver opens instead ({side: path}).
    """

    def __init__(
        self,
        ports: dict[str, str],
        *,
        baud: int = 38400,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        on_trip: Callable[[str], None] = lambda reason: None,
        on_lost: Callable[[str], None] = lambda reason: None,
        stderr: int | None = None,
        feed: str = 'none',
        driving: Callable[[], bool] = lambda: True,
    ) -> None:
        if feed not in FEED_LINES:
            raise GuardianError(f'feed must be one of {", ".join(FEED_LINES)}, not {feed!r}')
        self.feed = feed
        self.driving = driving
        self.feed_refused: dict[str, str] = {}
        self.ports = dict(ports)
        self.stderr = stderr  # the guardian's log lines (default: this process's stderr)
        self.baud = baud
        self.timeout_s = timeout_s
        self.on_trip = on_trip
        self.on_lost = on_lost
        self.proc: subprocess.Popen[bytes] | None = None
        self.sock: socket.socket | None = None
        self.proxy_ports: dict[str, str] = {}
        self.trips = 0
        self.lost = ''
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None

    def command(self, control_fd: int) -> list[str]:
        argv = [sys.executable, '-m', 'skidsteer_power.des.guardian', '--control-fd', str(control_fd)]
        argv += ['--baud', str(self.baud), '--timeout', repr(self.timeout_s)]
        if self.feed != 'none':
            argv += ['--feed', self.feed]
        for side, device in self.ports.items():
            argv += ['--port', f'{side}={device}']
        return argv

    def start(self, ready_timeout_s: float = READY_TIMEOUT_S) -> dict[str, str]:
        """Start the guardian and wait for its ports; GuardianError (with its reason) if it cannot."""
        ours, theirs = socket.socketpair()
        try:
            self.proc = subprocess.Popen(
                self.command(theirs.fileno()),
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                stderr=self.stderr,
                start_new_session=True,  # a terminal's Ctrl-C / Ctrl-Z reaches the driver, not the guardian
            )
        finally:
            theirs.close()
        self.sock = ours
        try:
            line = _read_line(ours, time.monotonic() + ready_timeout_s)
            answer = json.loads(line) if line else {'error': 'no answer (did it start?)'}
            if 'ports' not in answer:
                raise GuardianError(f'DES guardian: {answer.get("error", answer)}')
        except BaseException:
            self.close()
            raise
        ours.setblocking(False)
        self.proxy_ports = {str(k): str(v) for k, v in answer['ports'].items()}
        self.feed_refused = {str(k): str(v) for k, v in answer.get('feed_refused', {}).items()}
        self._thread = threading.Thread(target=self._beat, name='des-guardian-heartbeat', daemon=True)
        self._thread.start()
        return dict(self.proxy_ports)

    @property
    def alive(self) -> bool:
        """The guardian runs, answered its ports, and has not been lost."""
        return self.proc is not None and self.proc.poll() is None and bool(self.proxy_ports) and not self.lost

    def _beat(self) -> None:
        sock = self.sock
        assert sock is not None
        while not self._closing.wait(HEARTBEAT_PERIOD_S):
            try:
                sock.send(self._beat_byte())
                data = sock.recv(64)
            except BlockingIOError:
                data = None
            except OSError as err:
                data = b''
                reason = f'control channel failed: {err}'
            else:
                reason = 'guardian ended (control channel EOF)'
            if data == b'' and not self._closing.is_set():
                self.lost = reason
                self.on_lost(reason)
                return
            if data and TRIPPED in data and not self._closing.is_set():
                self.trips += 1
                # re-armed only once on_trip returned: if it raised, the stop stays latched (and the
                # heartbeats end with this thread)
                self.on_trip(f'guardian trip {self.trips}: it saw no heartbeat for {self.timeout_s:g} s')
                with contextlib.suppress(OSError):
                    sock.send(ARM)

    def _beat_byte(self) -> bytes:
        if self.feed == 'none':
            return HEARTBEAT  # no feed: the driver's state is not asked (as before the feed)
        try:
            return HEARTBEAT if self.driving() else IDLE
        except Exception:  # whatever went wrong, the feed holds: the safe side
            return IDLE

    def close(self, timeout_s: float = 3.0) -> None:
        """Ask the guardian to stop the amplifiers and end; kill it if it does not (idempotent)."""
        self._closing.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self._thread = None
        if self.sock is not None:
            with contextlib.suppress(OSError):
                self.sock.send(QUIT)
        if self.proc is not None:
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.sock is not None:
            self.sock.close()
            self.sock = None
        self.proxy_ports = {}


def _read_line(sock: socket.socket, deadline: float) -> bytes:
    data = b''
    while b'\n' not in data and (left := deadline - time.monotonic()) > 0:
        ready, _, _ = select.select([sock], [], [], left)
        if ready:
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
    return data.split(b'\n', 1)[0]


# -- the process --------------------------------------------------------------------------------------


def _port_arg(text: str) -> tuple[str, str]:
    name, sep, device = text.partition('=')
    if not sep or not name or not device:
        raise argparse.ArgumentTypeError(f'expected SIDE=DEVICE, not {text!r}')
    return name, device


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m skidsteer_power.des.guardian', description=__doc__)
    parser.add_argument('--control-fd', type=int, required=True, help='the socketpair end from the driver')
    parser.add_argument('--port', type=_port_arg, action='append', required=True, help='SIDE=DEVICE')
    parser.add_argument('--baud', type=int, default=38400, help='link speed [bit/s]')
    parser.add_argument(
        '--timeout', type=float, default=DEFAULT_TIMEOUT_S, help='heartbeat timeout [s] (0.05 .. 5)'
    )
    parser.add_argument(
        '--feed',
        choices=FEED_LINES,
        default='none',
        help="modem-control line of every port toggled as a hardware watchdog's feed (default none)",
    )
    args = parser.parse_args(argv)
    control = socket.socket(fileno=args.control_fd)
    if not 0.05 <= args.timeout <= 5.0:
        control.sendall(
            json.dumps({'error': f'--timeout {args.timeout} is outside 0.05 .. 5 s'}).encode() + b'\n'
        )
        return 2
    try:
        guardian = Guardian(dict(args.port), control, baud=args.baud, timeout_s=args.timeout, feed=args.feed)
    except GuardianError as err:
        with contextlib.suppress(OSError):
            control.sendall(json.dumps({'error': str(err)}).encode() + b'\n')
        return 2

    def on_signal(signum: int, _frame: object) -> None:
        guardian.ending = guardian.ending or f'signal {signal.Signals(signum).name}'

    for signum in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(signum, on_signal)
    try:
        control.sendall(guardian.ready_line())
        control.setblocking(False)
        return guardian.run()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        guardian.close()


if __name__ == '__main__':
    sys.exit(main())
