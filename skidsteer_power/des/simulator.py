"""A virtual DES 70/10 amplifier with its motor (the EC-45 by default), on a pseudo-terminal pair.

The simulator holds the master side of an :func:`os.openpty` pair and speaks the DES protocol in a
thread; the host opens the slave side (through a stable symlink, like a udev
``/dev/serial/by-id`` link) with :func:`serial.serial_for_url`, the robot's own code path.

The motor and its load (per side) live in :mod:`skidsteer_power.des.motor_model`: a load torque is
a number [N m at the motor shaft] or a callable ``load(omega_rad_s, t_s) -> N m`` (positive load
opposes positive rotation), e.g. a terramechanics axle torque divided by the gear ratio. The default
is a small viscous + Coulomb load. The current loop is taken as ideal (electrical time constant
L/R = 0.95 ms, below the 0.5 ms integration step's resolution of interest).

Fault injection: :meth:`SimulatedDes.inject` (drop, delay, corrupt CRC, answer 'F', go silent;
``inject(Fault.CORRUPT_CRC, -1)`` is a CRC storm: every reply and every repeat wrong),
:meth:`SimulatedDes.raise_error` (error bits), :meth:`SimulatedDes.close_port` and
:meth:`SimulatedDes.reopen_port` (the port disappears and comes back at the same path),
:meth:`SimulatedDes.self_reset` (the amplifier restarts by itself: power stage off, set point 0),
``latency_s`` / :meth:`SimulatedDes.set_latency` (a USB adapter's read latency: every answer reaches
the host that much later, as an FTDI adapter's latency timer, 16 ms by default, holds short packets).
"""

from __future__ import annotations

import collections
import contextlib
import enum
import math
import os
import select
import shutil
import tempfile
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypedDict, Unpack

from skidsteer_power.des.errors import DesCrcError, DesFrameError
from skidsteer_power.des.motor_model import (  # re-exported: the old import path of the motor model
    DEFAULT_VEHICLE,
    AxleLoad,
    LoadTorque,
    MotorModel,
    ViscousCoulombLoad,
    default_motor,
)
from skidsteer_power.des.protocol import (
    ACK_FAIL,
    ACK_OK,
    BAUD_CODES,
    REPLY_OPCODE,
    DesConfig,
    DesErrorFlags,
    Frame,
    FrameDecoder,
    FrameStart,
    OpCode,
    Param,
    ParamFormat,
    Status,
    SystemConfig,
    encode_body,
    join_lword,
    split_lword,
    to_int16,
    to_word,
)
from skidsteer_power.powertrain.motor import DES_70_10, RPM, MotorConstants

__all__ = [  # the motor model's names stay importable from here, their old home
    'DEFAULT_VEHICLE',
    'RPM',
    'SIM_VERSION',
    'AxleLoad',
    'CommandRecord',
    'Fault',
    'LoadTorque',
    'MotorModel',
    'SimulatedDes',
    'SimulatedPair',
    'ViscousCoulombLoad',
    'default_parameters',
]

SIM_VERSION = (0x2010, 0x6510, 0x0001, 0x0001)
"""ReadVersion words the simulator answers (its own, not a real firmware's)."""


class Fault(enum.Enum):
    """Counted link faults (see :meth:`SimulatedDes.inject`)."""

    DROP = 'drop'  # ignore a command's op code entirely (the host times out)
    DELAY = 'delay'  # answer each byte of a command ``delay_s`` late
    CORRUPT_CRC = 'corrupt_crc'  # send a reply with a wrong CRC (a repeat after 'F' is good)
    NAK = 'nak'  # answer 'F' to the op code
    SILENT = 'silent'  # answer nothing at all


