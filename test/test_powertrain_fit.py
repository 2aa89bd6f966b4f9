"""``skidsteer-power fit-internal`` on real CSV files and a real rosbag2 (MCAP) bag."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.cli.main import main

KT = 0.114  # EC-45 torque constant, Appendix B line 12

# Table 7.1, left drivetrain read as currents (see config/powertrains/test_robot.yaml): cumulative
# current of the assembly at each stage, i = a omega + b.
STAGES = {'motor': (0.0001, 0.0617), 'gear_train': (0.00008, 0.0177), 'track': (0.00012, 0.6489)}


def _cumulative() -> Iterator[tuple[str, float, float]]:
    a = b = 0.0
    for stage, (da, db) in STAGES.items():
        a += da
        b += db
        yield stage, a, b


def test_fit_internal_csv_recovers_table_7_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rpm = np.linspace(100, 3000, 15)
    lines = ['side,stage,speed_rpm,current_A']
    for stage, a, b in _cumulative():
        for n in rpm:
            lines.append(f'left,{stage},{n},{a * n * 2 * math.pi / 60 + b}')
    path = tmp_path / 'noload.csv'
    path.write_text('\n'.join(lines) + '\n')
    assert main(['fit-internal', str(path), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    track = out['components']['left']['track']
    assert track['coulomb_A'] == pytest.approx(0.6489, abs=1e-9)
    assert track['viscous_A_s'] == pytest.approx(0.00012, abs=1e-12)
    assert track['coulomb_Nm'] == pytest.approx(0.6489 * KT, abs=1e-9)
    assert out['fits']['left']['motor']['n_samples'] == 15


def test_fit_internal_wide_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / 'wide.csv'
    rows = ['left_speed_rpm,left_current_A,right_speed_rpm,right_current_A']
    for n in (200, 400, 800, 1600):
        w = n * 2 * math.pi / 60
        rows.append(f'{n},{0.05 + 1e-4 * w},{-n},{-(0.04 + 2e-4 * w)}')
    path.write_text('\n'.join(rows) + '\n')
    assert main(['fit-internal', str(path), '--json']) == 0
    fits = json.loads(capsys.readouterr().out)['fits']
    assert fits['left']['all']['coulomb_A'] == pytest.approx(0.05)
    assert fits['right']['all']['viscous_A_s'] == pytest.approx(2e-4)  # reverse running, same resistance


def test_fit_internal_uses_the_vehicles_motor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], strong_motor_vehicle: Path
) -> None:
    """A CSV current becomes torque through the K_t of --vehicle's motor: 0.228 N m/A (a preset
    override of the EC-45's 0.114, Appendix B line 12), so 0.05 A Coulomb current = 0.0114 N m."""
    vehicle = strong_motor_vehicle
    path = tmp_path / 'wide.csv'
    rows = ['left_speed_rpm,left_current_A']
    for n in (200, 400, 800, 1600):
        rows.append(f'{n},{0.05 + 1e-4 * n * 2 * math.pi / 60}')
    path.write_text('\n'.join(rows) + '\n')
    assert main(['fit-internal', str(path), '--vehicle', str(vehicle), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['torque_constant_Nm_A'] == 0.228
    assert out['fits']['left']['all']['coulomb_Nm'] == pytest.approx(0.05 * 0.228)
    assert main(['fit-internal', str(path), '--vehicle', str(tmp_path / 'none.yaml')]) == 2


def _write_bag(path: Path, samples: Iterable[tuple[float, float, float, float]]) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    JointState = store.types['sensor_msgs/msg/JointState']
    Header = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/joint_states', JointState.__msgtype__, typestore=store)
        for k, (omega_l, torque_l, omega_r, torque_r) in enumerate(samples):
            msg = JointState(
                header=Header(stamp=Time(sec=k, nanosec=0), frame_id=''),
                name=['left_motor', 'right_motor'],
                position=np.zeros(2),
                velocity=np.array([omega_l, omega_r]),
                effort=np.array([torque_l, torque_r]),
            )
            writer.write(conn, k * 10**9, store.serialize_cdr(msg, JointState.__msgtype__))


def test_fit_internal_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    omega = np.linspace(20, 400, 12)
    samples = [(w, 1e-5 * w + 0.007, w, 2e-5 * w + 0.009) for w in omega] + [(0.0, 0.0, 0.0, 0.0)]
    bag = tmp_path / 'noload_bag'
    _write_bag(bag, samples)
    assert main(['fit-internal', str(bag), '--stage', 'motor', '--json']) == 0
    fits = json.loads(capsys.readouterr().out)['fits']
    assert fits['left']['motor']['viscous_Nm_s'] == pytest.approx(1e-5)
    assert fits['right']['motor']['coulomb_Nm'] == pytest.approx(0.009)
    assert fits['left']['motor']['n_samples'] == 12  # the stationary sample is dropped


def test_fit_internal_bad_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['fit-internal', str(tmp_path / 'missing.csv')]) == 2
    bad = tmp_path / 'bad.csv'
    bad.write_text('speed_rpm,current_A\n100,abc\n')
    assert main(['fit-internal', str(bad)]) == 2
    err = capsys.readouterr().err
    assert 'bad.csv:2' in err and len(err.strip().splitlines()) == 2  # one line per failing call
    nocol = tmp_path / 'nocol.csv'
    nocol.write_text('x,y\n1,2\n')
    assert main(['fit-internal', str(nocol)]) == 2
    assert 'need a speed column' in capsys.readouterr().err
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'not a bag at all')
    assert main(['fit-internal', str(junk)]) == 2
    assert 'cannot read bag' in capsys.readouterr().err
