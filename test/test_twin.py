"""The digital twin (skidsteer_power/twin): independence from the predictor, energy conservation,
steady states against the chapter 2 / 3 / 4 reference models, getting stuck, sensors and the CLI."""

from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from scipy.optimize import brentq

from skidsteer_power.cli.main import main
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.models import wong_track, wong_wheel
from skidsteer_power.terramechanics import load_terrain, solve_wheel
from skidsteer_power.terramechanics import track as single_track
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.twin import (
    Segment,
    Twin,
    commands_from_csv,
    drive_until_empty,
    load_patches,
    run_commands,
    write_bag,
)
from skidsteer_power.twin.sensors import TwinTrace
from skidsteer_power.twin.wheel_contact import WheelContact
from skidsteer_power.vehicle import load_vehicle

TWIN_DIR = Path(__file__).resolve().parents[1] / 'skidsteer_power' / 'twin'
SAND_BIN = load_terrain('sand_bin')


def _settled(
    vehicle: str,
    speed: float,
    yaw_rate: float,
    seconds: float = 7.0,
    terrain: Terrain = SAND_BIN,
    **options: Any,
) -> tuple[Twin, TwinTrace]:
    twin = Twin(load_vehicle(vehicle), terrain, **options)
    trace = run_commands(twin, [Segment(speed, yaw_rate, seconds)])
    return twin, trace


# --------------------------------------------------------------------------- independence


def test_twin_source_never_imports_fess_or_maps() -> None:
    for path in TWIN_DIR.glob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ''] + [f'{node.module}.{a.name}' for a in node.names]
            for name in names:
                assert not name.startswith(('skidsteer_power.maps', 'skidsteer_power.models')), (path, name)


def test_importing_and_running_the_twin_loads_neither_fess_nor_maps() -> None:
    code = (
        'import sys\n'
        'from skidsteer_power.twin import Twin, Segment, run_commands\n'
        'from skidsteer_power.vehicle import load_vehicle\n'
        'from skidsteer_power.terramechanics import load_terrain\n'
        "twin = Twin(load_vehicle('test_robot_4wheel'), load_terrain('sand_bin'))\n"
        'run_commands(twin, [Segment(0.1, 0.1, 0.1)])\n'
        "bad = [m for m in sys.modules if m.startswith(('skidsteer_power.maps', 'skidsteer_power.models'))]\n"
        'print(bad)\n'
    )
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == '[]'


# --------------------------------------------------------------------------- energy


@pytest.mark.parametrize('vehicle', ['test_robot_track', 'test_robot_4wheel'])
def test_bus_energy_equals_terrain_work_plus_losses_plus_kinetic_energy(vehicle: str) -> None:
    # start, turn, reverse-steer, stop: bus energy = terrain work + internal losses + kinetic change
    twin = Twin(load_vehicle(vehicle), SAND_BIN)
    commands = [
        Segment(0.2, 0.0, 1.5),
        Segment(0.2, 0.3, 1.5),
        Segment(0.1, -0.2, 1.0),
        Segment(0.0, 0.0, 1.0),
    ]
    trace = run_commands(twin, commands)
    e = trace.ledger
    losses = e['amplifier_J'] + e['copper_J'] + e['friction_J']
    assert e['bus_J'] > 50.0
    assert e['terrain_J'] > 0.0 and losses > 0.0
    balance = e['terrain_J'] + losses + e['kinetic_J']  # kinetic energy at rest at the start: 0
    assert abs(e['bus_J'] - balance) / e['bus_J'] < 0.01
    assert trace.energy_J[-1] == pytest.approx(e['bus_J'])


# --------------------------------------------------------------------------- steady states
# The steady models (chapters 2-4) have no bulldozing and no slip-sinkage excavation: the twin is
# compared with them with those terms switched off (contact='classic'; docs/TWIN.md).


