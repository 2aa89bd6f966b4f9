"""Validation report files: CSV time series and segments, PNG plots, one Markdown page, JSON summary."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from skidsteer_power.bags.validate import Inputs, RunSeries, TraceSegment

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


def jsonable(value: Any) -> Any:
    """``value`` with numpy types made plain, NaN as null and infinities as "inf"/"-inf"."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value


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


def write_plots(
    directory: Path, series: RunSeries, inputs: Inputs, segments: list[TraceSegment]
) -> list[str]:
    """PNG plots: torque and power per side (predicted vs measured), trace with fitted circles."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    every = _thin(len(series.columns['t_s']))
    c = {name: values[every] for name, values in series.columns.items()}
    written = []
    for quantity, unit, label in (
        ('torque', 'Nm', 'motor torque [N m]'),
        ('power', 'W', 'terminal power [W]'),
    ):
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 5.5))
        for ax, side in zip(axes, ('left', 'right'), strict=True):
            ax.plot(c['t_s'], c[f'predicted_{quantity}_{side}_{unit}'], label='predicted', lw=1.2)
            if np.isfinite(c[f'measured_{quantity}_{side}_{unit}']).any():
                ax.plot(
                    c['t_s'], c[f'measured_{quantity}_{side}_{unit}'], label='measured', lw=0.8, alpha=0.8
                )
            ax.set_ylabel(f'{side} {label}')
            ax.grid(alpha=0.3)
            ax.legend(loc='upper right')
        axes[-1].set_xlabel('time from bag start [s]')
        name = f'{quantity}.png'
        fig.tight_layout()
        fig.savefig(directory / name, dpi=90)
        plt.close(fig)
        written.append(name)
    if inputs.pose_t.size:
        written.append(_trace_plot(plt, directory, inputs, segments))
    return written


def _trace_plot(plt: Any, directory: Path, inputs: Inputs, segments: list[TraceSegment]) -> str:
    fig, ax = plt.subplots(figsize=(6, 6))
    every = _thin(len(inputs.pose_t))
    x, y = inputs.pose_xy[every, 0], inputs.pose_xy[every, 1]
    ax.plot(x, y, '.', ms=2, color='0.5', label=inputs.pose_topic)
    angles = np.linspace(0, 2 * np.pi, 200)
    for s in segments:
        if math.isfinite(s.radius_m):
            ax.plot(
                s.center_x_m + s.radius_m * np.cos(angles), s.center_y_m + s.radius_m * np.sin(angles), lw=0.7
            )
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title('trace and fitted circles (eqs. 7.8-7.10)')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(directory / 'trace.png', dpi=90)
    plt.close(fig)
    return 'trace.png'


def _fmt(value: Any, digits: int = 4) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return '-'
        if math.isinf(value):
            return 'inf'
        return f'{value:.{digits}g}'
    return str(value)


def markdown(summary: dict[str, Any], plots: list[str]) -> str:
    """The report page: what was run, error metrics, battery, trace segments, plots."""
    m = summary['metrics']
    lines = [
        f'# Validation of `{Path(summary["bag"]).name}`',
        '',
        f'- bag: `{summary["bag"]}` ({summary["storage"]}, {summary["duration_s"]:.1f} s)',
        f'- vehicle `{summary["vehicle"]}`, terrain `{summary["terrain"]}`',
        f'- predictor: {summary["predictor"]}',
        f'- messages: {summary["messages"]}; rejected: {summary["rejected"]}',
        f'- motor data: {"yes" if summary["has_motor_data"] else "no (predictions only)"}; '
        f'poses from: {summary["pose_topic"] or "none"}',
    ]
    if summary['undecodable_topics']:
        lines.append(f'- topics skipped (unknown type): {", ".join(summary["undecodable_topics"])}')
    lines += ['', '## Predicted vs measured (motor side, fresh commands only)', '']
    lines += ['| quantity | side | MAE | RMSE |', '| --- | --- | --- | --- |']
    for quantity, unit in (('torque', 'Nm'), ('power', 'W')):
        for side in ('left', 'right'):
            e = m[f'{quantity}_{side}']
            lines.append(
                f'| {quantity} [{unit}] | {side} | {_fmt(e[f"mae_{unit}"])} | {_fmt(e[f"rmse_{unit}"])} |'
            )
    lines += [
        '',
        f'Samples compared: {m["samples_compared"]}. Energy (terminal power, both sides): predicted '
        f'{_fmt(m["energy_predicted_J"])} J, measured {_fmt(m["energy_measured_J"])} J, '
        f'error {_fmt(m["energy_error_pct"], 3)} %.',
        '',
        '## Battery (estimator run over the bag)',
        '',
        f'Energy drawn: measured {_fmt(summary["battery"]["energy_measured_J"])} J, predicted '
        f'{_fmt(summary["battery"]["energy_predicted_J"])} J; remaining '
        f'{_fmt(summary["battery"]["remaining_wh"])} Wh (state of charge {_fmt(summary["battery"]["soc"])}).',
        '',
        '## Trace analysis (constant-command segments; circle fit of eqs. 7.8-7.10)',
        '',
    ]
    if summary['segments']:
        lines += [
            '| start [s] | end [s] | V cmd [m/s] | yaw cmd [rad/s] | R cmd [m] | points | R fit [m] | '
            'V mean [m/s] | RMS residual [m] | note |',
            '| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |',
        ]
        for s in summary['segments']:
            lines.append(
                f'| {_fmt(s["t_start_s"])} | {_fmt(s["t_end_s"])} | {_fmt(s["speed_cmd_m_s"])} | '
                f'{_fmt(s["yaw_rate_cmd_rad_s"])} | {_fmt(s["radius_cmd_m"])} | {s["points"]} | '
                f'{_fmt(s["radius_m"])} | {_fmt(s["speed_m_s"])} | {_fmt(s["rms_residual_m"])} | '
                f'{s["note"]} |'
            )
    else:
        lines.append('No constant-command segment long enough, or no poses.')
    live = summary.get('live_comparison')
    if live:
        lines += [
            '',
            '## Live node comparison',
            '',
            f'{live["matching_within_1e-6"]} of {live["messages"]} `power/predicted` messages match the '
            f'offline prediction within 1e-6 N m (largest difference '
            f'{_fmt(live["max_abs_torque_diff_Nm"])} N m).',
        ]
    lines += ['', '## Plots', ''] + [f'![{p}]({p})' for p in plots]
    lines += ['', 'Files: `timeseries.csv` (aligned samples), `segments.csv`, `summary.json`.', '']
    return '\n'.join(lines)


def one_screen(summary: dict[str, Any]) -> str:
    """The validation summary for a terminal: metrics, energy, segments analysed, report location."""
    m = summary['metrics']
    lines = [
        f'bag {summary["bag"]}: {summary["duration_s"]:.1f} s, {summary["messages"]}',
        f'predictor: {summary["predictor"]}',
    ]
    if summary['has_motor_data']:
        for quantity, unit in (('torque', 'Nm'), ('power', 'W')):
            for side in ('left', 'right'):
                e = m[f'{quantity}_{side}']
                mae, rmse = _fmt(e[f'mae_{unit}']), _fmt(e[f'rmse_{unit}'])
                lines.append(f'{quantity:<6} {side:<5} MAE {mae} {unit}  RMSE {rmse} {unit}')
        lines.append(
            f'energy predicted {_fmt(m["energy_predicted_J"])} J, measured {_fmt(m["energy_measured_J"])} J, '
            f'error {_fmt(m["energy_error_pct"], 3)} %'
        )
    else:
        lines.append(f'no motor data: predicted energy {_fmt(m["energy_predicted_J"])} J')
    fitted = [s for s in summary['segments'] if math.isfinite(s['radius_m'])]
    lines.append(
        f'trace: {len(summary["segments"])} constant-command segments, {len(fitted)} with a fitted circle'
    )
    live = summary.get('live_comparison')
    if live:
        lines.append(f'live node: {live["matching_within_1e-6"]}/{live["messages"]} predictions reproduced')
    lines.append(f'report: {summary["report"]["markdown"]}')
    return '\n'.join(lines)


def write_report(
    directory: Path,
    summary: dict[str, Any],
    series: RunSeries,
    inputs: Inputs,
    segments: list[TraceSegment],
    plots: bool,
) -> dict[str, Any]:
    """Write every report file into ``directory``; returns their paths (also put into the JSON)."""
    _prepare(directory)
    write_series_csv(directory / 'timeseries.csv', series)
    write_segments_csv(directory / 'segments.csv', segments)
    plot_files = write_plots(directory, series, inputs, segments) if plots else []
    paths = {
        'directory': str(directory),
        'markdown': str(directory / 'report.md'),
        'timeseries_csv': str(directory / 'timeseries.csv'),
        'segments_csv': str(directory / 'segments.csv'),
        'summary_json': str(directory / 'summary.json'),
        'plots': [str(directory / p) for p in plot_files],
    }
    (directory / 'report.md').write_text(markdown(summary, plot_files), encoding='utf-8')
    (directory / 'summary.json').write_text(
        json.dumps(jsonable({**summary, 'report': paths}), indent=2) + '\n', encoding='utf-8'
    )
    return paths