def default_parameters(baudrate: int, motor: MotorConstants | None = None) -> dict[int, int]:
    """RAM parameters of a freshly configured amplifier for ``motor`` (default: :func:`default_motor`,
    the test robot's; :class:`SimulatedDes` passes its model's motor)."""
    motor = motor or default_motor()
    return {
        Param.BAUD_RATE: BAUD_CODES[baudrate],
        Param.SYSTEM_CONFIG: int(
            SystemConfig.ENABLE_BY_SOFTWARE
            | SystemConfig.MODE_FROM_BITS
            | SystemConfig.MAX_SPEED_FROM_SOFTWARE
        ),
        Param.CURRENT_P: 500,
        Param.CURRENT_I: 200,
        Param.SPEED_P: 1000,
        Param.SPEED_I: 100,
        Param.PEAK_CURRENT_MA: int(DES_70_10.continuous_current_A * 1000),
        Param.MAX_CONTINUOUS_CURRENT_MA: int(motor.nominal_current_A * 1000),
        Param.MAX_SPEED_RPM: round(motor.max_speed_rad_s / RPM),
        Param.ACCELERATION_RPM_PER_MS: 10,
        Param.ENCODER_RESOLUTION: motor.encoder_counts_per_turn,
        Param.POLE_PAIRS: motor.pole_pairs,
        Param.ERROR_PROCEDURE: 1,
        Param.MAX_SPEED_CURRENT_MODE_RPM: round(motor.max_speed_rad_s / RPM),
    }


class _Refuse(Exception):
    """The simulator answers 'F' to the frame."""


@dataclass
class _Exchange:
    """Where the DES side of the protocol stands."""

    state: str = 'idle'  # idle | await_start_ack | await_final_ack
    reply: tuple[int, ...] = ()
    last_byte_at: float = 0.0


@dataclass
class CommandRecord:
    """One command the simulator executed."""

    time_s: float
    opcode: OpCode
    words: tuple[int, ...]


@dataclass
class _Faults:
    counts: dict[Fault, int] = field(default_factory=dict)
    delay_s: float = 0.0

    def take(self, fault: Fault) -> bool:
        left = self.counts.get(fault, 0)
        if left == 0:
            return False
        if left > 0:
            self.counts[fault] = left - 1
        return True


