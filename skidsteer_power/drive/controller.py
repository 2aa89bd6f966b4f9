"""The robot's drive controller: cmd_vel -> wheel (axle) speed set points, as the robot makes them.

Shaped like ros2_controllers' diff_drive_controller (its ``update``: speed limiters on the twist, then
the wheel kinematics) and the motor drivers behind it (a per-wheel speed ceiling and a current
limit). For a twist command (V [m/s], w_z [rad/s], REP 103: x forward, positive yaw turns left):

1. velocity limits: V in [-max_speed_m_s, max_speed_m_s], w_z in [-max_yaw_rate_rad_s, ...]
   (diff_drive_controller ``linear.x.max_velocity``, ``angular.z.max_velocity``);
2. in time only (:class:`Ramp`): jerk, then acceleration limits on V and w_z (its SpeedLimiter:
   ``max_jerk``, ``max_acceleration``), each step of dt [s];
3. kinematics: with B = wheel_separation_multiplier x wheel_separation_m and r_side =
   side_radius_multiplier x wheel_radius_m,

       omega_left = (V - w_z B / 2) / r_left,   omega_right = (V + w_z B / 2) / r_right   [rad/s]

   (the side speeds of :func:`side_speeds`; diff_drive_controller's wheel velocities);
4. the per-wheel speed ceiling max_wheel_rad_s [rad/s] and how the controller meets it: ``scale``
   (both sides by one factor, the path curvature kept: the Husky's hardware, and the DES driver's
   set-point limit of this project) or ``clip`` (each side on its own; the curvature changes);
5. the driver's current limit current_limit_A [A] caps the motor current, and so the torque
   (:mod:`skidsteer_power.drive.current`); the current itself is the powertrain's model.

The vehicle file declares it under ``drive_controller:`` (:func:`controller_for_vehicle`, each number
with its source in ``sources:``); the vehicle's ``max_speed_m_s`` / ``max_yaw_rate_rad_s`` are its
velocity limits. Pure numpy; SI units; docs/DRIVE.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Literal, TypedDict, cast

import numpy as np

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.numeric import Real
from skidsteer_power.powertrain.motor import RPM, MotorConstants

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.powertrain.power_flow import Powertrain
    from skidsteer_power.vehicle import Vehicle

__all__ = [
    'CEILING_MODES',
    'DES_MAX_SPEED_1PP_RPM',
    'SET_POINT_LIMIT',
    'DriveController',
    'Ramp',
    'WheelSetpoints',
    'clamp_twist',
    'controller_for_vehicle',
    'limit_rate',
    'set_point_limit_rpm',
    'side_speeds',
    'wheels_to_twist',
]

CeilingMode = Literal['scale', 'clip']
CEILING_MODES: tuple[CeilingMode, ...] = ('scale', 'clip')

DES_MAX_SPEED_1PP_RPM = 25000.0
"""The DES 70/10's max. speed with a one-pole-pair motor [rpm] (Appendix A); p pole pairs: / p."""

SET_POINT_LIMIT = 'set_point_limit'
"""``max_wheel_speed_rad_s: set_point_limit`` in a vehicle file: the DES 70/10's set-point limit of the
vehicle's motor (:func:`set_point_limit_rpm`) through its reduction (the chapter 7 test robot)."""

# The numbers a vehicle file's ``drive_controller:`` mapping may declare (each needs a source).
FILE_NUMBERS = (
    'wheel_separation_m',
    'wheel_radius_m',
    'wheel_separation_multiplier',
    'left_wheel_radius_multiplier',
    'right_wheel_radius_multiplier',
    'max_accel_m_s2',
    'max_yaw_accel_rad_s2',
    'max_jerk_m_s3',
    'max_yaw_jerk_rad_s3',
    'max_wheel_speed_rad_s',
    'current_limit_A',
)
FILE_KEYS = (*FILE_NUMBERS, 'ceiling', 'sources')


class ControllerChanges(TypedDict, total=False):
    """The attributes :meth:`DriveController.with_values` replaces: the numbers and the ceiling mode."""

    wheel_separation_m: float
    wheel_radius_m: float
    wheel_separation_multiplier: float
    left_wheel_radius_multiplier: float
    right_wheel_radius_multiplier: float
    max_speed_m_s: float
    max_yaw_rate_rad_s: float
    max_accel_m_s2: float
    max_yaw_accel_rad_s2: float
    max_jerk_m_s3: float
    max_yaw_jerk_rad_s3: float
    max_wheel_rad_s: float
    ceiling: CeilingMode
    current_limit_A: float | None


