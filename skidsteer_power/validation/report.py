"""Validation report files: CSV time series and segments, PNG plots, one Markdown page, JSON summary."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.jsonout import jsonable as jsonable  # re-exported: its old import path
from skidsteer_power.validation.summary import QUANTITIES, SIDES, ReportFiles

if TYPE_CHECKING:
    from skidsteer_power.validation.series import Inputs, RunSeries, TraceSegment
    from skidsteer_power.validation.summary import ValidationSummary

SEGMENT_COLUMNS = (
    't_start_s',
    't_end_s',
    'speed_cmd_m_s',
    'yaw_rate_cmd_rad_s',
    'radius_cmd_m',
    'points',
    'radius_m',
    'center_x_m',
    'center_y_m',
    'rms_residual_m',
    'speed_m_s',
    'note',
)


def _prepare(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f'cannot create report folder {directory}: {err.strerror}') from err


def write_series_csv(path: Path, series: RunSeries) -> None:
    """One row per aligned sample; columns named with their SI unit."""
    names = list(series.columns)
    table = np.column_stack([series.columns[n] for n in names]) if names else np.zeros((0, 0))
    np.savetxt(path, table, delimiter=',', header=','.join(names), comments='', fmt='%.9g')


def write_segments_csv(path: Path, segments: list[TraceSegment]) -> None:
    with path.open('w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(SEGMENT_COLUMNS)
        for s in segments:
            writer.writerow([getattr(s, c) for c in SEGMENT_COLUMNS])


_MAX_PLOT_POINTS = 4000


def _thin(n: int) -> slice:
    """Every k-th sample so a line has at most ~4000 points (a 9-inch plot shows no more)."""
    return slice(None, None, max(1, n // _MAX_PLOT_POINTS))


def held_steps(t: np.ndarray, y: np.ndarray, hold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample-and-hold polyline of samples ``y`` at times ``t`` [s], each held ``hold`` [s] (NaN:
    until the next sample): a flat step per sample, a gap (NaN) where a hold ends before the next."""
    if t.size == 0:
        return t, y
    following = np.append(t[1:], t[-1])
    ends = np.where(np.isfinite(hold), np.minimum(t + np.nan_to_num(hold, posinf=0.0), following), following)
    ends[-1] = t[-1] + (hold[-1] if np.isfinite(hold[-1]) else 0.0)
    gap = np.append(ends[:-1] < t[1:], True)
    x = np.column_stack([t, ends, np.where(gap, ends, np.nan)]).ravel()
    v = np.column_stack([y, y, np.where(gap, np.nan, y)]).ravel()
    keep = ~(np.isnan(x))
    return x[keep], v[keep]


MIN_TURN_RAD = 0.2
"""A fitted circle is drawn only if the segment's path sweeps at least this angle of it [rad] (about
11 degrees; a 0.3 m run on the 1 m circle of Table 7.3 sweeps 0.3 rad): a circle fitted to a nearly
straight run (radius hundreds of m) says nothing a reader could see and is left out of the plot."""


MIN_FIT_POSES = 4
"""Fewest poses for a circle that counts as fitted: a circle passes through any 3 points exactly (no
residual, nothing fitted), so eqs. 7.8-7.10 over-determine it from 4 on."""

LEGEND_CIRCLES = 8
"""trace.png names at most this many circles in its legend (radius and time); the rest are counted."""


def is_fitted(segment: TraceSegment) -> bool:
    """A segment whose circle was fitted: finite radius, >= 4 poses."""
    return math.isfinite(segment.radius_m) and segment.points >= MIN_FIT_POSES


def is_turn(segment: TraceSegment) -> bool:
    """True if the segment's fitted circle (:func:`is_fitted`) describes a turn: finite radius and the
    arc driven (measured speed [m/s] x duration [s]) sweeps at least :data:`MIN_TURN_RAD` of it."""
    if not (math.isfinite(segment.radius_m) and segment.radius_m > 0 and math.isfinite(segment.speed_m_s)):
        return False
    if not is_fitted(segment):
        return False
    arc_m = abs(segment.speed_m_s) * (segment.t_end_s - segment.t_start_s)
    return arc_m / segment.radius_m >= MIN_TURN_RAD


def flagged_spans(
    t: np.ndarray, flag: np.ndarray, hold: np.ndarray, min_gap_s: float = 0.0
) -> list[tuple[float, float]]:
    """(start, end) [s] of the time the rows with ``flag`` set are in force (each row from its time
    ``t`` for ``hold`` [s], NaN: until the next row), spans less than ``min_gap_s`` apart merged (a
    plot cannot show a gap narrower than a pixel, and thousands of patches cost seconds)."""
    following = np.append(t[1:], t[-1]) if t.size else t
    ends = np.where(np.isfinite(hold), t + np.nan_to_num(hold, posinf=0.0), following)
    spans: list[tuple[float, float]] = []
    for start, end in zip(t[flag].tolist(), ends[flag].tolist(), strict=True):
        if spans and start <= spans[-1][1] + max(min_gap_s, 1e-9):
            spans[-1] = (spans[-1][0], max(spans[-1][1], end))
        else:
            spans.append((start, end))
    return spans


