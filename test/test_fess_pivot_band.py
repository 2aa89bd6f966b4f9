"""The pivot band of the set-point solve (issues 25, 36): tight turns with the inner side's set point
near zero or slightly reversed. There eq. 6.6's chord has roots, but their torque jumps between
neighbouring set points (an inner element turns past half a revolution in the contact); the band is
solved with FESS's pivot law instead (fess.pivot_blend: the chord up to half a revolution of an
element, then its slip path), continuous with the chord at the band's edges (docs/PREDICTION.md,
"The pivot band").

References: the equilibrium (eq. 3.19) under each law solved by an independent solver (scipy's
least_squares from the best node of a residual scan), not by the project's Newton; a hand
computation of the element turn (eqs. 6.3, 6.5) and of the blend; the twin (skidsteer_power.twin,
its own contact model, no FESS) at the same set points; the torque change of the same step outside
the band.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from skidsteer_power.commands import Segment
from skidsteer_power.models.fess import FessSolver, residual
from skidsteer_power.models.fess_problem import (
    PIVOT_BLEND_REV,
    PIVOT_REST_SPEED_M_S,
    pivot_blend,
    rolling_direction,
)
from skidsteer_power.models.setpoint import SetpointSolver
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.twin.model import Twin
from skidsteer_power.twin.sensors import run_commands
from skidsteer_power.vehicle import load_vehicle

RIGHT = 2.848  # [rad/s] outer (right) axle set point of test_robot_track, a node of its set-point map


@pytest.fixture(scope='module')
def solver() -> SetpointSolver:
    return SetpointSolver(FessSolver(load_vehicle('test_robot_track'), load_terrain('sand_bin')))


def _root(
    solver: SetpointSolver, left: float, start: np.ndarray | None = None
) -> tuple[np.ndarray, float, np.ndarray]:
    """(s0, V, w_z), the largest |residual| [N, N m] and the axle torques [N m] of FESS at the set
    points (left, RIGHT), found by least squares from ``start`` (continuation) or else from the best
    node of a residual scan."""
    sp = np.array([[left, RIGHT]])
    fn = solver._residual(sp, np.array([False]))
    veh = solver.fess.vehicle
    length, weight = solver._length_scale(), veh.mass_kg * 9.81
    scale = np.array([weight, weight, weight * length])
    v_top = RIGHT * solver.radius
    w_top = 2 * v_top / solver.tread
    grid = np.meshgrid(
        np.linspace(-0.45 * length, 0.45 * length, 15),
        np.linspace(0.0, v_top, 21),
        np.linspace(0.0, 1.2 * w_top, 21),
        indexing='ij',
    )
    nodes = np.stack(grid).reshape(3, -1).T
    norms = np.max(np.abs(fn(nodes, np.zeros(len(nodes), int))) / scale, axis=1)
    best = nodes[np.argmin(np.where(np.isfinite(norms), norms, np.inf))] if start is None else start
    fit = least_squares(
        lambda x: fn(x[None], np.zeros(1, int))[0] / scale,
        best,
        x_scale=[0.1 * length, 0.1 * v_top, 0.1 * w_top],
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        max_nfev=300,
    )
    out, _ = solver._fess_outputs(fit.x[None], sp, np.array([True]), np.array([False]))
    return fit.x, float(np.max(np.abs(fit.fun)) * weight), out.torque[0]


def test_chord_roots_in_the_band_jump(solver: SetpointSolver) -> None:
    """Why the band needs another law: eq. 6.6's chord does have roots there, but its torque falls
    by more than half between inner set points 0.05 rad/s apart while the motion moves little."""
    lefts = (-0.25, -0.20)  # 1.8 % of the outer set point apart, in the band
    roots = [_root(solver, -0.30)]  # continuation from a scanned root: the branch left -> 0
    for left in lefts:
        roots.append(_root(solver, left, roots[-1][0]))
    roots = roots[1:]
    for x, res, _ in roots:
        assert res < 1e-6  # a root of eq. 3.19 ...
        assert x[1] > 0 and x[2] > 0  # ... turning the way the set points ask
    (x_a, _, tq_a), (x_b, _, tq_b) = roots
    assert abs(x_b[1] / x_a[1] - 1) < 0.1  # the motion moves little ...
    assert np.all(np.abs(tq_a) > 2.0 * np.abs(tq_b))  # ... but both torques fall by more than half


def test_band_is_solved_by_the_pivot_law(solver: SetpointSolver) -> None:
    """The same set points, and a stopped inner side: a steady state, not limited, found by the pivot
    law; least squares on the pivot law's own residual from a scanned start finds the same root."""
    lefts = (-0.25, -0.20, 0.0)
    sol = solver.solve(np.array([[left, RIGHT] for left in lefts]))
    assert not sol.limited.any() and not sol.dug_in.any()
    assert sol.shear_path.all() and np.all(sol.element_turn > 0.5)
    assert np.all(sol.speed > 0) and np.all(sol.yaw_rate > 0)  # turning the way the set points ask
    pivot = solver.path_solver()
    assert pivot.fess.path_law
    for k, left in enumerate(lefts):
        x, res, torque = _root(pivot, left)
        assert res < 1e-6
        np.testing.assert_allclose([x[1], x[2]], [sol.speed[k], sol.yaw_rate[k]], rtol=1e-4)
        np.testing.assert_allclose(torque, sol.torque[k], rtol=1e-3)


