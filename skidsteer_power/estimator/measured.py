"""Measured power: from joint_states (motor shaft speed and Kt * I), or from what a robot publishes.

The vehicle file's ``measured_power:`` (docs/POWERTRAINS.md, :func:`parse_measured_power`) names the
topics of a measured current per side (or a whole-robot BatteryState) and what it is: a battery-side
current (V x I is the drive's electrical power, :func:`measure_battery_power`) or a motor current
(K_t x I is the torque, below).

The DES driver publishes, per motor, the shaft speed omega [rad/s] and effort = Kt * I [N m]
(DESIGN.md, ROS interface). Per motor (eq. 7.1 uses the same Kt * i torque):

    current                      I     = effort / Kt                             [A]
    mechanical (air-gap) power   P_m   = Kt * I * omega                          [W]
    terminal (electrical) power  P_e   = P_m + R * I**2   (winding copper loss)  [W]
    battery-side (DC bus) power  P_bus = P_e / eta, or P_e * eta_regen if P_e < 0 [W]

The last two are :func:`skidsteer_power.powertrain.motor.terminal_power` and ``bus_power`` (DES 70/10,
4-quadrant, 7.1.2), reused here so the measured and predicted sides share one motor model. Negative
power is regenerative braking.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from skidsteer_power.errors import ConfigError
from skidsteer_power.estimator.side_currents import (
    FieldRef,
    SideCurrentSource,
    decode_side_currents,
    efforts_at,
    source_in,
)
from skidsteer_power.powertrain.motor import (
    DES_70_10,
    AmplifierConstants,
    MotorConstants,
    bus_power,
    motor_current,
    terminal_power,
)

if TYPE_CHECKING:
    from skidsteer_power.bag_io.reader import BagReader
    from skidsteer_power.seams import PowertrainLike

Pair = tuple[float, float]


@dataclass(frozen=True)
class MeasuredPower:
    """Per-side (left, right) measured motor quantities, SI units.

    omega_rad_s : motor shaft speed [rad/s]; torque_Nm : Kt*I [N m]; current_A : I [A];
    mechanical_W : Kt*I*omega [W]; electrical_W : terminal power with R I^2 [W];
    bus_W : battery-side power through the amplifier [W];
    battery_side : True when the measurement IS the battery-side power (V x I, ``measured_power``
    with ``current_is: battery``) and the motor quantities are the powertrain's inverse of it.
    """

    omega_rad_s: Pair
    torque_Nm: Pair
    current_A: Pair
    mechanical_W: Pair
    electrical_W: Pair
    bus_W: Pair
    battery_side: bool = False

    @property
    def bus_total_W(self) -> float:
        """Battery power of both sides [W]."""
        return self.bus_W[0] + self.bus_W[1]

    @property
    def electrical_total_W(self) -> float:
        return self.electrical_W[0] + self.electrical_W[1]


def measure_motor_power(
    omega_rad_s: Pair,
    torque_Nm: Pair,
    motor: MotorConstants,
    amplifier: AmplifierConstants = DES_70_10,
    regen_efficiency: float | None = None,
) -> MeasuredPower:
    """Per-side measured power from motor shaft speed [rad/s] and Kt*I [N m] (see module docstring).

    ``regen_efficiency`` is the amplifier's bus/terminal power ratio when generating (None: its
    efficiency), as in :func:`skidsteer_power.powertrain.motor.bus_power`. Computed in floats, one
    side at a time (per message: :mod:`skidsteer_power.numeric`).
    """
    wl, wr = float(omega_rad_s[0]), float(omega_rad_s[1])
    tl, tr = float(torque_Nm[0]), float(torque_Nm[1])
    electrical = terminal_power(motor, tl, wl), terminal_power(motor, tr, wr)
    return MeasuredPower(
        omega_rad_s=(wl, wr),
        torque_Nm=(tl, tr),
        current_A=(motor_current(motor, tl), motor_current(motor, tr)),
        mechanical_W=(tl * wl, tr * wr),
        electrical_W=electrical,
        bus_W=(
            bus_power(electrical[0], amplifier, regen_efficiency),
            bus_power(electrical[1], amplifier, regen_efficiency),
        ),
    )


# -- measured power from what robots publish (issue 35): the vehicle file's ``measured_power:`` -----

CURRENT_KINDS = ('battery', 'motor')
"""``current_is``: 'battery' (the driver's battery-side current: V x I is the drive's electrical
power) or 'motor' (the motor current: K_t x I is the motor torque)."""
BATTERY_STATE = 'sensor_msgs/msg/BatteryState'
DEFAULT_MAX_AGE_S = 1.5
"""A current or voltage older than this [s] is no reading (as side_currents' max_age_s)."""


@dataclass(frozen=True)
class Signal:
    """One number a robot publishes: ``field`` (``name`` or ``name[index]``) of ``topic``'s
    ``msgtype`` messages, times ``scale`` (e.g. -1 for a current negative while discharging)."""

    topic: str
    msgtype: str
    field: FieldRef
    scale: float = 1.0

    def read(self, msg: object) -> float:
        """The value [A or V] in one message (NaN if the message lacks it)."""
        return self.field.read(msg) * self.scale

    def describe(self) -> str:
        return f'{self.topic} ({self.msgtype}: {self.field})'


@dataclass(frozen=True)
class PowerChannel:
    """One measured current (and its voltage) of one side or of the whole robot.

    current, voltage : the signals [A], [V]; voltage None: the powertrain's bus voltage
    current_is : 'battery' (V x I [W] is the electrical power) or 'motor' (K_t x I [N m] is the torque)
    signed : False for magnitudes only: a battery-side power is counted as drawn (|V I|), a motor
        current takes the sign of its side's wheel speed (motoring)
    max_age_s : a value older than this [s] is no reading
    """

    current: Signal
    voltage: Signal | None
    current_is: str
    signed: bool
    max_age_s: float = DEFAULT_MAX_AGE_S

    @property
    def signals(self) -> tuple[Signal, ...]:
        return (self.current,) if self.voltage is None else (self.current, self.voltage)


@dataclass(frozen=True)
class MeasuredPowerSource:
    """Where a robot's measured power comes from: per side (``left``, ``right``) or for the whole
    robot (``total``, split half per side)."""

    left: PowerChannel | None = None
    right: PowerChannel | None = None
    total: PowerChannel | None = None

    @property
    def channels(self) -> tuple[PowerChannel, ...]:
        if self.total is not None:
            return (self.total,)
        assert self.left is not None and self.right is not None
        return (self.left, self.right)

    @property
    def current_is(self) -> str:
        return self.channels[0].current_is

    @property
    def signals(self) -> tuple[Signal, ...]:
        return tuple(s for c in self.channels for s in c.signals)

    def topics(self) -> dict[str, str]:
        """topic -> message type of every signal."""
        return {s.topic: s.msgtype for s in self.signals}

    def describe(self) -> str:
        what = 'V x I' if self.current_is == 'battery' else 'K_t x I'
        names = ('left', 'right') if self.total is None else ('total',)
        parts = []
        for name, c in zip(names, self.channels, strict=True):
            voltage = f' x {c.voltage.describe()}' if c.voltage else ' x bus voltage'
            parts.append(f'{name}: {c.current.describe()}{voltage}')
        return f'measured power {what} from ' + '; '.join(parts)


def _msgtype(text: object) -> str:
    msgtype = str(text)
    return msgtype.replace('/', '/msg/') if msgtype.count('/') == 1 else msgtype


def _signal(config: object, what: str) -> Signal:
    if not isinstance(config, Mapping):
        raise ConfigError(f'measured_power: {what} must be a mapping {{topic, type, field}}, not {config!r}')
    unknown = sorted(set(config) - {'topic', 'type', 'field', 'scale'})
    missing = sorted({'topic', 'type', 'field'} - set(config))
    if unknown or missing:
        raise ConfigError(f'measured_power: {what}: unknown keys {unknown}, missing keys {missing}')
    scale = config.get('scale', 1.0)
    if (
        not isinstance(scale, int | float)
        or isinstance(scale, bool)
        or not math.isfinite(scale)
        or scale == 0
    ):
        raise ConfigError(f'measured_power: {what}.scale must be a finite non-zero number, not {scale!r}')
    return Signal(
        str(config['topic']).lstrip('/'),
        _msgtype(config['type']),
        FieldRef.parse(config['field']),
        float(scale),
    )


def _channel(config: object, what: str) -> PowerChannel:
    if not isinstance(config, Mapping):
        raise ConfigError(f'measured_power: {what} must be a mapping, not {config!r}')
    if 'current' not in config and _msgtype(config.get('type', '')) == BATTERY_STATE:  # a BatteryState
        unknown = sorted(set(config) - {'topic', 'type', 'signed', 'max_age_s'})
        if unknown or 'topic' not in config:
            raise ConfigError(
                f'measured_power: {what}: a BatteryState needs topic and type (unknown keys {unknown})'
            )
        topic = str(config['topic']).lstrip('/')
        # sensor_msgs/BatteryState: current [A] negative while discharging, voltage [V]
        current = Signal(topic, BATTERY_STATE, FieldRef('current'), -1.0)
        voltage: Signal | None = Signal(topic, BATTERY_STATE, FieldRef('voltage'))
        current_is, signed = 'battery', config.get('signed', True)
    else:
        unknown = sorted(set(config) - {'current', 'voltage', 'current_is', 'signed', 'max_age_s'})
        if unknown or 'current' not in config:
            raise ConfigError(
                f'measured_power: {what}: needs current (and optionally voltage, current_is, signed, '
                f'max_age_s); unknown keys {unknown}'
            )
        current = _signal(config['current'], f'{what}.current')
        voltage = None if config.get('voltage') is None else _signal(config['voltage'], f'{what}.voltage')
        current_is, signed = config.get('current_is', 'battery'), config.get('signed', True)
    if current_is not in CURRENT_KINDS:
        raise ConfigError(
            f'measured_power: {what}.current_is must be one of {CURRENT_KINDS}, not {current_is!r}'
        )
    if not isinstance(signed, bool):
        raise ConfigError(f'measured_power: {what}.signed must be true or false, not {signed!r}')
    max_age = config.get('max_age_s', DEFAULT_MAX_AGE_S)
    if not (isinstance(max_age, int | float) and math.isfinite(max_age) and 0 < max_age <= 60):
        raise ConfigError(f'measured_power: {what}.max_age_s must be in (0, 60] s, not {max_age!r}')
    return PowerChannel(current, voltage, str(current_is), signed, float(max_age))


def _source(config: object) -> MeasuredPowerSource:
    if not isinstance(config, Mapping):
        raise ConfigError(f'measured_power: each source is a mapping of left/right or total, not {config!r}')
    keys = set(config)
    if keys == {'total'}:
        total = _channel(config['total'], 'total')
        if total.current_is != 'battery':
            raise ConfigError(
                'measured_power: total: current_is must be battery (a motor current has a side)'
            )
        return MeasuredPowerSource(total=total)
    if keys == {'left', 'right'}:
        left, right = _channel(config['left'], 'left'), _channel(config['right'], 'right')
        if left.current_is != right.current_is:
            raise ConfigError('measured_power: left and right must have the same current_is')
        return MeasuredPowerSource(left=left, right=right)
    raise ConfigError(f'measured_power: give left and right, or total; got {sorted(map(str, keys))}')


def parse_measured_power(config: object) -> tuple[MeasuredPowerSource, ...]:
    """The sources of a vehicle file's ``measured_power:`` (a mapping, or a list of alternatives: the
    first whose topics a bag holds is used); None or empty: none. ConfigError for a bad entry."""
    if not config:
        return ()
    entries = list(config) if isinstance(config, list) else [config]
    sources = tuple(_source(entry) for entry in entries)
    kinds = {s.current_is for s in sources}
    if len(kinds) > 1:
        raise ConfigError('measured_power: every alternative must have the same current_is')
    return sources


def side_values(
    source: MeasuredPowerSource,
    currents: Sequence[np.ndarray],
    voltages: Sequence[np.ndarray | None],
    side_speed: np.ndarray,
    bus_voltage_V: float,
) -> np.ndarray:
    """Per-side effort values (n, 2) from each channel's current [A] and voltage [V] (None: the bus
    voltage ``bus_voltage_V`` [V]) at n instants, and the sides' wheel speeds (n, 2) [any unit; only
    the sign is used]: battery-side power V I [W] (``current_is: battery``; a total split half per
    side) or the motor current I [A] (``motor``), magnitudes signed as :class:`PowerChannel` says."""
    columns = []
    for k, channel in enumerate(source.channels):
        current = np.asarray(currents[k], dtype=float)
        volts = voltages[k]
        voltage = np.full_like(current, bus_voltage_V) if volts is None else np.asarray(volts, dtype=float)
        if channel.current_is == 'battery':
            value = voltage * current
            columns.append(value if channel.signed else np.abs(value))
        else:
            speed_sign = np.where(side_speed[:, k] < 0.0, -1.0, 1.0)
            columns.append(current if channel.signed else np.abs(current) * speed_sign)
    if source.total is not None:
        return np.column_stack([0.5 * columns[0], 0.5 * columns[0]])
    return np.column_stack(columns)


def measure_battery_power(omega_rad_s: Pair, bus_W: Pair, powertrain: PowertrainLike) -> MeasuredPower:
    """Per-side measured power from motor shaft speed [rad/s] and measured battery-side power V x I
    [W]: the terminal power and the motor torque are the powertrain's inverse (amplifier and idle
    terms, then T w + k_cu T^2 = P_t: :meth:`Powertrain.terminal_from_bus`, ``torque_from_terminal``),
    so torques still compare with predictions and feed the online correction."""
    wl, wr = float(omega_rad_s[0]), float(omega_rad_s[1])
    bl, br = float(bus_W[0]), float(bus_W[1])
    terminal = float(powertrain.terminal_from_bus(bl)), float(powertrain.terminal_from_bus(br))
    tl = float(powertrain.torque_from_terminal(terminal[0], wl))
    tr = float(powertrain.torque_from_terminal(terminal[1], wr))
    kt = powertrain.motor.torque_constant_Nm_A
    return MeasuredPower(
        omega_rad_s=(wl, wr),
        torque_Nm=(tl, tr),
        current_A=(tl / kt, tr / kt),
        mechanical_W=(tl * wl, tr * wr),
        electrical_W=terminal,
        bus_W=(bl, br),
        battery_side=True,
    )


def source_in_bag(
    bag: BagReader, sources: Sequence[MeasuredPowerSource]
) -> tuple[MeasuredPowerSource | None, str]:
    """(the first of ``sources`` whose every topic the bag holds with the declared type and can
    decode, why none if none: one line naming what was wanted)."""
    held = {name.lstrip('/'): info for name, info in bag.topics.items()}
    undecodable: list[str] = []
    for source in sources:
        infos = [held.get(topic) for topic in source.topics()]
        if any(
            info is None or info.msgtype != source.topics()[topic]
            for info, topic in zip(infos, source.topics(), strict=True)
        ):
            continue
        bad = [f'{t} ({m})' for t, m in source.topics().items() if not held[t].decodable]
        if bad:
            undecodable.extend(bad)
            continue
        return source, ''
    if undecodable:
        return None, f'no definition of {", ".join(undecodable)} in the bag: pass it with --msg'
    wanted = ' or '.join('; '.join(f'{t} ({m})' for t, m in s.topics().items()) for s in sources)
    return (
        None,
        f'the bag lacks the measured_power topics of the vehicle file (wanted {wanted}): no measured power',
    )


def latest_at(t: np.ndarray, sample_t: np.ndarray, values: np.ndarray, max_age_s: float) -> np.ndarray:
    """The latest of ``values`` (at ``sample_t`` [s], sorted) at or before each of ``t`` [s], NaN
    where none is at most ``max_age_s`` [s] old."""
    out = np.full(t.size, np.nan)
    if sample_t.size == 0:
        return out
    k = np.searchsorted(sample_t, t, side='right') - 1
    fresh = (k >= 0) & (t - sample_t[np.maximum(k, 0)] <= max_age_s)
    out[fresh] = values[np.maximum(k, 0)][fresh]
    return out


def decode_signals(
    bag: BagReader, source: MeasuredPowerSource, t0_ns: int
) -> dict[Signal, tuple[np.ndarray, np.ndarray]]:
    """Every signal of ``source`` in ``bag``: (t [s] from ``t0_ns``, values), each topic read once."""
    by_topic: dict[str, list[Signal]] = {}
    for signal in source.signals:
        by_topic.setdefault(signal.topic, []).append(signal)
    names = {name.lstrip('/'): name for name in bag.topics}
    out: dict[Signal, tuple[np.ndarray, np.ndarray]] = {}
    for topic, signals in by_topic.items():
        t: list[float] = []
        rows: list[list[float]] = []
        for message in bag.messages([names[topic]]):
            t.append((message.timestamp_ns - t0_ns) * 1e-9)
            msg = bag.deserialize(message)
            rows.append([s.read(msg) for s in signals])
        table = np.array(rows, dtype=float).reshape(-1, len(signals))
        order = np.argsort(np.array(t), kind='stable')
        for j, signal in enumerate(signals):
            out[signal] = (np.array(t, dtype=float)[order], table[order, j])
    return out


class SideJoints(Protocol):
    """What the joint_states arrays are rewritten by: the joints of each side and the vendor
    sources of their effort (:class:`~skidsteer_power.estimator.inputs.JointMap`, which imports
    this module)."""

    @property
    def left(self) -> tuple[str, ...]: ...

    @property
    def joints(self) -> tuple[str, ...]: ...

    @property
    def inverted(self) -> tuple[str, ...]: ...

    @property
    def measured_power(self) -> tuple[MeasuredPowerSource, ...]: ...

    @property
    def side_currents(self) -> tuple[SideCurrentSource, ...]: ...

    @property
    def bus_voltage_V(self) -> float | None: ...


def joint_efforts(
    bag: BagReader,
    joint_map: SideJoints,
    t0_ns: int,
    js_t: np.ndarray,
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray],
    present: np.ndarray,
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray, str]:
    """joint_states arrays (position, velocity, effort) with the effort from the vehicle's
    ``measured_power`` (:func:`side_values`, on each side's first joint, 0 on the others): rows
    without a fresh current (or a declared voltage) are NaN in every field (no data). Returns
    (arrays, present, note): which source was used, or why none."""
    source, why = source_in_bag(bag, joint_map.measured_power)
    if source is None:
        return arrays, np.zeros_like(present), why
    signals = decode_signals(bag, source, t0_ns)
    currents, voltages = [], []
    for channel in source.channels:
        currents.append(latest_at(js_t, *signals[channel.current], channel.max_age_s))
        voltage = channel.voltage
        voltages.append(None if voltage is None else latest_at(js_t, *signals[voltage], channel.max_age_s))
    position, velocity, _ = (a.copy() for a in arrays)
    n_left, n_joints = len(joint_map.left), len(joint_map.joints)
    sign = np.array([-1.0 if j in joint_map.inverted else 1.0 for j in joint_map.joints])
    signed_speed = velocity * sign if velocity.size else np.zeros((js_t.size, n_joints))
    finite = np.isfinite(signed_speed)
    summed = np.where(finite, signed_speed, 0.0)  # only the sign is used: a sum of the finite ones
    side_speed = np.column_stack([summed[:, :n_left].sum(axis=1), summed[:, n_left:].sum(axis=1)])
    bus = float(joint_map.bus_voltage_V or math.nan)
    values = side_values(source, currents, voltages, side_speed, bus).reshape(-1, 2)
    effort = np.zeros((js_t.size, n_joints))
    effort[:, 0] = values[:, 0] * sign[0]  # the reader applies the sign again: net +value
    effort[:, n_left] = values[:, 1] * sign[n_left]
    fresh = np.all(np.isfinite(values), axis=1)
    effort[~fresh] = np.nan
    position[~fresh] = np.nan
    velocity[~fresh] = np.nan
    count = max(signals[c.current][0].size for c in source.channels)
    return (position, velocity, effort), present, f'{source.describe()} ({count} messages)'


