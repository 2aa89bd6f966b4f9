"""The project's Newton-Raphson (eqs. 3.20-3.22): its result type, its rules and its drivers.

Every steady-state model solves a small nonlinear system per operating point (3 unknowns for tracks,
eq. 3.19; 5 for wheels, chapter 4). :func:`newton_solve` solves a whole batch of independent systems
at once (damped Newton with a line search, forward-difference Jacobian of eq. 3.22); the Wong track
and wheel models, the ICR model and the set-point solve call it with their residuals.

FESS's three unknowns (s0 [m], omega_left, omega_right [rad/s]) use the backtracking form: one
residual call per iteration on the state and its three perturbations (eq. 3.22), a trust region,
and halving of the last step when the largest residual does not drop. Its rules are written once
here, for a float or an array (:mod:`skidsteer_power.numeric`): the finite-difference steps
(:func:`fd_steps`), the trust region (:func:`trust_scale`), the linear solve with its singular rule
(:func:`solve3`), and :data:`MAX_HALVINGS`. Two drivers run them, the ``method`` of a FESS solve:
the batched :func:`skidsteer_power.models.fess.newton` (P points, masks) and the one-point
:func:`skidsteer_power.models.fess_point.newton_point` (Python floats: numpy costs about a
microsecond per call on one value).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from skidsteer_power.numeric import Real, maximum

TOLERANCE = 1e-3  # eq. 3.19 stopping rule (section 3.3.1): |each equation| < 0.001 (N, N, N m)
MAX_ITERATIONS = 60
MAX_HALVINGS = 12  # backtracking form: halvings of one step before a point gives up
FD_STEP = 1e-7  # eq. 3.22: forward-difference step, relative to the unknown's scale
TRUST_S0 = 0.2  # trust region: s0 moves less than this share of the contact span per step
TRUST_OMEGA = 0.5  # ... and each omega less than this share of max(|omega|, omega_ref)

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


def fd_steps(length: float, omega_ref: Real, omega_left: Real, omega_right: Real) -> tuple[float, Real, Real]:
    """Forward-difference steps (h_s0 [m], h_left, h_right [rad/s]) of eq. 3.22 for a 3-unknown FESS
    state: FD_STEP times the contact span ``length`` [m] and times max(|omega|, omega_ref) [rad/s]
    (floats, or arrays over a batch)."""
    return (
        FD_STEP * length,
        FD_STEP * maximum(abs(omega_left), omega_ref),
        FD_STEP * maximum(abs(omega_right), omega_ref),
    )


def trust_scale(
    length: float, omega_ref: Real, x: tuple[Real, Real, Real], step: tuple[Real, Real, Real]
) -> Real:
    """The factor (>= 1, NaN if the step is) a Newton step of a FESS state x = (s0, omega_left,
    omega_right) is divided by so that s0 moves less than TRUST_S0 of the contact span ``length``
    [m] and each omega less than TRUST_OMEGA of max(|omega|, omega_ref) [rad/s] (the trust region)."""
    ratio = maximum(
        maximum(
            abs(step[0]) / (TRUST_S0 * length), abs(step[1]) / (TRUST_OMEGA * maximum(abs(x[1]), omega_ref))
        ),
        abs(step[2]) / (TRUST_OMEGA * maximum(abs(x[2]), omega_ref)),
    )
    return maximum(ratio, 1.0)


def solve3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve the batched 3x3 systems a x = b (LAPACK's gesv); x = 0 where a is singular (|det| below
    1e-14 of the product of its row norms): a singular Jacobian makes no step (the backtracking
    then decides). :func:`solve3_floats` is the same step for one system in Python floats."""
    det = np.linalg.det(a)
    ok = np.abs(det) > 1e-14 * np.prod(np.linalg.norm(a, axis=2), axis=1)
    if ok.all():
        solved: np.ndarray = np.linalg.solve(a, b[..., None])[..., 0]
        return solved
    out = np.zeros_like(b)
    if ok.any():
        out[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    return out


def solve3_floats(a: list[list[float]], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """x with a x = b for ONE 3x3 system in floats: Gaussian elimination with partial pivoting (the
    LU of LAPACK's gesv that :func:`solve3` calls; about 2 us against np.linalg.solve's 5-10 us on
    one system). A zero pivot (singular) gives 0, as :func:`solve3`; NaN propagates."""
    m = [[a[i][0], a[i][1], a[i][2], b[i]] for i in range(3)]
    for col in range(3):
        pivot = max(range(col, 3), key=lambda i: abs(m[i][col]))
        if m[pivot][col] == 0.0:
            return (0.0, 0.0, 0.0)
        m[col], m[pivot] = m[pivot], m[col]
        top = m[col]
        for i in range(col + 1, 3):
            row = m[i]
            factor = row[col] / top[col]
            for c in range(col + 1, 4):
                row[c] -= factor * top[c]
    x2 = m[2][3] / m[2][2]
    x1 = (m[1][3] - m[1][2] * x2) / m[1][1]
    x0 = (m[0][3] - m[0][1] * x1 - m[0][2] * x2) / m[0][0]
    return (x0, x1, x2)
