"""Command ``map build|show`` and ``solve --model fess|fast`` (DESIGN.md command-line contract)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from test_models_solve_cli import KEYS as SOLVE_KEYS

from skidsteer_power.cli.main import main
from skidsteer_power.maps import PowerMap
from skidsteer_power.models import fess
from skidsteer_power.terramechanics.terrain import PRESETS
from skidsteer_power.vehicle import load_vehicle

BUILD = [
    'map',
    'build',
    '--vehicle',
    'chapter3_track',
    '--terrain',
    'clay',
    '--rings',
    '4',
    '--angles',
    '9',
    '--elements',
    '12',
    '--no-progress',
]


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict[str, Any]:
    assert main([*argv, '--json']) == 0
    loaded: dict[str, Any] = json.loads(capsys.readouterr().out)
    return loaded


def test_build_to_file_then_show_and_query(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / 'clay.npz'
    built = _json(capsys, [*BUILD, '--out', str(target)])
    assert built['path'] == str(target) and target.exists()
    assert built['total_points'] == 36 and built['model_version'].startswith('fess-')
    assert built['build_time_s'] > 0
    shown = _json(capsys, ['map', 'show', str(target), '--vehicle', 'chapter3_track', '--terrain', 'clay'])
    assert shown['vehicle'] == 'chapter3_track' and shown['grid']['rings'] == 4
    q = _json(capsys, ['map', 'show', str(target), '--speed', '0.4', '--yaw-rate', '-0.2'])
    direct = PowerMap.load(target).query(0.4, -0.2)
    assert q['torque_left_Nm'] == pytest.approx(direct.torque_left_Nm)
    assert q['total_power_W'] == pytest.approx(direct.power_left_W + direct.power_right_W)
    assert q['clamped'] is False


def test_build_into_the_cache_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    built = _json(capsys, [*BUILD, '--cache-dir', str(tmp_path)])
    assert Path(built['path']).parent == tmp_path
    shown = _json(
        capsys,
        ['map', 'show', '--vehicle', 'chapter3_track', '--terrain', 'clay', '--cache-dir', str(tmp_path)],
    )
    assert shown['path'] == built['path']


def test_mismatch_and_bad_input_give_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / 'clay.npz'
    assert main([*BUILD, '--out', str(target)]) == 0
    capsys.readouterr()
    cases = [
        (['map', 'show', str(target), '--terrain', 'dry_sand'], 'built for terrain'),
        (['map', 'show', str(target), '--vehicle', 'test_robot_track'], 'built for vehicle'),
        (['map', 'show', str(tmp_path / 'none.npz')], 'map file not found'),
        (['map', 'show', str(target), '--speed', '0.3'], 'both --speed and --yaw-rate'),
        (['map', 'show'], 'give a map file'),
        (
            [
                'map',
                'show',
                '--vehicle',
                'chapter3_track',
                '--terrain',
                'clay',
                '--cache-dir',
                str(tmp_path / 'x'),
            ],
            'no cached map',
        ),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and err.count('\n') == 1
    with pytest.raises(SystemExit) as exc:
        main([*BUILD[:-1], '--rings', '1'])
    assert exc.value.code == 2


def test_solve_fess_and_fast_keep_the_contract(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv('SKIDSTEER_POWER_CACHE', str(tmp_path))
    keys = set(SOLVE_KEYS)  # DESIGN.md's solve --json contract
    base = [
        'solve',
        '--vehicle',
        'chapter3_track',
        '--terrain',
        'sandy_loam',
        '--speed',
        '0.5',
        '--turn-radius',
        '3',
    ]
    out = _json(capsys, [*base, '--model', 'fess'])
    assert keys <= out.keys() and out['converged'] is True
    ref = fess.solve(load_vehicle('chapter3_track'), PRESETS['sandy_loam'], 0.5, 3.0)
    assert out['torque_outer_Nm'] == pytest.approx(float(ref.torque_outer_Nm))
    fast = _json(capsys, [*base, '--model', 'fast'])
    assert keys <= fast.keys()
    assert fast['torque_outer_Nm'] == pytest.approx(out['torque_outer_Nm'], rel=0.05)


def test_console_script_progress_goes_to_stderr(tmp_path: Path) -> None:
    exe = Path(sys.executable).with_name('skidsteer-power')
    proc = subprocess.run(
        [str(exe), *BUILD[:-1], '--out', str(tmp_path / 'm.npz'), '--json'],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0
    assert json.loads(proc.stdout)['converged_points'] == 36  # stdout is pure JSON
