"""FESS's one-point path (models/fess_point.py, issue 25's speed work): its residual kernel against
the batched residual of models/fess.py (the same equations in another array layout, an independent
implementation here), its 3 x 3 solve against numpy's LAPACK, and the warm start's rule."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from skidsteer_power.models import fess, fess_point, newton
from skidsteer_power.terramechanics.terrain import PRESETS, Terrain, load_terrain
from skidsteer_power.vehicle import load_vehicle

SAND = PRESETS['dry_sand']
# eqs. 2.4 (type B) and 2.5 (type C) on the same sand: the kernel calls the shear law by magnitude
TYPE_B = dataclasses.replace(SAND, shear_type='B', Kw=0.02)
TYPE_C = dataclasses.replace(SAND, shear_type='C', Kw=0.02, Kr=0.6)


@pytest.mark.parametrize(
    ('vehicle_name', 'terrain'),
    [
        ('chapter3_track', SAND),
        ('chapter3_track', TYPE_B),
        ('chapter3_track', TYPE_C),
        ('test_robot_track', load_terrain('sand_bin')),  # compliant belt: K_x / K = 4 (eq. 6.7 scaled)
        ('test_robot_6wheel', load_terrain('sand_bin')),  # 3 wheels per side, quadratic stress
    ],
)
@pytest.mark.parametrize(('speed', 'yaw'), [(0.5, 0.25), (0.3, -0.8), (0.0, 0.6), (0.7, 0.0)])
def test_kernel_residual_equals_the_batched_residual(
    vehicle_name: str, terrain: Terrain, speed: float, yaw: float
) -> None:
    solver = fess.FessSolver(load_vehicle(vehicle_name), terrain)
    problem = fess_point.point_problem(solver, speed, yaw)
    batch_problem = solver.problem(np.array([speed]), np.array([yaw]))
    kernel = fess_point.PointKernel(problem)
    rng = np.random.default_rng(5)
    base = fess.initial_guess(batch_problem)[0]
    states = [tuple(base), (0.01, -0.4, 1.2), (-0.02, 0.9, -0.3), (0.0, -1.1, -0.7)]  # reversed sides
    states += [tuple(base * rng.uniform(0.7, 1.3, 3)) for _ in range(3)]
    for x in states:
        h = (1e-3, 2e-3, -3e-3)  # the kernel's rows for x and x + h_k e_k
        got = np.array(kernel.perturbed(x, h))
        trial = np.array(x)[None, :] + np.vstack([np.zeros(3), np.diag(h)])
        want = fess.residual(batch_problem, trial[None])[0]
        scale = np.abs(want).max(axis=0) + 1.0  # residuals of N, N (x 1e9 straight), N m
        assert np.abs(got - want).max(axis=0) / scale == pytest.approx(np.zeros(3), abs=1e-11)
    # the axle torque r sum f_x w_t of the batch's element forces at the last state
    fx = fess.element_forces(batch_problem, np.array(states[-1])[None, None, :])[0]
    torque = batch_problem.radius * (fx * batch_problem.contact.wt[:, None]).sum(axis=(-2, -1))[0, 0]
    assert kernel.torque(states[-1]) == pytest.approx(torque, rel=1e-12, abs=1e-12)


def test_solve3_equals_numpy_and_gives_zero_when_singular() -> None:
    rng = np.random.default_rng(2)
    for _ in range(50):
        a, b = rng.normal(size=(3, 3)), rng.normal(size=3)
        got = newton.solve3_floats(a.tolist(), tuple(b))
        assert np.allclose(got, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    singular = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]]
    assert newton.solve3_floats(singular, (1.0, 2.0, 3.0)) == (0.0, 0.0, 0.0)


def test_a_warm_start_does_a_cold_solve_unless_it_can_save_steps() -> None:
    # a track: the warm solve IS the cold solve, whatever the previous state (same steps, same answer)
    track = fess.FessSolver(load_vehicle('chapter3_track'), SAND)
    previous = track.solve_point(0.2, 0.9).state  # a tight turn
    for v, w in [(0.5, 0.25), (0.2, 0.95), (-0.3, 0.5)]:
        cold, warm = track.solve_point(v, w), track.solve_point(v, w, x0=previous)
        assert warm.iterations == cold.iterations
        assert np.array_equal(warm.torque, cold.torque) and warm.s0 == cold.s0
    # wheels in consecutive tight turns the same way: the previous state is evaluated, and the answer
    # is the same steady state to the solver's tolerance
    wheels = fess.FessSolver(load_vehicle('packbot_4wheel'), PRESETS['clay'])
    solver_kernel = fess_point.PointKernel(fess_point.point_problem(wheels, 0.618, 0.824))
    tight = wheels.solve_point(0.6, 0.8)  # inner / outer side speed 0.58
    cold_guess = np.array(fess_point.first_guess(wheels, solver_kernel))
    assert fess_point._warm_start(solver_kernel, cold_guess, tight.state) is not None
    straight = wheels.solve_point(0.5, 0.0).state
    assert fess_point._warm_start(solver_kernel, cold_guess, straight) is None  # the previous not tight
    cold, warm = (
        wheels.solve_point(0.618, 0.824, tol=1e-8),
        wheels.solve_point(0.618, 0.824, x0=tight.state, tol=1e-8),
    )
    assert cold.converged and warm.converged
    assert warm.iterations < cold.iterations  # measured: 4 against 11
    assert warm.torque == pytest.approx(cold.torque, rel=1e-6)
    assert warm.omega == pytest.approx(cold.omega, rel=1e-6)