def write_plots(
    directory: Path, series: RunSeries, inputs: Inputs, segments: list[TraceSegment]
) -> list[str]:
    """PNG plots: torque and power per side (predicted vs measured, sample-and-hold steps), and the
    recorded path with the circles fitted to its constant-command segments."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    every = _thin(len(series.columns['t_s']))
    c = {name: values[every] for name, values in series.columns.items()}
    hold = c['hold_s'] * (1 if every.step in (None, 1) else np.nan)  # thinned: hold to the next kept
    t_all = series.columns['t_s']
    outside = flagged_spans(
        t_all,
        (series.columns['clamped'] > 0) | (series.columns['limited'] > 0),
        series.columns['hold_s'],
        min_gap_s=(float(t_all[-1] - t_all[0]) / 2000.0) if t_all.size else 0.0,  # ~1/2 pixel at 9 in
    )
    written = []
    for quantity, unit, label in (
        ('torque', 'Nm', 'motor torque [N m]'),
        ('power', 'W', 'terminal power [W]'),
    ):
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 5.5))
        for ax, side in zip(axes, ('left', 'right'), strict=True):
            predicted = np.where(c['cmd_fresh'] > 0, c[f'predicted_{quantity}_{side}_{unit}'], np.nan)
            ax.plot(*held_steps(c['t_s'], predicted, hold), label='predicted', lw=1.2)
            measured = c[f'measured_{quantity}_{side}_{unit}']
            if np.isfinite(measured).any():
                ax.plot(*held_steps(c['t_s'], measured, hold), label='measured', lw=0.8, alpha=0.8)
            for k, (start, end) in enumerate(outside):
                label_span = 'outside the power map (clamped or limited)' if k == 0 else None
                ax.axvspan(start, end, color='tab:red', alpha=0.12, lw=0, label=label_span)
            ax.set_ylabel(f'{side} {label}')
            ax.grid(alpha=0.3)
            ax.legend(loc='upper right')
        axes[-1].set_xlabel('time from bag start [s] (each sample held until the next or its hold ends)')
        name = f'{quantity}.png'
        fig.tight_layout()
        fig.savefig(directory / name, dpi=90)
        plt.close(fig)
        written.append(name)
    if inputs.pose_t.size:
        written.append(_trace_plot(directory, inputs, segments))
    return written


def trace_window(
    x: np.ndarray, y: np.ndarray, turns: list[TraceSegment]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """trace.png's square window ((x_lo, x_hi), (y_lo, y_hi)) [m]: the path and every turn's whole
    circle with a 4 % margin. A turn's circle sweeps >= MIN_TURN_RAD of the driven arc, so its radius
    is at most arc / MIN_TURN_RAD (no hundreds-of-m circle of a straight run, :func:`is_turn`)."""
    lo = np.array([x.min(), y.min()])
    hi = np.array([x.max(), y.max()])
    for s in turns:
        lo = np.minimum(lo, [s.center_x_m - s.radius_m, s.center_y_m - s.radius_m])
        hi = np.maximum(hi, [s.center_x_m + s.radius_m, s.center_y_m + s.radius_m])
    cx, cy = (hi + lo) / 2
    half = max(float(np.max(hi - lo)), 0.1) / 2 * 1.08
    return (float(cx - half), float(cx + half)), (float(cy - half), float(cy + half))


def _trace_plot(directory: Path, inputs: Inputs, segments: list[TraceSegment]) -> str:
    """The recorded path, scaled to itself, with the fitted circles clipped to the path's window."""
    import matplotlib.pyplot as plt  # Agg, chosen by write_plots

    fig, ax = plt.subplots(figsize=(6, 6))
    every = _thin(len(inputs.pose_t))
    x, y = inputs.pose_xy[every, 0], inputs.pose_xy[every, 1]
    ax.plot(x, y, '-', lw=0.8, color='0.5', label=f'path ({inputs.pose_topic})')
    ax.plot(x[:1], y[:1], 'o', color='0.3', ms=4, label='start')
    angles = np.linspace(0, 2 * np.pi, 721)
    turns = [s for s in segments if is_turn(s)]
    (x_lo, x_hi), (y_lo, y_hi) = trace_window(x, y, turns)
    for k, s in enumerate(turns):
        label = None
        if k < LEGEND_CIRCLES:
            label = f'circle R {s.radius_m:.2f} m, {s.t_start_s:.0f}-{s.t_end_s:.0f} s (eqs. 7.8-7.10)'
        elif k == LEGEND_CIRCLES:
            label = f'... and {len(turns) - LEGEND_CIRCLES} more fitted circles'
        circle_x = s.center_x_m + s.radius_m * np.cos(angles)
        circle_y = s.center_y_m + s.radius_m * np.sin(angles)
        ax.plot(circle_x, circle_y, lw=0.7, alpha=0.8, label=label)
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.set_aspect('equal', adjustable='box')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title('recorded path and fitted circles')
    ax.legend(loc='best', fontsize='small')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(directory / 'trace.png', dpi=90)
    plt.close(fig)
    return 'trace.png'


