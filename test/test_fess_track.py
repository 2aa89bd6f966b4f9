"""FESS for tracks (chapter 6): kinematics of eq. 6.6, straight-running limits, symmetry, failure
reporting, and agreement with this project's Wong model (section 3.3) on the 8 x 16 grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import fess, wong_track
from skidsteer_power.models import solve as solve_any
from skidsteer_power.terramechanics.terrain import PRESETS
from skidsteer_power.terramechanics.track import compaction_resistance, tractive_effort
from skidsteer_power.vehicle import load_vehicle

TRACK = load_vehicle('chapter3_track')  # Table 3.3
# the grid of Figures 3.6-3.10 / 6.6-6.8: 8 speeds x 16 radii (values: section 3.3.1, Figure 3.15)
GRID_V = np.linspace(0.2, 1.5, 8)[:, None]
GRID_R = np.geomspace(1.0, 500.0, 16)[None, :]


def test_eq_6_6_displacement_matches_the_printed_rotation_with_yaw_rate() -> None:
    """Element k of the outer track: ||(l/2 - s0 - k l/n, -R - B/2) - Rot (l/2 - s0, -R - B/2)||
    with the rotation angle k w_z l / (n omega r) (eq. 6.6, phi read as the yaw rate)."""
    solver = fess.FessSolver(TRACK, PRESETS['dry_sand'], n=10)
    v, yaw = 0.5, 0.25  # R = 2 m, left turn: the outer track is the right one
    prob = solver.problem(np.array([v]), np.array([yaw]))
    s0, w_left, w_right = 0.1, 4.6, 5.6
    jx, jy, _ = fess.element_displacement(prob, np.array([[[s0, w_left, w_right]]]))
    length, b_half, r, big_r, n = 0.7, 0.2, 0.1, 2.0, 10
    for k in (0, 3, 10):
        ang = k * yaw * length / (n * w_right * r)
        front = np.array([length / 2 - s0, -big_r - b_half])
        now = np.array([length / 2 - s0 - k * length / n, -big_r - b_half])
        rot = np.array([[math.cos(ang), math.sin(ang)], [-math.sin(ang), math.cos(ang)]])
        expected = now - rot @ front
        assert jx[0, 0, 1, 0, k] == pytest.approx(expected[0], abs=1e-12)
        assert jy[0, 0, 1, 0, k] == pytest.approx(expected[1], abs=1e-12)


def test_straight_running_thrust_equals_compaction_resistance_and_eq_2_17() -> None:
    """Straight: each track's thrust balances its compaction resistance (eq. 2.10, eq. 3.18 with
    R = inf), and FESS's thrust at the solved slip equals the closed form of eq. 2.17."""
    terrain = PRESETS['sandy_loam']
    # R_c is only 0.016 N here: tighten the 1e-3 N stopping rule of section 3.3.1 accordingly
    sol = fess.FessSolver(TRACK, terrain, n=400).solve_twist(0.8, 0.0, tol=1e-9)
    half_weight = TRACK.weight_N / 2
    rc = float(compaction_resistance(terrain, half_weight, 0.07, 0.7))
    assert sol.converged[0]
    assert sol.thrust[0] == pytest.approx([rc, rc], rel=1e-3)
    assert sol.torque[0] == pytest.approx([0.1 * rc, 0.1 * rc], rel=1e-3)  # T = F r, r = 0.1 m
    closed = float(tractive_effort(terrain, half_weight, 0.07, 0.7, sol.slip[0, 0]))
    assert sol.thrust[0, 0] == pytest.approx(closed, rel=1e-3)  # trapezoid, n = 400
    assert sol.s0[0] == pytest.approx(0.7 / 6, abs=0.01)  # R -> inf limit: lateral forces cancel at l/6


def test_mirror_symmetries_left_right_and_reverse() -> None:
    solver = fess.FessSolver(TRACK, PRESETS['clay'], n=20)
    sol = solver.solve_twist([0.6, 0.6, -0.6], [0.4, -0.4, 0.4])
    left, right, back = (sol.torque[i] for i in range(3))
    assert right == pytest.approx(left[::-1], rel=1e-6)  # (V, -w) is the mirror image of (V, w)
    # reverse: (-V, w) = (V, w) turned 180 degrees: sides swap, torque and omega change sign
    assert back == pytest.approx(-left[::-1], rel=1e-6)
    assert sol.omega[2] == pytest.approx(-sol.omega[0][::-1], rel=1e-6)
    assert sol.power[2] == pytest.approx(sol.power[0][::-1], rel=1e-6)


def test_batched_equals_single_point_solves() -> None:
    solver = fess.FessSolver(TRACK, PRESETS['dry_sand'], n=20)
    v = np.array([0.3, 1.0, 1.4])
    w = np.array([0.3, -0.05, 0.0])
    batch = solver.solve_twist(v, w)
    for k in range(3):
        one = solver.solve_twist(v[k], w[k])
        assert one.torque[0] == pytest.approx(batch.torque[k], rel=1e-5, abs=1e-6)


