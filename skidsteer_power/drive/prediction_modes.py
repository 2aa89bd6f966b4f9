"""What a command is predicted from: one name per idea, for every option that chooses it (issue 38).

- :data:`CMD` ``'cmd'``: the command at its wheel speed set points (the drive controller's,
  :mod:`skidsteer_power.drive.controller`); the terrain decides the motion (DESIGN.md's
  ``validate --kinematics cmd``). power_estimator's ``kinematics`` parameter, ``validate
  --kinematics`` and ``calibrate --fit-at`` all spell it so.
- :data:`TWIST` ``'twist'``: the command taken as the body motion itself (the (V, yaw rate) map).
- :data:`MOTION` ``'motion'``: the measured body motion (``calibrate --fit-at motion``; validate's
  ``odom`` / ``ground_truth`` name the topic it comes from).

The spellings of earlier rounds (``kinematics: setpoint``, ``--fit-at setpoints``) are still
accepted: :func:`prediction_mode` maps them to :data:`CMD` and says so once, so a saved parameter
file or script keeps working and its owner learns the new name.
"""

from __future__ import annotations

from skidsteer_power.errors import InputError

CMD = 'cmd'
TWIST = 'twist'
MOTION = 'motion'
FIT_AT = (CMD, MOTION)
"""``calibrate --fit-at``: what the model of a steady window is solved at (calibration/fit.py)."""
VALIDATE_KINEMATICS = (CMD, TWIST, 'odom', 'ground_truth')
"""``validate --kinematics``: from the command (:data:`CMD`, :data:`TWIST`) or from the measured motion
of the named odometry."""
RENAMED = {'setpoint': CMD, 'setpoints': CMD}
"""Earlier spellings of :data:`CMD` -> the name."""


def prediction_mode(value: str, option: str, choices: tuple[str, ...]) -> tuple[str, str]:
    """(the name, a note) for ``value`` of ``option`` (e.g. ``'--fit-at'``): an earlier spelling
    becomes its name with a one-line note saying so ('' otherwise); InputError naming ``choices``
    for anything else."""
    name = RENAMED.get(value, value) if RENAMED.get(value) in choices else value
    if name not in choices:
        raise InputError(f'{option} must be one of {", ".join(choices)}, not {value!r}')
    if name == value:
        return name, ''
    return name, f'{option} {value!r} is now spelled {name!r} (the old spelling still works)'