def apply_to_joint_arrays(
    bag: BagReader,
    joint_map: SideJoints,
    t0_ns: int,
    js_t: np.ndarray,
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray],
    present: np.ndarray,
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray, str]:
    """joint_states arrays (position, velocity, effort) with the effort from the drivetrain's side
    currents, if it names any: rows without fresh currents are NaN in every field (no data).
    Returns (arrays, present, note); the note says which source was used or why none. A vehicle
    file's ``measured_power`` (:func:`joint_efforts`) is applied the same way."""
    if getattr(joint_map, 'measured_power', ()):
        return joint_efforts(bag, joint_map, t0_ns, js_t, arrays, present)
    sources = getattr(joint_map, 'side_currents', ())
    if not sources:
        return arrays, present, ''
    source, why = source_in(bag, sources)
    if source is None:
        return arrays, np.zeros_like(present), why
    current_t, currents = decode_side_currents(bag, source, t0_ns)
    n_left = len(joint_map.left)
    effort, fresh = efforts_at(js_t, current_t, currents, n_left, len(joint_map.joints), source.max_age_s)
    position, velocity, _ = (a.copy() for a in arrays)
    position[~fresh] = np.nan
    velocity[~fresh] = np.nan
    note = f'motor currents from {source.topic} ({source.left}, {source.right}; {current_t.size} messages)'
    return (position, velocity, effort), present, note
