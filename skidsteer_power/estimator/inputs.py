"""Input checks for the estimator: finite, physically plausible values only; staleness.

A rejected input raises :class:`~skidsteer_power.errors.InputError` with one clear reason; the caller
counts it (:class:`RejectCounter`) and warns at a throttled rate. Nothing is clipped silently.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, TypedDict, cast

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator.energy import CLOCK_STEP_BACK_S

if TYPE_CHECKING:
    from skidsteer_power.estimator.measured import MeasuredPowerSource
    from skidsteer_power.estimator.side_currents import SideCurrentSource
    from skidsteer_power.powertrain.power_flow import Powertrain

_isfinite = math.isfinite

JOINT_NAMES = ('left_motor', 'right_motor')  # the test robot's (TEST_ROBOT_JOINTS)
LIMIT_MARGIN = 1.5
"""Readings up to this multiple of the driver's peak current are plausible (a current spike) [-]."""
SPEED_MARGIN = 1.15
"""Motor speeds up to this multiple of the motor's top speed are plausible [-]."""


@dataclass(frozen=True)
class InputLimits:
    """Largest magnitudes accepted as physical; beyond them an input is 'absurd' and rejected.

    Attributes
    ----------
    max_speed_m_s : forward speed command |V| [m/s]
    max_yaw_rate_rad_s : yaw-rate command |r| [rad/s]
    max_motor_speed_rad_s : motor shaft speed |omega| [rad/s] (EC-45: 10,000 rpm = 1047 rad/s, 7.1.2)
    max_motor_torque_Nm : motor torque Kt * I [N m] (DES 70/10: 10 A peak class, 7.1.2; with margin)
    max_side_power_W : one side's measured battery-side power |V x I| [W] (``measured_power``)

    The defaults are the test robot's; :meth:`for_powertrain` gives any vehicle's own (issue 35: a
    fixed 5 N m dropped 383 of 1407 readings of another motor). inf: no limit.
    """

    max_speed_m_s: float = 5.0
    max_yaw_rate_rad_s: float = 10.0
    max_motor_speed_rad_s: float = 1200.0
    max_motor_torque_Nm: float = 5.0
    max_side_power_W: float = math.inf

    def __post_init__(self) -> None:
        for name in ('max_speed_m_s', 'max_yaw_rate_rad_s', 'max_motor_speed_rad_s', 'max_motor_torque_Nm',
                     'max_side_power_W'):  # fmt: skip
            value = getattr(self, name)
            if not value > 0:  # NaN too
                raise InputError(f'{name} must be a number > 0, got {value!r}')

    @classmethod
    def for_powertrain(cls, powertrain: Powertrain, **overrides: float) -> InputLimits:
        """The limits of a vehicle's own motor and driver (``powertrain``: a
        :class:`~skidsteer_power.powertrain.Powertrain`), each with the margin :data:`LIMIT_MARGIN`:

        * motor speed: the larger of the motor's permissible speed and its no-load speed at the bus
          voltage (K_n V) [rad/s] (EC-45: 1047 rad/s x 1.15 = 1204, the old fixed 1200);
        * motor torque: K_t x the driver's peak current [N m] (EC-45 + DES 70/10: 0.114 x 30 A x 1.5
          = 5.1 N m, the old fixed 5); an effective powertrain (no driver limit): none;
        * battery-side power per side: bus voltage x peak current x 1.5 [W] (none without a limit).

        ``overrides`` (non-zero) replace single limits (the node's parameters)."""
        motor, amplifier = powertrain.motor, powertrain.amplifier
        bus = float(powertrain.nominal_bus_voltage_V())
        peak = max(float(amplifier.max_current_A), float(powertrain.current_limit_A))
        speed = max(motor.max_speed_rad_s, motor.speed_constant_rad_s_V * bus) * SPEED_MARGIN
        values = {
            'max_motor_speed_rad_s': speed,
            'max_motor_torque_Nm': motor.torque_constant_Nm_A * peak * LIMIT_MARGIN,
            'max_side_power_W': bus * peak * LIMIT_MARGIN,
        }
        values.update({k: float(v) for k, v in overrides.items() if v})
        return cls(**values)


