"""``skidsteer-power predict --commands FILE.csv``: many commands in one process (issue 36), and the
drive controller's limits on every prediction path from a command (predict from the map and direct)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_run import one_line_error, run_cli

from skidsteer_power.cli import predict as cli_predict
from skidsteer_power.models import predict as model_predict

ROWS = [(0.2, 0.0), (-0.3, 0.4), (0.0, 0.5), (0.6, -0.8)]
BASE = ['predict', '--vehicle', 'test_robot_track', '--terrain', 'sand_bin']


def _csv(path: Path, rows: list[tuple[float, float]], header: str = 'speed_m_s,yaw_rate_rad_s') -> Path:
    path.write_text('\n'.join([header, *(f'{v},{w}' for v, w in rows)]) + '\n')
    return path


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> object:
    assert run_cli(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_the_command_module_has_predicts_keys() -> None:
    assert cli_predict.JSON_KEYS == model_predict.JSON_KEYS  # written twice so --help imports no model


@pytest.mark.parametrize('direct', [False, True])
def test_each_row_is_the_single_command_answer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], direct: bool
) -> None:
    flags = ['--direct'] if direct else []
    batch = _json(capsys, [*BASE, '--commands', str(_csv(tmp_path / 'c.csv', ROWS)), *flags, '--json'])
    assert isinstance(batch, list) and len(batch) == len(ROWS)
    for (v, w), record in zip(ROWS, batch, strict=True):
        assert list(record) == list(cli_predict.JSON_KEYS)
        single = _json(capsys, [*BASE, '--speed', str(v), '--yaw-rate', str(w), *flags, '--json'])
        assert record == single


def test_without_json_a_csv_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli([*BASE, '--commands', str(_csv(tmp_path / 'c.csv', ROWS))]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split(',') == list(cli_predict.JSON_KEYS) and len(lines) == 1 + len(ROWS)
    assert lines[1].split(',')[:2] == ['0.2', '0.0']


def test_bad_command_files_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / 'bad.csv'
    msg = one_line_error(capsys, [*BASE, '--commands', str(_csv(bad, ROWS, 'v,w'))])
    assert 'missing column(s) speed_m_s, yaw_rate_rad_s' in msg
    bad.write_text('speed_m_s,yaw_rate_rad_s\n0.1,0\nfast,0\n')
    assert f'{bad}:3:' in one_line_error(capsys, [*BASE, '--commands', str(bad)])
    bad.write_text('speed_m_s,yaw_rate_rad_s\n0.1,99\n')
    assert 'yaw rate' in one_line_error(capsys, [*BASE, '--commands', str(bad)])
    many = _csv(tmp_path / 'many.csv', [(0.1, 0.0)] * (cli_predict.MAX_DIRECT_ROWS + 1))
    msg = one_line_error(capsys, [*BASE, '--commands', str(many), '--direct'])
    assert f'more than {cli_predict.MAX_DIRECT_ROWS:,} rows' in msg
    both = [*BASE, '--commands', str(many), '--speed', '0.1', '--yaw-rate', '0']
    assert 'either --commands or --speed' in one_line_error(capsys, both)
    assert '--speed and --yaw-rate' in one_line_error(capsys, [*BASE, '--speed', '0.1'])


@pytest.mark.parametrize('direct', [False, True])
def test_the_controllers_limits_apply_to_predict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], direct: bool
) -> None:
    """The Husky's controller (config/vehicles/husky_a200.yaml): V at most 1.0 m/s, w_z 2.0 rad/s, the
    wheel separation x 1.875, no wheel past 6.057 rad/s (both scaled)."""
    husky = ['predict', '--vehicle', 'husky_a200', '--terrain', 'sand_bin', *(['--direct'] if direct else [])]
    rows = [(1.5, 0.0), (1.0, 0.0), (0.0, 3.0), (0.0, 2.0), (0.3, 0.3)]
    out = _json(capsys, [*husky, '--commands', str(_csv(tmp_path / 'c.csv', rows)), '--json'])
    assert isinstance(out, list)
    fast, limit, spin, spin_limit, slow = out
    sp = ('setpoint_left_rad_s', 'setpoint_right_rad_s')
    assert [fast[k] for k in sp] == [limit[k] for k in sp] and fast['clamped']
    assert limit[sp[0]] == pytest.approx(1.0 / 0.1651, abs=1e-12)  # 6.0569 rad/s: under the ceiling
    # spin at 2 rad/s: sides -+ 2 x 1.875 x 0.5708 / 2 = 1.0703 m/s -> 6.482 rad/s, scaled to 6.057
    assert [spin[k] for k in sp] == [spin_limit[k] for k in sp] == pytest.approx([-6.057, 6.057])
    assert spin['clamped'] and spin_limit['clamped']
    # (0.3, 0.3): 0.3 -+ 0.3 x 0.5351 = 0.1395, 0.4605 m/s -> 0.8449, 2.789 rad/s: untouched
    assert [slow[k] for k in sp] == pytest.approx([0.13947 / 0.1651, 0.46053 / 0.1651], rel=1e-4)
    assert not slow['clamped']


def test_a_side_the_current_limit_holds_back_reports_its_real_motion() -> None:
    """An 8 A limit (the test robot's powertrain with current_limit_A 8) at (0.5 m/s, 1.0 rad/s) on the
    sand bin: the outer (right) side needs 8.4 A at its set point, so it falls behind it until its
    current is the limit; the motion reported is that one, slower and wider than at the set points."""
    from skidsteer_power.models.predict import REASON_CURRENT, CommandPredictor
    from skidsteer_power.powertrain.power_flow import Powertrain
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    vehicle, sand = load_vehicle('test_robot_track'), load_terrain('sand_bin')
    weak = Powertrain.from_config({'preset': 'test_robot', 'current_limit_A': 8.0}, 'track')
    full = CommandPredictor(vehicle, sand).predict([0.5], [1.0])
    held = CommandPredictor(vehicle, sand, weak).predict([0.5], [1.0])
    assert full.current[0, 1] > 8.0 > full.current[0, 0] and not full.limited[0]
    assert held.limited[0] and held.reason[0] == REASON_CURRENT
    assert held.omega is not None
    assert held.omega[0, 0] == held.setpoint[0, 0] and held.omega[0, 1] < held.setpoint[0, 1]  # right behind
    assert abs(held.current[0, 1]) <= 8.0 and abs(held.current[0, 1]) > 8.0 * 0.99  # at the limit
    assert 0 < held.speed[0] < full.speed[0] and 0 < held.yaw_rate[0] < full.yaw_rate[0]
    record = held.record(0)
    omega_right, setpoint_right = record['omega_right_rad_s'], record['setpoint_right_rad_s']
    assert isinstance(omega_right, float) and isinstance(setpoint_right, float)  # a record's numbers
    assert omega_right < setpoint_right


def test_a_side_that_needs_more_than_the_limit_at_any_speed_stalls() -> None:
    """A 5 A limit below the drivetrain's own Coulomb friction (about 6.8 A at any speed, eq. 7.1's c):
    the side stands, the motor pushing with the limit current."""
    from skidsteer_power.models.predict import REASON_STALL, CommandPredictor
    from skidsteer_power.powertrain.power_flow import Powertrain
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    weak = Powertrain.from_config({'preset': 'test_robot', 'current_limit_A': 5.0}, 'track')
    held = CommandPredictor(load_vehicle('test_robot_track'), load_terrain('sand_bin'), weak).predict(
        [0.2], [0.0]
    )
    assert held.reason[0] == REASON_STALL and held.speed[0] == 0.0
    assert held.omega is not None and np.all(held.omega[0] == 0.0)
    assert held.current[0] == pytest.approx([5.0, 5.0])
