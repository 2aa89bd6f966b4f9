"""energy_monitor's pure parts: rendering without a terminal, keys, case profiles, CSV; and the
raw-mode key reader on a real pseudo-terminal."""

from __future__ import annotations

import csv
import io
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from rich.console import Console

from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError
from skidsteer_power.ui.monitor import (
    CSV_COLUMNS,
    CaseProfile,
    CsvLog,
    FreeDrive,
    MonitorView,
    csv_row,
    decode_keys,
    format_duration,
    load_case_csv,
    render,
)

if TYPE_CHECKING:
    from skidsteer_power.nodes.energy_monitor import KeyReader


def screen(view: MonitorView) -> str:
    console = Console(file=io.StringIO(), width=110, record=True, color_system=None)
    console.print(render(view))
    return console.export_text()


def full_view(**changes: object) -> MonitorView:
    summary = {
        'predicted_left_W': 41.25, 'predicted_right_W': 12.5, 'measured_left_W': 44.0,
        'measured_right_W': 11.0, 'error_left_W': 2.75, 'error_right_W': -1.5, 'terrain_W': 30.0,
        'internal_W': 10.0, 'terrain_share': 0.75,
        'traction_margin': 0.42, 'traction_warning': 0.0, 'energy_source': 0.0, 'predicted_battery_W': 58.0,
        'measured_battery_W': 60.0, 'corrected_left_W': 43.75, 'corrected_right_W': 11.5,
        'corrected_battery_W': 59.5,
    }  # fmt: skip
    view = MonitorView(
        mode='free', command=(0.2, 0.1), ready=True, summary=summary,
        motor_speed_rad_s=(251.327, 209.44), motor_current_A=(1.5, -0.25), soc=0.8, voltage_V=47.9,
        remaining_wh=180.0, time_to_empty_s=7322.0,
    )  # fmt: skip
    for key, value in changes.items():
        setattr(view, key, value)
    return view


def test_render_shows_speeds_currents_power_battery_and_ready() -> None:
    text = screen(full_view())
    assert 'Ready' in text and 'Not Ready' not in text
    assert '2400' in text and '2000' in text  # 251.327 rad/s = 2400 rpm, 209.44 rad/s = 2000 rpm
    assert '1.50' in text and '-0.25' in text  # currents [A]
    assert '41.2' in text and '44.0' in text and '+2.8' in text  # predicted, measured, error [W]
    assert 'corrected (online) [W]' in text and '43.8' in text  # issue 27: the corrected estimate
    assert 'corrected 59.5 W' in text
    assert 'charge 80.0 %' in text and '180.0 Wh' in text
    assert 'time to empty 2:02:02' in text  # 7322 s
    assert 'terrain share 75 %' in text and 'energy from measured' in text
    assert 'TRACTION WARNING' not in text


def test_render_warns_about_traction_and_missing_link() -> None:
    text = screen(full_view(ready=False, summary={'traction_margin': -0.1, 'traction_warning': 1.0}))
    assert 'Not Ready' in text
    assert 'TRACTION WARNING: margin -0.10' in text
    assert 'predicted -- W' in text  # missing values are shown as --, never as a number


def test_render_case_progress() -> None:
    text = screen(full_view(mode='case', case_elapsed_s=3.0, case_total_s=12.5))
    assert 'case 3.0 / 12.5 s' in text and 'keys:' not in text


def test_format_duration() -> None:
    assert format_duration(math.inf) == 'idle'
    assert format_duration(math.nan) == '--'
    assert format_duration(3599.6) == '1:00:00'


def test_decode_arrow_keys_and_partial_sequences() -> None:
    keys, rest = decode_keys(b'\x1b[A\x1b[Bx\x1b[C\x1b[D q\x1b[')
    assert keys == ['up', 'down', 'right', 'left', 'stop', 'quit']
    assert rest == b'\x1b['
    keys, rest = decode_keys(rest + b'A')
    assert keys == ['up'] and rest == b''


def test_free_drive_steps_and_clamps() -> None:
    drive = FreeDrive(speed_step_m_s=0.1, yaw_step_rad_s=0.05, max_speed_m_s=0.2, max_yaw_rate_rad_s=0.1)
    command = (0.0, 0.0)
    for key in ('up', 'up', 'up', 'left', 'left', 'left'):
        command = drive.apply(command, key)
    assert command == (0.2, 0.1)
    assert drive.apply(command, 'right') == (0.2, 0.05)
    assert drive.apply(command, 'stop') == (0.0, 0.0)