def _finite_within(name: str, value: float, limit: float, unit: str) -> float:
    value = float(value)
    if math.isnan(value):
        raise InputError(f'{name} is NaN')
    if math.isinf(value):
        raise InputError(f'{name} is infinite')
    _within(name, value, limit, unit)
    return value


def _within(name: str, value: float, limit: float, unit: str) -> None:
    if not abs(value) <= limit:
        raise InputError(f'{name} = {value:g} {unit} exceeds the plausible limit {limit:g} {unit}')


def check_command(speed: float, yaw_rate: float, limits: InputLimits) -> tuple[float, float]:
    """Return (V [m/s], yaw rate [rad/s]) if both are finite and plausible; else raise InputError."""
    return (
        _finite_within('cmd_vel linear.x', speed, limits.max_speed_m_s, 'm/s'),
        _finite_within('cmd_vel angular.z', yaw_rate, limits.max_yaw_rate_rad_s, 'rad/s'),
    )


def check_joint_state(
    names: Sequence[str], velocity: Sequence[float], effort: Sequence[float], limits: InputLimits
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Pick left/right motor shaft speed [rad/s] and torque Kt*I [N m] out of a joint_states message
    of the test robot (``left_motor``/``right_motor``, :data:`TEST_ROBOT_JOINTS`).

    Returns ((omega_left, omega_right), (torque_left, torque_right)). Raises InputError when a motor
    is missing, arrays are short, or a value is NaN, infinite or beyond ``limits``.
    """
    reading = JointReader(TEST_ROBOT_JOINTS, 1.0, 1.0, limits).read(names, (), velocity, effort, 0.0)
    assert reading is not None  # velocity is reported: never waits for a second sample
    return reading


EFFORT_KINDS = ('torque', 'current', 'battery_power')
"""What an effort holds: a torque [N m], a motor current [A] or, with ``measured_power`` and
``current_is: battery``, the side's battery-side power V x I [W] (on its first joint)."""
LOCATIONS = ('motor', 'wheel')
INTERFACES = ('position', 'velocity', 'effort')


@dataclass(frozen=True)
class JointMap:
    """How a robot's ``sensor_msgs/JointState`` maps onto the two sides of a skid-steer drivetrain.

    Attributes
    ----------
    left, right : joint names of each side (any number per side; a side's torque is the sum over
        its joints, its speed the mean)
    effort_is : what JointState.effort holds: 'torque' [N m] or 'current' [A]
    location : where position, velocity and effort are measured: 'motor' (motor shaft, before the
        reduction) or 'wheel' (the wheel / sprocket joint, as ros2_control's joint_state_broadcaster
        reports it)
    gear_ratio : motor turns per wheel turn [-] of this drivetrain; None: the powertrain's
    torque_constant_Nm_A : motor torque per current [N m/A]; None: the powertrain motor's
    interfaces : which of 'position', 'velocity', 'effort' the robot publishes (speed is taken from
        velocity, else differentiated from position; no effort: no measured power)
    inverted : joints whose positive direction drives the robot backwards (all three values negated)
    source : where the mapping comes from
    side_currents : vendor topics whose per-side motor currents [A] are the effort (a
        :class:`~skidsteer_power.estimator.side_currents.SideCurrentSource` each; the first present
        is used), with ``effort_is: current``; empty: effort from joint_states
    measured_power : the vehicle file's ``measured_power:`` sources (a
        :class:`~skidsteer_power.estimator.measured.MeasuredPowerSource` each; the first present is
        used): the effort is then the side's V x I [W] (``effort_is: battery_power``) or its motor
        current [A] (``effort_is: current``)
    bus_voltage_V : the powertrain's bus voltage [V], for V x I without a measured voltage
    """

    left: tuple[str, ...] = ('left_motor',)
    right: tuple[str, ...] = ('right_motor',)
    effort_is: str = 'torque'
    location: str = 'motor'
    gear_ratio: float | None = None
    torque_constant_Nm_A: float | None = None
    interfaces: tuple[str, ...] = INTERFACES
    inverted: tuple[str, ...] = ()
    source: str = ''
    side_currents: tuple[SideCurrentSource, ...] = ()
    measured_power: tuple[MeasuredPowerSource, ...] = ()
    bus_voltage_V: float | None = None

    def __post_init__(self) -> None:
        for side in ('left', 'right'):
            joints = getattr(self, side)
            if not joints or not all(isinstance(j, str) and j for j in joints):
                raise ConfigError(f'joints: {side} must name at least one joint, got {joints!r}')
        both = set(self.left) & set(self.right)
        if both or len(set(self.joints)) != len(self.joints):
            raise ConfigError(f'joints: a joint is listed twice: {sorted(both) or list(self.joints)}')
        if self.effort_is not in EFFORT_KINDS:
            raise ConfigError(f'joints: effort_is must be one of {EFFORT_KINDS}, not {self.effort_is!r}')
        if self.location not in LOCATIONS:
            raise ConfigError(f'joints: location must be one of {LOCATIONS}, not {self.location!r}')
        unknown = set(self.interfaces) - set(INTERFACES)
        if unknown:
            raise ConfigError(f'joints: unknown interfaces {sorted(unknown)}; known: {INTERFACES}')
        for name in ('gear_ratio', 'torque_constant_Nm_A'):
            value = getattr(self, name)
            if value is not None and not (
                isinstance(value, (int, float)) and math.isfinite(value) and value > 0
            ):
                raise ConfigError(f'joints: {name} must be a number > 0 or null, not {value!r}')
        stray = set(self.inverted) - set(self.joints)
        if stray:
            raise ConfigError(f'joints: inverted joints {sorted(stray)} are not in left or right')
        if self.side_currents and (self.effort_is != 'current' or 'effort' not in self.interfaces):
            raise ConfigError('joints: side_currents needs effort_is: current and effort in interfaces')
        if self.side_currents and self.measured_power:
            raise ConfigError("declare measured power once: measured_power, or the joints' side_currents")
        if self.effort_is == 'battery_power' and not self.measured_power:
            raise ConfigError('joints: effort_is battery_power comes only from measured_power')

    @property
    def joints(self) -> tuple[str, ...]:
        """Left joints, then right joints."""
        return (*self.left, *self.right)

    @property
    def has_speed(self) -> bool:
        return 'velocity' in self.interfaces or 'position' in self.interfaces

    @property
    def has_power(self) -> bool:
        """True if joint_states give a measured power (an effort and a speed)."""
        return 'effort' in self.interfaces and self.has_speed

    @property
    def measures_battery(self) -> bool:
        """True when the measurement is battery-side power (V x I), compared with the predicted
        battery-side power."""
        return self.effort_is == 'battery_power'

    @property
    def vendor_sources(self) -> tuple[MeasuredPowerSource, ...] | tuple[SideCurrentSource, ...]:
        """The vendor topics the effort comes from: ``measured_power`` or ``side_currents``."""
        return self.measured_power or self.side_currents

    @classmethod
    def from_config(
        cls, config: object, measured_power: object = None, bus_voltage_V: float | None = None
    ) -> JointMap:
        """From a vehicle's ``joints:`` mapping (``preset`` expanded from config/joints/)
        and its ``measured_power:`` (:func:`~skidsteer_power.estimator.measured.parse_measured_power`;
        it sets ``effort_is`` and adds the effort interface), with the powertrain's bus voltage [V].

        None or an empty mapping gives the test robot's mapping; ConfigError for bad keys or values.
        """
        from skidsteer_power.powertrain.config import merged

        if measured_power:
            from skidsteer_power.estimator.measured import parse_measured_power

            sources = parse_measured_power(measured_power)
            base = cls.from_config(config)
            kind = 'battery_power' if sources[0].current_is == 'battery' else 'current'
            interfaces = base.interfaces if 'effort' in base.interfaces else (*base.interfaces, 'effort')
            return replace(base, effort_is=kind, interfaces=interfaces, measured_power=sources,
                           side_currents=(), bus_voltage_V=bus_voltage_V)  # fmt: skip
        if config is None:
            return (
                replace(TEST_ROBOT_JOINTS, bus_voltage_V=bus_voltage_V)
                if bus_voltage_V
                else TEST_ROBOT_JOINTS
            )
        if not isinstance(config, dict):
            raise ConfigError(f'joints must be a mapping, not {type(config).__name__}')
        cfg = merged('joints', config)
        cfg.pop('name', None)
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(cfg) - known)
        if unknown:
            raise ConfigError(
                f'joints: unknown key(s) {", ".join(unknown)}; known: {", ".join(sorted(known))}'
            )
        for key in ('left', 'right', 'interfaces', 'inverted'):
            if key in cfg:
                value = cfg[key]
                cfg[key] = (value,) if isinstance(value, str) else tuple(value or ())
        if 'source' in cfg:
            cfg['source'] = str(cfg['source'])
        if 'side_currents' in cfg:
            from skidsteer_power.estimator.side_currents import parse_sources

            cfg['side_currents'] = parse_sources(cfg['side_currents'])
        cfg['bus_voltage_V'] = bus_voltage_V
        return cls(**cfg)

    def with_overrides(self, **overrides: object) -> JointMap:
        """A copy with the given non-empty overrides (node parameters, CLI options) applied;
        comma-separated strings are accepted for the joint lists."""
        changes: dict[str, object] = {}
        for key, value in overrides.items():
            if value is None or value == '' or value == ():
                continue
            if key in ('left', 'right', 'interfaces', 'inverted') and isinstance(value, str):
                value = tuple(v.strip() for v in value.split(',') if v.strip())
            changes[key] = value
        # the values as given, for these fields (unchecked here: __post_init__ checks them)
        return replace(self, **cast('JointMapFields', changes)) if changes else self


