"""Serial transport of the DES 70/10 protocol: one :meth:`DesLink.transact` alone touches the port.

The port is opened with :func:`serial.serial_for_url`, so a device path, a pty path or a pyserial
URL (``loop://``, ``socket://``) all work. Every wait has a deadline from :func:`time.monotonic`;
failed transactions are retried a bounded number of times, with the input flushed in between, and a
whole transaction (its retries and the repeats of a reply refused for its CRC included) never takes
longer than ``LinkTiming.exchange_timeout_s`` (issue 34: a reply whose CRC was always wrong made one
exchange retry for 10 s, 3942 times). :attr:`DesLink.abort` (a stop became due) ends the retries at
the next step that leaves the amplifier's side of the protocol idle.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import serial

from skidsteer_power.des.errors import (
    DesCrcError,
    DesFrameError,
    DesLinkError,
    DesNak,
    DesPortError,
    DesTimeout,
)
from skidsteer_power.des.protocol import (
    ACK_FAIL,
    ACK_OK,
    DUMMY,
    DesConfig,
    Frame,
    FrameDecoder,
    FrameStart,
    body_length,
    encode_body,
)
from skidsteer_power.errors import ConfigError

_OK = bytes((ACK_OK,))
_FAIL = bytes((ACK_FAIL,))
_READ_SLICE_S = 0.005
_ANSWER_CAP_S = 0.25
"""Largest answer time [s] that lengthens the waits (:meth:`DesLink._wait_s`): at most 0.5 s."""
"""pyserial read timeout [s]: the granularity with which a deadline is checked while waiting."""


@dataclass(frozen=True)
class LinkTiming:
    """Deadlines and retries of one link.

    Attributes
    ----------
    ack_timeout_s : wait for each 'O'/'F' from the DES [s] (existing drivers: about 50 ms)
    reply_timeout_s : wait for the reply op code after the frame was acknowledged [s]
    slack_s : allowance beyond the byte time for a body to arrive [s]
    retries : extra attempts after a failed transaction (no answer, NAK, CRC, garbled) [-]
    crc_repeats : repeats of a reply asked for with 'F' after a wrong CRC, per attempt [-]
    exchange_timeout_s : longest time one transaction may take, retries and repeats included [s]
    """

    ack_timeout_s: float = 0.05
    reply_timeout_s: float = 0.05
    slack_s: float = 0.02
    retries: int = 2
    crc_repeats: int = 2
    exchange_timeout_s: float = 0.25

    def __post_init__(self) -> None:
        timeouts = (self.ack_timeout_s, self.reply_timeout_s, self.slack_s, self.exchange_timeout_s)
        if min(timeouts) <= 0 or self.retries < 0 or self.crc_repeats < 0:
            raise ConfigError(f'timeouts must be > 0, retries and crc_repeats >= 0: {self}')


@dataclass
class LinkStats:
    """Counters of one link (for diagnostics and benchmarks)."""

    transactions: int = 0
    failures: int = 0
    retries: int = 0
    timeouts: int = 0
    naks: int = 0
    crc_errors: int = 0
    frame_errors: int = 0
    bytes_sent: int = 0
    bytes_received: int = 0
    flushed_bytes: int = 0
    opens: int = 0
    lost: int = 0
    last_error: str = ''

    def as_dict(self) -> dict[str, int | str]:
        return dict(self.__dict__)


_COUNTER = {DesTimeout: 'timeouts', DesNak: 'naks', DesCrcError: 'crc_errors', DesFrameError: 'frame_errors'}


@dataclass
class DesLink:
    """One serial link to one DES amplifier.

    ``port`` is a device path or pyserial URL. Call :meth:`open` (or use ``with``); a lost port
    raises :class:`DesPortError` and closes the link, and :meth:`open` may be called again.
    """

    port: str
    config: DesConfig = field(default_factory=DesConfig)
    timing: LinkTiming = field(default_factory=LinkTiming)

    def __post_init__(self) -> None:
        self._serial: serial.SerialBase | None = None
        self._lock = threading.Lock()
        self.stats = LinkStats()
        self._byte_time_s = 10.0 / self.config.baudrate  # 8N1: start + 8 data + stop bits
        self._deadline = float('inf')  # of the transaction under way (time.monotonic) [s]
        self._answer_s = 0.0  # the slowest recent acknowledge, decaying by 2 % per answer [s]
        self.abort: Callable[[], bool] | None = None
        """True when the transaction under way should give up at its next retry or CRC repeat."""

    # -- port -----------------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self._serial is not None

    @property
    def byte_time_s(self) -> float:
        """Time one byte occupies the line at the configured baud rate [s]."""
        return self._byte_time_s

    def open(self) -> DesLink:
        """Open the port (8N1, no flow control); :class:`DesPortError` if that fails."""
        with self._lock:
            if self._serial is not None:
                return self
            try:
                self._serial = serial.serial_for_url(
                    self.port,
                    baudrate=self.config.baudrate,
                    bytesize=serial.EIGHTBITS,
                    parity=serial.PARITY_NONE,
                    stopbits=serial.STOPBITS_ONE,
                    timeout=_READ_SLICE_S,
                    write_timeout=1.0,
                )
            except (serial.SerialException, OSError, ValueError) as err:
                raise DesPortError(f'cannot open DES port {self.port}: {err}') from err
            self.stats.opens += 1
        return self

    def close(self) -> None:
        """Close the port (idempotent)."""
        with self._lock:
            self._close_locked()

    def _close_locked(self) -> None:
        ser, self._serial = self._serial, None
        if ser is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                ser.close()

    def __enter__(self) -> DesLink:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- transactions ---------------------------------------------------------------------------

    def transact(self, opcode: int, words: tuple[int, ...] = DUMMY, reply_words: int = 0) -> tuple[int, ...]:
        """Send one command and return the reply's words (``()`` when ``reply_words`` is 0).

        ``words`` are 16-bit words (see :func:`~skidsteer_power.des.protocol.to_word`);
        ``reply_words`` is the exact number of words the reply must hold. Raises a
        :class:`DesLinkError` after ``timing.retries`` failed retries, or :class:`DesPortError` at
        once when the port is lost (the link is then closed).
        """
        with self._lock:
            if self._serial is None:
                raise DesPortError(f'DES port {self.port} is not open')
            self.stats.transactions += 1
            last: DesLinkError | None = None
            self._deadline = time.monotonic() + self.timing.exchange_timeout_s
            for attempt in range(self.timing.retries + 1):
                if attempt:
                    if self._give_up(reply_words):
                        break
                    self.stats.retries += 1
                try:
                    return self._transact_once(opcode, words, reply_words)
                except DesPortError as err:
                    self.stats.lost += 1
                    self.stats.failures += 1
                    self.stats.last_error = str(err)
                    self._close_locked()
                    raise
                except (DesTimeout, DesNak, DesCrcError, DesFrameError) as err:
                    last = err
                    if not isinstance(err, DesCrcError):  # counted where the reply was refused
                        name = _COUNTER[type(err)]
                        setattr(self.stats, name, getattr(self.stats, name) + 1)
                    try:
                        self._flush_input()
                    except DesPortError:
                        self.stats.lost += 1
                        self._close_locked()
                        raise
            assert last is not None
            self.stats.failures += 1
            self.stats.last_error = str(last)
            raise last

    def _give_up(self, reply_words: int) -> bool:
        """The transaction's time is up, or it is a read and a stop is due (:attr:`abort`; a command
        without a reply, a set point or an enable, is never cut short by it)."""
        abort = self.abort if reply_words else None
        return time.monotonic() >= self._deadline or (abort is not None and bool(abort()))

    def _transact_once(self, opcode: int, words: tuple[int, ...], reply_words: int) -> tuple[int, ...]:
        self._drop_stale_input()
        body = encode_body(opcode, words)
        self._write(bytes((opcode,)))
        self._expect_ack(self._wait_s(self.timing.ack_timeout_s), f'op code 0x{opcode:02X}')
        self._write(body)
        body_s = len(body) * self._byte_time_s
        self._expect_ack(self._wait_s(self.timing.ack_timeout_s) + body_s, f'frame 0x{opcode:02X}')
        if not reply_words:
            return ()
        return self._receive_reply(opcode, reply_words)

    def _receive_reply(self, opcode: int, reply_words: int) -> tuple[int, ...]:
        decoder = FrameDecoder()
        deadline = time.monotonic() + self._wait_s(self.timing.reply_timeout_s)
        refused: DesCrcError | None = None
        repeats = 0
        while True:
            try:
                event = decoder.next_event()
            except DesCrcError as err:
                self.stats.crc_errors += 1
                if not self.config.des_repeats_reply_after_nak:
                    self._write(_FAIL)
                    raise
                if repeats >= self.timing.crc_repeats or self._give_up(reply_words):
                    # 'O': the amplifier's side of the exchange ends idle (an 'F' would make it
                    # repeat the reply into the next command); the reply is discarded all the same
                    self._write(_OK)
                    raise
                self._write(_FAIL)
                repeats += 1
                refused = err
                deadline = time.monotonic() + self._wait_s(self.timing.reply_timeout_s)
                continue
            if isinstance(event, FrameStart):
                self._write(_OK)
                body_time = body_length(reply_words - 1) * self._byte_time_s
                deadline = time.monotonic() + body_time + self.timing.slack_s + self.timing.ack_timeout_s
            elif isinstance(event, Frame):
                if len(event.words) != reply_words:
                    self._write(_FAIL)
                    raise DesFrameError(
                        f'reply to op code 0x{opcode:02X} has {len(event.words)} words, '
                        f'expected {reply_words}'
                    )
                self._write(_OK)
                return event.words
            else:
                data = self._read(decoder.needed, deadline)
                if not data:
                    if refused is not None:
                        raise refused
                    state = 'reply body' if decoder.in_frame else 'reply'
                    raise DesTimeout(f'no {state} to op code 0x{opcode:02X} from {self.port}')
                decoder.feed(data)

    # -- the only code that touches the port ----------------------------------------------------

    def _wait_s(self, timeout_s: float) -> float:
        """A wait for an answer [s]: the configured timeout, or twice the slowest recent answer if
        longer. An amplifier or adapter that answers late but surely (an FTDI latency timer, 45 ms
        late) then costs no spurious timeouts and retries, which made a stop's time unpredictable
        (issue 34); a silent one still times out after the configured time (it never answered)."""
        return max(timeout_s, 2.0 * self._answer_s)

    def _expect_ack(self, timeout_s: float, what: str) -> None:
        start = time.monotonic()
        data = self._read(1, start + timeout_s)
        if data:
            self._answer_s = min(max(time.monotonic() - start, 0.98 * self._answer_s), _ANSWER_CAP_S)
        if not data:
            raise DesTimeout(f'no acknowledge of {what} from {self.port}')
        if data == _FAIL:
            raise DesNak(f'DES on {self.port} refused {what}')
        if data != _OK:
            raise DesFrameError(f'unexpected byte 0x{data[0]:02X} instead of an acknowledge of {what}')

    def _read(self, size: int, deadline: float) -> bytes:
        """Up to ``size`` bytes, returning as soon as any arrived; b'' at the deadline (or at the
        transaction's own deadline, whichever is first)."""
        ser = self._serial
        assert ser is not None
        deadline = min(deadline, self._deadline)
        try:
            while True:
                data: bytes = ser.read(size)  # pyserial is untyped: read gives bytes
                if data:
                    self.stats.bytes_received += len(data)
                    return data
                if time.monotonic() >= deadline:
                    return b''
        except (serial.SerialException, OSError) as err:
            raise DesPortError(f'DES port {self.port} lost: {err}') from err

    def _write(self, data: bytes) -> None:
        ser = self._serial
        assert ser is not None
        try:
            ser.write(data)
        except serial.SerialTimeoutException as err:
            raise DesTimeout(f'write to {self.port} timed out') from err
        except (serial.SerialException, OSError) as err:
            raise DesPortError(f'DES port {self.port} lost: {err}') from err
        self.stats.bytes_sent += len(data)

    def _drop_stale_input(self) -> None:
        ser = self._serial
        assert ser is not None
        try:
            waiting = ser.in_waiting
        except (serial.SerialException, OSError) as err:
            raise DesPortError(f'DES port {self.port} lost: {err}') from err
        if waiting:
            self.stats.flushed_bytes += waiting
            self._flush_input()

    def _flush_input(self) -> None:
        ser = self._serial
        if ser is None:
            return
        try:
            ser.reset_input_buffer()
        except (serial.SerialException, OSError) as err:
            raise DesPortError(f'DES port {self.port} lost: {err}') from err
