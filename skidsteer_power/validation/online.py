"""What power_estimator would have published from a bag: the online correction replayed offline.

:func:`skidsteer_power.validation.validate.run_estimator` feeds the bag to the estimator core as the node
does; before each joint_states reading updates the core's online adaptation
(:mod:`skidsteer_power.estimator.adaptation`), :func:`online_figures` records the corrected
prediction the core holds at that moment (a one-sample-ahead estimate: it has learned from the
readings before, not from this one). :func:`online_summary` is validate's ``online_prediction``.

Series columns: ``online_torque_*`` [N m] and ``terrain_scale`` k [-] recorded per row; after the run
(:data:`DERIVED_COLUMNS`) ``online_power_*`` [W], ``online_battery_W`` (the corrected battery power
that feeds the node's energy integration) and ``scaled_power_*`` [W] (the terrain torque scaled by k
as the path energy does: internal torque + k x terrain torque at the motor).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.powertrain.motor import bus_power, terminal_power
from skidsteer_power.validation.summary import OnlinePrediction

if TYPE_CHECKING:
    from skidsteer_power.estimator import EstimatorCore
    from skidsteer_power.seams import PowertrainLike
    from skidsteer_power.validation.series import RunSeries

NO_ONLINE = (math.nan,) * 3
DERIVED_COLUMNS = (
    'online_power_left_W',
    'online_power_right_W',
    'online_battery_W',
    'scaled_power_left_W',
    'scaled_power_right_W',
)


def online_figures(core: EstimatorCore) -> tuple[float, float, float]:
    """What a row records of the core's online state: the corrected motor torques [N m] (left,
    right) and the terrain scale k [-]. Kept to three float reads per row (validate's speed); the
    powers follow from them after the run (:func:`online_columns`)."""
    p = core.prediction
    if p is None:
        return NO_ONLINE
    adaptation = core.adaptation
    torque = p.motor_torque_Nm
    if not adaptation.settings.enabled:
        return torque[0], torque[1], 1.0
    left, right = adaptation.sides  # TorqueAdaptation.corrected, inlined: this runs per reading
    return left.a * torque[0] + left.b, right.a * torque[1] + right.b, adaptation.terrain_scale()


def online_columns(
    c: dict[str, np.ndarray], powertrain: PowertrainLike, battery_side: bool = False
) -> dict[str, np.ndarray]:
    """:data:`DERIVED_COLUMNS` from a run's rows, vectorized: the corrected prediction's per-side
    power [W] at the predicted motor speeds, its battery power [W] (the prediction's plus the change
    the correction makes through the amplifier, as ``EstimatorCore.corrected_bus_W``), and the
    per-side power [W] of the terrain-scaled prediction (internal + k x terrain torque at the motor).

    The per-side powers are in the rows' own terms: terminal powers, or with ``battery_side`` (a
    measured V x I, whose rows hold battery-side ``predicted_power_*``) each side's predicted
    battery power plus the change the correction makes through the amplifier. Terminal powers there
    once compared with battery-side measurements: compare's online rows on a BorealTC import read
    -57 % where the corrected battery energy was -24 %."""
    motor, amplifier, regen = powertrain.motor, powertrain.amplifier, powertrain.regen_efficiency
    k = c['terrain_scale']
    out: dict[str, np.ndarray] = {}
    bus_change = np.zeros_like(k)
    with np.errstate(invalid='ignore'):
        for side in ('left', 'right'):
            omega = c[f'predicted_omega_{side}_rad_s']
            torque = c[f'predicted_torque_{side}_Nm']
            online = np.asarray(terminal_power(motor, c[f'online_torque_{side}_Nm'], omega))
            plain = np.asarray(terminal_power(motor, torque, omega))
            terrain = c[f'predicted_axle_torque_{side}_Nm'] / powertrain.gear_ratio
            scaled = np.asarray(terminal_power(motor, torque + (k - 1.0) * terrain, omega))
            plain_bus = np.asarray(bus_power(plain, amplifier, regen))
            side_change = np.asarray(bus_power(online, amplifier, regen)) - plain_bus
            bus_change = bus_change + side_change
            if battery_side:
                predicted = c[f'predicted_power_{side}_W']
                online = predicted + side_change
                scaled = predicted + np.asarray(bus_power(scaled, amplifier, regen)) - plain_bus
            out[f'online_power_{side}_W'] = online
            out[f'scaled_power_{side}_W'] = scaled
    out['online_battery_W'] = c['predicted_battery_W'] + bus_change
    return out


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


def online_summary(series: RunSeries, core: EstimatorCore) -> OnlinePrediction:
    """``online_prediction`` of the summary: what power_estimator would have published from the bag.

    ``metrics``: the prediction with the per-side online correction learned up to each reading
    (:func:`online_figures`); ``terrain_scaled``: energy and power errors with the terrain torque
    scaled by the online terrain scale k, as the path energy uses it; ``battery_energy_predicted_J``:
    the corrected battery energy; the adaptation's final state.
    """
    from skidsteer_power.validation.validate_metrics import error_metrics

    metrics = error_metrics(with_prediction(series, 'online_torque_{side}_Nm', 'online_power_{side}_W'))
    scaled = error_metrics(with_prediction(series, None, 'scaled_power_{side}_W'))
    state = core.adaptation.state()
    return OnlinePrediction(
        metrics=metrics,
        terrain_scaled=scaled,  # its energy and power figures are reported (OnlinePrediction.as_json)
        battery_energy_predicted_J=predicted_battery_J(series, 'online_battery_W'),
        adaptation_enabled=bool(core.adaptation.settings.enabled),
        terrain_scale=state.terrain_scale,
        correction_scale=state.scale,
        correction_offset_Nm=state.offset_Nm,
        terrain_changes=state.terrain_changes,
    )