class JointMapFields(TypedDict, total=False):
    """The fields of a :class:`JointMap`, as :meth:`JointMap.with_overrides` hands them to
    ``dataclasses.replace``."""

    left: tuple[str, ...]
    right: tuple[str, ...]
    effort_is: str
    location: str
    gear_ratio: float | None
    torque_constant_Nm_A: float | None
    interfaces: tuple[str, ...]
    inverted: tuple[str, ...]
    source: str
    side_currents: tuple[SideCurrentSource, ...]
    measured_power: tuple[MeasuredPowerSource, ...]
    bus_voltage_V: float | None


TEST_ROBOT_JOINTS = JointMap(
    source='the DES driver: left_motor/right_motor at the motor shaft, effort = Kt * I'
)


class JointReader:
    """Turns one joint_states message into per-side motor-equivalent speed [rad/s] and torque [N m].

    "Motor-equivalent" means referred to the motor shaft of the powertrain the predictions use
    (reduction ``powertrain_gear_ratio``), so measured and predicted values compare one to one:

        wheel speed  w_w = w / G_dt (motor joint)  or  w (wheel joint)               [rad/s]
        wheel torque T_w = T G_dt   (motor joint)  or  T (wheel joint)               [N m]
            with T = effort (torque) or Kt * effort (current; Kt G_dt at a wheel joint)
        side         T_side = sum of T_w,  w_side = mean of w_w
        motor-equiv. T_m = T_side / G_pt,  w_m = w_side G_pt

    G_dt and Kt default to the powertrain's. Velocity missing: differentiated from position between
    two messages (the first one gives no reading, :meth:`read` returns None). A battery-side
    measurement (``effort_is: battery_power``, V x I [W] per side) is returned as that power: the
    estimator core inverts it through its powertrain itself, calibration fits the power as it is.
    """

    def __init__(
        self,
        joint_map: JointMap,
        powertrain_gear_ratio: float,
        powertrain_torque_constant_Nm_A: float,
        limits: InputLimits,
    ) -> None:
        self.map = joint_map
        self.limits = limits
        g_pt = float(powertrain_gear_ratio)
        g_dt = float(joint_map.gear_ratio or g_pt)
        kt = float(joint_map.torque_constant_Nm_A or powertrain_torque_constant_Nm_A)
        at_motor = joint_map.location == 'motor'
        # per-joint factors to the motor-equivalent of one side (exactly 1.0 for the test robot)
        self._omega_factor = (g_pt / g_dt) if at_motor else g_pt
        self._torque_factor = (g_dt / g_pt) if at_motor else 1.0 / g_pt
        if joint_map.effort_is == 'current':
            self._torque_factor *= kt * (1.0 if at_motor else g_dt)
        self._power = joint_map.effort_is == 'battery_power'
        if self._power:  # the side's V x I [W], summed over its joints as it is
            self._torque_factor = 1.0
        self._sign = [-1.0 if j in joint_map.inverted else 1.0 for j in joint_map.joints]
        self._n_left = len(joint_map.left)
        self._last: tuple[float, list[float]] | None = None
        self._names: tuple[str, ...] | None = None  # the joint names of the last reading, and
        self._rows: list[int] = []  # where the mapped joints were in them

    def _pick(self, what: str, values: Sequence[float], rows: list[int]) -> list[float]:
        """The mapped joints' values (sign applied); InputError for a missing, NaN or infinite one."""
        try:
            out = [values[i] * sign for i, sign in zip(rows, self._sign)]  # noqa: B905 (same length)
        except IndexError:
            out = []
        # per value: a sum of finite values can overflow (9e307 + 9e307 = inf). all(map(isfinite))
        # also takes less time than the sum test it replaced (0.13 vs 0.19 us for two joints)
        if out and all(map(_isfinite, out)):
            return out
        for name, i in zip(self.map.joints, rows, strict=True):  # say which one, and why
            if i >= len(values):
                raise InputError(f'joint_states has no {what} for {name}')
            value = float(values[i])
            if math.isnan(value):
                raise InputError(f'{name} {what} is NaN')
            if math.isinf(value):
                raise InputError(f'{name} {what} is infinite')
        raise InputError(f'joint_states {what}: a value is not a finite number')  # e.g. inf * sign

    def _rows_of(self, names: Sequence[str]) -> list[int]:
        """Where the mapped joints are in ``names``; kept while a driver sends the same names (per
        message otherwise). InputError for a missing joint."""
        key = tuple(names)
        if key != self._names:
            index = {name: i for i, name in enumerate(key)}
            try:
                self._rows = [index[n] for n in self.map.joints]
            except KeyError:
                missing = [n for n in self.map.joints if n not in index]
                raise InputError(f'joint_states lacks {", ".join(missing)}') from None
            self._names = key
        return self._rows

    def read(
        self,
        names: Sequence[str],
        position: Sequence[float],
        velocity: Sequence[float],
        effort: Sequence[float],
        now_s: float,
    ) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """((w_m left, right) [rad/s], (T_m left, right) [N m]) or None while a position-differentiated
        speed needs a second sample. Raises InputError for a missing joint or value, NaN, infinity or
        a value beyond ``limits``."""
        rows = self._rows_of(names)
        interfaces = self.map.interfaces
        if 'effort' not in interfaces:
            raise InputError('the joints mapping declares no effort: no measured power')
        torque = self._pick('effort', effort, rows)
        if 'velocity' in interfaces:
            omega = self._pick('velocity', velocity, rows)
        elif 'position' in interfaces:
            angle = self._pick('position', position, rows)
            last, self._last = self._last, (now_s, angle)
            if last is None or now_s <= last[0]:
                return None
            dt = now_s - last[0]
            omega = [(a - b) / dt for a, b in zip(angle, last[1], strict=True)]
        else:
            raise InputError('the joints mapping declares neither velocity nor position')
        n, m = self._n_left, len(omega) - self._n_left
        w_f, t_f = self._omega_factor, self._torque_factor
        omega_m = (sum(omega[:n]) / n * w_f, sum(omega[n:]) / m * w_f)
        torque_m = (sum(torque[:n]) * t_f, sum(torque[n:]) * t_f)
        limits = self.limits
        t_max, unit = (limits.max_side_power_W, 'W') if self._power else (limits.max_motor_torque_Nm, 'N m')
        for k, joints in enumerate((self.map.left, self.map.right)):
            w, t = omega_m[k], torque_m[k]
            if abs(w) <= limits.max_motor_speed_rad_s and abs(t) <= t_max:
                continue
            label = joints[0] if len(joints) == 1 else f'{("left", "right")[k]} side (motor-equivalent)'
            # every value was finite: an inf here is a sum or product of huge ones, beyond the limit too
            _within(f'{label} velocity', w, limits.max_motor_speed_rad_s, 'rad/s')
            _within(f'{label} {"battery power" if self._power else "effort"}', t, t_max, unit)
        return omega_m, torque_m

    def no_data(
        self,
        names: Sequence[str],
        position: Sequence[float],
        velocity: Sequence[float],
        effort: Sequence[float],
    ) -> bool:
        """True when a mapped joint reads NaN in every number field the mapping uses: the driver's
        "no fresh data for this side" (des_driver's convention, docs/ROS.md "ROS 2 interface"), which is
        no reading, not a bad one. A NaN beside a finite value in another field stays bad input."""
        try:
            rows = self._rows_of(names)
        except InputError:
            return False
        used = [
            v
            for v, f in ((position, 'position'), (velocity, 'velocity'), (effort, 'effort'))
            if f in self.map.interfaces
        ]
        for i in rows:
            values = [float(v[i]) for v in used if i < len(v)]
            if values and all(math.isnan(x) for x in values):
                return True
        return False


