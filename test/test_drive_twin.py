"""The drive controller on the twin: a twin with a controller with limits drives a bag
(``skidsteer-power simulate``), and :func:`skidsteer_power.drive.identify` finds the limits back from
the bag's /cmd_vel and /joint_states (issue 36: "identify the limits from a twin bag and get them back").
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from cli_run import run_cli

from skidsteer_power.calibration.drive_limits import identify_drive
from skidsteer_power.calibration.segments import read_recording
from skidsteer_power.drive import DriveIdentification, controller_for_vehicle
from skidsteer_power.vehicle import load_vehicle

GEAR = 12.0  # the test robot's reduction (section 7.1.1): joint_states carry motor speeds
# (V, yaw rate) held 3 s each. With V_max 0.6 m/s, w_max 1.2 rad/s, B 0.426 m, r 0.1 m, ceiling 8 rad/s:
# 0.9 and (0.8, 0.3) pass V_max; (0.2, 2.0) and the spin pass w_max; (0.6, +-1.2) put the outer side
# at (0.6 + 1.2 x 0.213) / 0.1 = 8.56 rad/s, over the ceiling, scaled (the inner side 3.44 -> 3.21).
LIMITED = [(0.3, 0.0), (0.9, 0.0), (0.8, 0.3), (0.2, 2.0), (0.0, 2.5), (0.6, 1.2), (0.3, 0.0), (0.6, -1.2)]
LIMITED += [(-0.5, 0.0), (0.0, 0.0)]
GENTLE = [(0.3, 0.0), (0.5, 0.0), (0.4, 0.3), (0.2, 1.0), (0.0, 1.0), (0.5, 0.6), (0.3, 0.0), (-0.4, 0.0)]
GENTLE += [(0.0, 0.0)]


def _write_commands(path: Path, rows: list[tuple[float, float]]) -> Path:
    lines = ['t_s,speed_m_s,yaw_rate_rad_s'] + [f'{3 * i},{v},{w}' for i, (v, w) in enumerate(rows)]
    path.write_text('\n'.join([*lines, f'{3 * len(rows)},0,0']) + '\n')
    return path


def _identify_bag(bag: Path) -> DriveIdentification:
    prior = controller_for_vehicle(load_vehicle('test_robot_track'))  # what the vehicle file says
    found = identify_drive([read_recording(bag)], prior, GEAR)
    assert found is not None
    return found


@pytest.fixture(scope='module')
def limited_vehicle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = yaml.safe_load(Path('config/vehicles/test_robot_track.yaml').read_text())
    data.update(name='limited_robot', max_speed_m_s=0.6, max_yaw_rate_rad_s=1.2)
    numbers = {'max_wheel_speed_rad_s': 8.0, 'max_accel_m_s2': 0.5, 'max_yaw_accel_rad_s2': 1.5}
    data['drive_controller'] = {
        **numbers,
        'ceiling': 'scale',
        'sources': dict.fromkeys(numbers, 'ASSUMED (test)'),
    }
    path = tmp_path_factory.mktemp('drive') / 'limited_robot.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def test_the_twin_follows_its_controller_and_identify_gets_the_limits_back(
    tmp_path: Path, limited_vehicle: Path
) -> None:
    bag = tmp_path / 'limited.mcap'
    argv = ['simulate', '--vehicle', str(limited_vehicle), '--terrain', 'sand_bin', '-o', str(bag)]
    assert run_cli([*argv, '--commands', str(_write_commands(tmp_path / 'c.csv', LIMITED))]) == 0
    found = _identify_bag(bag).values
    expected = {
        'max_speed_m_s': 0.6,
        'max_yaw_rate_rad_s': 1.2,
        'max_wheel_rad_s': 8.0,
        'max_accel_m_s2': 0.5,
        'max_yaw_accel_rad_s2': 1.5,
    }
    for name, value in expected.items():
        assert found[name].reached, (name, found[name])
        assert found[name].value == pytest.approx(value, rel=0.03), name
    assert found['ceiling'].reached and found['ceiling'].value == 'scale'


def test_a_twin_bag_that_reaches_no_limit_keeps_the_vehicle_file(tmp_path: Path) -> None:
    bag = tmp_path / 'gentle.mcap'
    argv = ['simulate', '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '-o', str(bag)]
    assert run_cli([*argv, '--commands', str(_write_commands(tmp_path / 'c.csv', GENTLE))]) == 0
    found = _identify_bag(bag)
    prior = controller_for_vehicle(load_vehicle('test_robot_track'))
    for name in ('max_speed_m_s', 'max_yaw_rate_rad_s', 'max_wheel_rad_s', 'ceiling'):
        assert not found.values[name].reached, name
        assert 'kept from the vehicle file' in found.values[name].note
        assert getattr(found.controller, name) == getattr(prior, name)


def test_calibrate_fit_auto_identifies_the_limits_and_writes_them(
    tmp_path: Path, limited_vehicle: Path
) -> None:
    # Issue 36 / DESIGN.md: `calibrate --fit auto` identifies the drive limits too, and --out-vehicle
    # writes them (with sources). The twin's controller (limited_vehicle): V 0.6 m/s, w 1.2 rad/s.
    bag = tmp_path / 'limited.mcap'
    argv = ['simulate', '--vehicle', str(limited_vehicle), '--terrain', 'sand_bin', '-o', str(bag)]
    assert run_cli([*argv, '--commands', str(_write_commands(tmp_path / 'c.csv', LIMITED))]) == 0
    out_vehicle = tmp_path / 'identified.yaml'
    code = run_cli([
        'calibrate', str(bag), '--vehicle', str(limited_vehicle), '--terrain', 'sand_bin', '--fit', 'auto',
        '--out-terrain', str(tmp_path / 't.yaml'), '--out-vehicle', str(out_vehicle), '--json',
    ])  # fmt: skip
    assert code == 0
    written = yaml.safe_load(out_vehicle.read_text())
    assert written['max_speed_m_s'] == pytest.approx(0.6, rel=0.03)
    assert written['max_yaw_rate_rad_s'] == pytest.approx(1.2, rel=0.03)
    drive = written['drive_controller']
    assert drive['max_wheel_speed_rad_s'] == pytest.approx(8.0, rel=0.03)
    assert 'skidsteer-power calibrate' in drive['sources']['max_wheel_speed_rad_s']
    assert load_vehicle(str(out_vehicle)).max_speed_m_s == written['max_speed_m_s']  # it loads again
