"""The estimator's named figures: SI units in the names, NaN where unknown.

Published two ways (docs/INTERFACES.md says why): the key figures as one ``std_msgs/Float64`` topic
each, the latest value at the node's ``figure_period_s`` (:data:`COMMAND_FIGURES` after a new cmd_vel,
:data:`MEASUREMENT_FIGURES` after new joint_states), so every plotting tool finds them by topic name;
and all of :data:`SUMMARY_FIELDS`
as the key/value pairs of ``power/summary`` (diagnostic_msgs/DiagnosticArray, one status), read
back with :func:`summary_from_key_values`.

Power entries per side are motor terminal (electrical) power [W]: measured = Kt*I*omega + R*I^2,
predicted = the same for the predicted operating point. ``*_battery_W`` are both sides at the DC
bus (through the amplifiers), which is what the battery gives. ``error_*_W`` = measured - predicted.
``corrected_*_W`` are the prediction with the online correction applied (the estimate the battery
forecast uses, :meth:`EstimatorCore.corrected_bus_W`; equal to ``predicted_*`` until the correction
has settled). ``energy_source``: 0 measured, 1 predicted, 2 none (see
:mod:`skidsteer_power.estimator.energy`).
``soc`` and ``remaining_wh`` are as of the last battery update (the node's publish timer, 0.2 s).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

from skidsteer_power.estimator.energy import SOURCES

if TYPE_CHECKING:
    from skidsteer_power.estimator.core import Comparison, EstimatorCore
    from skidsteer_power.estimator.prediction import Prediction

SUMMARY_FIELDS: tuple[str, ...] = (
    'speed_cmd_m_s',
    'yaw_rate_cmd_rad_s',
    'predicted_motion_speed_m_s',
    'predicted_motion_yaw_rate_rad_s',
    'predicted_left_W',
    'predicted_right_W',
    'measured_left_W',
    'measured_right_W',
    'measured_mech_left_W',
    'measured_mech_right_W',
    'error_left_W',
    'error_right_W',
    'predicted_battery_W',
    'measured_battery_W',
    'terrain_W',
    'internal_W',
    'terrain_share',
    'predicted_speed_left_rad_s',
    'predicted_speed_right_rad_s',
    'measured_speed_left_rad_s',
    'measured_speed_right_rad_s',
    'predicted_torque_left_Nm',
    'predicted_torque_right_Nm',
    'measured_torque_left_Nm',
    'measured_torque_right_Nm',
    'predicted_current_left_A',
    'predicted_current_right_A',
    'measured_current_left_A',
    'measured_current_right_A',
    'traction_margin',
    'traction_warning',
    'clamped',
    'soc',
    'remaining_wh',
    'time_to_empty_s',
    'energy_source',
    'cmd_vel_stale',
    'joint_states_stale',
    'corrected_left_W',
    'corrected_right_W',
    'corrected_battery_W',
)

SUMMARY_STATUS_NAME = 'power summary'
"""``name`` of the one DiagnosticStatus in ``power/summary``."""

COMMAND_FIGURES: tuple[tuple[str, str], ...] = (
    ('power/predicted_left_w', 'predicted_left_W'),
    ('power/predicted_right_w', 'predicted_right_W'),
    ('power/predicted_battery_w', 'predicted_battery_W'),
    ('power/terrain_w', 'terrain_W'),
    ('power/internal_w', 'internal_W'),
    ('power/traction_margin', 'traction_margin'),
)
"""(topic, summary field) published as std_msgs/Float64 after accepted cmd_vel (``figure_period_s``)."""

MEASUREMENT_FIGURES: tuple[tuple[str, str], ...] = (
    ('power/measured_left_w', 'measured_left_W'),
    ('power/measured_right_w', 'measured_right_W'),
    ('power/measured_battery_w', 'measured_battery_W'),
)
"""(topic, summary field) published as std_msgs/Float64 after accepted joint_states (``figure_period_s``)."""


def _prediction_values(p: Prediction | None) -> dict[str, float]:
    if p is None:
        return {}
    return {
        'speed_cmd_m_s': p.speed_m_s,
        'yaw_rate_cmd_rad_s': p.yaw_rate_rad_s,
        'predicted_motion_speed_m_s': getattr(p, 'achieved_speed_m_s', math.nan),
        'predicted_motion_yaw_rate_rad_s': getattr(p, 'achieved_yaw_rate_rad_s', math.nan),
        'predicted_left_W': p.electrical_W[0],
        'predicted_right_W': p.electrical_W[1],
        'predicted_battery_W': p.bus_total_W,
        'terrain_W': p.terrain_total_W,
        'internal_W': p.internal_total_W,
        'terrain_share': p.terrain_share,
        'predicted_speed_left_rad_s': p.motor_omega_rad_s[0],
        'predicted_speed_right_rad_s': p.motor_omega_rad_s[1],
        'predicted_torque_left_Nm': p.motor_torque_Nm[0],
        'predicted_torque_right_Nm': p.motor_torque_Nm[1],
        'predicted_current_left_A': p.current_A[0],
        'predicted_current_right_A': p.current_A[1],
        'traction_margin': p.traction_margin,
        'clamped': float(p.clamped),
    }


def _measured_values(c: Comparison | None) -> dict[str, float]:
    if c is None:
        return {}
    m = c.measured
    return {
        'measured_left_W': m.electrical_W[0],
        'measured_right_W': m.electrical_W[1],
        'measured_mech_left_W': m.mechanical_W[0],
        'measured_mech_right_W': m.mechanical_W[1],
        'error_left_W': c.power_error_W[0],
        'error_right_W': c.power_error_W[1],
        'measured_battery_W': m.bus_total_W,
        'measured_speed_left_rad_s': m.omega_rad_s[0],
        'measured_speed_right_rad_s': m.omega_rad_s[1],
        'measured_torque_left_Nm': m.torque_Nm[0],
        'measured_torque_right_Nm': m.torque_Nm[1],
        'measured_current_left_A': m.current_A[0],
        'measured_current_right_A': m.current_A[1],
    }


def summary_dict(core: EstimatorCore, now_s: float) -> dict[str, float]:
    """Every :data:`SUMMARY_FIELDS` entry for an :class:`EstimatorCore` at ``now_s`` [s]."""
    values = dict.fromkeys(SUMMARY_FIELDS, math.nan)
    values.update(_prediction_values(core.prediction))
    values.update(_measured_values(core.comparison))
    if core.prediction is not None:
        left, right = core.corrected_terminal_W()
        values.update(
            corrected_left_W=left, corrected_right_W=right, corrected_battery_W=core.corrected_bus_W()
        )
    battery = core.battery
    values.update(
        traction_warning=float(core.traction_warning()),
        soc=float(battery.soc),
        remaining_wh=float(battery.remaining_wh),
        time_to_empty_s=float(core.time_to_empty_s),
        energy_source=float(SOURCES.index(core.energy.source(now_s))),
        cmd_vel_stale=float(not core.cmd_fresh.is_fresh(now_s)),
        joint_states_stale=float(not core.joint_fresh.is_fresh(now_s)),
    )
    return values


def summary_values(core: EstimatorCore, now_s: float) -> list[float]:
    """:func:`summary_dict` as a list in :data:`SUMMARY_FIELDS` order."""
    values = summary_dict(core, now_s)
    return [float(values[name]) for name in SUMMARY_FIELDS]


def prediction_figures(prediction: Prediction | None) -> list[float]:
    """:data:`COMMAND_FIGURES` values of a :class:`~skidsteer_power.estimator.prediction.Prediction`."""
    values = _prediction_values(prediction)
    return [float(values[field]) for _, field in COMMAND_FIGURES]


def measurement_figures(comparison: Comparison | None) -> list[float]:
    """:data:`MEASUREMENT_FIGURES` values of a :class:`~skidsteer_power.estimator.core.Comparison`."""
    values = _measured_values(comparison)
    return [float(values[field]) for _, field in MEASUREMENT_FIGURES]


def summary_key_values(core: EstimatorCore, now_s: float) -> list[tuple[str, str]]:
    """(name, value text) for every :data:`SUMMARY_FIELDS` entry; ``repr``-exact floats, 'nan' if unknown."""
    values = summary_dict(core, now_s)
    return [(name, repr(float(values[name]))) for name in SUMMARY_FIELDS]


def summary_from_key_values(pairs: Iterable[tuple[str, str]]) -> dict[str, float]:
    """Name -> value from received (key, value) pairs; values that are not numbers are skipped."""
    result: dict[str, float] = {}
    for key, text in pairs:
        try:
            result[key] = float(text)
        except ValueError:
            continue
    return result
