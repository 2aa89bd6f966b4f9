"""``skidsteer-power solve`` (DESIGN.md command-line contract)."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest

from skidsteer_power import models
from skidsteer_power.cli.main import main

KEYS = (
    's0_m',
    'omega_outer_rad_s',
    'omega_inner_rad_s',
    'torque_outer_Nm',
    'torque_inner_Nm',
    'power_outer_W',
    'power_inner_W',
    'converged',
    'solve_time_s',
)


def _solve(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, Any]:
    assert main(['solve', *argv, '--json']) == 0
    loaded: dict[str, Any] = json.loads(capsys.readouterr().out)
    return loaded


@pytest.mark.parametrize('model', sorted(models.MODELS))
def test_every_model_answers_with_the_contract_keys(capsys: pytest.CaptureFixture[str], model: str) -> None:
    out = _solve(
        capsys,
        '--vehicle',
        'chapter3_track',
        '--terrain',
        'dry_sand',
        '--speed',
        '0.5',
        '--turn-radius',
        '5',
        '--model',
        model,
    )
    assert set(KEYS) <= set(out)
    assert out['converged'] is True and out['solve_time_s'] > 0
    assert out['power_outer_W'] == pytest.approx(out['torque_outer_Nm'] * out['omega_outer_rad_s'])
    assert out['torque_outer_Nm'] > out['torque_inner_Nm']  # left turn: the outer (right) side pushes


@pytest.mark.parametrize('vehicle', ['test_robot_4wheel', 'packbot_6wheel', 'test_robot_track'])
def test_wheeled_and_tracked_vehicles_mirror(capsys: pytest.CaptureFixture[str], vehicle: str) -> None:
    common = ['--vehicle', vehicle, '--terrain', 'sandy_loam', '--speed', '0.2', '--model', 'wong']
    left = _solve(capsys, *common, '--turn-radius', '2')
    right = _solve(capsys, *common, '--turn-radius', '-2')
    assert left['outer_side'] == 'right' and right['outer_side'] == 'left'
    assert left['torque_right_Nm'] == pytest.approx(right['torque_left_Nm'])
    assert left['omega_left_rad_s'] == pytest.approx(right['omega_right_rad_s'])
    assert left['torque_outer_Nm'] == pytest.approx(right['torque_outer_Nm'])


def test_straight_running(capsys: pytest.CaptureFixture[str]) -> None:
    out = _solve(
        capsys,
        '--vehicle',
        'chapter4_4wheel',
        '--terrain',
        'clay',
        '--speed',
        '0.3',
        '--turn-radius',
        'inf',
        '--model',
        'wong',
    )
    assert out['turn_radius_m'] == 'inf' and out['yaw_rate_rad_s'] == 0.0 and out['s0_m'] == 0.0
    assert out['torque_left_Nm'] == out['torque_right_Nm'] > 0


def test_model_options(capsys: pytest.CaptureFixture[str]) -> None:
    common = ['--vehicle', 'chapter3_track', '--terrain', 'dry_sand', '--speed', '0.5', '--turn-radius', '5']
    low = _solve(capsys, *common, '--model', 'steeds', '--mu-t', '0.5')
    high = _solve(capsys, *common, '--model', 'steeds', '--mu-t', '0.9')
    assert high['torque_outer_Nm'] > low['torque_outer_Nm']
    fine = _solve(capsys, *common, '--model', 'wong', '--resolution', '48,4')
    coarse = _solve(capsys, *common, '--model', 'wong')
    assert fine['torque_outer_Nm'] == pytest.approx(coarse['torque_outer_Nm'], rel=5e-3)


@pytest.mark.parametrize(
    ('argv', 'message'),
    [
        (['--vehicle', 'nope', '--turn-radius', '2', '--model', 'wong'], 'nope'),
        (['--vehicle', 'chapter3_track', '--turn-radius', '0', '--model', 'wong'], 'non-zero'),
        (['--vehicle', 'chapter3_track', '--turn-radius', '0.1', '--model', 'wong'], 'B/2'),
        (['--vehicle', 'chapter3_track', '--turn-radius', '2', '--model', 'magic'], 'invalid choice'),
        (
            ['--vehicle', 'chapter3_track', '--turn-radius', '2', '--model', 'wong', '--mu-t', '0.5'],
            'steeds only',
        ),
        (
            ['--vehicle', 'chapter3_track', '--turn-radius', '0.25', '--model', 'wong'],
            'no steady state at V = 0.5',
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv: list[str], message: str) -> None:
    proc = subprocess.run(
        [
            sys.executable,
            '-m',
            'skidsteer_power.cli.main',
            'solve',
            '--terrain',
            'dry_sand',
            '--speed',
            '0.5',
            *argv,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and 'Traceback' not in proc.stderr
