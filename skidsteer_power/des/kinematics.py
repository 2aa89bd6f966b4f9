"""Skid-steer kinematics between a body twist and per-side motor speeds (no ROS), in motor rpm for
the DES 70/10; the one implementation is the drive controller's (:mod:`skidsteer_power.drive`).

REP 103: x forward, z up, positive yaw rate turns left. With an effective tread B_eff [m] (the
geometric tread widened by track/wheel slip in a skid-steered turn), the side speeds are

    v_left = v - omega B_eff / 2,   v_right = v + omega B_eff / 2          [m/s]

and a side's motor speed is v_side / r * G [rad/s] for drive radius r [m] and reduction G [-].
"""

from __future__ import annotations

import math

from skidsteer_power.drive.controller import (
    DES_MAX_SPEED_1PP_RPM,
    DriveController,
    set_point_limit_rpm,
    side_speeds,
)
from skidsteer_power.errors import InputError
from skidsteer_power.powertrain.motor import RPM

__all__ = [
    'DES_MAX_SPEED_1PP_RPM',
    'RPM',
    'drive_rpm',
    'set_point_limit_rpm',
    'side_speeds',
    'twist_to_motor_rpm',
    'unwrap_counter',
]


def twist_to_motor_rpm(
    linear_m_s: float,
    yaw_rate_rad_s: float,
    *,
    tread_m: float,
    drive_radius_m: float,
    gear_ratio: float,
    max_rpm: float,
) -> tuple[float, float]:
    """(left, right) motor speed set points [rpm], forward positive, for a body twist.

    The drive controller's kinematics and ceiling (:meth:`DriveController.wheels_one`): if either
    side would exceed ``max_rpm`` [rpm], both are scaled by the same factor so the commanded path
    curvature is kept. A non-finite input is an InputError, never a NaN set point.
    """
    values = (linear_m_s, yaw_rate_rad_s, tread_m, drive_radius_m, gear_ratio, max_rpm)
    if not all(math.isfinite(v) for v in values):
        raise InputError(f'non-finite twist or geometry: {values}')
    to_rpm = gear_ratio / RPM
    ctrl = DriveController(tread_m, drive_radius_m, max_wheel_rad_s=max_rpm / to_rpm)
    return drive_rpm(ctrl, linear_m_s, yaw_rate_rad_s, gear_ratio)


def drive_rpm(ctrl: DriveController, speed: float, yaw_rate: float, gear_ratio: float) -> tuple[float, float]:
    """(left, right) motor speed set points [rpm] of ``ctrl`` for a twist already within its velocity
    (and acceleration) limits (V [m/s], w_z [rad/s]), through the reduction ``gear_ratio``."""
    (left, _), (right, _) = ctrl.wheels_one(speed, yaw_rate)
    to_rpm = gear_ratio / RPM
    return left * to_rpm, right * to_rpm


def unwrap_counter(previous: int, current: int, expected_delta: float, modulus: int = 1 << 16) -> int:
    """Counts moved between two readings of a wrapping counter [counts].

    Of all deltas congruent to ``current - previous`` modulo ``modulus``, the one nearest
    ``expected_delta`` (speed x time since the last reading) is taken, so a fast motor that wraps
    the 16-bit counter between polls is still tracked.
    """
    base = (current - previous) % modulus
    return base + modulus * round((expected_delta - base) / modulus)