@pytest.mark.parametrize(('chord_left', 'pivot_left'), [(-0.90, -0.85), (0.55, 0.50)])
def test_torque_is_continuous_at_the_band_edges(
    solver: SetpointSolver, chord_left: float, pivot_left: float
) -> None:
    """One 0.05 rad/s step across each edge (the spin side, the forward side): the law switches from
    the chord to the pivot law, and the torque changes as little as a step outside the band does
    (< 10 %; before, the chord -> pure slip path switch jumped by a factor 20 at -0.90 -> -0.85)."""
    sol = solver.solve(np.array([[chord_left, RIGHT], [pivot_left, RIGHT]]))
    assert not sol.limited.any()
    assert not sol.shear_path[0] and sol.element_turn[0] <= 0.5  # the chord's own answer
    assert sol.shear_path[1] and sol.element_turn[1] > 0.5  # the pivot law's
    assert np.all(np.abs(sol.torque[1] / sol.torque[0] - 1) < 0.1)
    assert abs(sol.yaw_rate[1] / sol.yaw_rate[0] - 1) < 0.05


def test_pivot_law_is_the_chord_below_half_a_revolution(solver: SetpointSolver) -> None:
    """The blend by hand (0 up to half a revolution, 1 from 0.5 + PIVOT_BLEND_REV rev), and at a wide
    turn (every element below half a revolution) the pivot law's residual is the chord's, exactly."""
    half = np.pi * np.array([0.0, 0.5, 0.5 + PIVOT_BLEND_REV / 2, 0.5 + PIVOT_BLEND_REV, 3.0])
    np.testing.assert_array_equal(pivot_blend(half), [0.0, 0.0, 0.5, 1.0, 1.0])
    np.testing.assert_array_equal(pivot_blend(-half), pivot_blend(half))
    chord, pivot = solver.fess, solver.path_solver().fess
    speed, yaw = np.array([0.18]), np.array([0.29])  # set points (1.0, RIGHT): turn 0.21 rev
    state = np.array([[[0.02, 1.0, RIGHT]]])
    np.testing.assert_array_equal(
        residual(pivot.problem(speed, yaw), state), residual(chord.problem(speed, yaw), state)
    )


def test_inner_side_at_rest_over_the_ground_is_a_steady_state(solver: SetpointSolver) -> None:
    """Outer set point 7/3 rad/s, inner -0.68 .. -0.66: the inner side's ground speed V - w_z B / 2
    crosses 0 (a pivot about the inner track), its slip passes 0.95 (SLIP_LIMIT) and its compaction
    resistance would flip sign. These were dug in (no root with the jump, the slip test) and are now
    solved; least squares on the pivot law's residual, from the neighbour's root, agrees."""
    right = 7.0 / 3.0
    lefts = (-0.68, -0.67, -0.66)
    sol = solver.solve(np.array([[left, right] for left in lefts]))
    assert not sol.limited.any() and sol.shear_path.all()
    inner_ground = sol.speed - sol.yaw_rate * solver.tread / 2
    assert np.all(np.abs(inner_ground) < 0.005) and np.all(sol.slip[:, 0] > 0.95)
    assert np.all(sol.speed > 0) and np.all(sol.yaw_rate > 0)
    pivot = solver.path_solver()
    veh = pivot.fess.vehicle
    weight, length = veh.mass_kg * 9.81, pivot._length_scale()
    scale = np.array([weight, weight, weight * length])
    start = pivot.solve(np.array([[-0.70, right]])).state[0]
    for k, left in enumerate(lefts):
        fn = pivot._residual(np.array([[left, right]]), np.array([False]))
        fit = least_squares(
            lambda x, fn=fn: fn(x[None], np.zeros(1, int))[0] / scale,
            start,
            x_scale=[0.01 * length, 0.01, 0.01],
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
            max_nfev=400,
        )
        assert np.max(np.abs(fit.fun)) * weight < 1e-6
        np.testing.assert_allclose(fit.x[1:], [sol.speed[k], sol.yaw_rate[k]], rtol=1e-4)
        start = fit.x
    # the compaction resistance's direction by hand: sign(v) for the chord, a ramp of
    # PIVOT_REST_SPEED_M_S for the pivot law (a side at rest holds any resistance in [-R_c, R_c])
    left, right_side = 0.01, 0.5 * PIVOT_REST_SPEED_M_S  # side ground speeds [m/s]
    speed = np.array([(left + right_side) / 2])
    yaw = np.array([(right_side - left) / solver.tread])  # V -+ w_z B / 2 (left +B/2)
    for fess, expected in ((solver.fess, [1.0, 1.0]), (pivot.fess, [1.0, 0.5])):
        problem = fess.problem(speed, yaw)
        np.testing.assert_allclose(problem.side_speed, [[left, right_side]], atol=1e-15)
        np.testing.assert_allclose(rolling_direction(problem), [expected], rtol=1e-9)