def test_case_profile_commands() -> None:
    profile = CaseProfile((Segment(0.1, 0.0, 2.0), Segment(0.2, 0.35, 3.0)))
    assert profile.duration_s == 5.0
    assert profile.command_at(1.9) == (0.1, 0.0)
    assert profile.command_at(2.0) == (0.2, 0.35)
    assert profile.command_at(5.0) is None


def test_case_file(tmp_path: Path) -> None:
    path = tmp_path / 'case.csv'
    path.write_text('# Table 7.3 row: V = 0.2 m/s\nduration_s,speed_m_s,yaw_rate_rad_s\n5,0.2,0\n5,0.2,0.1\n')
    assert load_case_csv(path).steps[1] == Segment(0.2, 0.1, 5.0)


@pytest.mark.parametrize(
    ('text', 'match'),
    [
        ('speed,yaw\n1,2\n', 'need a header'),
        ('duration_s,speed_m_s,yaw_rate_rad_s\n5,fast,0\n', 'line 2: not a number'),
        ('duration_s,speed_m_s,yaw_rate_rad_s\n-1,0.1,0\n', 'duration must be > 0'),
        ('duration_s,speed_m_s,yaw_rate_rad_s\n1,nan,0\n', 'finite'),
    ],
)
def test_bad_case_file(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / 'case.csv'
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        load_case_csv(path)


def test_csv_log_writes_what_was_shown(tmp_path: Path) -> None:
    log = CsvLog(tmp_path / 'shown.csv')
    log.write([csv_row(full_view(), 0.2), csv_row(full_view(soc=0.79), 0.4)])
    log.close()
    with (tmp_path / 'shown.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == list(CSV_COLUMNS)
    assert [r['soc'] for r in rows] == ['0.8', '0.79']
    assert rows[0]['measured_left_W'] == '44' and rows[0]['speed_cmd_m_s'] == '0.2'


def read_keys_until(reader: KeyReader, count: int) -> list[str]:
    """Poll the non-blocking reader (the pty delivers bytes asynchronously) until ``count`` keys came."""
    keys: list[str] = []
    deadline = time.monotonic() + 5.0
    while len(keys) < count and time.monotonic() < deadline:
        keys += reader.read_keys()
        time.sleep(0.005)
    return keys


def test_key_reader_on_a_pseudo_terminal() -> None:
    from skidsteer_power.nodes.energy_monitor import KeyReader

    master, slave = os.openpty()
    try:
        reader = KeyReader(slave)
        assert reader.read_keys() == []  # nothing typed: returns at once
        os.write(master, b'\x1b[A\x1b[')
        first = read_keys_until(reader, 1)
        os.write(master, b'D ')
        assert first == ['up'] and read_keys_until(reader, 2) == ['left', 'stop']
        reader.close()
    finally:
        os.close(master)
        os.close(slave)


def test_render_marks_stale_sources_but_keeps_their_last_values() -> None:
    from skidsteer_power.ui.monitor import SOURCES

    text = screen(full_view(stale=frozenset(SOURCES), ready=False))
    assert 'command V +0.20 m/s, yaw rate +0.10 rad/s (stale)' in text
    assert 'speed [rpm] (stale)' in text and '2400' in text
    assert 'measured power [W] (stale)' in text and '44.0' in text
    assert 'Battery (stale)' in text and 'traction margin 0.42 (stale)' in text
    assert 'no data from the robot' in text
    fresh = screen(full_view())
    assert 'stale' not in fresh


def test_render_shows_the_time_to_empty_band_and_a_stale_terrain_line() -> None:
    # 7322 s = 2:02:02; p10 5400 s = 1:30:00; p90 9000 s = 2:30:00
    text = screen(full_view(time_to_empty_p10_s=5400.0, time_to_empty_p90_s=9000.0))
    assert 'time to empty 2:02:02 (p10 1:30:00 - p90 2:30:00)' in text
    assert 'p10' not in screen(full_view())  # nothing arrived yet: no band
    stale = screen(full_view(stale=frozenset({'summary'})))
    assert 'terrain 30.0 W, internal 10.0 W (terrain share 75 %) (stale)' in stale
