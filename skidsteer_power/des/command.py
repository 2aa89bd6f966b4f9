"""Checks on a body-twist command before it may reach a motor (no ROS).

Every number from outside passes :func:`limit_twist` where it enters the driver: a non-finite value is
rejected (:class:`~skidsteer_power.errors.InputError`), a finite one is clamped to
:class:`CommandLimits`. :class:`SlewLimiter` then bounds how fast the commanded twist may change
(linear and angular acceleration), so a step on ``cmd_vel`` becomes a ramp at the motors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from skidsteer_power.des.kinematics import twist_to_motor_rpm
from skidsteer_power.drive.controller import clamp_twist, limit_rate
from skidsteer_power.errors import ConfigError, InputError

if TYPE_CHECKING:
    from skidsteer_power.drive.controller import DriveController


@dataclass(frozen=True)
class CommandLimits:
    """Largest body twist and twist change the driver passes on.

    Attributes
    ----------
    max_speed_m_s : |V| forward speed [m/s]
    max_yaw_rate_rad_s : |w_z| yaw rate [rad/s]
    max_accel_m_s2 : |dV/dt| [m/s^2] (speeding up and slowing down on command)
    max_yaw_accel_rad_s2 : |dw_z/dt| [rad/s^2]
    """

    max_speed_m_s: float = 1.5
    max_yaw_rate_rad_s: float = 2.0
    max_accel_m_s2: float = 1.0
    max_yaw_accel_rad_s2: float = 4.0

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ConfigError(f'{name} must be a finite number > 0, not {value!r}')


VEHICLE_DEFAULT = 0.0
"""A des_driver limit parameter at 0: the vehicle file's drive controller (:func:`limits_for`)."""
FALLBACK_ACCEL = (1.0, 4.0)
"""The slew limits [m/s^2, rad/s^2] where the vehicle's controller has none: the driver always slews
(ASSUMED: the driver's defaults before vehicle files declared their controller)."""


def limits_for(controller: DriveController, given: Mapping[str, float]) -> CommandLimits:
    """The driver's limits: each of ``given`` (``max_speed_m_s``, ``max_yaw_rate_rad_s``,
    ``max_accel_m_s2``, ``max_yaw_accel_rad_s2``; SI units) where > 0, else the vehicle's drive
    ``controller``'s (an acceleration it does not limit: :data:`FALLBACK_ACCEL`)."""
    own = {
        'max_speed_m_s': controller.max_speed_m_s,
        'max_yaw_rate_rad_s': controller.max_yaw_rate_rad_s,
        'max_accel_m_s2': controller.max_accel_m_s2,
        'max_yaw_accel_rad_s2': controller.max_yaw_accel_rad_s2,
    }
    fallback = dict(zip(('max_accel_m_s2', 'max_yaw_accel_rad_s2'), FALLBACK_ACCEL, strict=True))
    values = {}
    for name, vehicle_value in own.items():
        value = float(given.get(name, VEHICLE_DEFAULT))
        if value == VEHICLE_DEFAULT:
            value = vehicle_value if math.isfinite(vehicle_value) else fallback.get(name, vehicle_value)
        values[name] = value
    return CommandLimits(**values)


@dataclass(frozen=True)
class CheckedTwist:
    """A twist that passed :func:`limit_twist`: V [m/s], w_z [rad/s], and whether it was clamped."""

    linear_m_s: float
    yaw_rate_rad_s: float
    clamped: bool


def limit_twist(linear_m_s: float, yaw_rate_rad_s: float, limits: CommandLimits) -> CheckedTwist:
    """Reject a non-finite twist (InputError), clamp a finite one to ``limits`` (each axis alone)."""
    v, w = float(linear_m_s), float(yaw_rate_rad_s)
    if not (math.isfinite(v) and math.isfinite(w)):
        raise InputError(f'non-finite command: V {v!r} m/s, yaw rate {w!r} rad/s')
    cv, cw = clamp_twist(v, w, limits.max_speed_m_s, limits.max_yaw_rate_rad_s)  # the drive layer's
    return CheckedTwist(cv, cw, clamped=(cv, cw) != (v, w))


class SlewLimiter:
    """Moves a twist toward a target at no more than the limits' accelerations (not thread-safe).

    :meth:`step` advances by the time since the previous call, at most ``max_step_s`` [s] (so a
    stall of the caller never turns into a jump); :meth:`reset` puts it at rest.
    """

    def __init__(self, limits: CommandLimits, max_step_s: float = 0.1) -> None:
        self.limits = limits
        self.max_step_s = max_step_s
        self.linear_m_s = 0.0
        self.yaw_rate_rad_s = 0.0
        self._v, self._w = [0.0, 0.0], [0.0, 0.0]
        self._last_s: float | None = None

    def reset(self, now_s: float) -> None:
        self.linear_m_s = self.yaw_rate_rad_s = 0.0
        self._v, self._w = [0.0, 0.0], [0.0, 0.0]  # last outputs, as skidsteer_power.drive.Ramp keeps
        self._last_s = now_s

    def step(
        self, target_linear_m_s: float, target_yaw_rate_rad_s: float, now_s: float
    ) -> tuple[float, float]:
        """The twist (V [m/s], w_z [rad/s]) to command at ``now_s`` [s] (time.monotonic)."""
        dt = 0.0 if self._last_s is None else min(self.max_step_s, max(0.0, now_s - self._last_s))
        self._last_s = now_s
        # the drive layer's acceleration limit (skidsteer_power.drive.controller.limit_rate), no jerk limit
        self.linear_m_s = limit_rate(target_linear_m_s, self._v, self.limits.max_accel_m_s2, math.inf, dt)
        self.yaw_rate_rad_s = limit_rate(
            target_yaw_rate_rad_s, self._w, self.limits.max_yaw_accel_rad_s2, math.inf, dt
        )
        return self.linear_m_s, self.yaw_rate_rad_s


@dataclass(frozen=True)
class DriveGeometry:
    """From a body twist to per-side motor set points [rpm, amplifier sense].

    Attributes
    ----------
    tread_m : B, centre-to-centre of the two sides [m] (the vehicle file's ``tread_m``)
    drive_radius_m : sprocket or wheel radius r [m] (the vehicle file)
    gear_ratio : motor-to-axle reduction G [-] (the vehicle's powertrain)
    polarity : amplifier sense of forward motion per side (+1 / -1)
    max_rpm : largest motor set point [rpm]; both sides are scaled together beyond it
    """

    tread_m: float
    drive_radius_m: float
    gear_ratio: float
    polarity: dict[str, int]
    max_rpm: float

    def motor_rpm(self, linear_m_s: float, yaw_rate_rad_s: float) -> dict[str, float]:
        """Set points [rpm, amplifier sense] for V [m/s] and w_z [rad/s] (see kinematics)."""
        left, right = twist_to_motor_rpm(
            linear_m_s,
            yaw_rate_rad_s,
            tread_m=self.tread_m,
            drive_radius_m=self.drive_radius_m,
            gear_ratio=self.gear_ratio,
            max_rpm=self.max_rpm,
        )
        return {'left': left * self.polarity['left'], 'right': right * self.polarity['right']}