def test_pivot_band_on_the_twin(solver: SetpointSolver) -> None:
    """The twin (its own contact model, no FESS; docs/TWIN.md) driven at band set points from rest
    turns as the pivot law says: mean speed and yaw rate after 3 s within 20 % (measured 2026-12-03:
    speed +10 / +17 %, yaw rate +13 / +14 % at a reversed / stopped inner side)."""
    veh = solver.fess.vehicle
    r, tread = veh.drive_radius_m, veh.tread_m
    lefts = (-0.25, 0.0)
    sol = solver.solve(np.array([[left, RIGHT] for left in lefts]))
    for k, left in enumerate(lefts):
        speed_cmd, yaw_cmd = r * (left + RIGHT) / 2, r * (RIGHT - left) / tread  # no-slip kinematics
        trace = run_commands(Twin(veh, load_terrain('sand_bin')), [Segment(speed_cmd, yaw_cmd, 8.0)])
        settled = trace.t >= 3.0
        speed = float(np.hypot(trace.twist[settled, 0], trace.twist[settled, 1]).mean())
        yaw = float(trace.twist[settled, 2].mean())
        assert abs(speed / sol.speed[k] - 1) < 0.2
        assert abs(yaw / sol.yaw_rate[k] - 1) < 0.2


def test_same_step_outside_the_band_is_smooth(solver: SetpointSolver) -> None:
    sol = solver.solve(np.array([[-1.0, RIGHT], [-0.95, RIGHT]]))  # the spin side of the band
    assert not sol.limited.any()
    change = np.abs(sol.torque[1] / sol.torque[0] - 1)
    assert np.all(change < 0.1)  # 6-8 % per 0.05 rad/s here, against 60-80 % inside the band


def test_roots_past_half_a_revolution_are_solved_not_flagged(solver: SetpointSolver) -> None:
    """Just outside the old band the chord's Newton converges, but the inner element turns 1-2 rev in
    the contact and its torque is erratic (0.72 / 0.15 / 1.01 N m on the outer side at +0.15 / +0.20
    / +0.25 rad/s, docs/PREDICTION.md). The pivot law solves them, smoothly; a wide turn keeps the
    chord."""
    lefts = np.array([0.15, 0.20, 0.25, 1.50])
    sol = solver.solve(np.column_stack([lefts, np.full(4, RIGHT)]))
    assert not sol.dug_in.any() and not sol.limited.any() and np.all(sol.speed > 0)
    # hand check of eqs. 6.3/6.5: w_z l / (omega_inner r) / 2 pi, with l = 0.45 m, the track's contact
    # length (config/vehicles/test_robot_track.yaml) and r its sprocket radius
    by_hand = sol.yaw_rate * 0.45 / (lefts * solver.radius) / (2 * np.pi)
    np.testing.assert_allclose(sol.element_turn, by_hand, rtol=1e-9)
    assert np.all(sol.element_turn[:3] > 0.5) and sol.shear_path[:3].all()
    outer = sol.torque[:3, 1]
    assert np.all(np.abs(np.diff(outer)) < 0.1 * outer[0])  # smooth steps, not 0.72 -> 0.15 -> 1.01
    assert sol.element_turn[3] < 0.5 and not sol.shear_path[3]  # a wide turn: the chord's answer