@dataclass
class RejectCounter:
    """Counts rejected inputs per topic and decides when a warning may be logged again.

    ``period_s`` is the least time between two warnings for the same topic [s].
    """

    period_s: float = 2.0
    counts: Counter[str] = field(default_factory=Counter)
    _last_warned: dict[str, float] = field(default_factory=dict)

    def reject(self, topic: str, now_s: float) -> bool:
        """Count one rejection on ``topic`` at time ``now_s`` [s]; True if a warning should be logged."""
        self.counts[topic] += 1
        last = self._last_warned.get(topic)
        if last is None or now_s - last >= self.period_s:
            self._last_warned[topic] = now_s
            return True
        return False


@dataclass
class Freshness:
    """Tracks when an input last arrived; stale after ``timeout_s`` [s] without one."""

    timeout_s: float
    last_s: float | None = None

    def mark(self, now_s: float) -> None:
        self.last_s = now_s

    def age_s(self, now_s: float) -> float:
        """Seconds since the last input (inf if none ever arrived, or if the clock stepped back
        more than :data:`CLOCK_STEP_BACK_S` past it: not known to be recent)."""
        if self.last_s is None:
            return math.inf
        age = now_s - self.last_s
        return math.inf if age < -CLOCK_STEP_BACK_S else max(0.0, age)

    def is_fresh(self, now_s: float) -> bool:
        return self.age_s(now_s) <= self.timeout_s
