"""The operator's Foxglove layout (``config/foxglove/operator_layout.json``), built with the
foxglove-sdk's layout types so the file is what the app reads.

Panels (topics as the suite publishes them, default namespace):

* predicted vs measured motor power, left and right [W] (Plot: ``power/predicted_*_w``,
  ``power/measured_*_w``; dashed = predicted);
* battery gauge (state of charge, 0..1, ``battery/state.percentage``) and battery power predicted vs
  measured [W];
* time to empty [s] (``energy/time_to_empty_s``; Indicator: red below 10 min);
* traction margin [-] (Plot + Indicator: red at or below 0.1, the estimator's default warning margin);
* path energy [Wh] (Plot: ``energy/path_required_wh``, ``energy/path_margin_wh``; Indicator on the
  margin: red below 0 Wh, the robot cannot drive the planned path and come back with the reserve);
* trace from odometry (XY plot of ``odom.pose.pose.position``, x vs y [m]);
* estimator diagnostics (stale inputs, energy source);
* Teleop on ``/cmd_vel`` (geometry_msgs/Twist) at :data:`TELEOP_RATE_HZ`: the panel's default is
  1 Hz, and des_driver's watchdog (``cmd_timeout_s`` 0.5 s) stops the robot when no command came
  for 0.5 s, so at 1 Hz the robot moves about half the time in jerks; 10 Hz gives five commands per
  watchdog period (with ``bridge --allow-publish cmd_vel``).

``python -m skidsteer_power.ui.foxglove_layout [PATH]`` writes it (the shipped file is its output;
test/test_foxglove_bridge.py checks they agree).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Literal

import foxglove.layouts as fl

LOW_TIME_TO_EMPTY_S = 600.0
TRACTION_WARNING_MARGIN = 0.1  # power_estimator's traction_warning_margin default
TELEOP_RATE_HZ = 10.0
"""The Teleop panel's publish rate [Hz]: at least 2 / cmd_timeout_s (des_driver: 0.5 s -> 4 Hz) so a
held button never lets the watchdog stop the robot; the panel's own default, 1 Hz, does."""
TELEOP_SPEED_M_S = 0.3  # ASSUMED: a gentle forward speed for the arrow buttons [m/s]
TELEOP_YAW_RATE_RAD_S = 0.5  # ASSUMED: a gentle turn rate for the arrow buttons [rad/s]

Comparison = Literal['=', '<', '<=', '>', '>=']
"""An IndicatorRule's operator."""

PREDICTED = '#1f77b4'
MEASURED = '#d62728'
ALARM = '#d62728'
OK = '#2ca02c'


def _series(topic: str, label: str, color: str, dashed: bool = False) -> fl.PlotSeries:
    return fl.PlotSeries(
        value=f'{topic}.data',
        label=label,
        color=color,
        enabled=True,
        timestamp_method='receiveTime',
        line_style='dashed' if dashed else 'solid',
    )


def _indicator(
    title: str, topic: str, alarm: tuple[Comparison, str], alarm_label: str, ok_label: str
) -> fl.IndicatorPanel:
    """A red/green indicator of ``topic``'s Float64: red with ``alarm_label`` while ``data <op> value``
    for ``alarm`` = (op, value), else green with ``ok_label``."""
    operator, value = alarm
    return fl.IndicatorPanel(
        title=title,
        config=fl.IndicatorConfig(
            path=f'{topic}.data',
            style='background',
            font_size=28,
            rules=[fl.IndicatorRule(operator=operator, raw_value=value, color=ALARM, label=alarm_label)],
            fallback_color=OK,
            fallback_label=ok_label,
        ),
    )


def _time_plot(
    title: str, paths: list[fl.PlotSeries], window_s: float, y_axis_label: str | None = None
) -> fl.PlotPanel:
    """A plot of ``paths`` over the last ``window_s`` seconds (sliding), legend on top."""
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=paths,
            show_legend=True,
            legend_display='top',
            time_window_mode='sliding',
            following_view_width=window_s,
            y_axis_label=y_axis_label,
        ),
    )


def _power_plot(side: str) -> fl.PlotPanel:
    paths = [
        _series(f'/power/predicted_{side}_w', f'predicted {side} [W]', PREDICTED, dashed=True),
        _series(f'/power/measured_{side}_w', f'measured {side} [W]', MEASURED),
    ]
    return _time_plot(f'{side} motor power: predicted vs measured [W]', paths, 60.0, y_axis_label='W')


def _battery_gauge() -> fl.GaugePanel:
    return fl.GaugePanel(
        title='battery state of charge [-]',
        config=fl.GaugeConfig(
            path='/battery/state.percentage', min_value=0.0, max_value=1.0, color_mode='colormap',
            color_map='red-yellow-green',
        ),
    )  # fmt: skip


def _battery_power_plot() -> fl.PlotPanel:
    return _time_plot('battery power: predicted vs measured [W]', [
        _series('/power/predicted_battery_w', 'predicted [W]', PREDICTED, dashed=True),
        _series('/power/measured_battery_w', 'measured [W]', MEASURED),
    ], 600.0)  # fmt: skip


def _time_to_empty_indicator() -> fl.IndicatorPanel:
    return _indicator(
        'time to empty [s]', '/energy/time_to_empty_s', ('<', str(LOW_TIME_TO_EMPTY_S)),
        'battery low: under 10 min', 'time to empty',
    )  # fmt: skip