class SimulatedDes:
    """One virtual DES 70/10 on a pty. Use as a context manager or call :meth:`start` / :meth:`stop`.

    Parameters
    ----------
    baudrate : the link speed it emulates [bit/s]; with ``emulate_baud`` every byte costs its
        byte time (10 bits, 8N1) on the line, so link throughput is realistic on a pty
    config : protocol options (UNCONFIRMED items); the simulator answers in the same convention
    model : motor model (default: :class:`MotorModel` of ``motor``)
    motor : the motor constants of the default model (default: :data:`DEFAULT_VEHICLE`'s motor;
        give a vehicle's powertrain motor to simulate that vehicle's amplifier)
    link_path : stable path of the port (a symlink to the pty); default in a fresh temp directory
    """

    INTER_BYTE_TIMEOUT_S = 0.1

    def __init__(
        self,
        baudrate: int = 38400,
        *,
        config: DesConfig | None = None,
        model: MotorModel | None = None,
        motor: MotorConstants | None = None,
        link_path: str | None = None,
        emulate_baud: bool = True,
        name: str = 'des',
        latency_s: float = 0.0,
    ) -> None:
        self.config = config or DesConfig(baudrate=baudrate)
        self.baudrate = baudrate
        self.model = model or MotorModel(motor)
        self.name = name
        self.emulate_baud = emulate_baud
        self.latency_s = latency_s
        self.self_resets = 0
        self._byte_time_s = 10.0 / baudrate
        self._tmpdir = None if link_path else tempfile.mkdtemp(prefix='des-sim-')
        self.port = link_path or os.path.join(self._tmpdir or '', name)
        self.device = ''
        self.commands: collections.deque[CommandRecord] = collections.deque(maxlen=20000)
        self._lock = threading.RLock()
        self._faults = _Faults()
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._decoder = FrameDecoder(frozenset(int(op) for op in OpCode))
        self._exchange = _Exchange()
        self._wire_free_at = 0.0
        self._t0 = time.monotonic()
        self._last_step = self._t0
        self._reset_state()

    # -- lifecycle ------------------------------------------------------------------------------

    def start(self) -> SimulatedDes:
        """Open the pty, publish its symlink at :attr:`port` and start answering."""
        self._open_pty()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f'sim-{self.name}', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close the pty and remove the symlink (and its temp directory)."""
        if self._wake_w < 0:
            return  # already stopped
        self._stop.set()
        os.write(self._wake_w, b'x')
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_pty()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1
        if self._tmpdir:
            shutil.rmtree(self._tmpdir, ignore_errors=True)

    def __enter__(self) -> SimulatedDes:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def close_port(self) -> None:
        """Make the port disappear, as an unplugged USB adapter does (the host's reads fail)."""
        with self._lock:
            self._close_pty()

    def reopen_port(self) -> None:
        """Bring the port back at the same :attr:`port` path (a new pty behind the symlink)."""
        with self._lock:
            if self._master is None:
                self._open_pty()
        os.write(self._wake_w, b'x')

    @property
    def port_open(self) -> bool:
        return self._master is not None

    # -- fault injection and state access -------------------------------------------------------

    def inject(self, fault: Fault, count: int = 1, *, delay_s: float = 0.2) -> None:
        """Apply ``fault`` to the next ``count`` commands (``-1``: until :meth:`clear_faults`).

        For :attr:`Fault.DELAY`, ``delay_s`` [s] is added before each answer byte.
        """
        with self._lock:
            self._faults.counts[fault] = count
            if fault is Fault.DELAY:
                self._faults.delay_s = delay_s

    def clear_faults(self) -> None:
        """Stop every injected link fault."""
        with self._lock:
            self._faults = _Faults()

    def set_latency(self, seconds: float) -> None:
        """Every answer from now reaches the host ``seconds`` [s] after the amplifier sent it (each
        'O', each reply op code and body: a USB adapter's latency timer)."""
        with self._lock:
            self.latency_s = max(0.0, float(seconds))

    def self_reset(self) -> None:
        """The amplifier restarts by itself (a brown-out, a watchdog of its own): power stage off,
        set points 0, RAM parameters from EEPROM, errors cleared; the motor coasts down."""
        with self._lock:
            self._advance()
            self._reset_state()
            self.self_resets += 1

    def raise_error(self, errors: DesErrorFlags) -> None:
        """Set amplifier error bits (bit 15 'any error' is added); the power stage switches off."""
        with self._lock:
            self.errors |= DesErrorFlags(errors) | DesErrorFlags.ANY

    def send_raw(self, data: bytes) -> None:
        """Put ``data`` on the line unasked (line noise, a stale answer)."""
        with self._lock:
            self._send(data)

    def set_load(self, load_torque: LoadTorque) -> None:
        """Replace the load torque at the motor shaft [N m or f(omega_rad_s, t_s)]."""
        with self._lock:
            self.model.load_torque = load_torque

    def arrival_s(self, opcode: OpCode, words: tuple[int, ...], after_s: float) -> float:
        """Arrival time (time.monotonic) [s] of the first ``opcode`` command with ``words`` at or after
        ``after_s`` [s] (NaN: none), e.g. the first zero set point after a fault."""
        for record in list(self.commands):
            if record.time_s >= after_s and record.opcode == opcode and record.words == words:
                return record.time_s
        return math.nan

    def commands_of(self, opcode: OpCode) -> list[CommandRecord]:
        """Executed commands with this op code, oldest first."""
        with self._lock:
            return [c for c in self.commands if c.opcode == opcode]

    @property
    def speed_rpm(self) -> float:
        """Instantaneous motor speed [rpm] (for tests)."""
        with self._lock:
            self._advance()
            return self.model.omega_rad_s / RPM

    def settled(self, tolerance_rpm: float = 2.0) -> bool:
        """Whether the speed loop is at rest on its set point (for tests to wait on): powered in
        speed mode, and both the instantaneous and the mean speed within ``tolerance_rpm`` [rpm] of
        the set point. A speed passing through the band (the mean during the ramp, about 100 rpm
        behind the instantaneous speed; either one in the overshoot) is not settled; the approach
        after the overshoot is monotonic, so a settled motor stays within the band."""
        with self._lock:
            self._advance()
            if not self.powered or self.current_mode:
                return False
            setpoint = (0 if self.stopped else self.speed_setpoint_rpm) * RPM
            tolerance = tolerance_rpm * RPM
            model = self.model
            return (
                abs(model.omega_rad_s - setpoint) <= tolerance
                and abs(model.mean_omega_rad_s - setpoint) <= tolerance
            )

    @property
    def powered(self) -> bool:
        """True when the power stage drives the motor (enabled, no error)."""
        return self.enabled and not self.errors

    # -- amplifier state ------------------------------------------------------------------------

    def _reset_state(self) -> None:
        self.eeprom = default_parameters(self.baudrate, self.model.motor)
        self.params = dict(self.eeprom)
        self.errors: DesErrorFlags = DesErrorFlags(0)
        self.enabled: bool = False
        self.current_mode = False
        self.stopped = False
        self.speed_setpoint_rpm = 0
        self.current_setpoint_ma = 0

    def status_word(self) -> Status:
        status = Status.HALL_FOUND | Status.ROTOR_POSITION_FOUND | Status.CURRENT_OFFSETS_DETECTED
        if abs(self.model.theta_rad) >= 2.0 * math.pi:
            status |= Status.INDEX_FOUND
        if self.errors:
            status |= Status.ERROR
        if self.enabled:
            status |= Status.ENABLED
        if self.powered:
            status |= Status.POWER_STAGE_HIGH
        if self.stopped:
            status |= Status.BRAKING
        if self.model.current_limited:
            status |= Status.CURRENT_LIMITED_CONTINUOUS
        if abs(self.model.current_A) * 1000 > self.params[Param.MAX_CONTINUOUS_CURRENT_MA]:
            status |= Status.HIGH_CURRENT_REGION
        return status

    def _advance(self) -> None:
        """Integrate the motor model up to now."""
        now = time.monotonic()
        model, params = self.model, self.params
        setpoint_rpm = 0 if self.stopped else self.speed_setpoint_rpm
        while now - self._last_step >= model.STEP_S:
            self._last_step += model.STEP_S
            model.step(
                model.STEP_S,
                self._last_step - self._t0,
                powered=self.powered,
                current_mode=self.current_mode,
                speed_setpoint_rad_s=setpoint_rpm * RPM,
                current_setpoint_A=self.current_setpoint_ma / 1000.0,
                peak_current_A=params[Param.PEAK_CURRENT_MA] / 1000.0,
                acceleration_rad_s2=params[Param.ACCELERATION_RPM_PER_MS] * 1000.0 * RPM,
            )
        if abs(model.omega_rad_s) > 1.25 * params[Param.MAX_SPEED_RPM] * RPM:
            self.errors |= DesErrorFlags.OVER_SPEED | DesErrorFlags.ANY

    def _status_variable(self, number: int, lword: bool) -> int:
        sv, model = self.config.status_variables, self.model
        counts_per_rad = (
            self.params[Param.ENCODER_RESOLUTION] * self.config.quadrature_counts_per_count / (2.0 * math.pi)
        )
        values = {
            sv.system_status: int(self.status_word()),
            sv.mean_current_d: 0,
            sv.mean_current_q: round(model.mean_current_A * 1000),
            sv.current_setpoint: self.current_setpoint_ma,
            sv.rotor_position: round(model.theta_rad * counts_per_rad)
            % self.params[Param.ENCODER_RESOLUTION],
            sv.speed_setpoint: 0 if self.stopped else self.speed_setpoint_rpm,
            sv.mean_speed: round(model.mean_omega_rad_s / RPM),
            sv.absolute_position: round(model.theta_rad * counts_per_rad),
            sv.error: int(self.errors),
            sv.instantaneous_current_q: round(model.current_A * 1000),
            sv.instantaneous_speed: round(model.omega_rad_s / RPM),
            sv.encoder_counter: round(model.theta_rad * counts_per_rad) & 0xFFFF,
            sv.counter_at_index: 0,
            sv.hall_pattern: 1 + int(model.theta_rad * self.params[Param.POLE_PAIRS] * 3 / math.pi) % 6,
        }
        if number not in values:
            raise _Refuse
        value = values[number]
        if lword:
            return value & 0xFFFF_FFFF
        return value & 0xFFFF if -0x8000 <= value <= 0xFFFF else (0x7FFF if value > 0 else 0x8000)

    # -- command execution ----------------------------------------------------------------------

    def _execute(self, opcode: int, words: tuple[int, ...]) -> tuple[int, ...]:
        """Run one command; return the reply words (empty: no reply). ``_Refuse`` -> 'F'."""
        op = OpCode(opcode)
        self._advance()
        self.commands.append(CommandRecord(time.monotonic(), op, words))
        handler: Callable[[tuple[int, ...]], tuple[int, ...]] = getattr(self, f'_op_{op.name.lower()}')
        return handler(words)

    def _op_read_sys_status(self, words: tuple[int, ...]) -> tuple[int, ...]:
        return (int(self.status_word()),)

    def _op_read_error(self, words: tuple[int, ...]) -> tuple[int, ...]:
        return (int(self.errors),)

    def _op_clear_error(self, words: tuple[int, ...]) -> tuple[int, ...]:
        self.errors = DesErrorFlags(0)
        return ()

    def _op_reset(self, words: tuple[int, ...]) -> tuple[int, ...]:
        self._reset_state()
        return ()

    def _op_enable(self, words: tuple[int, ...]) -> tuple[int, ...]:
        if not self.params[Param.SYSTEM_CONFIG] & SystemConfig.ENABLE_BY_SOFTWARE:
            raise _Refuse
        self.enabled = bool(words[0])
        return ()

    def _op_read_temp_param(self, words: tuple[int, ...]) -> tuple[int, ...]:
        if len(words) != 2 or words[1] not in (ParamFormat.WORD, ParamFormat.LWORD):
            raise _Refuse
        number, lword = words[0], words[1] == ParamFormat.LWORD
        if number >= 128:
            value = self._status_variable(number, lword)
        elif number in self.params:
            value = self.params[number]
        else:
            raise _Refuse
        return split_lword(value, self.config) if lword else (to_word(value),)

    def _op_set_temp_param(self, words: tuple[int, ...]) -> tuple[int, ...]:
        if len(words) < 3 or words[0] not in self.params:
            raise _Refuse
        lword = words[1] == ParamFormat.LWORD
        if len(words) != (4 if lword else 3):
            raise _Refuse
        value = join_lword((words[2], words[3]), self.config) if lword else words[2]
        if words[0] == Param.BAUD_RATE and value not in BAUD_CODES.values():
            self.errors |= DesErrorFlags.PARAMETER_RANGE | DesErrorFlags.ANY
            return ()
        self.params[words[0]] = value
        return ()

    def _op_reset_temp_param(self, words: tuple[int, ...]) -> tuple[int, ...]:
        self.params = dict(self.eeprom)
        return ()

    def _op_save_temp_param(self, words: tuple[int, ...]) -> tuple[int, ...]:
        self.eeprom = dict(self.params)
        return ()

    def _op_read_version(self, words: tuple[int, ...]) -> tuple[int, ...]:
        return SIM_VERSION

    def _op_set_velocity(self, words: tuple[int, ...]) -> tuple[int, ...]:
        limit = self.params[Param.MAX_SPEED_RPM]
        self.speed_setpoint_rpm = max(-limit, min(limit, to_int16(words[0])))
        self.current_mode = False
        return ()

    def _op_set_current(self, words: tuple[int, ...]) -> tuple[int, ...]:
        limit = self.params[Param.PEAK_CURRENT_MA]
        self.current_setpoint_ma = max(-limit, min(limit, to_int16(words[0])))
        self.current_mode = True
        return ()

    def _op_stop_motion(self, words: tuple[int, ...]) -> tuple[int, ...]:
        self.stopped = not self.stopped
        return ()

    def _op_read_velocity_is_must(self, words: tuple[int, ...]) -> tuple[int, ...]:
        model = self.model
        omega = model.omega_rad_s if words[0] else model.mean_omega_rad_s
        setpoint = 0 if self.stopped else self.speed_setpoint_rpm
        return (to_word(round(omega / RPM)), to_word(setpoint))

    def _op_read_current_is_must(self, words: tuple[int, ...]) -> tuple[int, ...]:
        model = self.model
        current = model.current_A if words[0] else model.mean_current_A
        pair = [to_word(round(current * 1000)), to_word(self.current_setpoint_ma)]
        if self.config.current_is_must_actual_index == 1:
            pair.reverse()
        return tuple(pair)

    # -- the pty and the protocol state machine -------------------------------------------------

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing before the host configures the port
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.device = os.ttyname(slave)
        tmp = f'{self.port}.tmp'
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(self.device, tmp)
        os.replace(tmp, self.port)
        self._decoder.reset()
        self._exchange = _Exchange()

    def _close_pty(self) -> None:
        master, slave = self._master, self._slave
        self._master = self._slave = None
        for fd in (master, slave):
            if fd is not None:
                os.close(fd)
        if os.path.lexists(self.port):
            os.unlink(self.port)

    def _run(self) -> None:
        while not self._stop.is_set():
            master = self._master
            fds = [self._wake_r] if master is None else [master, self._wake_r]
            try:
                ready, _, _ = select.select(fds, [], [], 0.005)
            except (OSError, ValueError):
                continue  # the port was closed under select
            if self._wake_r in ready:
                os.read(self._wake_r, 64)
            with self._lock:
                self._advance()
                if master is not None and master in ready and master == self._master:
                    self._receive(master)
                self._expire_exchange()

    def _receive(self, master: int) -> None:
        try:
            data = os.read(master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # EIO: no host has the slave open at the moment
        now = time.monotonic()
        self._wire_free_at = max(self._wire_free_at, now) + len(data) * self._byte_time_s
        self._exchange.last_byte_at = now
        for byte in data:
            self._on_byte(byte)

    def _on_byte(self, byte: int) -> None:
        ex = self._exchange
        if self._faults.counts.get(Fault.SILENT, 0):
            self._decoder.reset()
            return
        if ex.state == 'await_start_ack':
            ex.state = 'await_final_ack' if byte == ACK_OK else 'idle'
            if byte == ACK_OK:
                self._send_reply_body(ex.reply)
            return
        if ex.state == 'await_final_ack':
            if byte == ACK_FAIL and self.config.des_repeats_reply_after_nak:
                self._send(bytes((REPLY_OPCODE,)))
                ex.state = 'await_start_ack'
            else:
                ex.state = 'idle'
            return
        self._decoder.feed(bytes((byte,)))
        try:
            event = self._decoder.next_event()
        except (DesCrcError, DesFrameError):
            self._send(bytes((ACK_FAIL,)))
            return
        if isinstance(event, FrameStart):
            self._on_opcode()
        elif isinstance(event, Frame):
            self._on_frame(event)

    def _on_opcode(self) -> None:
        faults = self._faults
        if faults.take(Fault.DROP):
            self._decoder.reset()
            return
        if faults.take(Fault.NAK):
            self._decoder.reset()
            self._send(bytes((ACK_FAIL,)))
            return
        if faults.take(Fault.DELAY):
            self._sleep(faults.delay_s)
        self._send(bytes((ACK_OK,)))

    def _on_frame(self, frame: Frame) -> None:
        try:
            reply = self._execute(frame.opcode, frame.words)
        except _Refuse:
            self._send(bytes((ACK_FAIL,)))
            return
        self._send(bytes((ACK_OK,)))
        if reply:
            self._exchange.reply = reply
            self._exchange.state = 'await_start_ack'
            self._send(bytes((REPLY_OPCODE,)))

    def _send_reply_body(self, reply: tuple[int, ...]) -> None:
        body = encode_body(REPLY_OPCODE, reply)
        if self._faults.take(Fault.CORRUPT_CRC):
            body = body[:-2] + bytes((body[-2] ^ 0xFF, body[-1]))
        self._send(body)

    def _expire_exchange(self) -> None:
        ex = self._exchange
        busy = ex.state != 'idle' or self._decoder.in_frame
        if busy and time.monotonic() - ex.last_byte_at > self.INTER_BYTE_TIMEOUT_S:
            self._decoder.reset()
            ex.state = 'idle'

    def _send(self, data: bytes) -> None:
        if self.latency_s > 0:
            self._sleep(self.latency_s)
        if self.emulate_baud:
            start = max(self._wire_free_at, time.monotonic())
            self._wire_free_at = start + len(data) * self._byte_time_s
            self._sleep_until(self._wire_free_at)
        master = self._master
        if master is None:
            return
        with contextlib.suppress(OSError):  # the host is gone; it will time out or reopen
            os.write(master, data)

    def _sleep(self, seconds: float) -> None:
        self._sleep_until(time.monotonic() + seconds)

    @staticmethod
    def _sleep_until(deadline: float) -> None:
        while (left := deadline - time.monotonic()) > 0:
            time.sleep(left)


class SimulatorOptions(TypedDict, total=False):
    """The keyword arguments of :class:`SimulatedDes` a :class:`SimulatedPair` gives both sides."""

    config: DesConfig | None
    model: MotorModel | None
    motor: MotorConstants | None
    link_path: str | None
    emulate_baud: bool
    latency_s: float


class SimulatedPair:
    """Two virtual amplifiers, ``left`` and ``right`` (one per side, as on the robot)."""

    def __init__(self, baudrate: int = 38400, **kwargs: Unpack[SimulatorOptions]) -> None:
        """``kwargs``: the keyword arguments of :class:`SimulatedDes` but ``name``, for both sides."""
        self.left = SimulatedDes(baudrate, name='des_left', **kwargs)
        self.right = SimulatedDes(baudrate, name='des_right', **kwargs)

    def start(self) -> SimulatedPair:
        self.left.start()
        self.right.start()
        return self

    def stop(self) -> None:
        self.left.stop()
        self.right.stop()

    def __enter__(self) -> SimulatedPair:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