def _fmt(value: float | int | str, digits: int = 4) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return '-'
        if math.isinf(value):
            return 'inf'
        return f'{value:.{digits}g}'
    return str(value)


def _energy_words(joules: float) -> str:
    return f'{_fmt(joules)} J ({_fmt(joules / 3600.0, 3)} Wh)'


def markdown(summary: ValidationSummary, plots: list[str]) -> str:
    """The report page: what was run, how commands were read, the comparison (only where motor data
    exist), the battery, the trace (only where poses exist), plots."""
    m = summary.metrics
    joints = summary.joints
    lines = [
        f'# Validation of `{Path(summary.bag).name}`',
        '',
        f'- bag: `{summary.bag}` ({summary.storage}, {summary.duration_s:.1f} s)',
        f'- vehicle `{summary.vehicle}`, terrain `{summary.terrain}`',
        f'- predictor: {summary.predictor}',
        f'- messages: {summary.messages.as_json()}; rejected: {summary.rejected}',
    ]
    if summary.has_motor_data:
        lines.append(
            f'- motor data: joints {", ".join(joints.left)} (left) and '
            f'{", ".join(joints.right)} (right), effort as {joints.effort_is} at the {joints.at}'
        )
    else:
        lines.append(f'- motor data: none ({summary.motor_data_note or "no joint_states"}): predictions only')
    lines.append(f'- poses from: {summary.pose_topic or "none"}')
    if summary.undecodable_topics:
        lines.append(f'- topics skipped (unknown type): {", ".join(summary.undecodable_topics)}')
    lines += ['', '## Commands', '', summary.cmd_timing]
    clamped_t, clamped_e = summary.coverage.clamped_time_fraction, summary.coverage.clamped_energy_fraction
    if clamped_t > 0 or clamped_e > 0:
        lines.append(
            f'**{100 * clamped_t:.1f} % of the time and {100 * clamped_e:.1f} % of the predicted energy** '
            'come from commands outside what the power map covers (clamped to its edge, or solved at '
            'its tightest turn): treat those predictions with care.'
        )
    else:
        lines.append('Every command lay inside the power map.')
    if summary.has_motor_data:
        lines += ['', '## Predicted vs measured (at the motor, while a command is in force)', '']
        lines += ['| quantity | side | MAE | RMSE |', '| --- | --- | --- | --- |']
        for quantity, unit in QUANTITIES:
            for side in SIDES:
                e = m.error(quantity, side)
                lines.append(f'| {quantity} [{unit}] | {side} | {_fmt(e.mae)} | {_fmt(e.rmse)} |')
        lines += [
            '',
            f'{m.samples_compared} samples compared. Energy at the motor terminals, both sides: '
            f'predicted {_energy_words(m.energy_predicted_J)}, '
            f'measured {_energy_words(m.energy_measured_J)}; '
            f'the prediction is off by {_fmt(m.energy_error_pct, 3)} %.',
        ]
    else:
        lines += [
            '',
            '## Predicted energy',
            '',
            f'At the motor terminals, both sides, while commands were in force: '
            f'{_energy_words(m.energy_predicted_J)}.',
        ]
    lines += _battery_lines(summary)
    if summary.pose_topic:
        lines += _trace_lines(summary)
    live = summary.live_comparison
    if live:
        lines += [
            '',
            '## Live node comparison',
            '',
            f'{live.matching_within_1e_6} of {live.messages} `power/predicted` messages match the '
            f'offline prediction within 1e-6 N m (largest difference '
            f'{_fmt(live.max_abs_torque_diff_Nm)} N m).',
        ]
    if plots:
        lines += ['', '## Plots', ''] + [f'![{p}]({p})' for p in plots]
    lines += ['', 'Files: `timeseries.csv` (aligned samples), `segments.csv`, `summary.json`.', '']
    return '\n'.join(lines)


