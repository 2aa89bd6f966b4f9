"""What power_estimator would have published from a bag: the online correction replayed offline.

:func:`skidsteer_power.bags.validate.run_estimator` feeds the bag to the estimator core as the node
does; before each joint_states reading updates the core's online adaptation
(:mod:`skidsteer_power.estimator.adaptation`), :func:`online_figures` records the corrected
prediction the core holds at that moment (a one-sample-ahead estimate: it has learned from the
readings before, not from this one). :func:`online_summary` is validate's ``online_prediction``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from skidsteer_power.powertrain.motor import terminal_power

if TYPE_CHECKING:
    from skidsteer_power.bags.validate import RunSeries

NO_ONLINE = (math.nan,) * 7


def online_figures(core: Any) -> tuple[float, ...]:
    """The online columns of :data:`SERIES_COLUMNS` for the core's current state: torques [N m],
    terminal powers [W] and battery power [W] of the corrected prediction, and the terminal powers of
    the terrain-scaled one (internal + k x terrain torque at the motor) [W]."""
    p = core.prediction
    if p is None:
        return NO_ONLINE
    motor = core.powertrain.motor
    torque = core.corrected_torque_Nm()
    k = core.adaptation.terrain_scale()
    gear = core.powertrain.gear_ratio
    scaled = [t + (k - 1.0) * a / gear for t, a in zip(p.motor_torque_Nm, p.terrain_torque_Nm, strict=True)]
    w = p.motor_omega_rad_s
    return (
        torque[0],
        torque[1],
        terminal_power(motor, torque[0], w[0]),
        terminal_power(motor, torque[1], w[1]),
        core.corrected_bus_W(),
        terminal_power(motor, scaled[0], w[0]),
        terminal_power(motor, scaled[1], w[1]),
    )


def predicted_battery_J(series: RunSeries, column: str = 'predicted_battery_W') -> float:
    """Battery-side energy [J] of a predicted power ``column`` [W] over the rows whose command is in
    force, each row weighted by its ``hold_s`` as the measured energy is (no command in force: the
    driver stops the motors, no drive power is predicted)."""
    c = series.columns
    fresh = c['cmd_fresh'] > 0
    weights = np.nan_to_num(c['hold_s'], nan=0.0, posinf=0.0)
    return float(np.sum(np.nan_to_num(c[column] * weights)[fresh]))


def with_prediction(series: RunSeries, torque: str | None, power: str) -> RunSeries:
    """``series`` whose predicted torques and powers are the columns named ``torque`` / ``power``
    with ``{side}`` in them (torque None: unchanged), for :func:`error_metrics`."""
    columns = dict(series.columns)
    for side in ('left', 'right'):
        if torque is not None:
            columns[f'predicted_torque_{side}_Nm'] = columns[torque.format(side=side)]
        columns[f'predicted_power_{side}_W'] = columns[power.format(side=side)]
    return replace(series, columns=columns)


def online_summary(series: RunSeries, core: Any) -> dict[str, Any]:
    """``online_prediction`` of the summary: what power_estimator would have published from the bag.

    ``metrics``: the prediction with the per-side online correction learned up to each reading
    (:func:`online_figures`); ``terrain_scaled``: energy and power errors with the terrain torque
    scaled by the online terrain scale k, as the path energy uses it; ``battery_energy_predicted_J``:
    the corrected battery energy; the adaptation's final state.
    """
    from skidsteer_power.bags.validate import error_metrics

    metrics = error_metrics(with_prediction(series, 'online_torque_{side}_Nm', 'online_power_{side}_W'))
    scaled = error_metrics(with_prediction(series, None, 'scaled_power_{side}_W'))
    state = core.adaptation.state()
    return {
        'metrics': metrics,
        'terrain_scaled': {
            key: scaled[key] for key in ('energy_predicted_J', 'energy_measured_J', 'energy_error_pct')
        }
        | {'power_left': scaled['power_left'], 'power_right': scaled['power_right']},
        'battery_energy_predicted_J': predicted_battery_J(series, 'online_battery_W'),
        'adaptation_enabled': bool(core.adaptation.settings.enabled),
        'terrain_scale': state.terrain_scale,
        'correction_scale': list(state.scale),
        'correction_offset_Nm': list(state.offset_Nm),
        'terrain_changes': state.terrain_changes,
    }