def test_straight_track_agrees_with_the_single_track_equations() -> None:
    # steady straight running: each track's drawbar pull F_s - R_c = 0 (eq. 2.18) at load W/2
    twin, trace = _settled('test_robot_track', 0.2, 0.0, contact='classic')
    v = twin.vehicle
    load, b, length = v.weight_N / 2, v.tracks().track_width_m, v.tracks().track_length_m
    rc = float(single_track.compaction_resistance(SAND_BIN, load, b, length))  # eq. 2.10
    slip = brentq(lambda s: float(single_track.tractive_effort(SAND_BIN, load, b, length, s)) - rc, 1e-9, 0.9)
    sprocket = twin.omega_m.mean() / twin.G
    twin_slip = 1.0 - twin.vel[0] / (v.drive_radius_m * sprocket)  # eq. 2.13
    assert twin_slip == pytest.approx(slip, rel=0.02)
    assert trace.axle_torque_Nm[-1] == pytest.approx([v.drive_radius_m * rc] * 2, rel=0.02)


@pytest.mark.parametrize('vehicle', ['test_robot_4wheel', 'test_robot_6wheel'])
def test_straight_wheels_agree_with_the_single_wheel_equations(vehicle: str) -> None:
    # steady straight running: every wheel has zero drawbar pull at load W / n (eqs. 2.28-2.29)
    twin, trace = _settled(vehicle, 0.2, 0.0, seconds=4.0, contact='classic')
    v = twin.vehicle
    wheels = v.wheels()
    ref = solve_wheel(
        SAND_BIN, v.weight_N / wheels.n_wheels, 0.0, wheels.wheel_radius_m, wheels.wheel_width_m
    )
    sprocket = twin.omega_m.mean() / twin.G
    twin_slip = 1.0 - twin.vel[0] / (v.drive_radius_m * sprocket)
    assert twin_slip == pytest.approx(float(ref.slip), rel=0.02)
    per_wheel = trace.axle_torque_Nm[-1] / v.wheels_per_side
    assert per_wheel == pytest.approx([float(ref.drive_torque_Nm)] * 2, rel=0.02)
    assert isinstance(twin.contact, WheelContact)
    assert twin.contact.z == pytest.approx(float(ref.sinkage_m), rel=0.02)


@pytest.mark.parametrize(
    ('vehicle', 'model'),
    [('test_robot_track', wong_track), ('test_robot_4wheel', wong_wheel), ('test_robot_6wheel', wong_wheel)],
)
def test_steady_turn_agrees_with_wongs_theory_at_the_actual_motion(vehicle: str, model: ModuleType) -> None:
    # The twin turns less than commanded (slip); Wong's theory (ch. 3 tracks, ch. 4 wheels) solved at
    # the twin's actual speed and radius must give its sprocket/axle torques and speeds.
    # Tolerance 1 %: the twin discretizes the patches differently (32 trapezoid intervals along a
    # track, 24 along a wheel's arc, vs Gauss-Legendre) and omits the r sin(theta) yaw term of eq.
    # 4.3 and the hull's turn during a wheel's contact; measured differences are <= 0.1 %.
    twin, trace = _settled(vehicle, 0.2, 0.2, seconds=6.0, contact='classic')
    speed, yaw = twin.vel[0], twin.vel[2]
    assert 0.0 < yaw < 0.2  # a left turn, wider than commanded
    state = model.solve(twin.vehicle, SAND_BIN, speed, speed / yaw)
    inner, outer = trace.axle_torque_Nm[-1]  # left turn: left = inner
    assert inner == pytest.approx(float(state.torque_inner_Nm), rel=0.01, abs=0.01)
    assert outer == pytest.approx(float(state.torque_outer_Nm), rel=0.01)
    omega = twin.omega_m / twin.G
    assert omega == pytest.approx([float(state.omega_inner_rad_s), float(state.omega_outer_rad_s)], rel=0.01)


# --------------------------------------------------------------------------- stuck