def _battery_lines(summary: ValidationSummary) -> list[str]:
    battery = summary.battery
    parts = []
    if battery.energy_measured_J:
        parts.append(f'{_energy_words(battery.energy_measured_J)} from measured power')
    if battery.energy_drawn_from_prediction_J:
        where = ' where no measurement was fresh' if battery.energy_measured_J else ''
        parts.append(f'{_energy_words(battery.energy_drawn_from_prediction_J)} from predicted power{where}')
    drawn = ' and '.join(parts) if parts else 'nothing'
    return [
        '',
        '## Battery',
        '',
        f'The battery model (through the amplifiers, so a little more than at the motors) drew {drawn}; '
        f'{_fmt(battery.remaining_wh)} Wh remain (state of charge {_fmt(battery.soc)}). '
        f'The model predicted {_energy_words(battery.energy_predicted_J)} at the battery while '
        'commands were in force.',
    ]


def _trace_lines(summary: ValidationSummary) -> list[str]:
    lines = ['', '## Trace (constant-command segments; circle fit of eqs. 7.8-7.10)', '']
    if summary.segments:
        lines += [
            '| start [s] | end [s] | V cmd [m/s] | yaw cmd [rad/s] | R cmd [m] | poses | R fit [m] | '
            'V mean [m/s] | RMS residual [m] | note |',
            '| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |',
        ]
        for s in summary.segments:
            lines.append(
                f'| {_fmt(s.t_start_s)} | {_fmt(s.t_end_s)} | {_fmt(s.speed_cmd_m_s)} | '
                f'{_fmt(s.yaw_rate_cmd_rad_s)} | {_fmt(s.radius_cmd_m)} | {s.points} | '
                f'{_fmt(s.radius_m)} | {_fmt(s.speed_m_s)} | {_fmt(s.rms_residual_m)} | '
                f'{s.note} |'
            )
    else:
        lines.append('No constant-command segment was long enough to analyse.')
    few = summary.segments_with_too_few_poses
    if few:
        lines += ['', f'{few} more segment(s) had fewer than 2 poses after settling and are left out.']
    return lines


def one_screen(summary: ValidationSummary) -> str:
    """The validation summary for a terminal: metrics, energy, segments analysed, report location."""
    m = summary.metrics
    lines = [
        f'bag {summary.bag}: {summary.duration_s:.1f} s, {summary.messages.as_json()}',
        f'predictor: {summary.predictor}',
    ]
    if summary.has_motor_data:
        for quantity, unit in QUANTITIES:
            for side in SIDES:
                e = m.error(quantity, side)
                lines.append(f'{quantity:<6} {side:<5} MAE {_fmt(e.mae)} {unit}  RMSE {_fmt(e.rmse)} {unit}')
        lines.append(
            f'energy predicted {_fmt(m.energy_predicted_J)} J, measured {_fmt(m.energy_measured_J)} J, '
            f'error {_fmt(m.energy_error_pct, 3)} %'
        )
    else:
        lines.append(f'no motor data: predicted energy {_fmt(m.energy_predicted_J)} J')
    hold = summary.cmd_hold_s
    held = 'until the next command' if math.isinf(hold) else f'at most {_fmt(hold, 3)} s'
    lines.append(f'cmd_vel published as {summary.cmd_vel_mode}, each held {held}')
    lines.append(
        f'outside the power map: {100 * summary.coverage.clamped_time_fraction:.1f} % of the time, '
        f'{100 * summary.coverage.clamped_energy_fraction:.1f} % of the predicted energy'
    )
    fitted = [s for s in summary.segments if is_fitted(s)]
    lines.append(
        f'trace: {len(summary.segments)} constant-command segments, {len(fitted)} with a fitted circle'
    )
    live = summary.live_comparison
    if live:
        lines.append(f'live node: {live.matching_within_1e_6}/{live.messages} predictions reproduced')
    if summary.report is not None:
        lines.append(f'report: {summary.report.markdown}')
    return '\n'.join(lines)


def write_report(
    directory: Path,
    summary: ValidationSummary,
    series: RunSeries,
    inputs: Inputs,
    segments: list[TraceSegment],
    plots: bool,
) -> ReportFiles:
    """Write every report file into ``directory``; returns their paths (also put into the JSON)."""
    _prepare(directory)
    write_series_csv(directory / 'timeseries.csv', series)
    write_segments_csv(directory / 'segments.csv', segments)
    plot_files = write_plots(directory, series, inputs, segments) if plots else []
    paths = ReportFiles(
        directory=str(directory),
        markdown=str(directory / 'report.md'),
        timeseries_csv=str(directory / 'timeseries.csv'),
        segments_csv=str(directory / 'segments.csv'),
        summary_json=str(directory / 'summary.json'),
        plots=tuple(str(directory / p) for p in plot_files),
    )
    (directory / 'report.md').write_text(markdown(summary, plot_files), encoding='utf-8')
    (directory / 'summary.json').write_text(
        json.dumps(jsonable({**summary.as_json(), 'report': paths.as_json()}), indent=2) + '\n',
        encoding='utf-8',
    )
    return paths
