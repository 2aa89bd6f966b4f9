"""The pivot band of the set-point solve (issue 25): tight turns with the inner side's set point near
zero, flagged ``limited``. Why: FESS has roots there, but they are not a steady state the robot can
be predicted at, because the torque jumps between neighbouring set points (docs/PREDICTION.md,
"The pivot band").

Reference: FESS's own equilibrium (eq. 3.19) solved by an independent solver (scipy's
least_squares from the best node of a residual scan), not by the project's Newton; the jump is
measured against the torque change of the same step outside the band.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from skidsteer_power.models.fess import FessSolver
from skidsteer_power.models.setpoint import SetpointSolver
from skidsteer_power.terramechanics.terrain import load_terrain
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


def test_band_is_flagged_although_fess_has_roots_there(solver: SetpointSolver) -> None:
    lefts = (-0.25, -0.20)  # inner set points 0.05 rad/s apart (1.8 % of the outer one), in the band
    sol = solver.solve(np.array([[left, RIGHT] for left in lefts]))
    assert sol.limited.all()
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


def test_same_step_outside_the_band_is_smooth(solver: SetpointSolver) -> None:
    sol = solver.solve(np.array([[-1.0, RIGHT], [-0.95, RIGHT]]))  # the spin side of the band
    assert not sol.limited.any()
    change = np.abs(sol.torque[1] / sol.torque[0] - 1)
    assert np.all(change < 0.1)  # 6-8 % per 0.05 rad/s here, against 60-80 % inside the band


def test_roots_past_half_a_revolution_are_flagged_not_dug_in(solver: SetpointSolver) -> None:
    """Just outside the band Newton converges, but the inner element turns 1-2 rev in the contact and
    the torque is as erratic (docs/PREDICTION.md's table: +0.15 -> +0.20 -> +0.25 rad/s gives
    0.72 / 0.15 / 1.01 N m on the outer side). Those roots are kept and flagged with their reason."""
    sol = solver.solve(np.array([[0.15, RIGHT], [0.20, RIGHT], [0.25, RIGHT], [1.50, RIGHT]]))
    assert not sol.dug_in[:3].any() and np.all(sol.speed[:3] > 0)  # FESS's roots, not the dug-in state
    # hand check of eqs. 6.3/6.5: w_z l / (omega_inner r) / 2 pi, with l = 0.45 m, the track's contact
    # length (config/vehicles/test_robot_track.yaml) and r its sprocket radius
    by_hand = sol.yaw_rate * 0.45 / (np.array([0.15, 0.20, 0.25, 1.50]) * solver.radius) / (2 * np.pi)
    np.testing.assert_allclose(sol.element_turn, by_hand, rtol=1e-9)
    assert np.all(sol.element_turn[:3] > 0.5) and sol.limited[:3].all()
    assert all('half a revolution' in reason for reason in sol.reason[:3])
    assert sol.element_turn[3] < 0.5 and not sol.limited[3]  # a wide turn: an ordinary answer