@pytest.mark.parametrize('vehicle', ['test_robot_4wheel', 'test_robot_6wheel'])
def test_table_7_3_cells_on_sand_bin_complete_or_get_stuck_as_the_real_robot(vehicle: str) -> None:
    # ch. 7.3.4, Table 7.3 (skidsteer_power.real_robot): the test robot completed 0.1 m/s up to
    # 0.2 rad/s and 0.2 m/s up to 0.35 rad/s, and got stuck "because of the large sinkage" at
    # 0.1 m/s, 0.25-0.35 rad/s (the empty cells). A bounded subset; all 66 cells are in
    # benchmarks/bench_twin_motion.py. Nothing is fitted to the grid (docs/TWIN.md).
    from skidsteer_power.real_robot import table_7_3_completed
    from skidsteer_power.twin.motion import twin_completes

    for speed, yaw_rate in [(0.1, 0.3), (0.2, 0.35)]:
        assert twin_completes(vehicle, speed, yaw_rate) is table_7_3_completed(speed, yaw_rate), (
            speed,
            yaw_rate,
        )
    # stuck by digging in: without slip-sinkage and the step's bulldozing the empty cell keeps moving
    assert twin_completes(vehicle, 0.1, 0.3, contact='classic') is True


@pytest.mark.parametrize(
    ('vehicle', 'speed', 'yaw_rate', 'radius_real'),
    [('test_robot_track', 0.2, 0.02, 17.48), ('test_robot_6wheel', 0.2, 0.25, 1.62)],
)
def test_turn_radius_matches_appendix_d_where_nothing_was_fitted(
    vehicle: str, speed: float, yaw_rate: float, radius_real: float
) -> None:
    # Appendix D (skidsteer_power.real_robot.APPENDIX_D_RADII); the track's longitudinal shear modulus
    # was fitted to the track's 0.1 m/s cells only, so these two are a check. Goal of issue 26:
    # max |R_twin / R_real - 1| <= 30 % (all 14 cells: benchmarks/bench_twin_motion.py).
    from skidsteer_power.twin.motion import twin_turn

    radius, _speed = twin_turn(vehicle, speed, yaw_rate)
    assert abs(radius / radius_real - 1.0) <= 0.30
    # the classic laws turn the track far tighter than the real one (Appendix D: 1.75x commanded)
    if vehicle == 'test_robot_track':
        classic, _speed = twin_turn(vehicle, speed, yaw_rate, contact='classic')
        assert classic < 0.75 * radius_real


def test_extended_track_torques_stay_wongs_at_the_actual_motion() -> None:
    # Chapter 7.3.4 (Figure 7.41): FESS (Wong's track theory) at the measured speed and radius was
    # "validated by the experiments" on the real track's axle torques. The fitted longitudinal
    # modulus widens the twin's turns as Appendix D's, and keeps that: Wong's theory at the twin's
    # actual motion gives its outer torque within 15 % (measured 2-10 % over 0.04-0.2 rad/s; the
    # lateral-stiffness law that fits the same radii gave 2-3x).
    twin, trace = _settled('test_robot_track', 0.1, 0.1, seconds=6.0)
    speed, yaw = twin.vel[0], twin.vel[2]
    assert speed / yaw > 1.3  # wider than the commanded 1 m, as the real track (1.44 m)
    state = wong_track.solve(twin.vehicle, SAND_BIN, speed, speed / yaw)
    outer = trace.axle_torque_Nm[-1][1]  # left turn: right = outer
    assert outer == pytest.approx(float(state.torque_outer_Nm), rel=0.15)


