"""Skid-steer kinematics between a body twist and per-side motor speeds (no ROS).

REP 103: x forward, z up, positive yaw rate turns left. With an effective tread B_eff [m] (the
geometric tread widened by track/wheel slip in a skid-steered turn), the side speeds are

    v_left = v - omega B_eff / 2,   v_right = v + omega B_eff / 2          [m/s]

and a side's motor speed is v_side / r * G [rad/s] for drive radius r [m] and reduction G [-].
"""

from __future__ import annotations

import math

from skidsteer_power.errors import InputError
from skidsteer_power.numeric import Real
from skidsteer_power.powertrain.motor import RPM, MotorConstants

__all__ = [
    'DES_MAX_SPEED_1PP_RPM',
    'RPM',
    'set_point_limit_rpm',
    'side_speeds',
    'twist_to_motor_rpm',
    'unwrap_counter',
]

DES_MAX_SPEED_1PP_RPM = 25000.0
"""The DES 70/10's max. speed with a one-pole-pair motor [rpm] (Appendix A); p pole pairs: / p."""


def set_point_limit_rpm(motor: MotorConstants) -> float:
    """The largest speed set point for ``motor`` on a DES 70/10 [rpm]: the motor's max. permissible
    speed (EC-45: 10 000 rpm, Appendix B line 23), at most the amplifier's 25 000 rpm / pole pairs."""
    return min(motor.max_speed_rad_s / RPM, DES_MAX_SPEED_1PP_RPM / motor.pole_pairs)


def side_speeds(linear_m_s: Real, yaw_rate_rad_s: Real, tread_m: float) -> tuple[Real, Real]:
    """(left, right) track/wheel ground speeds [m/s] for a body twist (v [m/s], yaw rate [rad/s]);
    floats or arrays (:mod:`skidsteer_power.numeric`)."""
    half = 0.5 * yaw_rate_rad_s * tread_m
    return linear_m_s - half, linear_m_s + half


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

    If either side would exceed ``max_rpm`` [rpm], both are scaled by the same factor so the
    commanded path curvature is kept. A non-finite input is an InputError, never a NaN set point.
    """
    values = (linear_m_s, yaw_rate_rad_s, tread_m, drive_radius_m, gear_ratio, max_rpm)
    if not all(math.isfinite(v) for v in values):
        raise InputError(f'non-finite twist or geometry: {values}')
    left, right = side_speeds(linear_m_s, yaw_rate_rad_s, tread_m)
    scale = gear_ratio / drive_radius_m / RPM
    rpm_left, rpm_right = left * scale, right * scale
    peak = max(abs(rpm_left), abs(rpm_right))
    if not math.isfinite(peak):
        raise InputError(f'twist ({linear_m_s!r} m/s, {yaw_rate_rad_s!r} rad/s) overflows the motor speed')
    if peak > max_rpm:
        rpm_left, rpm_right = rpm_left * max_rpm / peak, rpm_right * max_rpm / peak
    return rpm_left, rpm_right


def unwrap_counter(previous: int, current: int, expected_delta: float, modulus: int = 1 << 16) -> int:
    """Counts moved between two readings of a wrapping counter [counts].

    Of all deltas congruent to ``current - previous`` modulo ``modulus``, the one nearest
    ``expected_delta`` (speed x time since the last reading) is taken, so a fast motor that wraps
    the 16-bit counter between polls is still tracked.
    """
    base = (current - previous) % modulus
    return base + modulus * round((expected_delta - base) / modulus)
