"""The driver's current limit (step 5 of :mod:`skidsteer_power.drive.controller`): what a side's
amplifier gives when the steady state asks more current than its limit.

The amplifier holds the motor current at the limit, so the motor gives K_t i_limit and the axle that
torque less the drivetrain's internal resistance (eq. 7.1) through the reduction:
T_axle = G (K_t i_limit sign(i) - T_int(G omega)). One formula for a float (the set-point map's
per-query path) and for arrays (the direct prediction), :mod:`skidsteer_power.numeric`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.numeric import Real, sign, where

if TYPE_CHECKING:
    from skidsteer_power.powertrain.power_flow import MotorPoint, Powertrain

__all__ = ['current_limited']


def current_limited(
    powertrain: Powertrain, side: str, torque: Real, omega: Real, limit_A: float
) -> tuple[Real, Real, MotorPoint[Real], Real | bool]:
    """One side at axle torque [N m] and axle speed [rad/s] under the current limit ``limit_A`` [A]:
    (the axle torque the amplifier gives, the motor current [A] (|.| <= limit_A), the motor point
    (:meth:`Powertrain.motor_side`) at that torque, over the limit). A side within the limit keeps
    its torque and point."""
    point = powertrain.motor_side(side, torque, omega)
    current = point.current_A
    over = abs(current) > limit_A
    if not np.any(over) if isinstance(over, np.ndarray) else not over:
        return torque, current, point, over
    held = sign(current) * limit_A  # the amplifier holds the current at its limit: that torque, no more
    internal = powertrain.resistance(side).torque(powertrain.gear_ratio * omega)
    gear, kt = powertrain.gear_ratio, powertrain.motor.torque_constant_Nm_A
    torque = where(over, gear * (held * kt - internal), torque)
    point = powertrain.motor_side(side, torque, omega)
    return torque, where(over, held, point.current_A), point, over