def test_track_sinks_deeper_with_slip_in_the_extended_laws() -> None:
    # Lyasko's slip-sinkage (contact.slip_sinkage_factor) under a track as under a wheel: a slipping
    # outer track in a tight turn sinks deeper than the static eq. 2.6 sinkage the classic laws keep
    twin, trace = _settled('test_robot_track', 0.1, 0.3, seconds=3.0)
    _plain, classic = _settled('test_robot_track', 0.1, 0.3, seconds=3.0, contact='classic')
    static = float(single_track.track_sinkage(SAND_BIN, 0.5 * twin.vehicle.weight_N, 0.074, 0.45))
    assert classic.sinkage_m.max() == pytest.approx(static, rel=0.1)  # (lateral load transfer: < 10 %)
    assert trace.sinkage_m.max() > 1.05 * classic.sinkage_m.max()


def test_the_real_robots_observations_are_the_dissertations() -> None:
    from skidsteer_power.real_robot import APPENDIX_D_RADII, table_7_3_cells

    cells = table_7_3_cells()
    assert len(cells) == 66 and sum(not done for *_, done in cells) == 9  # 3 empty cells x 3 configurations
    assert len(APPENDIX_D_RADII) == 14
    assert sum(c.vehicle == 'test_robot_track' for c in APPENDIX_D_RADII) == 9


# --------------------------------------------------------------------------- sensors, patches, CLI


def test_odometry_drifts_with_slip_and_ground_truth_does_not() -> None:
    twin, trace = _settled('test_robot_4wheel', 0.2, 0.0, seconds=3.0)
    true_x, odom_x = trace.pose[-1, 0], trace.odom_pose[-1, 0]
    slip = 1.0 - twin.vel[0] / (twin.r * twin.omega_m.mean() / twin.G)
    assert slip > 0.1
    assert odom_x > 1.1 * true_x  # the encoders count the slipping wheel's turns
    # effort: Kt I to 1 mA, with noise around the true current
    kt = twin.kt
    counts = trace.joint_effort_Nm / kt / 0.001
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    assert np.abs(trace.joint_effort_Nm / kt - trace.current_A).mean() < 0.05


def test_a_patch_of_other_terrain_changes_the_load(tmp_path: Path) -> None:
    patch = tmp_path / 'patches.yaml'
    patch.write_text('patches:\n  - terrain: clay\n    polygon: [[0.3, -2], [5, -2], [5, 2], [0.3, 2]]\n')
    patches = load_patches(patch)
    vehicle = load_vehicle('test_robot_4wheel')
    plain = run_commands(Twin(vehicle, SAND_BIN), [Segment(0.2, 0.0, 4.0)])
    patched = run_commands(Twin(vehicle, SAND_BIN, patches=patches), [Segment(0.2, 0.0, 4.0)])
    assert patched.axle_torque_Nm[10] == pytest.approx(plain.axle_torque_Nm[10])  # before the patch
    assert patched.sinkage_m[-1] < 0.5 * plain.sinkage_m[-1]  # clay (Table 2.1) is much firmer
    bad = tmp_path / 'bad.yaml'
    bad.write_text('patches:\n  - terrain: clay\n    polygon: [[0, 0], [1, 1]]\n')
    with pytest.raises(ConfigError, match='polygon'):
        load_patches(bad)


def test_command_csv_rows_hold_until_the_next(tmp_path: Path) -> None:
    csv = tmp_path / 'cmd.csv'
    csv.write_text('t_s,speed_m_s,yaw_rate_rad_s\n0.5,0.1,0\n2,0.2,0.1\n3,0,0\n')
    assert commands_from_csv(csv) == [Segment(0.0, 0.0, 0.5), Segment(0.1, 0.0, 1.5), Segment(0.2, 0.1, 1.0)]
    csv.write_text('t_s,speed_m_s,yaw_rate_rad_s\n0,0.1,x\n1,0,0\n')
    with pytest.raises(InputError, match=':2:'):
        commands_from_csv(csv)


