"""FESS driven by wheel speed set points (skidsteer_power.models.setpoint / predict, issue 25).

References: the round trip compares with FESS's own forward solve (test_fess_track.py checks that
against the text); symmetry follows from the vehicle's left-right mirror symmetry (CG on the
centreline, module doc of fess.py); the current limit is the DES 70/10's 10 A (Appendix A:
I_cont 10 A); the Appendix D radii are the real robot's (dissertation lines 2131-2246).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from skidsteer_power.cli.main import main
from skidsteer_power.drive import controller_for_vehicle
from skidsteer_power.models import appendix_d, fess
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.models.predict import JSON_KEYS, CommandPredictor
from skidsteer_power.models.setpoint import SetpointSolver, command_setpoints
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.real_robot import APPENDIX_D_RADII
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain
from skidsteer_power.vehicle import load_vehicle

VEHICLES = ('test_robot_track', 'test_robot_6wheel')


@pytest.fixture(scope='module')
def sand() -> Terrain:
    return load_terrain('sand_bin')


def _solver(name: str, sand: Terrain) -> SetpointSolver:
    return SetpointSolver(FessSolver(load_vehicle(name), sand))


def test_setpoints_are_the_drivers_kinematics() -> None:
    # hand calculation: V 0.1 m/s, w 0.2 rad/s, B 0.426 m, r 0.1 m: (0.1 -+ 0.0426) / 0.1
    sp, clamped = command_setpoints([0.1], [0.2], tread_m=0.426, drive_radius_m=0.1, max_axle_rad_s=30.0)
    np.testing.assert_allclose(sp[0], [0.574, 1.426])
    assert not clamped[0]
    # 5 m/s straight asks 50 rad/s: both sides scaled to the 30 rad/s ceiling, curvature kept
    sp, clamped = command_setpoints(
        [5.0, 5.0], [0.0, 1.0], tread_m=0.426, drive_radius_m=0.1, max_axle_rad_s=30.0
    )
    assert clamped.all() and np.max(np.abs(sp)) == pytest.approx(30.0)
    assert (sp[1, 1] - sp[1, 0]) / sp[1].mean() == pytest.approx(2 * 0.426 / 2 * 1.0 / 5.0)


@pytest.mark.parametrize('name', VEHICLES)
def test_spin_is_symmetric_both_ways(name: str, sand: Terrain) -> None:
    sol = _solver(name, sand).solve(np.array([[-2.0, 2.0], [2.0, -2.0]]))
    assert not sol.limited.any()
    np.testing.assert_allclose(sol.speed, 0.0, atol=1e-9)  # spinning in place
    assert sol.yaw_rate[0] > 0 and sol.yaw_rate[1] == pytest.approx(-sol.yaw_rate[0], rel=1e-9)
    for k in range(2):  # equal and opposite torques on the two sides
        assert sol.torque[k, 0] == pytest.approx(-sol.torque[k, 1], rel=1e-6)
    np.testing.assert_allclose(sol.torque[1], sol.torque[0][::-1], rtol=1e-6)


@pytest.mark.parametrize('name', VEHICLES)
def test_round_trip_through_the_forward_solve(name: str, sand: Terrain) -> None:
    fess = FessSolver(load_vehicle(name), sand)
    v = np.array([0.1, 0.3, -0.2, 0.05, 0.0])
    w = np.array([0.1, -0.5, 0.3, 0.0, 0.3])
    forward = fess.solve_twist(v, w, tol=1e-5)
    assert forward.converged.all()
    back = SetpointSolver(fess).solve(forward.omega, tol=1e-5)
    assert not back.limited.any()
    np.testing.assert_allclose(back.speed, v, atol=1e-6)
    np.testing.assert_allclose(back.yaw_rate, w, atol=1e-6)
    np.testing.assert_allclose(back.torque, forward.torque, atol=1e-4)


@pytest.mark.parametrize('name', VEHICLES)
def test_continuous_across_spin_straight_and_reverse(name: str, sand: Terrain) -> None:
    solver = _solver(name, sand)
    # the mean set point swept through 0 at a fixed difference (spin -> forward, reverse -> spin)
    mean = np.linspace(-0.2, 0.2, 41)
    sol = solver.solve(np.column_stack([mean - 1.0, mean + 1.0]))
    assert not sol.limited.any()
    for series in (sol.speed, sol.yaw_rate, sol.torque[:, 0], sol.torque[:, 1]):
        jumps = np.abs(np.diff(series))
        assert jumps.max() < 5 * np.median(jumps) + 1e-9  # no step larger than the sweep's own slope
    assert np.all(np.diff(sol.speed) > 0)  # V grows with the mean set point, through 0
    # the difference swept through 0 at a fixed mean (left turn -> straight -> right turn)
    diff = np.linspace(-0.1, 0.1, 21)
    sol = solver.solve(np.column_stack([1.0 - diff, 1.0 + diff]))
    assert not sol.limited.any() and np.all(np.diff(sol.yaw_rate) > 0)
    for series in (sol.speed, sol.torque[:, 0], sol.torque[:, 1]):
        jumps = np.abs(np.diff(series))
        assert jumps.max() < 5 * np.median(jumps) + 1e-6


def test_reverse_is_the_mirror_image(sand: Terrain) -> None:
    sol = _solver('test_robot_6wheel', sand).solve(np.array([[0.6, 1.4], [-1.4, -0.6]]))
    assert sol.speed[1] == pytest.approx(-sol.speed[0], rel=1e-9)
    assert sol.yaw_rate[1] == pytest.approx(sol.yaw_rate[0], rel=1e-9)  # same circle, driven backwards
    np.testing.assert_allclose(sol.torque[1], -sol.torque[0][::-1], rtol=1e-6)


def test_current_limit_is_never_exceeded(sand: Terrain) -> None:
    vehicle = load_vehicle('test_robot_6wheel')
    assert Powertrain.for_vehicle(vehicle).current_limit_A == 10.0  # config/powertrains/test_robot.yaml
    weak = Powertrain.from_config({'preset': 'test_robot', 'current_limit_A': 2.0}, 'wheel')
    pred = CommandPredictor(vehicle, sand, weak).predict([0.2, 0.2, 0.0], [0.0, 0.3, 0.0])
    assert np.all(np.abs(pred.current) <= 2.0 + 1e-12)
    assert pred.limited[:2].all() and all('current limit' in r for r in pred.reason[:2])
    assert not pred.limited[2]  # at rest nothing is drawn
    full = CommandPredictor(vehicle, sand).predict([0.2, 0.2], [0.0, 0.3])
    assert np.all(np.abs(full.current) > 2.0) and not full.limited.any()


def test_no_motor_past_its_no_load_speed(sand: Terrain) -> None:
    vehicle = load_vehicle('test_robot_track')
    unlimited = controller_for_vehicle(vehicle).with_values(
        max_speed_m_s=math.inf, max_yaw_rate_rad_s=math.inf
    )
    pred = CommandPredictor(vehicle, sand, controller=unlimited).predict([5.0], [1.0])
    motor_rad_s = np.abs(pred.setpoint) * 12.0  # 12:1 reduction (ch. 7.1.1)
    # EC-45: 84 rpm/V (Appendix B) at the 12S pack's full 50.4 V (config/batteries/test_robot.yaml)
    assert motor_rad_s.max() == pytest.approx(84.0 * 50.4 * 2 * np.pi / 60)
    assert pred.clamped[0]


@pytest.mark.parametrize('form', [['--direct'], []])
def test_predict_cli_keys_and_bad_input(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, form: list[str]
) -> None:
    monkeypatch.setenv('SKIDSTEER_POWER_CACHE', str(tmp_path))  # the map form builds its map here
    argv = ['predict', '--vehicle', 'test_robot_track', '--terrain', 'sand_bin', '--speed', '0.1', *form]
    assert main([*argv, '--yaw-rate', '0.2', '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert tuple(out) == JSON_KEYS
    assert out['setpoint_left_rad_s'] == pytest.approx(0.574) and out['limited'] is False
    assert 0 < out['yaw_rate_rad_s'] < 0.2  # the track skids: less yaw than commanded
    with pytest.raises(SystemExit) as stop:
        main([*argv, '--yaw-rate', 'nan'])
    assert stop.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_appendix_d_subset_beats_the_commanded_radius() -> None:
    # a bounded subset (one cell per vehicle and speed); the full 14 cells: benchmarks/bench_fess.py
    cells = (APPENDIX_D_RADII[4], APPENDIX_D_RADII[8], APPENDIX_D_RADII[10])
    rows = appendix_d.check(cells)
    for row in rows:
        assert not row.limited
        assert row.radius_m > row.cell.commanded_radius_m  # wider than commanded, as measured
        assert row.error < row.commanded_error
    # the track's K_x / K was fitted to its 0.1 m/s cells (rows[0], measured +2.7 %); 0.2 m/s is a
    # check (measured -14.2 %; issue 25's goal for every cell: <= 30 %)
    assert rows[0].error < 0.05
    assert rows[1].error < 0.20
    assert rows[2].error < 0.15  # six wheels, 0.2 m/s, 0.2 rad/s: measured 1.92 m


def test_track_belt_law_widens_the_turn_from_set_points_but_not_the_torque_at_a_motion(sand: Terrain) -> None:
    """K_x = 4 K (a compliant belt in series with the soil) lets each track slip more for the same
    thrust: from set points the turn widens (Appendix D: the real track turned on 1.44 m at 1 m
    commanded), while at a given motion the torques stay those of Wong's inextensible belt, the
    model ch. 7.3.4 found "validated by the experiments" at the measured motion."""
    track = load_vehicle('test_robot_track')
    belt = dataclasses.replace(
        track, gear=dataclasses.replace(track.tracks(), track_longitudinal_shear_ratio=1.0)
    )  # Wong's
    wide = CommandPredictor(track, sand).predict(0.1, 0.1).turn_radius[0]
    tight = CommandPredictor(belt, sand).predict(0.1, 0.1).turn_radius[0]
    assert wide > 1.25 * tight  # measured 1.48 against 1.11 m (R_real 1.44 m)
    motion = (0.1, 1.44)  # the real robot's V and R in that cell (Appendix D)
    with_law, without = fess.solve(track, sand, *motion), fess.solve(belt, sand, *motion)
    assert float(with_law.torque_outer_Nm) == pytest.approx(float(without.torque_outer_Nm), rel=0.02)
    assert float(with_law.torque_inner_Nm) == pytest.approx(float(without.torque_inner_Nm), rel=0.02)
    assert float(with_law.slip_outer) > 2.0 * float(without.slip_outer)  # the belt's compliance slips


def test_a_routes_commands_give_back_its_motion(sand: Terrain) -> None:
    """Mission energy reports, per route segment, the set points that produce its (V, R) and the
    command the driver turns into them; predicting from that command must give the route's motion
    back (reference: the route itself; the mission's set points are FESS's side speeds there)."""
    from skidsteer_power.missions.energy import run_mission
    from skidsteer_power.missions.routes import patrol

    vehicle = load_vehicle('test_robot_6wheel')
    result = run_mission(vehicle, sand, patrol(0.2), source='direct')
    commands = result.commands()
    turn = next(c for c in commands if math.isfinite(c['turn_radius_m']))
    assert turn['speed_cmd_m_s'] > turn['speed_m_s']  # six wheels slip: ask for more than you get
    pred = CommandPredictor(vehicle, sand).predict(turn['speed_cmd_m_s'], turn['yaw_rate_cmd_rad_s'])
    assert pred.speed[0] == pytest.approx(turn['speed_m_s'], abs=1e-5)
    assert pred.turn_radius[0] == pytest.approx(turn['turn_radius_m'], rel=1e-4)
