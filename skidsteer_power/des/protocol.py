"""maxon DES 70/10 (and DES 50/5) RS232 protocol: pure functions over bytes.

Everything here is free of I/O, so ``bytes`` exercise it (see ``../shared/des-protocol.md``).

Wire format (8N1, 16-bit words little-endian):

- host -> DES: op code; DES -> 'O'/'F'; host -> body; DES -> 'O'/'F'.
- DES -> host (commands with data): op code 0x00; host -> 'O'; DES -> body; host -> 'O'/'F'.
- body = len-1 (one byte: number of words minus one), the words (low byte first), the CRC word (low
  byte first). A frame is never empty: a command without parameters sends one dummy word 0x0000.
- CRC-16/XMODEM (poly 0x1021, init 0, no reflection, no final XOR) over op code, len-1 and each word
  high byte first. maxon's word-wise routine (augmented with one extra 0x0000 word) gives the same
  value; the tests check this equivalence.

Items the public sources leave UNCONFIRMED live in :class:`DesConfig` and nowhere else.
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass, field

from skidsteer_power.des.errors import DesCrcError, DesFrameError
from skidsteer_power.des.errors import DesErrorFlags as DesErrorFlags  # its home is errors.py
from skidsteer_power.errors import ConfigError, InputError

ACK_OK = 0x4F
"""'O': op code or frame accepted (either direction)."""
ACK_FAIL = 0x46
"""'F': op code or frame refused (either direction)."""
REPLY_OPCODE = 0x00
"""Op code with which the DES starts a reply frame."""
MAX_WORDS = 8
"""Longest frame accepted [words]; the longest real one (ReadVersion reply) has 4."""
DUMMY = (0,)
"""Data of a command without parameters: one dummy word."""

_WORD_MIN, _WORD_MAX = -0x8000, 0xFFFF
_BE_WORD = struct.Struct('>H')
_LE_WORD = struct.Struct('<H')


class OpCode(enum.IntEnum):
    """DES 70/10 op codes (des-protocol.md, command table)."""

    READ_SYS_STATUS = 0x01
    READ_ERROR = 0x02
    CLEAR_ERROR = 0x03
    RESET = 0x04
    ENABLE = 0x05
    READ_TEMP_PARAM = 0x14
    SET_TEMP_PARAM = 0x15
    RESET_TEMP_PARAM = 0x16
    SAVE_TEMP_PARAM = 0x17
    READ_VERSION = 0x1A
    SET_VELOCITY = 0x21
    SET_CURRENT = 0x22
    STOP_MOTION = 0x23
    READ_VELOCITY_IS_MUST = 0x28
    READ_CURRENT_IS_MUST = 0x29


class ParamFormat(enum.IntEnum):
    """Second word of ReadTempParam / SetTempParam."""

    WORD = 0
    LWORD = 1


class Param(enum.IntEnum):
    """Parameter numbers (RAM parameters, read with 0x14, set with 0x15)."""

    BAUD_RATE = 0
    SYSTEM_CONFIG = 1
    CURRENT_P = 2
    CURRENT_I = 3
    SPEED_P = 5
    SPEED_I = 6
    PEAK_CURRENT_MA = 14
    MAX_CONTINUOUS_CURRENT_MA = 15
    MAX_SPEED_RPM = 17
    ACCELERATION_RPM_PER_MS = 18
    ENCODER_RESOLUTION = 20
    POLE_PAIRS = 21
    ERROR_PROCEDURE = 43
    MAX_SPEED_CURRENT_MODE_RPM = 44


BAUD_CODES = {9600: 0, 14400: 1, 19200: 2, 38400: 3, 57600: 4, 115200: 5}
"""Baud rate -> value of system parameter 0."""


class SystemConfig(enum.IntFlag):
    """Bits of system parameter 1 (system configuration)."""

    SETPOINT_FROM_ANALOG = 1 << 0
    RAMP_OFF = 1 << 1
    CURRENT_REGULATOR = 1 << 2
    MONITOR_TORQUE = 1 << 4
    STOP_BY_SOFTWARE = 1 << 7
    MAX_SPEED_FROM_SOFTWARE = 1 << 8
    OFFSET_FROM_SOFTWARE = 1 << 9
    MAX_CURRENT_FROM_SOFTWARE = 1 << 10
    GAINS_FROM_SOFTWARE = 1 << 11
    ENABLE_BY_SOFTWARE = 1 << 12
    MONITOR_FROM_SOFTWARE = 1 << 13
    MODE_FROM_BITS = 1 << 15


class Status(enum.IntFlag):
    """System status word (ReadSysStatus, status variable 128)."""

    INDEX_FOUND = 1 << 0
    HALL_FOUND = 1 << 1
    ROTOR_POSITION_FOUND = 1 << 2
    WRITING_EEPROM = 1 << 3
    CURRENT_LIMITED_CONTINUOUS = 1 << 7
    HIGH_CURRENT_REGION = 1 << 8
    ERROR = 1 << 9
    ENABLED = 1 << 10
    ENABLE_DEBOUNCING = 1 << 11
    CURRENT_OFFSETS_DETECTED = 1 << 12
    BRAKING = 1 << 13
    POWER_STAGE_LOW = 1 << 14
    POWER_STAGE_HIGH = 1 << 15

    @property
    def power_stage(self) -> str:
        """'off' (00), 'refresh' (01) or 'on' (10, 11): bits 14-15."""
        code = (int(self) >> 14) & 0b11
        return ('off', 'refresh', 'on', 'on')[code]

    def describe(self) -> str:
        """Comma-separated flag names (power stage bits folded into ``power_stage=...``)."""
        names = [f.name for f in Status if f in self and f.value < (1 << 14) and f.name]
        return ', '.join([*names, f'power_stage={self.power_stage}'])


@dataclass(frozen=True)
class StatusVariables:
    """Status-variable numbers (read with ReadTempParam). One source is off by one from 135 on;
    these follow the others (des-protocol.md)."""

    system_status: int = 128
    mean_current_d: int = 129
    mean_current_q: int = 130
    current_setpoint: int = 131
    rotor_position: int = 132
    speed_setpoint: int = 133
    mean_speed: int = 134
    absolute_position: int = 136
    error: int = 137
    instantaneous_current_q: int = 139
    instantaneous_speed: int = 140
    encoder_counter: int = 143
    counter_at_index: int = 144
    hall_pattern: int = 145


@dataclass(frozen=True)
class DesConfig:
    """Every UNCONFIRMED protocol item, in one place (des-protocol.md).

    Attributes
    ----------
    baudrate : link speed [bit/s]; the factory default is UNCONFIRMED, drivers in the wild use 38400
    lword_low_word_first : 32-bit (LWORD) values: True = low word first (UNCONFIRMED word order)
    current_source : how ``read_current`` gets the current [mA]: 'status_variable' (130 mean /
        139 instantaneous q-axis, documented) or 'is_must' (op code 0x29, UNCONFIRMED layout)
    current_is_must_actual_index : index of the actual current among the 0x29 reply words
        (UNCONFIRMED; the simulator answers (actual, set point) like 0x28)
    des_repeats_reply_after_nak : True if the DES re-sends a reply the host refused with 'F'
        ("may then repeat"); the host then waits for the repeat before giving up
    quadrature_counts_per_count : encoder-counter counts per encoder line [-]; the status variables
        count quadrature edges, so 4 (2048 lines -> 8192 counts per turn)
    status_variables : status-variable numbers (one source's table is off by one from 135 on)
    """

    baudrate: int = 38400
    lword_low_word_first: bool = True
    current_source: str = 'status_variable'
    current_is_must_actual_index: int = 0
    des_repeats_reply_after_nak: bool = True
    quadrature_counts_per_count: int = 4
    status_variables: StatusVariables = field(default_factory=StatusVariables)

    def __post_init__(self) -> None:
        if self.baudrate not in BAUD_CODES:
            raise ConfigError(f'baud rate {self.baudrate} is not one the DES supports: {sorted(BAUD_CODES)}')
        if self.current_source not in ('status_variable', 'is_must'):
            raise ConfigError(
                f"current_source must be 'status_variable' or 'is_must', not {self.current_source!r}"
            )


# -- words --------------------------------------------------------------------------------------


def to_word(value: int) -> int:
    """A signed (int16) or unsigned (uint16) integer as the 16-bit word on the wire."""
    value = int(value)
    if not _WORD_MIN <= value <= _WORD_MAX:
        raise InputError(f'{value} does not fit in a 16-bit word')
    return value & 0xFFFF


def to_int16(word: int) -> int:
    """A 16-bit word read as a signed int16."""
    return word - 0x10000 if word & 0x8000 else word


def split_lword(value: int, config: DesConfig) -> tuple[int, int]:
    """A 32-bit value (signed or unsigned) as two words in the configured (UNCONFIRMED) order."""
    value = int(value)
    if not -0x8000_0000 <= value <= 0xFFFF_FFFF:
        raise InputError(f'{value} does not fit in 32 bits')
    value &= 0xFFFF_FFFF
    low, high = value & 0xFFFF, value >> 16
    return (low, high) if config.lword_low_word_first else (high, low)


def join_lword(words: tuple[int, int], config: DesConfig, *, signed: bool = False) -> int:
    """Two words in the configured order as one 32-bit value."""
    low, high = words if config.lword_low_word_first else (words[1], words[0])
    value = (high << 16) | low
    return value - 0x1_0000_0000 if signed and value & 0x8000_0000 else value


# -- CRC and frames -----------------------------------------------------------------------------


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM of ``data`` (check value 0x31C3 for b'123456789').

    ``binascii.crc_hqx`` with initial value 0 is exactly CRC-16/XMODEM (poly 0x1021, no reflection,
    no final XOR), in C, so no hand-written table is needed.
    """
    return binascii.crc_hqx(data, 0)


def frame_crc(opcode: int, words: tuple[int, ...] | list[int]) -> int:
    """CRC of a frame: over op code, len-1 and each word high byte first."""
    head = bytes((opcode, len(words) - 1))
    return crc16_xmodem(head + b''.join(_BE_WORD.pack(w) for w in words))


def encode_body(opcode: int, words: tuple[int, ...] | list[int]) -> bytes:
    """Body sent after the op code handshake: len-1, words (low byte first), CRC (low byte first).

    ``words`` are already 16-bit (see :func:`to_word`); an empty tuple is refused (never empty).
    """
    if not 1 <= len(words) <= MAX_WORDS:
        raise ValueError(f'a frame holds 1..{MAX_WORDS} words, not {len(words)}')
    data = b''.join(_LE_WORD.pack(w) for w in words)
    return bytes((len(words) - 1,)) + data + _LE_WORD.pack(frame_crc(opcode, words))


def body_length(len_minus_one: int) -> int:
    """Bytes in a body whose first byte is ``len_minus_one`` (that byte included)."""
    return 1 + 2 * (len_minus_one + 1) + 2


def command_bytes(opcode: int, n_words: int, reply_words: int) -> int:
    """Bytes on the wire, both directions, for one command with ``n_words`` data words and a reply
    of ``reply_words`` words (0 = no reply): the link's byte-time budget of a transaction."""
    count = 1 + 1 + body_length(n_words - 1) + 1
    if reply_words:
        count += 1 + 1 + body_length(reply_words - 1) + 1
    return count


# -- incremental decoder ------------------------------------------------------------------------


@dataclass(frozen=True)
class FrameStart:
    """A frame's op code arrived; the receiver must now answer 'O' (or 'F')."""

    opcode: int


@dataclass(frozen=True)
class Frame:
    """A complete frame with a good CRC."""

    opcode: int
    words: tuple[int, ...]


class FrameDecoder:
    """Incremental decoder over a byte buffer, for either direction.

    ``start_bytes`` are the op codes that may start a frame: ``{0x00}`` on the host (replies), the
    known op codes on the amplifier (commands). Bytes that cannot start a frame are discarded
    (counted in ``discarded``), so a garbage byte or a half frame resynchronizes instead of
    crashing. :meth:`next_event` returns an event, ``None`` when it needs more bytes, or raises
    :class:`DesFrameError` / :class:`DesCrcError` after dropping the bad bytes; every call that does
    not return ``None`` consumes at least one byte, so a loop over it always ends.
    """

    def __init__(self, start_bytes: frozenset[int] | set[int] = frozenset({REPLY_OPCODE})) -> None:
        self._start_bytes = frozenset(start_bytes)
        self._buffer = bytearray()
        self._opcode: int | None = None
        self.discarded = 0

    @property
    def in_frame(self) -> bool:
        """True between a :class:`FrameStart` and the end of its body."""
        return self._opcode is not None

    @property
    def needed(self) -> int:
        """Bytes worth reading next: the rest of the current body, else 1 [bytes]."""
        if self._opcode is None or not self._buffer:
            return 1
        return max(1, body_length(min(self._buffer[0], MAX_WORDS)) - len(self._buffer))

    @property
    def pending(self) -> int:
        """Bytes buffered but not yet decoded."""
        return len(self._buffer)

    def feed(self, data: bytes) -> None:
        """Append received bytes."""
        self._buffer += data

    def reset(self) -> None:
        """Forget the buffer and any half frame (after a timeout or an input flush)."""
        self.discarded += len(self._buffer)
        self._buffer.clear()
        self._opcode = None

    def next_event(self) -> FrameStart | Frame | None:
        """The next event in the buffer; see the class docstring."""
        if self._opcode is None:
            return self._hunt()
        return self._body()

    def _hunt(self) -> FrameStart | None:
        buf = self._buffer
        for index, byte in enumerate(buf):
            if byte in self._start_bytes:
                self.discarded += index
                del buf[: index + 1]
                self._opcode = byte
                return FrameStart(byte)
        self.discarded += len(buf)
        buf.clear()
        return None

    def _body(self) -> Frame | None:
        buf, opcode = self._buffer, self._opcode
        assert opcode is not None
        if not buf:
            return None
        n_words = buf[0] + 1
        if n_words > MAX_WORDS:
            self._opcode = None
            self.discarded += 1
            del buf[0]
            raise DesFrameError(f'frame for op code 0x{opcode:02X} claims {n_words} words (max {MAX_WORDS})')
        size = body_length(n_words - 1)
        if len(buf) < size:
            return None
        body = bytes(buf[:size])
        del buf[:size]
        self._opcode = None
        words = struct.unpack_from(f'<{n_words}H', body, 1)
        (received,) = _LE_WORD.unpack_from(body, size - 2)
        expected = frame_crc(opcode, words)
        if received != expected:
            raise DesCrcError(
                f'CRC mismatch in frame for op code 0x{opcode:02X}: got 0x{received:04X}, '
                f'expected 0x{expected:04X}'
            )
        return Frame(opcode, tuple(words))