def test_simulate_cli_writes_the_bag_and_reports_the_contract_keys(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from skidsteer_power.bag_io.reader import open_bag

    csv = tmp_path / 'cmd.csv'
    csv.write_text('t_s,speed_m_s,yaw_rate_rad_s\n0,0.2,0.1\n2,0,0\n')
    out = tmp_path / 'twin.mcap'
    argv = ['simulate', '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--commands', str(csv)]
    assert main([*argv, '--seed', '3', '-o', str(out), '--json']) == 0
    payload = json.loads(capsys.readouterr().out)
    assert set(payload) == {
        'duration_s',
        'messages',
        'energy_J',
        'distance_m',
        'max_sinkage_m',
        'stuck',
        'contact',
    }
    assert payload['contact'] == 'extended'  # the default
    assert payload['duration_s'] == pytest.approx(3.0, abs=0.01)  # 1 s lead-in + 2 s
    assert 0.2 < payload['distance_m'] < 0.4 and payload['stuck'] is False
    with open_bag(out) as bag:
        counts = {name: info.count for name, info in bag.topics.items()}
    assert counts == payload['messages']
    assert set(counts) == {'/cmd_vel', '/joint_states', '/odom', '/ground_truth/odom', '/battery/measured'}
    assert counts['/joint_states'] == 151  # 50 Hz over 3 s, both ends
    # bad input: one line, exit 2
    assert main([*argv, '-o', str(out)]) == 2  # exists
    assert main(['simulate', '--vehicle', 'test_robot_track', '--terrain', 'nowhere', '--route', 'patrol',
                 '-o', str(tmp_path / 'x.mcap')]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert err.count('\n') == 2 and 'Traceback' not in err
    classic = tmp_path / 'classic.mcap'
    assert main([*argv, '--contact', 'classic', '-o', str(classic), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['contact'] == 'classic'


def test_twin_refuses_unknown_contact_laws() -> None:
    with pytest.raises(InputError, match='classic, extended'):
        Twin(load_vehicle('test_robot_4wheel'), SAND_BIN, contact='lyasko')


def test_write_bag_needs_a_new_path(tmp_path: Path) -> None:
    trace = run_commands(Twin(load_vehicle('test_robot_track'), SAND_BIN), [Segment(0.1, 0.0, 0.2)])
    write_bag(trace, tmp_path / 'a.mcap')
    with pytest.raises(InputError, match='exists'):
        write_bag(trace, tmp_path / 'a.mcap')


# --------------------------------------------------------------------------- live coupling, kinematics


def test_live_coupling_moves_the_twin_with_the_amplifiers_motor_speeds() -> None:
    from skidsteer_power.twin.live import TwinCoupling, TwinLoad

    twin = Twin(load_vehicle('test_robot_4wheel'), SAND_BIN)
    coupling = TwinCoupling(twin)
    left, right = TwinLoad(coupling, 'left', 1), TwinLoad(coupling, 'right', -1)
    omega = 0.2 / twin.r * twin.G  # 0.2 m/s at the wheels [rad/s at the motor]
    for k in range(2000):  # 1 s of 0.5 ms amplifier steps; the right amplifier turns the other way
        t = 0.0005 * k
        load_left = left(omega, t)
        load_right = right(-omega, t + 0.0001)
    assert twin.t == pytest.approx(1.0, abs=0.01)
    assert 0.1 < twin.vel[0] < 0.2  # the robot drives forward, slower than its wheels (slip)
    friction = twin.powertrain.left.total.coulomb_Nm
    assert load_left > friction + 0.05  # the soil adds torque over the drivetrain's own friction
    assert load_right < -(friction + 0.05)  # in the right amplifier's sense
    pose, _twist, odom = coupling.snapshot()
    assert odom[0] > pose[0] > 0.05  # encoder odometry runs ahead of the slipping robot


@pytest.fixture(scope='module')
def turning_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp('kinematics')
    trace = run_commands(
        Twin(load_vehicle('test_robot_4wheel'), SAND_BIN), [Segment(0.0, 0.0, 1.0), Segment(0.2, 0.2, 5.0)]
    )
    return write_bag(trace, folder / 'turn.mcap'), folder


def test_validate_kinematics_predicts_from_the_motion(turning_bag: tuple[Path, Path]) -> None:
    from skidsteer_power.bag_io.reader import open_bag
    from skidsteer_power.validation.validate import ValidateOptions, validate

    bag_path, folder = turning_bag
    summaries = {}
    for kinematics in ('cmd', 'twist', 'odom', 'ground_truth'):
        options = ValidateOptions(
            'test_robot_4wheel', 'sand_bin', folder / kinematics, map_cache_dir=folder / 'maps', plots=False,
            kinematics=kinematics,
        )  # fmt: skip
        with open_bag(bag_path) as bag:
            summaries[kinematics] = validate(bag, options).as_json()
    cmd = summaries['cmd']
    assert cmd['kinematics'] == 'cmd' and cmd['motion_prediction']['kinematics'] == 'ground_truth'
    error = {k: abs(s['metrics']['energy_error_pct']) for k, s in summaries.items()}
    # the wheeled robot turns less than commanded: the true motion predicts its energy far better than
    # the command taken as the motion (twist), and so do the set points (cmd, issue 25)
    assert error['ground_truth'] < 0.5 * error['twist']
    assert error['cmd'] < 0.5 * error['twist']
    assert cmd['motion_prediction']['metrics']['energy_error_pct'] == pytest.approx(
        summaries['ground_truth']['metrics']['energy_error_pct']
    )
    assert summaries['odom']['motion_prediction'] is None


def test_validate_kinematics_without_odometry_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from skidsteer_power.bag_io.synthetic import write_drive_bag

    bag = tmp_path / 'no_odom.mcap'
    write_drive_bag(bag, [Segment(0.2, 0.0, 1.0)], odom_hz=None)
    argv = ['validate', str(bag), '--vehicle', 'test_robot_4wheel', '--terrain', 'sand_bin']
    code = main([*argv, '--report', str(tmp_path / 'r'), '--kinematics', 'ground_truth', '--no-plots'])
    assert code == 2
    assert 'ground_truth' in capsys.readouterr().err


def _rise_time(t: np.ndarray, speed: np.ndarray) -> float:
    """Time [s] at which the body speed first reaches 90 % of its final value (last sample)."""
    return float(t[np.argmax(speed >= 0.9 * speed[-1])])


def _live_step_response(configure: bool, seconds: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The live path without ptys: two simulated-amplifier motor models (des/simulator.MotorModel,
    0.5 ms explicit steps as SimulatedDes runs them) loaded by the twin through TwinCoupling."""
    from skidsteer_power.des.kinematics import RPM
    from skidsteer_power.des.simulator import MotorModel
    from skidsteer_power.twin.live import TwinCoupling, TwinLoad, configure_amplifier

    twin = Twin(load_vehicle('test_robot_4wheel'), SAND_BIN)
    coupling = TwinCoupling(twin)
    polarity = (1, -1)
    models = []
    for side, sign in zip(('left', 'right'), polarity, strict=True):
        model = MotorModel(load_torque=TwinLoad(coupling, side, sign))
        if configure:
            configure_amplifier(model, twin)
        models.append(model)
    twin.set_command(0.2, 0.0)  # only for the motor speed targets [rad/s] (the driver's mapping)
    targets = twin._target.tolist()
    step = MotorModel.STEP_S
    times, speeds, currents = [], [], []
    for k in range(round(seconds / step)):
        for model, sign, target in zip(models, polarity, targets, strict=True):
            model.step(
                step,
                k * step,
                powered=True,
                current_mode=False,
                speed_setpoint_rad_s=sign * target,
                current_setpoint_A=0.0,
                peak_current_A=twin.peak_A,
                acceleration_rad_s2=10.0 * 1000.0 * RPM,
            )
        if k % 20 == 0:
            times.append(twin.t)
            speeds.append(float(twin.vel[0]))
            currents.append(models[0].current_A)
    return np.array(times), np.array(speeds), np.array(currents)


def test_live_path_counts_the_body_inertia_once() -> None:
    """Issue 14: the simulated amplifiers integrate the motors, the twin the body; the body's mass
    must not also sit in the amplifiers' motor inertia. A 0.2 m/s step from rest on the 4-wheel
    robot: the motor current peaks while the drivetrain and the body accelerate; live and offline
    peaks agree within 5 % (live: 0.5 ms explicit motor steps, instantaneous current sampled every
    10 ms; offline: 2 ms semi-implicit steps, 10 ms means), and so do the body's 90 % rise times
    (10 %). With half the body's mass also in each motor (the old double count: m r^2 / (2 G^2)
    = 1.0e-3 kg m^2 besides Twin.J = 8.5e-5 kg m^2), the extra 1.0e-3 kg m^2 x the 1047 rad/s^2
    set-point ramp (10 rpm/ms) asks ~1 N m more of the motor: the peak is far higher."""
    offline = Twin(load_vehicle('test_robot_4wheel'), SAND_BIN)
    trace = run_commands(offline, [Segment(0.2, 0.0, 2.0)], rate_hz=100.0)
    reference_rise = _rise_time(trace.t, trace.twist[:, 0])
    reference_peak = float(trace.current_A[:, 0].max())
    t, speed, current = _live_step_response(configure=True)
    assert float(current.max()) == pytest.approx(reference_peak, rel=0.05)
    assert _rise_time(t, speed) == pytest.approx(reference_rise, rel=0.10)
    _t, _speed, doubled = _live_step_response(configure=False)
    assert float(doubled.max()) > 1.3 * reference_peak  # the test can tell the double count


def test_bulldozing_and_slip_sinkage_laws_by_hand() -> None:
    from skidsteer_power.twin.contact import (
        SOIL_UNIT_WEIGHT_N_M3,
        bulldozing_coefficients,
        slip_sinkage_factor,
    )

    # dry sand (Table 2.1): phi = 30 deg, c = 1000 Pa. X_c = 45 - 15 = 30 deg; cot X_c = sqrt(3);
    # D1 = sqrt(3) + tan(60 deg) = 2 sqrt(3); D2 = sqrt(3) + 3 / sqrt(3) = 2 sqrt(3) (Hegedus)
    a, b = bulldozing_coefficients(load_terrain('dry_sand'))
    assert a == pytest.approx(2 * np.sqrt(3) * 1000.0)
    assert b == pytest.approx(0.5 * 12.0 * SOIL_UNIT_WEIGHT_N_M3)
    # Lyasko: K_j = (1 + i) / (1 - 0.5 i): 2 at i = 0.5, 4 at i = 1; no excavation when braking
    assert slip_sinkage_factor(np.array([0.0, 0.5, 1.0, -0.3])) == pytest.approx([1.0, 2.0, 4.0, 1.0])


def test_drive_until_empty_refuses_a_segment_that_is_not_whole_pieces() -> None:
    """0.1 s would round to no 0.2 s piece at all, 0.3 s to 0.4 s: both said, not driven."""
    twin = Twin(load_vehicle('test_robot_track'), SAND_BIN)
    for seconds in (0.1, 0.3):
        with pytest.raises(InputError, match='whole number'):
            drive_until_empty(twin, [Segment(0.2, 0.0, 1.0), Segment(0.2, 0.0, seconds)])
    assert twin.t == 0.0  # refused before driving


def test_live_twin_stands_still_with_the_amplifiers_off() -> None:
    """Issue 37 item 9: the simulated robot drifted at rest (``run --simulate``, no command: 0.19 m and
    0.045 rad in 25 s, up to 0.58 W measured). The unpowered motor model asked its load at 1 rad/s
    (the friction that holds a coasting motor) and the live twin moved with that speed. Two motor
    models as SimulatedDes runs them (0.5 ms steps, amplifiers off), loaded by the twin: nothing
    pushes a robot at rest, so its pose, motor speeds and terrain work stay exactly 0."""
    from skidsteer_power.des.kinematics import RPM
    from skidsteer_power.des.simulator import MotorModel
    from skidsteer_power.twin.live import TwinCoupling, TwinLoad, configure_amplifier

    twin = Twin(load_vehicle('test_robot_track'), SAND_BIN)
    coupling = TwinCoupling(twin)
    models = []
    for side, sign in (('left', 1), ('right', -1)):
        model = MotorModel(load_torque=TwinLoad(coupling, side, sign))
        configure_amplifier(model, twin)
        models.append(model)
    step = MotorModel.STEP_S
    for k in range(round(2.0 / step)):
        for model in models:
            model.step(
                step, k * step, powered=False, current_mode=False, speed_setpoint_rad_s=0.0,
                current_setpoint_A=0.0, peak_current_A=twin.peak_A, acceleration_rad_s2=1e4 * RPM,
            )  # fmt: skip
    assert twin.t > 1.9  # the twin did step along
    assert np.all(twin.pose == 0.0) and np.all(twin.vel == 0.0), (twin.pose, twin.vel)
    assert [m.omega_rad_s for m in models] == [0.0, 0.0] and twin.energy.terrain_J == 0.0
    # what holds the coasting motor is the side's internal resistance at 1 rad/s (eq. 7.1: b w + c)
    r = twin.powertrain.resistance('left').total
    assert models[0].holding_torque(0.0) == pytest.approx(
        r.viscous_Nm_s + r.coulomb_Nm * math.tanh(1.0)
    )  # w_s = 1 rad/s


def test_live_twin_holds_still_at_zero_set_points_after_a_turn() -> None:
    """Issue 37 item 9, powered: after a turn at zero set points the live twin yawed on (2.320 ->
    2.437 rad in 5 s, issue; 0.32 rad in 17 s measured here with run --simulate) drawing ~8 W: the
    explicit motor step chattered at zero speed (c dt / (J w_s) = 0.77 N m x 0.5 ms / (1.4e-4 kg m^2
    x 1 rad/s) = 2.7 > 2) with a non-zero mean. With the friction slope implicit the motors settle and
    the stored shear is held: the last 3 s move the heading by less than 1 mrad (before: 92 mrad)."""
    from skidsteer_power.des.kinematics import RPM
    from skidsteer_power.des.simulator import MotorModel
    from skidsteer_power.twin.live import TwinCoupling, TwinLoad, configure_amplifier

    twin = Twin(load_vehicle('test_robot_track'), load_terrain('dry_sand'))
    coupling = TwinCoupling(twin)
    polarity, models = (1, -1), []
    for side, sign in zip(('left', 'right'), polarity, strict=True):
        model = MotorModel(load_torque=TwinLoad(coupling, side, sign))
        configure_amplifier(model, twin)
        models.append(model)
    twin.set_command(0.2, 0.5)  # only for the motor speed targets [rad/s] (the driver's mapping)
    turning = twin._target.tolist()
    step, yaw_at = MotorModel.STEP_S, {}
    for k in range(round(7.0 / step)):
        targets = turning if k * step < 2.0 else [0.0, 0.0]
        for model, sign, target in zip(models, polarity, targets, strict=True):
            model.step(
                step, k * step, powered=True, current_mode=False, speed_setpoint_rad_s=sign * target,
                current_setpoint_A=0.0, peak_current_A=twin.peak_A, acceleration_rad_s2=1e4 * RPM,
            )  # fmt: skip
        if k in (round(4.0 / step), round(7.0 / step) - 1):
            yaw_at[k] = float(twin.pose[2])
    early, late = yaw_at.values()
    assert early > 0.4  # it did turn (0.5 rad/s commanded for 2 s)
    assert abs(late - early) < 1e-3, (early, late)
    assert max(abs(m.omega_rad_s) for m in models) < 0.05
