"""Every steady-state solver against one reference, and properties of the solvers (issue 38).

Reference (straight running, hand calculation): with no drawbar pull, sum F_x = 0 (eq. 3.19) makes
each track's thrust equal its compaction resistance, R_c = b (n + 1)^-1 (k_c / b + k_phi)^(-1/n)
(W / (b l))^((n + 1) / n) (eq. 2.10, :func:`~skidsteer_power.terramechanics.track.compaction_resistance`
at W = half the weight), so each sprocket's torque is r R_c. Every model of
:data:`skidsteer_power.models.MODELS`, FESS's one-point path and the set-point solve must give it
to the stopping rule of section 3.3.1 (|each equation| < 0.001 N) times r.

Properties (hypothesis), on the chapter 7 test robot: the mirror image of a left turn is the right
turn (sides swapped); reverse driving is the fore-aft mirror image (module doc of fess.py: exact by
construction); a small change of the command changes the torques a little (away from the pivot
band: |R| >= 1 m); and the set-point map answers within its stated tolerance of the direct solve
(module doc of maps/setpoint_map.py: 1 % battery power, 5 mm/s speed, where neither flags the
command limited).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skidsteer_power.maps.setpoint_map import SetpointMap
from skidsteer_power.models import MODELS, solve
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.models.setpoint import SetpointSolver
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.terramechanics.track import compaction_resistance
from skidsteer_power.vehicle import load_vehicle

STOP_N = 1e-3  # eq. 3.19 stopping rule (section 3.3.1) [N]
SOLVERS = (*MODELS, 'fess-point', 'fess-setpoint')
SPEED = 0.5  # [m/s]

PROPERTY = settings(max_examples=25, deadline=None, derandomize=True)
speeds = st.floats(0.05, 0.8)
radii = st.floats(1.0, 30.0).flatmap(lambda r: st.sampled_from([r, -r]))


@functools.cache
def _fess(vehicle: str = 'test_robot_track', terrain: str = 'dry_sand') -> FessSolver:
    return FessSolver(load_vehicle(vehicle), load_terrain(terrain))


def _sprocket_torques(name: str) -> tuple[float, float]:
    """(outer, inner) sprocket torque [N m] of chapter 3's track on dry sand, straight at SPEED."""
    vehicle, terrain = load_vehicle('chapter3_track'), load_terrain('dry_sand')
    if name in MODELS:
        state = solve(vehicle, terrain, SPEED, np.inf, name)
        return float(state.torque_outer_Nm), float(state.torque_inner_Nm)
    solver = FessSolver(vehicle, terrain)
    if name == 'fess-point':
        point = solver.solve_point(SPEED, 0.0)
        assert point.converged
        return float(point.torque[0]), float(point.torque[1])
    omega = solver.solve_twist(SPEED, 0.0).omega  # the set points straight running at SPEED needs
    sol = SetpointSolver(solver).solve(omega)
    assert sol.speed[0] == pytest.approx(SPEED, abs=1e-6) and not sol.limited[0]
    return float(sol.torque[0, 0]), float(sol.torque[0, 1])


@pytest.mark.parametrize('name', SOLVERS)
def test_every_solver_runs_straight_at_the_compaction_resistance(name: str) -> None:
    vehicle, terrain = load_vehicle('chapter3_track'), load_terrain('dry_sand')
    tracks = vehicle.tracks()
    resistance = float(
        compaction_resistance(terrain, vehicle.weight_N / 2, tracks.track_width_m, tracks.track_length_m)
    )
    reference = vehicle.drive_radius_m * resistance  # 0.1 m x 0.345 N = 0.0345 N m (eq. 2.10)
    assert reference == pytest.approx(0.0345, rel=0.01)
    outer, inner = _sprocket_torques(name)
    assert outer == pytest.approx(reference, abs=STOP_N * vehicle.drive_radius_m)
    assert inner == pytest.approx(reference, abs=STOP_N * vehicle.drive_radius_m)


