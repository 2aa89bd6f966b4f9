"""Exceptions of the DES 70/10 driver.

``DesError`` is a :class:`~skidsteer_power.errors.SkidsteerError`, so the CLI reports it as one line.
Two branches keep apart what the caller must handle differently:

- :class:`DesFault`: the amplifier answered correctly and reports an error word (over-current,
  under-voltage, ...). Stop the motors; clear only on request.
- :class:`DesLinkError`: the link failed (no answer, bad CRC, 'F' refusal, garbled frame, lost port).
  Retry, reopen.
"""

from __future__ import annotations

import enum

from skidsteer_power.errors import SkidsteerError


class DesErrorFlags(enum.IntFlag):
    """Error word (ReadError, status variable 137). Sources label bits 0-3 differently."""

    HALL_OR_OFFSET = 1 << 0
    INDEX_PROCESSING = 1 << 1
    ENCODER_RESOLUTION = 1 << 2
    HALL3_OR_INITIAL_POSITION = 1 << 3
    OVER_CURRENT = 1 << 4
    OVER_VOLTAGE = 1 << 5
    OVER_SPEED = 1 << 6
    UNDER_VOLTAGE = 1 << 7
    ANGLE_DETECTION = 1 << 8
    OVER_TEMPERATURE = 1 << 11
    PARAMETER_RANGE = 1 << 13
    ANY = 1 << 15

    def describe(self) -> str:
        """Comma-separated flag names, unknown bits as hex; 'none' for 0."""
        if not self:
            return 'none'
        names = [f.name for f in DesErrorFlags if f in self and f.name]
        unknown = int(self) & ~sum(int(f) for f in DesErrorFlags)
        if unknown:
            names.append(f'0x{unknown:04X}')
        return ', '.join(names)


class DesError(SkidsteerError, RuntimeError):
    """Base of every DES 70/10 driver error."""


class DesFault(DesError):
    """The amplifier reports an error word (``errors``, a :class:`DesErrorFlags`)."""

    def __init__(self, errors: DesErrorFlags, port: str = '') -> None:
        self.errors = errors
        self.port = port
        where = f' on {port}' if port else ''
        super().__init__(f'DES amplifier{where} reports errors 0x{int(errors):04X} ({errors.describe()})')


class DesLinkError(DesError):
    """The serial link to the amplifier failed."""


class DesTimeout(DesLinkError):
    """No (complete) answer before the deadline."""


class DesNak(DesLinkError):
    """The amplifier refused an op code or a frame with 'F'."""


class DesCrcError(DesLinkError):
    """A reply frame failed its CRC-16 check."""


class DesFrameError(DesLinkError):
    """A reply frame is malformed (impossible length, wrong number of words, unexpected byte)."""


class DesPortError(DesLinkError):
    """The serial port could not be opened, or it was lost (unplugged adapter, closed pty)."""
