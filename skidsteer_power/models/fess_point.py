"""FESS's one-point Newton for on-board use (:meth:`FessSolver.solve_point
<skidsteer_power.models.fess.FessSolver.solve_point>`), and its warm start.

The iteration is :func:`skidsteer_power.models.fess.newton`'s (eqs. 3.20-3.22), written for one
point without the batch bookkeeping; the residual, steps and trust region are fess.py's.
"""

from __future__ import annotations

import math

import numpy as np

from skidsteer_power.models.fess import (
    _PERTURBED,
    _UNKNOWNS,
    FORCE_TOL_N,
    MAX_HALVINGS,
    MAX_ITERATIONS,
    Problem,
    residual,
    residual_and_forces,
)

STALL_ITERATIONS = 8  # newton_point: steps without STALL_GAIN progress before it gives up
STALL_GAIN = 1e-2  # relative decrease of the largest residual that counts as progress
WARM_MARGIN = 2.0  # _pick_start: a warm guess's scaled residual must be this much smaller


def newton_point(
    problem: Problem,
    x0: np.ndarray,
    tol: float = FORCE_TOL_N,
    *,
    alternatives: np.ndarray | None = None,
    forces: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, bool, int]:
    """FESS's :func:`~skidsteer_power.models.fess.newton` for ONE operating point, without the batch
    bookkeeping (the on-board path).

    The same iteration, step by step: one residual call per iteration on the state and its three
    forward-difference perturbations (eq. 3.22), the trust region of :func:`_limit`, and halving of
    the last step when the largest residual does not drop (at most MAX_HALVINGS times). Returns
    (x, residual, converged, iterations). Measured against :func:`newton` on one point: the same
    iterates, about 2.5x less time (benchmarks/bench_fess.py). Unlike :func:`newton` it stops a point
    whose largest residual has not fallen by STALL_GAIN in STALL_ITERATIONS steps: where FESS has no
    steady state (tight turns) that used to cost all MAX_ITERATIONS steps (a tenth of 200 random
    commands, half of all their Newton steps).

    ``alternatives`` (k, 3): other first guesses (a warm start). The first iteration evaluates every
    guess with its perturbations in the same residual call and goes on from the one
    :func:`_pick_start` prefers, so choosing costs no extra call.

    ``forces``: if given, a converged answer leaves there as ``'fx'`` the element forces (1, 1, 2, G,
    N) [Pa] of the returned state, from the residual call that found it converged (the caller's
    torque then needs no further force evaluation; not set after the warm start's first call).
    """
    x = np.array(x0, dtype=float)
    length = problem.contact.length_scale
    omega_ref = float(problem.omega_ref[0])
    h = np.empty(3)
    trial = np.empty((1, 4, 3))
    x_prev, step_prev = x.copy(), np.zeros(3)
    norm_prev, halvings = math.inf, 0
    best, best_at = math.inf, 0
    f = np.full(3, np.nan)
    for iteration in range(1, MAX_ITERATIONS + 1):
        h[0] = 1e-7 * length
        h[1] = 1e-7 * max(abs(x[1]), omega_ref)
        h[2] = 1e-7 * max(abs(x[2]), omega_ref)
        trial[0] = x
        trial[0, _PERTURBED, _UNKNOWNS] += h
        if iteration == 1 and alternatives is not None and alternatives.size:
            x, h, fall = _pick_start(problem, x, h, trial[0], alternatives)
            fx = None
        else:
            fall_p, fx_p = residual_and_forces(problem, trial)
            fall, fx = fall_p[0], fx_p[:, :1]
        f = fall[0]
        norm = float(np.abs(f).max())
        if not norm < math.inf:
            norm = math.inf
        if norm < tol:
            if forces is not None and fx is not None:
                forces['fx'] = fx
            return x, f, True, iteration
        if norm < (1.0 - STALL_GAIN) * best:
            best, best_at = norm, iteration
        elif iteration - best_at >= STALL_ITERATIONS:  # no root here: stop (not converged)
            return x, f, False, iteration
        if norm >= norm_prev:  # backtrack: halve the last step
            if halvings >= MAX_HALVINGS:
                return x, f, False, iteration
            step_prev *= 0.5
            x = x_prev + step_prev
            halvings += 1
            continue
        jac = (fall[1:] - f).T / h
        try:
            step = np.linalg.solve(jac, -f)
        except np.linalg.LinAlgError:
            step = np.zeros(3)
        step = _limit_point(length, omega_ref, x, step)
        x_prev, norm_prev, step_prev, halvings = x, norm, step, 0
        x = x + step
    return x, f, False, MAX_ITERATIONS


