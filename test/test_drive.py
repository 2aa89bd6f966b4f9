"""The drive controller (skidsteer_power/drive): set points, ramps, the vehicle file, identification.

Reference values are hand calculations written beside each assertion (v -+ w B / 2, / r).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from skidsteer_power.des.kinematics import twist_to_motor_rpm
from skidsteer_power.drive import DriveController, Ramp, controller_for_vehicle, identify
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.models.setpoint import command_setpoints
from skidsteer_power.powertrain.motor import RPM
from skidsteer_power.vehicle import load_vehicle, vehicle_fingerprint

HUSKY = DriveController(0.5708, 0.1651, max_speed_m_s=1.0, max_yaw_rate_rad_s=2.0, max_wheel_rad_s=6.1)


def test_kinematics_and_multipliers() -> None:
    ctrl = DriveController(0.4, 0.1, wheel_separation_multiplier=1.5, left_wheel_radius_multiplier=0.5)
    out = ctrl.apply([0.2], [1.0])
    # B = 1.5 x 0.4 = 0.6: left (0.2 - 0.3) / (0.5 x 0.1) = -2.0, right (0.2 + 0.3) / 0.1 = 5.0 rad/s
    assert out.setpoint[0] == pytest.approx([-2.0, 5.0])
    v, w = ctrl.twist_of(out.setpoint)
    assert (v[0], w[0]) == pytest.approx((0.2, 1.0))  # the inverse kinematics
    assert not out.clamped[0]


def test_velocity_limits_then_scale_keeps_the_curvature() -> None:
    out = HUSKY.apply([1.5, 0.0, 1.0], [0.0, 3.0, 2.0])
    # 1.5 m/s -> 1.0: 1.0 / 0.1651 = 6.057 rad/s, under the 6.1 ceiling
    assert out.setpoint[0] == pytest.approx([1 / 0.1651] * 2)
    assert out.velocity_limited[0] and not out.ceiling_reached[0]
    # spin 3 -> 2 rad/s: sides -+ 2 x 0.2854 = 0.5708 m/s -> 3.457 rad/s
    assert out.setpoint[1] == pytest.approx([-0.5708 / 0.1651, 0.5708 / 0.1651])
    # (1.0, 2.0): sides 0.4292, 1.5708 m/s -> 2.600, 9.514 rad/s; scaled by 6.1 / 9.514
    raw = np.array([0.4292, 1.5708]) / 0.1651
    assert out.setpoint[2] == pytest.approx(raw * 6.1 / raw[1])
    assert out.setpoint[2, 0] / out.setpoint[2, 1] == pytest.approx(raw[0] / raw[1])  # curvature kept
    assert out.ceiling_reached[2] and out.clamped.all()


def test_clip_changes_only_the_fast_side() -> None:
    clip = HUSKY.with_values(ceiling='clip')
    out = clip.apply([1.0], [2.0])
    assert out.setpoint[0] == pytest.approx([0.4292 / 0.1651, 6.1])


def test_one_command_in_floats_is_the_array_answer() -> None:
    v = np.linspace(-1.6, 1.6, 17)
    w = np.linspace(-3.0, 3.0, 13)
    V, W = (a.ravel() for a in np.meshgrid(v, w))
    for ctrl in (HUSKY, HUSKY.with_values(ceiling='clip')):
        batch = ctrl.apply(V, W)
        for k in range(V.size):
            left, right, clamped = ctrl.apply_one(float(V[k]), float(W[k]))
            assert (left, right) == (batch.setpoint[k, 0], batch.setpoint[k, 1])  # bit for bit
            assert clamped == batch.clamped[k]


def test_the_old_callers_are_the_controller() -> None:
    # command_setpoints (models) and twist_to_motor_rpm (the DES driver) delegate to it
    sp, clamped = command_setpoints(
        [0.1, 5.0], [0.2, 1.0], tread_m=0.426, drive_radius_m=0.1, max_axle_rad_s=30.0
    )
    ctrl = DriveController(0.426, 0.1, max_wheel_rad_s=30.0)
    assert np.array_equal(sp, ctrl.apply([0.1, 5.0], [0.2, 1.0]).setpoint)
    assert list(clamped) == [False, True]
    rpm = twist_to_motor_rpm(
        5.0, 1.0, tread_m=0.426, drive_radius_m=0.1, gear_ratio=12.0, max_rpm=30.0 * 12 / RPM
    )
    assert np.array(rpm) * RPM / 12.0 == pytest.approx(sp[1], rel=1e-12)


def test_non_finite_commands_are_refused() -> None:
    with pytest.raises(InputError):
        HUSKY.apply([math.nan], [0.0])
    with pytest.raises(InputError):
        HUSKY.apply_one(0.0, math.inf)
    with pytest.raises(InputError):
        Ramp(HUSKY.with_values(max_accel_m_s2=1.0)).step(0.5, 0.0, math.nan)


def test_ramp_acceleration_and_jerk() -> None:
    ramp = Ramp(HUSKY.with_values(max_accel_m_s2=0.5, max_yaw_accel_rad_s2=1.0))
    speeds = [ramp.step(0.8, 0.0, 0.1) for _ in range(20)]
    # 0.5 m/s^2 x 0.1 s = 0.05 m/s a step: 0.05, 0.10, ... up to the command 0.8 after 16 steps
    v = [0.5 * (left + right) * 0.1651 for left, right, _ in speeds]
    assert v[:3] == pytest.approx([0.05, 0.10, 0.15])
    assert v[15:] == pytest.approx([0.8] * 5)
    jerk = Ramp(HUSKY.with_values(max_accel_m_s2=10.0, max_jerk_m_s3=1.0))
    out = [jerk.step(1.0, 0.0, 0.1) for _ in range(3)]
    # SpeedLimiter::limit_jerk: dv - dv0 at most j 2 dt^2 = 0.02 m/s: 0.02, 0.06, 0.12
    assert [0.5 * (a + b) * 0.1651 for a, b, _ in out] == pytest.approx([0.02, 0.06, 0.12])
    plain = Ramp(HUSKY)  # no acceleration limit: the steady set points at once
    assert plain.step(1.0, 2.0, 0.01) == HUSKY.apply_one(1.0, 2.0)


def test_vehicle_files(tmp_path: Path) -> None:
    husky = controller_for_vehicle(load_vehicle('husky_a200'))
    assert (husky.max_speed_m_s, husky.max_yaw_rate_rad_s) == (1.0, 2.0)  # the vehicle file's envelope
    assert husky.max_wheel_rad_s == pytest.approx(1.0 / 0.1651, abs=1e-3)  # hardware max_speed / r
    assert husky.separation_m == pytest.approx(1.875 * 0.5708) and husky.ceiling == 'scale'
    test_robot = controller_for_vehicle(load_vehicle('test_robot_track'))
    # the DES 70/10 set-point limit: EC-45 10 000 rpm / 12 = 87.27 rad/s at the sprocket
    assert test_robot.max_wheel_rad_s == pytest.approx(10000 * 2 * math.pi / 60 / 12)
    data = yaml.safe_load(Path('config/vehicles/test_robot_track.yaml').read_text())
    data['drive_controller'] = {'max_accel_m_s2': 1.0}
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match='no source for max_accel_m_s2'):
        controller_for_vehicle(load_vehicle(path))
    data['drive_controller'] = {'max_accel': 1.0, 'sources': {'max_accel': 'x'}}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match='unknown key'):
        controller_for_vehicle(load_vehicle(path))
    data['drive_controller'] = {'ceiling': 'squash'}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match='ceiling'):
        controller_for_vehicle(load_vehicle(path))
    # the controller makes set points, it changes no map node: the fingerprint stays
    data['drive_controller'] = {'max_accel_m_s2': 1.0, 'sources': {'max_accel_m_s2': 'ASSUMED'}}
    path.write_text(yaml.safe_dump(data))
    assert vehicle_fingerprint(load_vehicle(path)) == vehicle_fingerprint(load_vehicle('test_robot_track'))


def _recording(
    ctrl: DriveController, commands: list[tuple[float, float]], noise: float, seed: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A synthetic recording: the controller in time, wheels following with a 50 ms lag, sensor noise
    [rad/s]; 4 s per command at 50 Hz."""
    rng = np.random.default_rng(seed)
    dt, ramp, y = 0.02, Ramp(ctrl), np.zeros(2)
    t: list[float] = []
    cmd: list[tuple[float, float]] = []
    meas: list[np.ndarray] = []
    for v, w in commands:
        for _ in range(200):
            left, right, _ = ramp.step(v, w, dt)
            y = y + (np.array([left, right]) - y) * dt / 0.05
            t.append(len(t) * dt)
            cmd.append((v, w))
            meas.append(y + rng.normal(0.0, noise, 2))
    return np.array(t), np.array(cmd), np.array(meas)


