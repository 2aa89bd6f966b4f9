"""Metrics and segments of a validation run (:mod:`skidsteer_power.validation.validate`): the errors of the
predicted against the measured torque [N m], power [W] and energy [J]; the share outside the power
map; the trace analysis of each constant-command segment (eqs. 7.8-7.10); the match of the offline
predictions with the live node's. Pure functions of a run's series and inputs; validate re-exports them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.analysis.trace import fit_circle, mean_speed
from skidsteer_power.errors import InputError
from skidsteer_power.validation.series import TraceSegment as TraceSegment  # re-exported: its old import path
from skidsteer_power.validation.summary import (
    NO_ERROR,
    QUANTITIES,
    SIDES,
    ErrorMetrics,
    LiveComparison,
    MapCoverage,
    SideError,
)

if TYPE_CHECKING:
    from skidsteer_power.estimator.prediction import Predictor
    from skidsteer_power.validation.series import Inputs, RunSeries, ValidateOptions


def error_metrics(series: RunSeries) -> ErrorMetrics:
    """MAE and RMSE per side of torque [N m] and power [W]; energy over the run and its error [%].

    Only rows with a command in force and a measurement count. Energy is the sample-and-hold
    integral of both sides' terminal power over those rows, each weighted by its ``hold_s`` (a
    measurement: until the next one, at most the joint timeout; a command without measurements:
    as long as it is in force).
    """
    c = series.columns
    valid = (c['cmd_fresh'] > 0) & np.isfinite(c['measured_torque_left_Nm'])
    errors: dict[str, SideError] = {}
    for quantity, unit in QUANTITIES:
        for side in SIDES:
            error = (
                c[f'measured_{quantity}_{side}_{unit}'][valid]
                - c[f'predicted_{quantity}_{side}_{unit}'][valid]
            )
            errors[f'{quantity}_{side}'] = (
                SideError(float(np.mean(np.abs(error))), float(np.sqrt(np.mean(error**2))), unit)
                if error.size
                else NO_ERROR[unit]
            )
    weights = np.nan_to_num(c['hold_s'], nan=0.0, posinf=0.0)
    fresh = c['cmd_fresh'] > 0
    predicted = c['predicted_power_left_W'] + c['predicted_power_right_W']
    measured = c['measured_power_left_W'] + c['measured_power_right_W']
    e_pred = (
        float(np.sum((predicted * weights)[valid]))
        if valid.any()
        else float(np.sum((predicted * weights)[fresh]))
    )
    e_meas = float(np.sum((measured * weights)[valid])) if valid.any() else math.nan
    return ErrorMetrics(
        samples_compared=int(valid.sum()),
        torque_left=errors['torque_left'],
        torque_right=errors['torque_right'],
        power_left=errors['power_left'],
        power_right=errors['power_right'],
        energy_predicted_J=e_pred,
        energy_measured_J=e_meas,
        energy_error_pct=100.0 * (e_pred - e_meas) / abs(e_meas) if abs(e_meas) > 1e-9 else math.nan,
    )


def map_coverage(series: RunSeries) -> MapCoverage:
    """Share of the time and of the predicted energy (|terminal power| x hold) with a command in
    force whose prediction came from outside the power map (clamped or limited) [-]."""
    c = series.columns
    fresh = c['cmd_fresh'] > 0
    outside = ((c['clamped'] > 0) | (c['limited'] > 0)) & fresh
    weights = np.nan_to_num(c['hold_s'], nan=0.0, posinf=0.0)
    energy = np.abs(np.nan_to_num(c['predicted_power_left_W'] + c['predicted_power_right_W'])) * weights
    time_total, energy_total = float(weights[fresh].sum()), float(energy[fresh].sum())
    return MapCoverage(
        clamped_time_fraction=float(weights[outside].sum()) / time_total if time_total > 0 else 0.0,
        clamped_energy_fraction=float(energy[outside].sum()) / energy_total if energy_total > 0 else 0.0,
    )


def command_segments(
    cmd_t: np.ndarray,
    cmd: np.ndarray,
    timeout_s: float,
    min_duration_s: float,
    hold_end: np.ndarray | None = None,
) -> list[tuple[float, float, float, float]]:
    """(start, end, V, yaw rate) of runs of one repeated command, split where it stops being in force.

    ``hold_end`` [s]: when each command stops being in force (:func:`validation.cmd_timing.hold_ends`);
    None: at the next command, at most ``timeout_s`` later. A run ends where its last command's hold
    ends. Runs shorter than ``min_duration_s`` and standstill runs (V = yaw rate = 0) are dropped.
    """
    if cmd_t.size == 0:
        return []
    if hold_end is None:
        hold_end = np.minimum(np.append(cmd_t[1:], math.inf), cmd_t + timeout_s)
    change = np.any(np.diff(cmd, axis=0) != 0, axis=1) | (hold_end[:-1] < cmd_t[1:])
    starts = np.concatenate([[0], np.flatnonzero(change) + 1])
    ends = np.concatenate([starts[1:], [cmd_t.size]])
    segments = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        end = float(hold_end[b - 1])
        speed, yaw = float(cmd[a, 0]), float(cmd[a, 1])
        if end - cmd_t[a] >= min_duration_s and (speed != 0 or yaw != 0):
            segments.append((float(cmd_t[a]), float(end), speed, yaw))
    return segments


def trace_segments(
    inputs: Inputs, options: ValidateOptions, predictor: Predictor | None = None
) -> list[TraceSegment]:
    """Trace analysis (eqs. 7.8-7.10) of every constant-command segment (a note says why where the
    poses are too few or collinear), beside the motion ``predictor`` expects for its command
    (``predicted_speed_m_s`` and ``predicted_radius_m``, |V / yaw rate|; NaN without a predictor)."""
    result: list[TraceSegment] = []
    if inputs.pose_t.size < 3:
        return result
    runs = command_segments(
        inputs.cmd_t, inputs.cmd, options.segment_gap_s, options.min_segment_s, inputs.cmd_end
    )
    for start, end, speed, yaw in runs:
        radius_cmd = speed / yaw if yaw != 0 else math.inf
        inside = (inputs.pose_t >= start + options.settle_s) & (inputs.pose_t <= end)
        t, xy = inputs.pose_t[inside], inputs.pose_xy[inside]
        keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
        t, xy = t[keep], xy[keep]
        fit, speed_m, note = None, math.nan, ''
        try:
            speed_m = mean_speed(t, xy[:, 0], xy[:, 1])
            fit = fit_circle(xy[:, 0], xy[:, 1])
        except InputError as err:
            note = str(err)
        predicted_speed, predicted_radius = _predicted_motion(predictor, speed, yaw)
        if t.size == 2:
            note = 'only 2 poses: mean speed, no circle'
        elif t.size == 3 and fit is not None:
            note = 'only 3 poses: the circle passes through them exactly'
        result.append(
            TraceSegment(
                t_start_s=start,
                t_end_s=end,
                speed_cmd_m_s=speed,
                yaw_rate_cmd_rad_s=yaw,
                radius_cmd_m=abs(radius_cmd),
                points=int(t.size),
                radius_m=fit.radius_m if fit else (math.inf if 'collinear' in note else math.nan),
                center_x_m=fit.center_x_m if fit else math.nan,
                center_y_m=fit.center_y_m if fit else math.nan,
                rms_residual_m=fit.rms_residual_m if fit else math.nan,
                speed_m_s=speed_m,
                note=note,
                predicted_speed_m_s=predicted_speed,
                predicted_radius_m=predicted_radius,
            )
        )
    return result


def _predicted_motion(predictor: Predictor | None, speed: float, yaw: float) -> tuple[float, float]:
    """(|V| [m/s], |R| [m]) of the motion ``predictor`` expects for a command; NaN if unknown."""
    if predictor is None:
        return math.nan, math.nan
    p = predictor.predict(speed, yaw)
    v, w = p.achieved_speed_m_s, p.achieved_yaw_rate_rad_s
    radius = abs(v / w) if w != 0 else (math.inf if v != 0 else math.nan)
    return abs(v), radius


LIVE_TOLERANCE_NM = 1e-6


def live_comparison(inputs: Inputs, predictor: Predictor) -> LiveComparison | None:
    """Offline predictions against the live node's ``power/predicted`` motor torques [N m].

    The node publishes one prediction per command it takes, in order, but may lag behind (a busy
    executor) or miss commands sent before it was matched; so live messages are matched in order
    to the commands' offline predictions (each live message to the next command at or after the
    previous match whose prediction agrees within 1e-6 N m). A live message with no such command
    is a mismatch; its difference is taken against the last command received before it.
    """
    if inputs.live_t.size == 0 or inputs.cmd_t.size == 0:
        return None
    offline = np.array([predictor.predict(float(v), float(r)).motor_torque_Nm for v, r in inputs.cmd])
    # Commands repeat: compare each live message with the distinct predictions only.
    unique, command_kind = np.unique(offline, axis=0, return_inverse=True)
    agrees = np.abs(inputs.live_torque[:, None, :] - unique[None, :, :]).max(axis=2) <= LIVE_TOLERANCE_NM
    positions = [np.flatnonzero(command_kind.ravel() == u) for u in range(len(unique))]
    matched, pointer, mismatched = 0, 0, []
    for k in range(inputs.live_t.size):
        found = _next_position([positions[u] for u in np.flatnonzero(agrees[k])], pointer)
        if found is not None:
            matched += 1
            pointer = found + 1
        else:
            mismatched.append(k)
    worst = 0.0
    if mismatched:
        which = np.searchsorted(inputs.cmd_t, inputs.live_t[mismatched], side='right') - 1
        which = np.maximum(which, 0)
        worst = float(np.abs(offline[which] - inputs.live_torque[mismatched]).max())
    return LiveComparison(
        messages=int(inputs.live_t.size),
        matching_within_1e_6=matched,
        max_abs_torque_diff_Nm=worst,
        commands_without_live_prediction=int(inputs.cmd_t.size - matched),
    )


def _next_position(sorted_positions: list[np.ndarray], start: int) -> int | None:
    """Smallest entry >= ``start`` over several sorted index arrays, or None."""
    found: int | None = None
    for positions in sorted_positions:
        i = int(np.searchsorted(positions, start))
        if i < positions.size and (found is None or positions[i] < found):
            found = int(positions[i])
    return found
