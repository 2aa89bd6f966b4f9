"""The drive layer: what the robot's own controller makes of a command, below the physics (no ROS).

A body twist command (cmd_vel: V [m/s], w_z [rad/s]) becomes per-side wheel (axle) speed set points
[rad/s] the way a ros2_controllers diff_drive_controller and the robot's motor drivers make them:
velocity, acceleration and jerk limits on the twist, the wheel separation and radius (with their
multipliers), the per-wheel speed ceiling met by scaling both sides together (curvature kept) or by
clipping each side, and the driver's current limit where it caps torque
(:mod:`skidsteer_power.drive.controller`). :func:`~skidsteer_power.drive.identification.identify` finds the
limits from recordings (commanded against measured wheel speeds). docs/DRIVE.md.
"""

from __future__ import annotations

from skidsteer_power.drive.controller import (
    CEILING_MODES,
    DriveController,
    Ramp,
    WheelSetpoints,
    controller_for_vehicle,
)
from skidsteer_power.drive.identification import DriveIdentification, IdentifiedValue, identify

__all__ = [
    'CEILING_MODES',
    'DriveController',
    'DriveIdentification',
    'IdentifiedValue',
    'Ramp',
    'WheelSetpoints',
    'controller_for_vehicle',
    'identify',
]
