"""Offline calibration (issue 15) on twin bags whose truth the fit does not see.

The bag comes from the digital twin (``skidsteer_power.twin``: its own dynamics and contact model,
never FESS or the maps) driving a terrain that is no preset (:data:`TRUTH`, ASSUMED values); the
calibration starts from dry sand and only ever reads the bag.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from skidsteer_power.bag_io.synthetic import write_drive_bag
from skidsteer_power.calibration.fit import select_identifiable
from skidsteer_power.calibration.io import read_calibration
from skidsteer_power.calibration.segments import SegmentOptions, SteadyWindow, find_segments, read_recording
from skidsteer_power.cli.main import main
from skidsteer_power.commands import Segment
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.terramechanics.terrain import PRESETS, Terrain, load_terrain
from skidsteer_power.vehicle import load_vehicle

VEHICLE = 'test_robot_4wheel'
TRUTH = PRESETS['dry_sand'].__class__(
    name='hidden_sand', n=0.95, kc=2000.0, kphi=2.0e6, c=1400.0, phi=math.radians(32.0), K=0.02
)
ISSUE_KEYS = {
    'parameters',
    'correlations_warnings',
    'segments_fit',
    'segments_holdout',
    'torque_rmse_before_Nm',
    'torque_rmse_after_Nm',
    'holdout_energy_error_before',
    'holdout_energy_error_after',
    'seconds',
}


def twin_commands() -> list[Segment]:
    """Nine Table 7.3 commands (V 0.2 and 0.1 m/s, several yaw rates), 3.5 s each, stops between."""
    commands = []
    for speed, yaw_rates in ((0.2, (0.0, 0.05, 0.1, 0.2, 0.3)), (0.1, (0.0, 0.05, 0.1, 0.2))):
        for yaw in yaw_rates:
            commands += [Segment(speed, yaw, 3.5), Segment(0.0, 0.0, 0.5)]
    return commands


@pytest.fixture(scope='module')
def twin_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from skidsteer_power.twin import Twin, run_commands, write_bag
    from skidsteer_power.vehicle import load_vehicle

    path = tmp_path_factory.mktemp('twin') / 'drive.mcap'
    write_bag(run_commands(Twin(load_vehicle(VEHICLE), TRUTH, seed=3), twin_commands()), path)
    return path


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope='module')
def calibrated(twin_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path]:
    out = tmp_path_factory.mktemp('cal') / 'my_sand.yaml'
    code, stdout, stderr = run_cli(
        [
            'calibrate',
            str(twin_bag),
            '--vehicle',
            VEHICLE,
            '--terrain',
            'dry_sand',
            '--out-terrain',
            str(out),
            '--json',
        ]
    )
    assert code == 0, stderr
    return json.loads(stdout), out


def test_json_has_the_issue_keys_and_parameter_entries(calibrated: tuple[dict[str, Any], Path]) -> None:
    payload, _ = calibrated
    assert set(payload) >= ISSUE_KEYS
    for entry in payload['parameters'].values():
        assert {'value', 'ci95', 'unit'} <= set(entry)
    assert payload['segments_fit'] + payload['segments_holdout'] == 9  # every moving command
    assert payload['segments_holdout'] == 3  # round(0.3 * 9), split by segment


def test_fit_recovers_the_twins_torque_behaviour(calibrated: tuple[dict[str, Any], Path]) -> None:
    """Issue goal: hold-out energy error <= 5 % after calibration; dry sand is far off before
    (+12 % since the twin digs and bulldozes, issue 14; +20 % or more before that)."""
    p, _ = calibrated
    assert abs(p['holdout_energy_error_before']) > 0.1
    assert abs(p['holdout_energy_error_after']) <= 0.05
    # the twin's contact has terms FESS lacks (slip-sinkage, bulldozing: docs/TWIN.md), so the fit
    # cannot reach its torques exactly: measured 0.099 -> 0.040 N m (it was better than / 5 before)
    assert p['torque_rmse_after_Nm'] < p['torque_rmse_before_Nm'] / 2


def test_kc_is_reported_non_identifiable_and_left_at_its_start(
    calibrated: tuple[dict[str, Any], Path],
) -> None:
    """k_c enters only through kc / b + kphi (eq. 2.1). Hand calculation for the start (dry sand) and
    the 0.074 m wheel: kc / b = 900 / 0.074 = 12 162 against kphi = 1 523 400, so a 10 % change of kc
    changes k_eq by 0.1 x 12 162 / 1 535 562 = 0.08 %: invisible in the torque."""
    kc = calibrated[0]['parameters']['kc']
    assert kc['identifiable'] is False
    assert kc['fitted'] is False
    assert kc['ci95'] is None
    assert kc['value'] == pytest.approx(900.0)


def test_fitted_values_lie_inside_their_intervals_and_are_written(
    calibrated: tuple[dict[str, Any], Path],
) -> None:
    payload, path = calibrated
    terrain = load_terrain(path)  # the calibrated file is a terrain file like any other
    fitted = {n: e for n, e in payload['parameters'].items() if e['fitted'] and not e['at_bound']}
    assert fitted, 'at least one parameter fitted'
    # issue 27: a parameter the fit left at a bound (here phi at 50 deg: the twin's friction is 32 deg,
    # FESS buys the torque it misses with phi) has no interval and is not in the covariance
    pinned = [n for n, e in payload['parameters'].items() if e['at_bound']]
    assert all(payload['parameters'][n]['ci95'] is None for n in pinned)
    for name, entry in fitted.items():
        lo, hi = entry['ci95']
        assert lo < entry['value'] < hi
        si = entry['value'] * (math.pi / 180 if name == 'phi' else 1.0)
        assert getattr(terrain, name) == pytest.approx(si, rel=1e-12)
    block = yaml.safe_load(path.read_text())['calibration']
    assert block['parameters'] == list(fitted)
    assert {'covariance', 'bags', 'date', 'residual_rms_Nm'} <= set(block)
    _, names, values, cov = read_calibration(path)
    assert names == list(fitted)
    assert np.all(np.diag(cov) > 0)
    # the 95 % interval and the covariance agree: half-width ~ t(0.975) sigma (delta method)
    for k, name in enumerate(names):
        lo, hi = fitted[name]['ci95']
        if name == 'phi' or name == 'n':  # searched linearly: exactly symmetric
            assert (hi - lo) / 2 == pytest.approx(2.0 * math.sqrt(cov[k, k]), rel=0.25)
        assert values[k] == pytest.approx(fitted[name]['value'])


def test_calibrated_terrain_works_in_solve(calibrated: tuple[dict[str, Any], Path]) -> None:
    _, path = calibrated
    code, out, err = run_cli(
        [
            *('solve', '--vehicle', VEHICLE, '--terrain', str(path)),
            *('--speed', '0.2', '--turn-radius', 'inf'),
            '--model',
            'fess',
            '--json',
        ]
    )
    assert code == 0, err
    assert json.loads(out)['converged'] is True


@pytest.mark.parametrize(
    ('extra', 'match'),
    [
        (['--fit', 'kphi,bogus'], "unknown parameter 'bogus'"),
        (['--holdout', '1.5'], 'holdout must lie in'),
        (['--out-powertrain', 'x.yaml'], 'needs internal'),
        (['--odom-topic', '/nope'], 'no odometry or pose topic /nope'),
    ],
)
def test_bad_arguments_give_one_line_and_exit_2(
    twin_bag: Path, tmp_path: Path, extra: list[str], match: str
) -> None:
    argv = ['calibrate', str(twin_bag), '--vehicle', VEHICLE, '--terrain', 'dry_sand']
    code, _, err = run_cli([*argv, '--out-terrain', str(tmp_path / 'o.yaml'), *extra])
    assert code == 2
    assert match in err
    assert err.count('\n') == 1 and 'Traceback' not in err


def test_missing_bag_and_bag_without_motor_data(tmp_path: Path) -> None:
    code, _, err = run_cli(
        [
            *('calibrate', str(tmp_path / 'none.mcap'), '--vehicle', VEHICLE, '--terrain', 'dry_sand'),
            '--out-terrain',
            str(tmp_path / 'o.yaml'),
        ]
    )
    assert code == 2 and 'no such file' in err
    bag = tmp_path / 'nojs.mcap'
    write_drive_bag(bag, [Segment(0.2, 0.0, 4.0)], rate_hz=20, joint_states=False)
    code, _, err = run_cli(
        [
            'calibrate',
            str(bag),
            '--vehicle',
            VEHICLE,
            '--terrain',
            'dry_sand',
            '--out-terrain',
            str(tmp_path / 'o.yaml'),
        ]
    )
    assert code == 2 and 'no /joint_states topic' in err


def test_segments_are_the_settled_moving_commands(tmp_path: Path) -> None:
    """Synthetic ideal drive (bag_io/synthetic.py): odometry twist = command, so the measured motion of
    each segment is its command; stops are dropped, and each window starts settle_s after the change."""
    bag = tmp_path / 'ideal.mcap'
    plan = [Segment(0.2, 0.0, 4.0), Segment(0.0, 0.0, 1.0), Segment(0.1, 0.2, 4.0)]
    write_drive_bag(bag, plan, rate_hz=50)
    segments, dropped = find_segments(read_recording(bag), SegmentOptions(settle_s=1.5))
    assert [s.command for s in segments] == [(0.2, 0.0), (0.1, 0.2)]
    assert dropped['standing'] == 1
    for seg in segments:
        assert seg.motion_source == 'odometry twist'
        assert (seg.speed_m_s, seg.yaw_rate_rad_s) == pytest.approx(seg.command, abs=1e-9)
        assert seg.duration_s == pytest.approx(4.0 - 1.5, abs=0.03)
        assert seg.motor_torque_Nm == pytest.approx((0.1, 0.1))  # the synthetic bag's constant effort


def test_a_parameter_the_others_explain_is_not_selected() -> None:
    """Orthogonalization: b's effect is exactly 2 x a's, so once a is in, b adds nothing."""
    a = np.array([1.0, 2.0, 3.0, 4.0])
    columns = {'a': a, 'b': 2.0 * a, 'c': np.array([1.0, -1.0, 1.0, -1.0]), 'd': np.full(4, 1e-6)}
    picked, unexplained = select_identifiable(columns, ['a', 'b', 'c'], tol=1e-3)
    assert picked == ['a', 'c'] or picked == ['b', 'c']
    assert unexplained['d'] < 1e-3
    assert min(unexplained['a'], unexplained['b']) < 1e-9


def test_internal_resistance_of_the_bundled_track_bag(tmp_path: Path) -> None:
    """The bundled twin bag of the tracked robot (bags/README.md) was driven with the Table 7.1
    drivetrain, whose Coulomb terms sum per side to 0.0617 + 0.0177 + 0.0448 + 0.6489 = 0.7731 N m
    (left) and 0.0499 + 0.0248 + 0.0497 + 0.6314 = 0.7558 N m (right). The fit of ``internal`` finds
    them within 1 % (the rest is the twin-vs-FESS difference of the small terrain torque) and writes a
    powertrain file that loads as a preset."""
    from skidsteer_power.powertrain import Powertrain

    bag = Path(__file__).resolve().parents[1] / 'bags' / 'test_robot_track_sand_bin.mcap'
    out, pt_out = tmp_path / 't.yaml', tmp_path / 'pt.yaml'
    code, stdout, err = run_cli(
        [
            'calibrate',
            str(bag),
            '--vehicle',
            'test_robot_track',
            '--terrain',
            'sand_bin',
            '--fit',
            'phi,internal',
            '--out-terrain',
            str(out),
            '--out-powertrain',
            str(pt_out),
            '--json',
        ]
    )
    assert code == 0, err
    params = json.loads(stdout)['parameters']
    assert params['left_c']['value'] == pytest.approx(0.7731, rel=0.01)
    assert params['right_c']['value'] == pytest.approx(0.7558, rel=0.01)
    powertrain = Powertrain.from_config({'preset': str(pt_out)}, 'track')
    assert powertrain.left.total.coulomb_Nm == pytest.approx(params['left_c']['value'], rel=1e-9)
    assert set(powertrain.left.components) == {'motor', 'gear_train', 'roller_chain', 'track'}
    block = yaml.safe_load(pt_out.read_text())['calibration']
    assert 'left_c' in block['parameters'] and len(block['covariance']) == len(block['parameters'])
    terrain_block = yaml.safe_load(out.read_text())['calibration']
    assert 'left_c' in terrain_block['powertrain_parameters']


def test_four_wheel_joints_in_newton_metres_at_the_wheel_give_the_same_segments(
    twin_bag: Path, tmp_path: Path
) -> None:
    """calibrate reads joint_states through the vehicle file's drivetrain mapping (issue 16), as the
    estimator and validate do. The twin bag's two motor joints (effort Kt I at the motor, N m) are
    re-written as a ros2_control robot's four wheel joints (config/joints/ros2_control_4wheel):
    per side two joints each carrying half the axle torque, T_w = T_m G / 2, at the axle speed
    w_w = w_m / G (G = 12, the test robot's reduction). Mapped back (sum of T_w / G, mean of w_w x G)
    this is the motor's own reading again, so both bags must give the same steady segments."""
    from skidsteer_power.bag_io import open_bag
    from skidsteer_power.bag_io.writer import BagWriter
    from skidsteer_power.estimator import factory
    from skidsteer_power.estimator.inputs import InputLimits, JointReader

    vehicle = load_vehicle(VEHICLE)
    powertrain = Powertrain.for_vehicle(vehicle)
    g = powertrain.gear_ratio
    assert g == 12.0  # chapter 7: 12:1 reduction
    wheels = factory.joint_map_for(vehicle, left='front_left_wheel_joint,rear_left_wheel_joint',
                                   right='front_right_wheel_joint,rear_right_wheel_joint',
                                   effort_is='torque', location='wheel')  # fmt: skip
    rewritten = tmp_path / 'ros2_control.mcap'
    with open_bag(twin_bag) as bag, BagWriter(rewritten) as writer:
        out = {name: writer.add_topic(name, info.msgtype) for name, info in bag.topics.items()}
        store = bag.typestore
        for message in bag.messages():
            data = message.data
            if message.topic == '/joint_states':
                msg = bag.deserialize(message)
                w_m, t_m = np.asarray(msg.velocity), np.asarray(msg.effort)  # left_motor, right_motor
                msg.name = [*wheels.left, *wheels.right]
                msg.position = np.repeat(np.asarray(msg.position) / g, 2)
                msg.velocity = np.repeat(w_m / g, 2)
                msg.effort = np.repeat(t_m * g / 2.0, 2)
                data = store.serialize_cdr(msg, message.msgtype)
            writer.write(out[message.topic], message.timestamp_ns, data)
    reader = JointReader(wheels, g, powertrain.motor.torque_constant_Nm_A, InputLimits())
    options = SegmentOptions(settle_s=1.5)
    motors, _ = find_segments(read_recording(twin_bag, options), options, powertrain.motor)
    four, _ = find_segments(read_recording(rewritten, options, reader), options, powertrain.motor)
    assert len(four) == len(motors) >= 6
    for a, b in zip(motors, four, strict=True):
        assert b.command == a.command
        assert b.motor_torque_Nm == pytest.approx(a.motor_torque_Nm, rel=1e-9)
        assert b.motor_omega_rad_s == pytest.approx(a.motor_omega_rad_s, rel=1e-9)


@pytest.fixture(scope='module')
def holdout_segments(tmp_path_factory: pytest.TempPathFactory) -> list[SteadyWindow]:
    """Steady segments of a second twin bag (same terrain, seed 5) with commands the training bag
    never drove, inside its envelope: the hold-out the calibration never sees."""
    from skidsteer_power.twin import Twin, run_commands, write_bag
    from skidsteer_power.vehicle import load_vehicle

    commands: list[Segment] = []
    for speed, yaw in ((0.15, 0.0), (0.15, 0.08), (0.15, 0.15), (0.15, 0.25), (0.12, 0.03), (0.18, 0.12)):
        commands += [Segment(speed, yaw, 3.5), Segment(0.0, 0.0, 0.5)]
    path = tmp_path_factory.mktemp('holdout') / 'holdout.mcap'
    write_bag(run_commands(Twin(load_vehicle(VEHICLE), TRUTH, seed=5), commands), path)
    options = SegmentOptions(settle_s=1.5)
    segments, _ = find_segments(read_recording(path, options), options)
    assert len(segments) == 6
    return segments


def command_energy_error(terrain: Terrain, segments: list[SteadyWindow]) -> float:
    """Signed energy error [-] of the set-point prediction from each segment's command (as the node
    predicts) against the twin's measured motor terminal energy."""
    from skidsteer_power.calibration.fit import setpoint_check

    vehicle = load_vehicle(VEHICLE)
    measured = np.array([s.motor_torque_Nm for s in segments])
    every = np.arange(len(segments))
    check = setpoint_check(
        vehicle, terrain, Powertrain.for_vehicle(vehicle), segments, measured, every, every
    )
    return check['holdout_energy_error']


def test_calibrating_never_worsens_the_prediction_from_the_command(
    calibrated: tuple[dict[str, Any], Path], holdout_segments: list[SteadyWindow]
) -> None:
    """Issue 27: calibrate fits what the node predicts (the torques at the set points of each
    command), so the hold-out prediction from the command is no worse after than before. Reference:
    the twin's measured motor power on a bag the fit never read (FESS is not in the twin)."""
    payload, path = calibrated
    assert payload['fit_at'] == 'cmd'
    assert yaml.safe_load(path.read_text())['calibration']['fit_at'] == 'cmd'  # the file says so
    before = command_energy_error(load_terrain('dry_sand'), holdout_segments)
    after = command_energy_error(load_terrain(path), holdout_segments)
    assert abs(after) <= abs(before)  # measured +18.8 % -> -0.3 %
    assert abs(after) <= 0.05
    # the calibration's own hold-out segments, predicted from their commands: the same (to the
    # solvers' tolerance: the fit's solve is warm-started, the check's is not)
    assert abs(payload['holdout_energy_error_after']) <= abs(payload['holdout_energy_error_before'])
    assert payload['from_cmd']['holdout_energy_error'] == pytest.approx(
        payload['holdout_energy_error_after'], abs=1e-4
    )
    print(f'hold-out bag from the command: before {before:+.2%}, after {after:+.2%}')


def test_fit_at_the_motion_stays_available(
    twin_bag: Path, tmp_path: Path, holdout_segments: list[SteadyWindow]
) -> None:
    """``--fit-at motion`` solves the segments at the measured motion (the twin's ground truth); its
    terrain then predicts the commands through the set points, reported in ``from_cmd``."""
    out = tmp_path / 'motion.yaml'
    code, stdout, stderr = run_cli(
        [
            'calibrate',
            str(twin_bag),
            '--vehicle',
            VEHICLE,
            '--terrain',
            'dry_sand',
            '--fit-at',
            'motion',
            '--out-terrain',
            str(out),
            '--json',
        ]
    )
    assert code == 0, stderr
    p = json.loads(stdout)
    assert p['fit_at'] == 'motion'
    sp = p['from_cmd']
    keys = {'torque_rmse_Nm', 'holdout_energy_error', 'speed_error_median', 'yaw_rate_error_median'}
    assert set(sp) == keys | {'limited_segments'}
    assert sp['speed_error_median'] < 0.05  # measured 2.1 %
    assert abs(p['holdout_energy_error_after']) < abs(p['holdout_energy_error_before'])
    # reported, not asserted (docs/COMPARE_RESULTS.md): on the hold-out bag the motion fit's terrain
    # predicts the commands to within a few % too; the set-point fit is the one that cannot lose
    code, text, _ = run_cli(
        ['calibrate', str(twin_bag), '--vehicle', VEHICLE, '--terrain', 'dry_sand', '--fit-at', 'motion',
         '--out-terrain', str(tmp_path / 'again.yaml')]
    )  # fmt: skip
    assert code == 0 and 'solved at the measured motion' in text  # the table says what was fitted
    motion_error = command_energy_error(load_terrain(out), holdout_segments)
    assert math.isfinite(motion_error)
    print(f'hold-out bag from the command, motion-fitted terrain: {motion_error:+.2%}')
