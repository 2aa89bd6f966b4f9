"""``simulate --commands CSV`` holds each row for its own duration (issue 28): rows shorter than the
twin's 2 ms step, or not a multiple of it, were rounded to whole steps (0.5 ms rows over 10 s drove
0 m with 0 J; 3 ms rows over 10 s ran 12.16 s). The reference is the same twin driven by the same
command as one row, which its fixed 2 ms steps integrate exactly as before."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from skidsteer_power.cli.main import main
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin import Segment, Twin, run_commands
from skidsteer_power.twin.sensors import SENSOR_RATE_HZ
from skidsteer_power.vehicle import load_vehicle

SPEED, YAW = 0.3, 0.2  # [m/s], [rad/s]


def _twin() -> Twin:
    return Twin(load_vehicle('test_robot_track'), load_terrain('dry_sand'))


def _rows(period_s: float, duration_s: float) -> list[Segment]:
    return [Segment(SPEED, YAW, period_s)] * round(duration_s / period_s)


@pytest.mark.parametrize('period_s', [0.5e-3, 3e-3])
def test_short_and_off_grid_rows_drive_like_one_row(period_s: float) -> None:
    one = run_commands(_twin(), [Segment(SPEED, YAW, 1.5)])
    rows = run_commands(_twin(), _rows(period_s, 1.5))
    assert rows.duration_s == pytest.approx(1.5, abs=1e-9)
    assert rows.t.size == one.t.size == 1 + round(1.5 * SENSOR_RATE_HZ)  # samples on the 50 Hz grid
    assert rows.t == pytest.approx(one.t, abs=1e-9)
    # the same command, integrated with shorter steps: the same motion and energy to a few percent
    assert rows.distance_m == pytest.approx(one.distance_m, rel=0.02) and one.distance_m > 0.2
    assert rows.ledger['bus_J'] == pytest.approx(one.ledger['bus_J'], rel=0.02) and one.ledger['bus_J'] > 1.0
    assert np.max(np.abs(rows.pose[-1, :2] - one.pose[-1, :2])) < 0.02  # [m]


def test_a_run_ending_between_samples_lasts_its_commands() -> None:
    trace = run_commands(_twin(), [Segment(SPEED, 0.0, 0.1), Segment(0.0, 0.0, 0.007)])
    assert trace.duration_s == pytest.approx(0.107, abs=1e-9)


def test_simulate_cli_with_3_ms_rows_lasts_the_csv_plus_the_lead_in(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """1 s lead-in + 3 s of rows every 3 ms (the issue: 10 s of them gave 13.16 s instead of 11 s)."""
    t = np.arange(0, 1001) * 3e-3  # 1000 rows held 3 ms each; the last row ends the run at 3.0 s
    csv = tmp_path / 'cmd.csv'
    csv.write_text('t_s,speed_m_s,yaw_rate_rad_s\n' + ''.join(f'{x:.3f},{SPEED},0\n' for x in t))
    assert main(['simulate', '--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--commands',
                 str(csv), '-o', str(tmp_path / 'o.mcap'), '--json']) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out['duration_s'] == pytest.approx(4.0, abs=1e-6)
    assert out['distance_m'] > 0.5 and out['energy_J'] > 1.0  # 3 s at 0.3 m/s, less slip