@PROPERTY
@given(speed=speeds, radius=radii)
def test_a_right_turn_is_the_mirror_image_of_the_left_turn(speed: float, radius: float) -> None:
    solver = _fess()
    w = speed / radius
    left, right = solver.solve_twist(speed, w), solver.solve_twist(speed, -w)
    assert left.converged[0] and right.converged[0]
    tol = STOP_N * solver.vehicle.drive_radius_m  # both stop within the rule, not at the same bits
    np.testing.assert_allclose(left.torque[0], right.torque[0, ::-1], rtol=1e-6, atol=tol)
    np.testing.assert_allclose(left.omega[0], right.omega[0, ::-1], rtol=1e-6)
    assert left.s0[0] == pytest.approx(right.s0[0], rel=1e-6, abs=1e-9)
    one, other = solver.solve_point(speed, w), solver.solve_point(speed, -w)
    np.testing.assert_allclose(one.torque, other.torque[::-1], rtol=1e-6, atol=tol)


@PROPERTY
@given(speed=speeds, radius=radii)
def test_reverse_driving_is_the_fore_aft_mirror_image(speed: float, radius: float) -> None:
    solver = _fess()
    w = speed / radius
    ahead, back = solver.solve_twist(speed, -w), solver.solve_twist(-speed, w)
    np.testing.assert_array_equal(back.torque, -ahead.torque)  # exact: the same solve, mirrored
    np.testing.assert_array_equal(back.omega, -ahead.omega)
    np.testing.assert_array_equal(back.s0, -ahead.s0)
    np.testing.assert_array_equal(back.sinkage, ahead.sinkage)
    point_ahead, point_back = solver.solve_point(speed, -w), solver.solve_point(-speed, w)
    np.testing.assert_array_equal(point_back.torque, -point_ahead.torque)
    setpoints = np.array([ahead.omega[0]])
    sp = SetpointSolver(solver)
    fwd, rev = sp.solve(setpoints), sp.solve(-setpoints)
    np.testing.assert_array_equal(rev.torque, -fwd.torque)
    np.testing.assert_array_equal(rev.speed, -fwd.speed)


@PROPERTY
@given(speed=speeds, radius=radii, step=st.floats(-1e-3, 1e-3))
def test_a_small_change_of_the_command_changes_the_torque_a_little(
    speed: float, radius: float, step: float
) -> None:
    solver = _fess()
    w = speed / radius
    base = solver.solve_twist(speed, w)
    moved = solver.solve_twist(speed * (1 + step), w * (1 + step))
    assert base.converged[0] and moved.converged[0]
    scale = np.max(np.abs(base.torque))
    # torque grows about linearly with the command here (measured: 2 x the relative step at most)
    bound = 10 * abs(step) * scale + STOP_N * solver.vehicle.drive_radius_m
    assert np.max(np.abs(moved.torque - base.torque)) <= bound


@functools.cache
def _setpoint_map() -> SetpointMap:
    return SetpointMap.build(load_vehicle('test_robot_track'), load_terrain('sand_bin'))


@PROPERTY
@given(v=st.floats(-1.0, 1.0), w=st.floats(-1.0, 1.0))
def test_the_set_point_map_answers_within_its_tolerance_of_the_direct_solve(v: float, w: float) -> None:
    smap = _setpoint_map()
    vehicle = smap.predictor.vehicle
    speed, yaw = v * vehicle.max_speed_m_s, w * vehicle.max_yaw_rate_rad_s
    query = smap.query(speed, yaw)
    direct = smap.predictor.predict(speed, yaw)
    if query.limited or direct.limited[0]:
        return  # the tolerance is stated for commands neither flags
    power = float(direct.battery_power[0])
    assert abs(query.battery_power_W - power) <= 0.01 * max(abs(power), 1.0)
    assert abs(query.speed_m_s - float(direct.speed[0])) <= 0.005
