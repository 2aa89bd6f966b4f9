"""The drive controller's limits from the calibration's recordings (issue 36; docs/DRIVE.md).

The bags' commanded twists (cmd_vel) against their measured wheel speeds (joint_states) go to
:func:`skidsteer_power.drive.identify`: the wheels follow the controller's set points whatever the
ground does, so this part of ``calibrate --fit auto`` needs no motor torque and no body motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.drive import DriveIdentification, identify

if TYPE_CHECKING:
    from skidsteer_power.calibration.segments import Recording
    from skidsteer_power.drive import DriveController

__all__ = ['CMD_TIMEOUT_S', 'commands_in_force', 'identify_drive']

CMD_TIMEOUT_S = 0.5
"""A command older than this [s] no longer drives: the robot is commanded to stand (ASSUMED: the
default ``cmd_vel_timeout`` of ros2_controllers' diff_drive_controller, 0.5 s, and this project's
des_driver ``cmd_timeout_s``)."""
GAP_S = 10.0
"""Time [s] put between two recordings so that no ramp is measured across the seam."""


def commands_in_force(cmd_t: np.ndarray, cmd: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 2) the command (V [m/s], w_z [rad/s]) in force at each time ``t`` [s]: the last one sent
    at or before it, zero before the first and once it is older than :data:`CMD_TIMEOUT_S`."""
    if not cmd_t.size:
        return np.zeros((t.size, 2))
    k = np.searchsorted(cmd_t, t, side='right') - 1
    held = np.maximum(k, 0)
    fresh = (k >= 0) & (t - cmd_t[held] <= CMD_TIMEOUT_S)
    return np.where(fresh[:, None], cmd[held], 0.0)


def identify_drive(
    recordings: Sequence[Recording], prior: DriveController, gear_ratio: float
) -> DriveIdentification | None:
    """Identify the drive controller's limits from every recording with commands and wheel speeds.

    recordings : decoded bags (:func:`~skidsteer_power.calibration.segments.read_recording`), whose
        ``omega`` is the motor-equivalent speed [rad/s] of a powertrain with reduction ``gear_ratio``
        [-] (the axle speed is omega / gear_ratio); prior : the vehicle file's controller (geometry
        used, values kept where no limit is reached). None when no recording has both.
    """
    times, commanded, measured = [], [], []
    offset = 0.0
    for rec in recordings:
        if rec.cmd_t.size == 0 or rec.js_t.size < 2:
            continue
        times.append(rec.js_t + offset)
        commanded.append(commands_in_force(rec.cmd_t, rec.cmd, rec.js_t))
        measured.append(rec.omega / gear_ratio)
        offset = float(times[-1][-1]) + GAP_S
    if not times:
        return None
    return identify(np.concatenate(times), np.concatenate(commanded), np.concatenate(measured), prior=prior)