def _traction_indicator() -> fl.IndicatorPanel:
    return _indicator(
        'traction margin [-]', '/power/traction_margin', ('<=', str(TRACTION_WARNING_MARGIN)),
        'TRACTION WARNING: the robot may get stuck', 'traction ok',
    )  # fmt: skip


def _traction_plot() -> fl.PlotPanel:
    """Traction margin and time to empty (right axis: seconds, not a ratio)."""
    return _time_plot('traction margin [-] and time to empty [s]', [
        _series('/power/traction_margin', 'traction margin [-]', '#9467bd'),
        fl.PlotSeries(value='/energy/time_to_empty_s.data', label='time to empty [s]', enabled=True,
                      color='#2ca02c', timestamp_method='receiveTime', use_right_y_axis=True),
    ], 120.0)  # fmt: skip


def _path_margin_indicator() -> fl.IndicatorPanel:
    return _indicator(
        'path margin [Wh]', '/energy/path_margin_wh', ('<', '0'),
        'CANNOT drive the path and return', 'path and return ok',
    )  # fmt: skip


def _path_energy_plot() -> fl.PlotPanel:
    return _time_plot('planned path: energy required and margin [Wh]', [
        _series('/energy/path_required_wh', 'required [Wh]', PREDICTED),
        _series('/energy/path_margin_wh', 'margin after return and reserve [Wh]', '#2ca02c'),
    ], 600.0)  # fmt: skip


def _trace_plot() -> fl.PlotPanel:
    """The odometry position as an XY plot, y [m] against x [m], equal scales."""
    odom_x = fl.PlotXAxisPath(value='/odom.pose.pose.position.x', enabled=True)
    return fl.PlotPanel(
        title='trace from odometry: y [m] vs x [m]',
        config=fl.PlotConfig(
            paths=[fl.PlotSeries(value='/odom.pose.pose.position.y', label='trace', enabled=True,
                                 color='#ff7f0e', timestamp_method='receiveTime')],
            x_axis_val='custom', x_axis_path=odom_x,
            x_axis_label='x [m]', y_axis_label='y [m]', axis_scales_mode='lockedScales', show_legend=False,
        ),
    )  # fmt: skip


def _teleop() -> fl.TeleopPanel:
    """Arrow buttons on /cmd_vel at :data:`TELEOP_RATE_HZ` (module doc: the watchdog)."""
    return fl.TeleopPanel(
        title=f'teleop: /cmd_vel at {TELEOP_RATE_HZ:g} Hz (watchdog 0.5 s)',
        config=fl.TeleopConfig(
            topic='/cmd_vel', publish_rate=TELEOP_RATE_HZ,
            up_button=fl.TeleopButton(field='linear-x', value=TELEOP_SPEED_M_S),
            down_button=fl.TeleopButton(field='linear-x', value=-TELEOP_SPEED_M_S),
            left_button=fl.TeleopButton(field='angular-z', value=TELEOP_YAW_RATE_RAD_S),
            right_button=fl.TeleopButton(field='angular-z', value=-TELEOP_YAW_RATE_RAD_S),
        ),
    )  # fmt: skip


def _column(panels: list[tuple[fl.BasePanel, float]]) -> fl.SplitContainer:
    """A column of (panel, proportion) pairs, top to bottom."""
    return fl.SplitContainer(
        direction='column',
        items=[fl.SplitItem(proportion=proportion, content=panel) for panel, proportion in panels],
    )


def operator_layout() -> fl.Layout:
    """The layout as a :class:`foxglove.layouts.Layout`: three columns, motor and battery power
    (twice as wide); battery and traction; trace, path energy, diagnostics and teleop."""
    power = _column(
        [
            (_power_plot('left'), 1.0),
            (_power_plot('right'), 1.0),
            (_battery_power_plot(), 1.0),
        ],
    )
    battery = _column(
        [
            (_battery_gauge(), 1.0),
            (_time_to_empty_indicator(), 0.5),
            (_traction_indicator(), 0.5),
            (_traction_plot(), 1.0),
        ],
    )
    path = _column(
        [
            (_trace_plot(), 2.0),
            (_path_margin_indicator(), 0.5),
            (_path_energy_plot(), 1.0),
            (fl.DiagnosticsSummaryPanel(title='estimator and driver diagnostics'), 1.0),
            (_teleop(), 1.0),
        ],
    )
    columns = [(power, 2.0), (battery, 1.0), (path, 1.0)]
    return fl.Layout(
        content=fl.SplitContainer(
            direction='row',
            items=[fl.SplitItem(proportion=proportion, content=column) for column, proportion in columns],
        ),
    )


def layout_json() -> str:
    """The layout file's text: the SDK's JSON, indented for review, with a final newline."""
    return json.dumps(json.loads(operator_layout().to_json()), indent=2) + '\n'


def topics_used(text: str) -> set[str]:
    """Topics the layout reads (the part of each path before the first '.')."""
    found: set[str] = set()

    def walk(value: object) -> None:
        if isinstance(value, dict):
            for v in value.values():
                walk(v)
        elif isinstance(value, list):
            for v in value:
                walk(v)
        elif isinstance(value, str) and value.startswith('/') and '.' in value:
            found.add(value.split('.', 1)[0])

    walk(json.loads(text))
    return found


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else Path('config/foxglove/operator_layout.json')
    path.write_text(layout_json(), encoding='utf-8')
    print(f'wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