def _limit_point(length: float, omega_ref: float, x: np.ndarray, step: np.ndarray) -> np.ndarray:
    """:func:`~skidsteer_power.models.fess._limit` (the trust region) for one point, in floats: the same
    operations without the batch's array set-up (a tenth of a cold solve_point's time under cProfile)."""
    ratios = (
        abs(step[0]) / (0.2 * length),
        abs(step[1]) / (0.5 * max(abs(x[1]), omega_ref)),
        abs(step[2]) / (0.5 * max(abs(x[2]), omega_ref)),
    )
    ratio = math.nan if any(r != r for r in ratios) else max(ratios)  # NaN propagates, as np.max
    return step / max(ratio, 1.0)


def warm_alternatives(cold: np.ndarray, warm: np.ndarray) -> np.ndarray:
    """First guesses (k, 3) a warm start adds to the physics-based ``cold`` (3,): the previous state
    ``warm`` itself and ``cold`` with the previous turning-centre offset (s0 is what the cold guess
    knows least; the side speeds follow the command). None finite: (0, 3)."""
    warm = np.asarray(warm, dtype=float).reshape(3)
    if not (math.isfinite(warm[0]) and math.isfinite(warm[1]) and math.isfinite(warm[2])):
        return _NO_ALTERNATIVES
    out = np.empty((2, 3))
    out[0] = cold
    out[0, 0] = warm[0]
    out[1] = warm
    return out


_NO_ALTERNATIVES = np.zeros((0, 3))


def _pick_start(
    problem: Problem, x: np.ndarray, h: np.ndarray, trial: np.ndarray, alternatives: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate ``x`` with its perturbations and every alternative (unperturbed) in ONE residual call;
    keep the one with the smallest residual (forces over the weight, the moment over weight x contact
    span), an alternative only if that is under 1 / WARM_MARGIN of ``x``'s. Returns (x, steps,
    residuals (4, 3) of x and its perturbations).

    Only a chosen alternative's perturbations cost a second call: evaluating all of them up front
    (3 x 4 states) made a warm start slower than a cold one at equal iterations (issue 25,
    docs/PREDICTION.md "Speed")."""
    omega_ref = float(problem.omega_ref[0])
    k_alt = len(alternatives)
    states = np.empty((1, 4 + k_alt, 3))
    states[0, :4] = trial
    states[0, 4:] = alternatives
    fall = residual(problem, states)[0]
    weight = problem.vehicle.mass_kg * 9.81
    scale = (weight, weight * float(problem.lateral_scale[0]), weight * problem.contact.length_scale)
    k, best = 0, math.inf
    for row in (0, *range(4, 4 + k_alt)):  # k_alt + 1 rows of 3: floats beat array set-up here
        a, b, c = abs(fall[row, 0]) / scale[0], abs(fall[row, 1]) / scale[1], abs(fall[row, 2]) / scale[2]
        if not (a < math.inf and b < math.inf and c < math.inf):  # NaN or inf: never chosen
            norm = math.inf
        else:
            # a warm guess must beat the physics guess clearly to be taken
            norm = max(a, b, c) * (WARM_MARGIN if row else 1.0)
        if norm < best:
            k, best = (row - 3 if row else 0), norm
    if k == 0:
        return x, h, fall[:4]
    start = alternatives[k - 1].copy()
    steps = h.copy()
    steps[1:] = 1e-7 * np.maximum(np.abs(start[1:]), omega_ref)
    perturbed = np.repeat(start[None, None, :], 3, axis=1)
    perturbed[0, _PERTURBED - 1, _UNKNOWNS] += steps
    rest = residual(problem, perturbed)[0]
    return start, steps, np.vstack([fall[3 + k][None, :], rest])