def test_solution_satisfies_equilibrium_3_18() -> None:
    solver = fess.FessSolver(TRACK, PRESETS['sandy_loam'], n=30)
    sol = solver.solve_twist([0.5, 1.2], [0.5, -0.1])
    prob = solver.problem(np.array([0.5, 1.2]), np.array([0.5, -0.1]))
    res = fess.residual(prob, sol.state[:, None, :])[:, 0]
    assert np.all(np.abs(res) < fess.FORCE_TOL_N)


def test_rest_gives_zero_and_spin_in_place_is_antisymmetric() -> None:
    sol = fess.FessSolver(TRACK, PRESETS['dry_sand'], n=20).solve_twist([0.0, 0.0], [0.0, 1.0])
    assert sol.converged.all()
    assert sol.torque[0] == pytest.approx([0.0, 0.0])
    assert sol.omega[1, 0] == pytest.approx(-sol.omega[1, 1], rel=1e-6)  # sides turn opposite ways
    assert sol.torque[1, 0] == pytest.approx(-sol.torque[1, 1], abs=1e-4)


def test_elements_study_converges() -> None:
    """Trapezoidal sums over n elements: torque changes < 1 % from n = 20 to n = 160."""
    v, r = np.array([0.5, 1.0]), np.array([1.5, 20.0])
    coarse = fess.solve(TRACK, PRESETS['clay'], v, r, n=20)
    fine = fess.solve(TRACK, PRESETS['clay'], v, r, n=160)
    assert coarse.torque_outer_Nm == pytest.approx(fine.torque_outer_Nm, rel=0.01)


@pytest.mark.parametrize('terrain_name', ['dry_sand', 'sandy_loam', 'clay'])
def test_torque_within_3_percent_of_wong_on_the_8x16_grid(terrain_name: str) -> None:
    """Section 6.4 / Figures 6.6-6.8: FESS matches Wong's track model. Tolerance 3 % of the larger
    side torque at each point (the inner torque crosses zero at large R, where a relative error of
    that side alone is meaningless)."""
    terrain = PRESETS[terrain_name]
    ref = wong_track.solve(TRACK, terrain, GRID_V, GRID_R)
    got = fess.solve(TRACK, terrain, GRID_V, GRID_R)
    assert ref.converged.all() and got.converged.all()
    scale = np.maximum(np.abs(ref.torque_outer_Nm), np.abs(ref.torque_inner_Nm))
    assert np.max(np.abs(got.torque_outer_Nm - ref.torque_outer_Nm) / scale) < 0.03
    assert np.max(np.abs(got.torque_inner_Nm - ref.torque_inner_Nm) / scale) < 0.03
    assert got.s0_m == pytest.approx(ref.s0_m, rel=0.01)


def test_failures_are_reported_not_dropped() -> None:
    # 3 m/s around a 0.5 m radius on dry sand: 18 m/s^2, no steady state (tips / outruns traction)
    state = fess.solve(TRACK, PRESETS['dry_sand'], [0.5, 3.0], [2.0, 0.5])
    assert state.converged.tolist() == [True, False]
    assert state.torque_outer_Nm.shape == (2,)
    with pytest.raises(ConvergenceError, match=r'V = 3 m/s, R = 0\.5 m'):
        fess.solve(TRACK, PRESETS['dry_sand'], 3.0, 0.5)


def test_dispatch_through_models_solve_and_bad_input() -> None:
    state = solve_any(TRACK, PRESETS['clay'], 0.5, -3.0, model='fess')
    assert state.outer_is_left and state.converged
    assert state.side('torque', 'left') == pytest.approx(state.torque_outer_Nm)
    with pytest.raises(InputError, match='elements'):
        fess.FessSolver(TRACK, PRESETS['clay'], n=1)
    with pytest.raises(InputError):
        fess.solve(TRACK, PRESETS['clay'], 0.5, 0.0)
    with pytest.raises(InputError):
        fess.solve(TRACK, PRESETS['clay'], float('nan'), 2.0)
    with pytest.raises(InputError, match='unknown FESS option'):
        fess.solve(TRACK, PRESETS['clay'], 0.5, 2.0, resolution=(3, 3))


@pytest.mark.parametrize('vehicle_name', ['chapter3_track', 'test_robot_6wheel'])
def test_lean_point_solver_equals_the_batched_solver(vehicle_name: str) -> None:
    solver = fess.FessSolver(load_vehicle(vehicle_name), PRESETS['sandy_loam'], n=20)
    v = [0.5, 0.5, 0.0, -0.7, 1.2, 0.0]
    w = [0.25, 0.0, 1.0, 0.3, -0.05, 0.0]
    # both stop at |residual| < tol; a tight tol makes their different iterate paths meet
    batch = solver.solve_twist(v, w, tol=1e-8)
    for k in range(len(v)):
        one = solver.solve_point(v[k], w[k], tol=1e-8)
        assert one.converged == bool(batch.converged[k])
        assert one.torque == pytest.approx(batch.torque[k], rel=1e-7, abs=1e-9)
        assert one.omega == pytest.approx(batch.omega[k], rel=1e-7, abs=1e-9)
        assert one.power == pytest.approx(batch.power[k], rel=1e-6, abs=1e-9)
    warm = solver.solve_point(0.52, 0.26, x0=solver.solve_point(0.5, 0.25).state, tol=1e-8)
    assert warm.torque == pytest.approx(solver.solve_twist(0.52, 0.26, tol=1e-8).torque[0], rel=1e-6)
