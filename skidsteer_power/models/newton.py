"""The project's one batched Newton-Raphson (eqs. 3.20-3.22) and its result type.

Every steady-state model solves a small nonlinear system per operating point (3 unknowns for tracks,
eq. 3.19; 5 for wheels, chapter 4). :func:`newton_solve` solves a whole batch of independent systems
at once (damped Newton, forward-difference Jacobian of eq. 3.22); the Wong track and wheel models and
the ICR model call it with their residuals. FESS (:mod:`skidsteer_power.models.fess`) runs the same
iteration in a driver specialised to its residual, which evaluates a state and its three
perturbations in ONE batched call (eq. 3.22), and returns the same :class:`NewtonResult`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

TOLERANCE = 1e-3  # eq. 3.19 stopping rule (section 3.3.1): |each equation| < 0.001 (N, N, N m)
MAX_ITERATIONS = 60

Residual = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class NewtonResult:
    x: np.ndarray  # (N, k) last iterate
    residual: np.ndarray  # (N, k) residual at x
    converged: np.ndarray  # (N,) bool
    iterations: np.ndarray  # (N,) int: Newton steps taken per point


def newton_solve(
    residual: Residual,
    x0: np.ndarray,
    *,
    steps: np.ndarray,
    tol: float = TOLERANCE,
    max_iter: int = MAX_ITERATIONS,
    limit_step: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> NewtonResult:
    """Damped Newton-Raphson over a batch of independent k-dimensional systems.

    residual(x, idx) -> F: x (M, k) iterates of the points ``idx`` (M,), F (M, k). The Jacobian is
    by forward differences with per-unknown steps ``steps`` (k,) scaled by max(1, |x|) (eq. 3.22).
    A step is halved (up to 10 times) until the residual norm drops; ``limit_step(x, dx, idx)``
    may return the largest admissible fraction (M,) of a full step (to keep iterates physical).
    Only the points not yet converged are evaluated. Converged: every |F| < tol.
    """
    x = np.array(x0, dtype=float, copy=True)
    n, k = x.shape
    idx_all = np.arange(n)
    f = residual(x, idx_all)
    iterations = np.zeros(n, dtype=int)
    active = ~_done(f, tol)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        xa, fa = x[idx], f[idx]
        jac = np.empty((idx.size, k, k))
        for col in range(k):
            h = steps[col] * np.maximum(1.0, np.abs(xa[:, col]))
            xp = xa.copy()
            xp[:, col] += h
            jac[:, :, col] = (residual(xp, idx) - fa) / h[:, None]
        dx = solve_linear(jac, -fa)
        alpha = np.ones(idx.size) if limit_step is None else np.minimum(1.0, limit_step(xa, dx, idx))
        norm0 = np.linalg.norm(fa, axis=1)
        pending = np.ones(idx.size, dtype=bool)
        for _halving in range(11):
            sub = np.flatnonzero(pending)
            trial = xa[sub] + alpha[sub, None] * dx[sub]
            ft = residual(trial, idx[sub])
            better = np.all(np.isfinite(ft), axis=1) & (np.linalg.norm(ft, axis=1) < norm0[sub])
            accept = sub[better]
            x[idx[accept]] = trial[better]
            f[idx[accept]] = ft[better]
            pending[accept] = False
            alpha[sub[~better]] *= 0.5
            if not np.any(pending):
                break
        iterations[idx] += 1
        stalled = idx[pending]  # no decrease even with a tiny step: give up on those points
        active[stalled] = False
        active[idx] &= ~_done(f[idx], tol)
    return NewtonResult(x, f, _done(f, tol), iterations)


def _done(f: np.ndarray, tol: float) -> np.ndarray:
    done: np.ndarray = np.all(np.abs(f) < tol, axis=1)  # (M,) bool
    return done


def solve_linear(jac: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Batched J dx = rhs; least squares where J is singular (then the step search decides)."""
    try:
        return np.linalg.solve(jac, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.zeros_like(rhs)
        for i in range(rhs.shape[0]):
            out[i] = np.linalg.lstsq(jac[i], rhs[i], rcond=None)[0]
        return out
