"""Typed calls to one DES 70/10 amplifier over a :class:`~skidsteer_power.des.transport.DesLink`.

Units as the amplifier uses them: rpm at the motor shaft, mA, encoder quadrature counts. Positive
speed is counter-clockwise seen from the shaft end (des-protocol.md, op code 0x21).
"""

from __future__ import annotations

from dataclasses import dataclass

from skidsteer_power.des.errors import DesFault
from skidsteer_power.des.protocol import (
    DesConfig,
    DesErrorFlags,
    OpCode,
    ParamFormat,
    Status,
    join_lword,
    split_lword,
    to_int16,
    to_word,
)
from skidsteer_power.des.transport import DesLink, LinkTiming
from skidsteer_power.errors import InputError

INT16_MIN, INT16_MAX = -0x8000, 0x7FFF


@dataclass(frozen=True)
class Velocity:
    """ReadVelocityIsMust reply: actual speed and speed set point [rpm]."""

    actual_rpm: int
    setpoint_rpm: int


@dataclass(frozen=True)
class Version:
    """ReadVersion reply (four raw words)."""

    software: int
    hardware: int
    application_number: int
    application_version: int


def _int16_arg(name: str, value: int) -> int:
    value = int(value)
    if not INT16_MIN <= value <= INT16_MAX:
        raise InputError(f'{name} {value} is outside the int16 range {INT16_MIN}..{INT16_MAX}')
    return to_word(value)


class DesAmplifier:
    """One DES 70/10 amplifier.

    >>> amp = DesAmplifier.open('/dev/ttyUSB0')          # doctest: +SKIP
    >>> amp.enable(); amp.set_velocity(1200); amp.read_velocity().actual_rpm   # doctest: +SKIP
    """

    def __init__(self, link: DesLink) -> None:
        self.link = link

    @classmethod
    def open(
        cls,
        port: str,
        baudrate: int = 38400,
        *,
        config: DesConfig | None = None,
        timing: LinkTiming | None = None,
    ) -> DesAmplifier:
        """Open ``port`` (device path or pyserial URL) at ``baudrate`` [bit/s]."""
        if config is None:
            config = DesConfig(baudrate=baudrate)
        elif config.baudrate != baudrate:
            raise InputError(f'baud rate {baudrate} differs from config.baudrate {config.baudrate}')
        return cls(DesLink(port, config, timing or LinkTiming()).open())

    @property
    def config(self) -> DesConfig:
        return self.link.config

    @property
    def port(self) -> str:
        return self.link.port

    def close(self) -> None:
        self.link.close()

    def __enter__(self) -> DesAmplifier:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- status and errors ----------------------------------------------------------------------

    def read_status(self) -> Status:
        """System status word (op code 0x01)."""
        (word,) = self.link.transact(OpCode.READ_SYS_STATUS, reply_words=1)
        return Status(word)

    def read_errors(self) -> DesErrorFlags:
        """Error word (op code 0x02); 0 when no error."""
        (word,) = self.link.transact(OpCode.READ_ERROR, reply_words=1)
        return DesErrorFlags(word)

    def raise_for_errors(self) -> None:
        """Read the error word and raise :class:`DesFault` if any bit is set."""
        errors = self.read_errors()
        if errors:
            raise DesFault(errors, self.port)

    def clear_errors(self) -> None:
        """Clear the error word (op code 0x03)."""
        self.link.transact(OpCode.CLEAR_ERROR)

    def reset(self) -> None:
        """Software restart (op code 0x04)."""
        self.link.transact(OpCode.RESET)

    def enable(self, on: bool = True) -> None:
        """Enable (or disable) the power stage by software (op code 0x05; needs config bit 12)."""
        self.link.transact(OpCode.ENABLE, (1 if on else 0,))

    def disable(self) -> None:
        self.enable(False)

    # -- set points -----------------------------------------------------------------------------

    def set_velocity(self, rpm: int) -> None:
        """Speed set point [rpm] (op code 0x21, speed mode; positive = counter-clockwise)."""
        self.link.transact(OpCode.SET_VELOCITY, (_int16_arg('velocity set point [rpm]', rpm),))

    def set_current(self, milliamps: int) -> None:
        """Current set point [mA] (op code 0x22, current mode)."""
        self.link.transact(OpCode.SET_CURRENT, (_int16_arg('current set point [mA]', milliamps),))

    def stop_motion(self) -> None:
        """Toggle the software stop (op code 0x23, speed mode)."""
        self.link.transact(OpCode.STOP_MOTION)

    # -- measurements ---------------------------------------------------------------------------

    def read_velocity(self, instantaneous: bool = False) -> Velocity:
        """Actual speed and set point [rpm], mean (default) or instantaneous (op code 0x28)."""
        actual, setpoint = self.link.transact(OpCode.READ_VELOCITY_IS_MUST, (int(instantaneous),), 2)
        return Velocity(to_int16(actual), to_int16(setpoint))

    def read_current(self, instantaneous: bool = False) -> int:
        """Motor (q-axis) current [mA], signed; mean (default) or instantaneous.

        By default read as status variable 130 / 139; with ``config.current_source == 'is_must'``
        through op code 0x29, whose reply layout is UNCONFIRMED (see :class:`DesConfig`).
        """
        if self.config.current_source == 'is_must':
            words = self.link.transact(OpCode.READ_CURRENT_IS_MUST, (int(instantaneous),), 2)
            return to_int16(words[self.config.current_is_must_actual_index])
        variables = self.config.status_variables
        number = variables.instantaneous_current_q if instantaneous else variables.mean_current_q
        return self.read_parameter(number, signed=True)

    def read_encoder_counter(self) -> int:
        """Encoder counter, 16 bits, wrapping [quadrature counts, 0..65535] (status variable 143)."""
        return self.read_parameter(self.config.status_variables.encoder_counter)

    def read_version(self) -> Version:
        """Software, hardware, application number and application version words (op code 0x1A)."""
        return Version(*self.link.transact(OpCode.READ_VERSION, reply_words=4))

    # -- parameters -----------------------------------------------------------------------------

    def read_parameter(self, number: int, *, lword: bool = False, signed: bool = False) -> int:
        """RAM parameter or status variable ``number`` (op code 0x14), as WORD or LWORD."""
        fmt = ParamFormat.LWORD if lword else ParamFormat.WORD
        words = self.link.transact(OpCode.READ_TEMP_PARAM, (to_word(number), fmt), 2 if lword else 1)
        if lword:
            return join_lword((words[0], words[1]), self.config, signed=signed)
        return to_int16(words[0]) if signed else words[0]

    def set_parameter(self, number: int, value: int, *, lword: bool = False) -> None:
        """Write RAM parameter ``number`` (op code 0x15); :meth:`save_parameters` makes it permanent."""
        try:
            data = split_lword(value, self.config) if lword else (to_word(value),)
        except ValueError as err:
            raise InputError(f'parameter {number}: {err}') from err
        fmt = ParamFormat.LWORD if lword else ParamFormat.WORD
        self.link.transact(OpCode.SET_TEMP_PARAM, (to_word(number), fmt, *data))

    def reset_parameters(self) -> None:
        """Reload the RAM parameters from EEPROM (op code 0x16)."""
        self.link.transact(OpCode.RESET_TEMP_PARAM)

    def save_parameters(self) -> None:
        """Store the RAM parameters in EEPROM (op code 0x17)."""
        self.link.transact(OpCode.SAVE_TEMP_PARAM)