def set_point_limit_rpm(motor: MotorConstants) -> float:
    """The largest speed set point for ``motor`` on a DES 70/10 [rpm]: the motor's max. permissible
    speed (EC-45: 10 000 rpm, Appendix B line 23), at most the amplifier's 25 000 rpm / pole pairs."""
    return min(motor.max_speed_rad_s / RPM, DES_MAX_SPEED_1PP_RPM / motor.pole_pairs)


def side_speeds(linear_m_s: Real, yaw_rate_rad_s: Real, tread_m: float) -> tuple[Real, Real]:
    """(left, right) track/wheel ground speeds [m/s] for a body twist (v [m/s], yaw rate [rad/s]);
    floats or arrays (:mod:`skidsteer_power.numeric`): v -+ w B / 2."""
    half = 0.5 * yaw_rate_rad_s * tread_m
    return linear_m_s - half, linear_m_s + half


def wheels_to_twist(
    setpoint: ArrayLike, r_left: float, r_right: float, separation_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """(V [m/s], w_z [rad/s]) of wheel speeds (P, 2) (left, right) [rad/s] with wheel radii [m] and
    separation B [m]: the inverse of :func:`side_speeds` (V = (v_l + v_r) / 2, w_z = (v_r - v_l) / B,
    v = omega r; with no slip, the body motion)."""
    sp = np.atleast_2d(np.asarray(setpoint, dtype=float))
    left, right = sp[:, 0] * r_left, sp[:, 1] * r_right
    return 0.5 * (left + right), (right - left) / separation_m


@dataclass(frozen=True)
class WheelSetpoints:
    """Set points of P commands (SI units).

    setpoint : (P, 2) (left, right) wheel / axle speed set points [rad/s]
    speed, yaw_rate : (P,) the twist after the velocity (and, in time, acceleration) limits [m/s, rad/s]
    velocity_limited : (P,) a velocity limit changed the command
    ceiling_reached : (P,) the wheel speed ceiling changed the set points
    """

    setpoint: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    velocity_limited: np.ndarray
    ceiling_reached: np.ndarray

    @property
    def clamped(self) -> np.ndarray:
        """(P,) the controller changed the command (a velocity limit or the ceiling)."""
        out: np.ndarray = self.velocity_limited | self.ceiling_reached
        return out


@dataclass(frozen=True)
class DriveController:
    """A robot's drive controller (module doc). Validated on construction; SI units.

    Attributes
    ----------
    wheel_separation_m : B before its multiplier [m] (the vehicle's ``tread_m``)
    wheel_radius_m : r before the multipliers [m] (the vehicle's drive radius)
    wheel_separation_multiplier, left_wheel_radius_multiplier, right_wheel_radius_multiplier : [-]
    max_speed_m_s, max_yaw_rate_rad_s : velocity limits on |V| [m/s], |w_z| [rad/s] (inf: none)
    max_accel_m_s2, max_yaw_accel_rad_s2 : acceleration limits [m/s^2], [rad/s^2] (inf: none)
    max_jerk_m_s3, max_yaw_jerk_rad_s3 : jerk limits [m/s^3], [rad/s^3] (inf: none)
    max_wheel_rad_s : per-wheel speed ceiling [rad/s] (inf: none)
    ceiling : how it is met, ``scale`` (both sides together) or ``clip`` (each side)
    current_limit_A : the driver's motor current limit [A] (None: the powertrain's)
    sources : where each number comes from (key -> text; ASSUMED where not published)
    """

    wheel_separation_m: float
    wheel_radius_m: float
    wheel_separation_multiplier: float = 1.0
    left_wheel_radius_multiplier: float = 1.0
    right_wheel_radius_multiplier: float = 1.0
    max_speed_m_s: float = math.inf
    max_yaw_rate_rad_s: float = math.inf
    max_accel_m_s2: float = math.inf
    max_yaw_accel_rad_s2: float = math.inf
    max_jerk_m_s3: float = math.inf
    max_yaw_jerk_rad_s3: float = math.inf
    max_wheel_rad_s: float = math.inf
    ceiling: CeilingMode = 'scale'
    current_limit_A: float | None = None
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, hash=False)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ('ceiling', 'sources') or (f.name == 'current_limit_A' and value is None):
                continue
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or math.isnan(value)
                or value <= 0
            ):
                raise ConfigError(f'drive controller: {f.name} must be a number > 0, not {value!r}')
            if f.name.endswith(('_m', 'multiplier')) and not math.isfinite(value):
                raise ConfigError(f'drive controller: {f.name} must be finite, not {value!r}')
        if self.ceiling not in CEILING_MODES:
            raise ConfigError(
                f'drive controller: ceiling must be one of {CEILING_MODES}, not {self.ceiling!r}'
            )

    @property
    def separation_m(self) -> float:
        """The wheel separation the controller uses, multiplier x B [m]."""
        return self.wheel_separation_multiplier * self.wheel_separation_m

    @property
    def radii_m(self) -> tuple[float, float]:
        """The (left, right) wheel radii the controller uses [m]."""
        r = self.wheel_radius_m
        return self.left_wheel_radius_multiplier * r, self.right_wheel_radius_multiplier * r

    @property
    def has_ramps(self) -> bool:
        """Any finite acceleration or jerk limit (then the set points depend on time: :class:`Ramp`)."""
        limits = (
            self.max_accel_m_s2,
            self.max_yaw_accel_rad_s2,
            self.max_jerk_m_s3,
            self.max_yaw_jerk_rad_s3,
        )
        return any(math.isfinite(x) for x in limits)

    def with_values(self, **values: float | str) -> DriveController:
        """A copy with some attributes replaced (validated again): numbers, ``ceiling`` a mode."""
        return replace(self, **cast('ControllerChanges', values))  # each checked by __post_init__

    # -- steady set points (no time) ------------------------------------------------------------
    def apply(
        self, speed_cmd: ArrayLike, yaw_cmd: ArrayLike, *, ceiling_rad_s: float | None = None
    ) -> WheelSetpoints:
        """Set points of P commands (V [m/s], w_z [rad/s], broadcast) held long enough for every ramp
        to end: velocity limits, kinematics, wheel speed ceiling (module doc, steps 1, 3, 4).

        ``ceiling_rad_s`` [rad/s]: a further ceiling (e.g. the motor's no-load speed), met the same
        way; the lower of the two applies. A non-finite command is an InputError.
        """
        v, w = np.broadcast_arrays(np.asarray(speed_cmd, dtype=float), np.asarray(yaw_cmd, dtype=float))
        v, w = v.ravel(), w.ravel()
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
            raise InputError('commanded speed and yaw rate must be finite numbers (m/s, rad/s)')
        vl = np.clip(v, -self.max_speed_m_s, self.max_speed_m_s)
        wl = np.clip(w, -self.max_yaw_rate_rad_s, self.max_yaw_rate_rad_s)
        sp, reached = self.wheels(vl, wl, ceiling_rad_s=ceiling_rad_s)
        return WheelSetpoints(sp, vl, wl, (vl != v) | (wl != w), reached)

    def wheels(
        self, speed: np.ndarray, yaw_rate: np.ndarray, *, ceiling_rad_s: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(set points (P, 2) [rad/s], ceiling reached (P,)) of twists already within the velocity
        limits: the kinematics and the ceiling (module doc, steps 3 and 4)."""
        sp = self._kinematic_wheels(speed, yaw_rate)
        top = self.ceiling_for(ceiling_rad_s)
        peak = np.max(np.abs(sp), axis=1)
        reached = peak > top
        if self.ceiling == 'scale':
            scale = np.where(reached, top / np.where(peak > 0, peak, 1.0), 1.0)
            return sp * scale[:, None], reached
        return np.clip(sp, -top, top), reached

    def _kinematic_wheels(self, speed: np.ndarray, yaw_rate: np.ndarray) -> np.ndarray:
        """(P, 2) wheel speeds [rad/s] of twists through the kinematics alone (module doc, step 3)."""
        left, right = side_speeds(speed, yaw_rate, self.separation_m)
        r_left, r_right = self.radii_m
        if r_left == r_right:
            out: np.ndarray = np.column_stack([left, right]) / r_left
            return out
        return np.column_stack([left / r_left, right / r_right])

    def ceiling_for(self, ceiling_rad_s: float | None = None) -> float:
        """The wheel speed ceiling that applies [rad/s]: the controller's, or a lower ``ceiling_rad_s``."""
        return self.max_wheel_rad_s if ceiling_rad_s is None else min(self.max_wheel_rad_s, ceiling_rad_s)

    def apply_one(
        self, speed_cmd: float, yaw_cmd: float, *, ceiling_rad_s: float | None = None
    ) -> tuple[float, float, bool]:
        """(left, right set point [rad/s], clamped) of one command in plain floats, the arithmetic of
        :meth:`apply` (for per-message and per-query callers; a numpy call costs ~1 us per value)."""
        v, w = float(speed_cmd), float(yaw_cmd)
        if not (math.isfinite(v) and math.isfinite(w)):
            raise InputError(f'non-finite command: V {v!r} m/s, yaw rate {w!r} rad/s')
        vl, wl = clamp_twist(v, w, self.max_speed_m_s, self.max_yaw_rate_rad_s)
        left, right = self.wheels_one(vl, wl, ceiling_rad_s=ceiling_rad_s)
        return left[0], right[0], (vl, wl) != (v, w) or left[1]

    def wheels_one(
        self, speed: float, yaw_rate: float, *, ceiling_rad_s: float | None = None
    ) -> tuple[tuple[float, bool], tuple[float, bool]]:
        """((left [rad/s], ceiling reached), (right [rad/s], ceiling reached)) of one twist within the
        velocity limits, in floats (:meth:`wheels`)."""
        left, right = side_speeds(speed, yaw_rate, self.separation_m)
        r_left, r_right = self.radii_m
        left, right = left / r_left, right / r_right
        if not (math.isfinite(left) and math.isfinite(right)):
            raise InputError(f'twist ({speed!r} m/s, {yaw_rate!r} rad/s) overflows the wheel speed')
        top = self.ceiling_for(ceiling_rad_s)
        peak = max(abs(left), abs(right))
        if peak <= top:
            return (left, False), (right, False)
        if self.ceiling == 'scale':
            scale = top / peak
            return (left * scale, True), (right * scale, True)
        return (min(top, max(-top, left)), True), (min(top, max(-top, right)), True)

    def path_scale(
        self, speed: ArrayLike, yaw_rate: ArrayLike, *, ceiling_rad_s: float | None = None
    ) -> np.ndarray:
        """(P,) factor s in (0, 1] by which a path follower slows the twists (V [m/s], w_z [rad/s],
        broadcast) so the controller carries them out unchanged: the same path (curvature w_z / V)
        at the highest speed within the velocity limits and the wheel speed ceiling (module doc,
        steps 1, 3, 4; ``ceiling_rad_s`` as in :meth:`apply`). 1 where nothing limits. Unlike
        :meth:`apply`, which limits V and w_z each on its own as diff_drive_controller does, this
        keeps the path, as a route or a planned path asks (missions)."""
        v, w = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(yaw_rate, dtype=float))
        v, w = v.ravel(), w.ravel()
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
            raise InputError('path speed and yaw rate must be finite numbers (m/s, rad/s)')
        peak = np.max(np.abs(self._kinematic_wheels(v, w)), axis=1)  # wheel speed [rad/s]
        with np.errstate(divide='ignore'):  # x / 0 = inf: that limit does not bind
            ratios = (
                self.max_speed_m_s / np.abs(v),
                self.max_yaw_rate_rad_s / np.abs(w),
                self.ceiling_for(ceiling_rad_s) / peak,
            )
        out: np.ndarray = np.minimum.reduce([np.ones_like(v), *ratios])
        return out

    def twist_of(self, setpoint: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(V [m/s], w_z [rad/s]) of wheel speeds (P, 2) [rad/s] through the controller's kinematics
        (the inverse of step 3; with no slip, the body motion)."""
        r_left, r_right = self.radii_m
        return wheels_to_twist(setpoint, r_left, r_right, self.separation_m)


class Ramp:
    """The controller in time: jerk and acceleration limits on the twist (diff_drive_controller's
    SpeedLimiter), then :meth:`DriveController.wheels_one`. Plain floats; not thread-safe.

    :meth:`step` advances by dt [s]; :meth:`reset` puts it at rest. With no finite acceleration or
    jerk limit it returns :meth:`DriveController.apply_one` exactly.
    """

    def __init__(self, controller: DriveController) -> None:
        self.controller = controller
        self.reset()

    def reset(self, speed_m_s: float = 0.0, yaw_rate_rad_s: float = 0.0) -> None:
        """Hold the twist (V [m/s], w_z [rad/s]) with no acceleration."""
        self._v = [float(speed_m_s), float(speed_m_s)]  # the last two outputs (v0, v1)
        self._w = [float(yaw_rate_rad_s), float(yaw_rate_rad_s)]

    @property
    def twist(self) -> tuple[float, float]:
        """The twist last put out (V [m/s], w_z [rad/s])."""
        return self._v[0], self._w[0]

    def step(
        self, speed_cmd: float, yaw_cmd: float, dt: float, *, ceiling_rad_s: float | None = None
    ) -> tuple[float, float, bool]:
        """(left, right set point [rad/s], clamped) after dt [s] toward the command (V [m/s], w_z [rad/s])."""
        c = self.controller
        if not c.has_ramps:
            return c.apply_one(speed_cmd, yaw_cmd, ceiling_rad_s=ceiling_rad_s)
        v, w = float(speed_cmd), float(yaw_cmd)
        if not (math.isfinite(v) and math.isfinite(w) and math.isfinite(dt) and dt >= 0):
            raise InputError(f'non-finite command or step: V {v!r} m/s, yaw rate {w!r} rad/s, dt {dt!r} s')
        vl, wl = clamp_twist(v, w, c.max_speed_m_s, c.max_yaw_rate_rad_s)
        vl = limit_rate(vl, self._v, c.max_accel_m_s2, c.max_jerk_m_s3, dt)
        wl = limit_rate(wl, self._w, c.max_yaw_accel_rad_s2, c.max_yaw_jerk_rad_s3, dt)
        left, right = c.wheels_one(vl, wl, ceiling_rad_s=ceiling_rad_s)
        return left[0], right[0], (vl, wl) != (v, w) or left[1]


def clamp_twist(speed: float, yaw_rate: float, max_speed: float, max_yaw_rate: float) -> tuple[float, float]:
    """(V [m/s], w_z [rad/s]) each clamped to its velocity limit (module doc, step 1), in floats."""
    return min(max_speed, max(-max_speed, speed)), min(max_yaw_rate, max(-max_yaw_rate, yaw_rate))


def limit_rate(target: float, last: list[float], accel: float, jerk: float, dt: float) -> float:
    """SpeedLimiter::limit_jerk then limit_acceleration (ros2_controllers control_toolbox): the value
    after dt [s] toward ``target`` from the last two outputs ``last`` = [v0, v1], at most ``accel``
    per second and ``jerk`` per second squared (inf: none); updates ``last``."""
    v0, v1 = last
    v = target
    if math.isfinite(jerk):
        dv, dv0 = v - v0, v0 - v1
        da_max = jerk * 2.0 * dt * dt
        v = v0 + dv0 + min(da_max, max(-da_max, dv - dv0))
    if math.isfinite(accel):
        dv_max = accel * dt
        v = v0 + min(dv_max, max(-dv_max, v - v0))
    last[1], last[0] = v0, v
    return v


def controller_for_vehicle(vehicle: Vehicle, powertrain: Powertrain | None = None) -> DriveController:
    """The vehicle's drive controller: its ``drive_controller:`` mapping (module doc; ConfigError for an
    unknown key, a bad value or a number without a source), the vehicle's ``max_speed_m_s`` /
    ``max_yaw_rate_rad_s`` as the velocity limits, its tread and drive radius as B and r unless the
    mapping declares the controller's own ``wheel_separation_m`` / ``wheel_radius_m``. Without a
    mapping: no acceleration limit and the DES 70/10 set-point limit of its motor, scaled (the
    project's des_driver)."""
    data: JsonObject = getattr(vehicle, 'drive_controller', None) or {}
    origin = f'vehicle {vehicle.name!r}: drive_controller'
    if not isinstance(data, Mapping):
        raise ConfigError(f'{origin} must be a mapping, not {type(data).__name__}')
    unknown = sorted(set(map(str, data)) - set(FILE_KEYS))
    if unknown:
        raise ConfigError(f'{origin}: unknown key(s) {", ".join(unknown)}; known: {", ".join(FILE_KEYS)}')
    sources = data.get('sources') or {}
    if not isinstance(sources, Mapping):
        raise ConfigError(f'{origin}: sources must be a mapping of key -> source text')
    missing = [k for k in data if k in FILE_NUMBERS and not str(sources.get(k, '')).strip()]
    if missing:
        raise ConfigError(
            f'{origin}: no source for {", ".join(missing)} (cite one under sources:, or ASSUMED)'
        )
    values: JsonObject = {k: data[k] for k in FILE_NUMBERS if k in data}
    ceiling_value = values.pop('max_wheel_speed_rad_s', SET_POINT_LIMIT)
    if ceiling_value == SET_POINT_LIMIT:
        if powertrain is None:
            from skidsteer_power.powertrain.power_flow import Powertrain

            powertrain = Powertrain.for_vehicle(vehicle)
        ceiling_value = set_point_limit_rpm(powertrain.motor) * RPM / powertrain.gear_ratio
    try:
        values.setdefault('wheel_separation_m', float(vehicle.tread_m))
        values.setdefault('wheel_radius_m', float(vehicle.drive_radius_m))
        return DriveController(
            max_speed_m_s=float(vehicle.max_speed_m_s),
            max_yaw_rate_rad_s=float(vehicle.max_yaw_rate_rad_s),
            max_wheel_rad_s=ceiling_value,
            ceiling=data.get('ceiling', 'scale'),
            sources={str(k): str(v) for k, v in sources.items()},
            **values,
        )
    except ConfigError as err:
        raise ConfigError(f'{origin}: {str(err).removeprefix("drive controller: ")}') from None