COMMANDS = [(0.5, 0.0), (1.5, 0.0), (0.0, 3.0), (-1.4, 0.0), (1.2, -1.0), (0.3, 0.3), (0.0, -2.6), (1.0, 2.0)]


def test_identify_recovers_limits_through_noise() -> None:
    true = HUSKY.with_values(max_speed_m_s=0.8, max_accel_m_s2=0.8)  # 0.8 m/s: apart from the ceiling
    prior = HUSKY.with_values(max_speed_m_s=1.5, max_yaw_rate_rad_s=2.5, max_wheel_rad_s=math.inf)
    t, cmd, meas = _recording(true, COMMANDS, noise=0.03)
    meas[::97] += 3.0  # outliers: a sample in 97 off by 3 rad/s
    found = identify(t, cmd, meas, prior=prior)
    v = found.values
    assert v['max_speed_m_s'].reached and v['max_speed_m_s'].value == pytest.approx(0.8, rel=0.01)
    assert v['max_yaw_rate_rad_s'].reached and v['max_yaw_rate_rad_s'].value == pytest.approx(2.0, rel=0.01)
    assert v['max_wheel_rad_s'].reached and v['max_wheel_rad_s'].value == pytest.approx(6.1, rel=0.01)
    assert v['ceiling'].reached and v['ceiling'].value == 'scale'
    assert v['max_accel_m_s2'].reached and v['max_accel_m_s2'].value == pytest.approx(0.8, rel=0.05)
    assert found.controller.max_wheel_rad_s == v['max_wheel_rad_s'].value
    entries = found.vehicle_entries('identified from test')
    assert entries['max_speed_m_s'] == v['max_speed_m_s'].value
    assert entries['drive_controller']['ceiling'] == 'scale'
    assert set(entries['drive_controller']['sources']) == set(entries['drive_controller']) - {
        'ceiling',
        'sources',
    }


