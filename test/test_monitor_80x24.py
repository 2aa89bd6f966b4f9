"""The energy monitor in an 80x24 terminal (issue 37 items 4 and 10): the header on one line, the
battery gauge across the panel, and the prediction of a robot standing on a stale command marked."""

from __future__ import annotations

from rich.console import Console

from skidsteer_power.ui.monitor import MonitorView, render


def screen(view: MonitorView) -> list[str]:
    console = Console(width=80, height=24, record=True, color_system=None)
    console.print(render(view))
    return console.export_text().splitlines()


def test_header_fits_and_gauge_spans_the_panel() -> None:
    view = MonitorView(
        mode='case', ready=False, command=(-1.25, -0.75), case_elapsed_s=123.4, case_total_s=456.7, soc=0.5
    )
    lines = screen(view)
    assert lines[0].startswith(
        'Not Ready  case  command V -1.25 m/s, yaw rate -0.75 rad/s  case 123.4 / 456.7 s'
    )
    assert 'case' not in lines[1]  # nothing wrapped onto the next line
    gauge = next(line for line in lines if '█' in line).strip('│ ')
    assert len(gauge) == 76 and gauge.count('█') == 38  # the panel's width, half filled (not 30)


def test_a_standing_prediction_is_marked() -> None:
    summary = {'predicted_left_W': 0.0, 'predicted_right_W': 0.0, 'cmd_vel_stale': 1.0}
    text = '\n'.join(screen(MonitorView(summary=summary)))
    assert 'predicted power (standing) [W]' in text
    moving = '\n'.join(screen(MonitorView(summary={**summary, 'cmd_vel_stale': 0.0})))
    assert 'predicted power [W]' in moving and '(standing)' not in moving
