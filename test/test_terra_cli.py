"""Commands ``track``, ``wheel`` and ``terrains`` (DESIGN.md command-line contract)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from skidsteer_power.cli.main import main
from skidsteer_power.terramechanics import PRESETS
from skidsteer_power.terramechanics.track import single_track
from skidsteer_power.terramechanics.wheel import wheel_at_slip

TRACK = ['track', '--terrain', 'dry_sand', '--load', '100', '--width', '0.07', '--length', '0.7']
WHEEL = ['wheel', '--terrain', 'dry_sand', '--load', '100', '--width', '0.07', '--radius', '0.1']


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict[str, Any]:
    assert main([*argv, '--json']) == 0
    loaded: dict[str, Any] = json.loads(capsys.readouterr().out)
    return loaded


def test_track_json_keys_and_values(capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(capsys, [*TRACK, '--slip', '0.2'])
    assert {'sinkage_m', 'compaction_resistance_N', 'drawbar_pull_N'} <= out.keys()
    ref = single_track(PRESETS['dry_sand'], 100.0, 0.07, 0.7, 0.2)
    assert out['sinkage_m'] == pytest.approx(float(ref.sinkage_m))
    assert out['drawbar_pull_N'] == pytest.approx(float(ref.drawbar_pull_N))
    # eq. 2.6 hand value for this case (see test_terra_track.py): 2.4258 mm
    assert out['sinkage_m'] == pytest.approx(2.4258e-3, rel=2e-4)


def test_track_default_slip_is_zero(capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(capsys, TRACK)
    assert out['slip'] == 0.0
    assert out['drawbar_pull_N'] == pytest.approx(-out['compaction_resistance_N'])


def test_wheel_json_keys_and_values(capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(capsys, [*WHEEL, '--slip', '0.3', '--speed', '0.5'])
    keys = {'sinkage_m', 'drawbar_pull_N', 'torque_Nm', 'entry_angle_rad', 'exit_angle_rad'}
    assert keys <= out.keys()
    ref = wheel_at_slip(PRESETS['dry_sand'], 100.0, 0.3, 0.1, 0.07)
    assert out['drawbar_pull_N'] == pytest.approx(float(ref.Fx_N))
    assert out['torque_Nm'] == pytest.approx(float(ref.drive_torque_Nm))
    assert out['exit_angle_rad'] == pytest.approx(-0.45 * out['entry_angle_rad'])  # eq. 2.20, Table 2.4
    # eq. 2.13 driving: r w = V / (1 - s) = 0.5 / 0.7 -> w = 7.142857 rad/s
    assert out['wheel_speed_rad_s'] == pytest.approx(7.142857, rel=1e-6)
    assert out['shaft_power_W'] == pytest.approx(out['torque_Nm'] * 7.142857, rel=1e-6)


def test_wheel_accepts_yaml_terrain(capsys: pytest.CaptureFixture[str]) -> None:
    path = Path(__file__).resolve().parents[1] / 'config' / 'terrains' / 'clay.yaml'
    from_file = _json(capsys, ['wheel', '--terrain', str(path), *WHEEL[3:], '--slip', '0.1'])
    preset = _json(capsys, ['wheel', '--terrain', 'clay', *WHEEL[3:], '--slip', '0.1'])
    assert from_file['sinkage_m'] == preset['sinkage_m']


def test_terrains_lists_presets_with_units(capsys: pytest.CaptureFixture[str]) -> None:
    out = _json(capsys, ['terrains'])
    assert set(out['presets']) == set(PRESETS)
    assert out['presets']['lete_sand']['values']['kc'] == 102000.0  # Table 8.3
    assert out['presets']['dry_sand']['values']['phi_deg'] == pytest.approx(30.0)  # Table 2.2
    assert out['units']['kphi'] == 'N/m^(n+2)'
    assert main(['terrains']) == 0
    assert 'sand_bin' in capsys.readouterr().out


@pytest.mark.parametrize(
    ('argv', 'match'),
    [
        (
            [*WHEEL[:4], '-5', *WHEEL[5:], '--slip', '0.2'],
            'load = -5 N is outside its range \\[0, 100000\\] N',
        ),
        ([*WHEEL[:6], '0', *WHEEL[7:], '--slip', '0.2'], 'width = 0 m is outside its range'),
        ([*WHEEL, '--slip', '1.5'], 'slip must lie in \\[-1, 1\\]'),
        ([*TRACK, '--slip', '-2'], 'slip must lie in \\[-1, 1\\]'),
        (['wheel', '--terrain', 'mud', *WHEEL[3:], '--slip', '0.2'], "unknown terrain 'mud'"),
        ([*WHEEL[:4], '9e4', *WHEEL[5:], '--slip', '0.2'], 'deeper than its radius'),
        ([*WHEEL, '--slip', '1', '--speed', '0.5'], 'wheel speed is not set'),
    ],
)
def test_bad_input_is_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], match: str
) -> None:
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1
    assert 'error' in err
    assert re.search(match, err)


def test_console_script_no_traceback(tmp_path: Path) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('name: x\nn: 0\nkc: 1\nkphi: 1\nc: 1\nphi_deg: 30\nK: 0.01\n')
    cmd = [sys.executable, '-m', 'skidsteer_power.cli.main', 'track', '--terrain', str(bad), *TRACK[3:]]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "skidsteer-power: error: terrain 'x': field 'n' must be > 0, got 0.0"