def test_identify_tells_clip_from_scale() -> None:
    true = HUSKY.with_values(ceiling='clip')
    t, cmd, meas = _recording(true, COMMANDS, noise=0.02)
    found = identify(t, cmd, meas, prior=HUSKY)
    assert found.values['ceiling'].value == 'clip' and found.values['ceiling'].reached


def test_identify_a_recording_that_reaches_no_limit() -> None:
    gentle = [(0.2, 0.0), (0.25, 0.3), (0.0, 0.5), (-0.2, 0.1), (0.1, -0.4)]
    t, cmd, meas = _recording(HUSKY, gentle, noise=0.03)
    prior = HUSKY.with_values(max_accel_m_s2=3.0)
    found = identify(t, cmd, meas, prior=prior)
    for name in ('max_speed_m_s', 'max_yaw_rate_rad_s', 'max_wheel_rad_s', 'ceiling', 'max_yaw_accel_rad_s2'):
        item = found.values[name]
        assert not item.reached and 'kept from the vehicle file' in item.note, name
        assert item.value == getattr(prior, name)
    assert found.controller == prior.with_values(max_accel_m_s2=found.controller.max_accel_m_s2)


def test_identify_refuses_bad_input() -> None:
    t = np.arange(20) * 0.1
    with pytest.raises(InputError, match='at least 10'):
        identify(t[:5], np.zeros((5, 2)), np.zeros((5, 2)), prior=HUSKY)
    with pytest.raises(InputError, match='increase'):
        identify(t[::-1], np.zeros((20, 2)), np.zeros((20, 2)), prior=HUSKY)
    with pytest.raises(InputError, match='finite'):
        identify(t, np.full((20, 2), math.nan), np.zeros((20, 2)), prior=HUSKY)
    with pytest.raises(InputError, match=r'\(N, 2\)'):
        identify(t, np.zeros((20, 3)), np.zeros((20, 2)), prior=HUSKY)
