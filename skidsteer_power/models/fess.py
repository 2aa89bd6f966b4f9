"""Finite Element Skid Steering (FESS) model, tracks and wheels (chapter 6, eqs. 6.1-6.12).

Each side's contact is cut into ``n`` elements along its length (eq. 6.5); the shear displacement of
each element is the distance between where it is now and the ground point it gripped when it entered
the contact (eqs. 6.1-6.4, 6.6); the shear stress follows eq. 6.7 (any of soil types A, B, C via
:func:`~skidsteer_power.terramechanics.soil.shear_fraction`); the forces and moments are trapezoidal
sums over the elements; and the three unknowns (s0, omega_left, omega_right) solve the equilibrium of
eq. 3.18 by Newton-Raphson. Wheels (section 6.3) use the same kernel on a flattened contact whose
normal stress is the quadratic approximation of eqs. 6.8-6.10, placed along the vehicle by eq. 6.11.

Kinematics in (V, yaw rate)
---------------------------
The model works in the vehicle frame (REP 103: x forward, y left) with the forward speed V [m/s]
(the x velocity of the hull centreline) and the signed yaw rate w_z [rad/s] as inputs, never the
turning radius R = V / w_z itself. Every place the text writes R multiplies a sine or 1 - cos of the
yaw angle, R sin(w_z t) = V t sin(th)/th and R (1 - cos th) = V t (1 - cos th)/th, so straight running
(w_z = 0) and spinning in place (V = 0) are ordinary points with no division by zero. The centrifugal
force m V^2 / R of eq. 3.18 is m V w_z; the load transfer of eq. 6.12 is m V w_z h / B.

Eq. 6.6 typo: the text writes the rotation angle of the k-th element as k phi L / (n omega r), with
phi (the turning angle) where the *yaw rate* phi-dot is meant: by eqs. 6.3 and 6.5 the angle is
phi-dot times the element's time in contact, k L / (n omega r). We use w_z * k L / (n |omega| r).

An element of a side turning backwards (omega < 0, e.g. the inner side spinning in place) enters the
contact at the rear; the kernel mirrors the contact for that side (the same eq. 6.6 with the entry
point at the rear end). Reverse driving (V < 0) is the fore-aft mirror image of forward driving:
solution(-V, w_z) = solution(V, -w_z) with omega, torque, thrust and s0 negated, power, sinkage and
traction margin unchanged (exact for the CG at the geometric centre, the text's assumption).

Compaction resistance acts against each side's motion over the ground, sign(V - w_z y_side); a side
that does not move over the ground (w_z y_side = V) makes no rut.
"""

from __future__ import annotations

import time
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import fess_point
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.fess_contact import _free_wheel_table as _free_wheel_table
from skidsteer_power.models.fess_problem import (
    DEFAULT_ELEMENTS,
    FORCE_TOL_N,
    GUESS_FRICTION,
    MAX_HALVINGS,
    RETRY_ROUNDS,
    RIGID_MARGIN_MIN,
    SIDE_Y_SIGN,
    SLIP_LIMIT,
    STEEDS_S0_SCALE,
    STRAIGHT_YAW,
    Problem,
    build_problem,
    centrifugal,
    chord_displacement,
    pivot_blend,
    slip_ratio,
    steeds_s0,
)
from skidsteer_power.models.fess_steady import PointSolution, TwistSolution, reshape_state, to_steady_state
from skidsteer_power.models.newton import MAX_ITERATIONS, NewtonResult, fd_steps, solve3, trust_scale
from skidsteer_power.terramechanics.soil import shear_fraction

__all__ = [
    'DEFAULT_ELEMENTS',
    'FORCE_TOL_N',
    'GUESS_FRICTION',
    'MAX_HALVINGS',
    'RIGID_MARGIN_MIN',
    'SIDE_Y_SIGN',
    'SLIP_LIMIT',
    'STEEDS_S0_SCALE',
    'STRAIGHT_YAW',
    'FessSolver',
    'PointSolution',
    'Problem',
    'TwistSolution',
    'element_displacement',
    'element_forces',
    'initial_guess',
    'newton',
    'residual',
    'residual_and_forces',
    'slip_ratio',
    'solve',
]

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle


# --------------------------------------------------------------------------------------------------
# The residual of eq. 3.18 over a batch of operating points and trial states
# --------------------------------------------------------------------------------------------------


def element_displacement(problem: Problem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shear displacement (eq. 6.6) of every element for trial states x (P, S, 3).

    Returns (jx, jy, xk), shapes (P, S, 2, G, N): the displacement [m] of each element from the
    ground point it gripped at touch-down, along the vehicle's current x and y axes, and each
    element's x relative to the turning-centre projection [m].
    """
    s0 = x[..., 0][..., None, None, None]  # (P, S, 1, 1, 1)
    omega = x[..., 1:][..., None, None]  # (P, S, 2, 1, 1)
    forward = omega >= 0  # omega < 0: entry at the rear (mirrored contact)
    if problem.path_law and problem.terrain.is_rigid:  # the slip path (rigid_contact module doc)
        return _rigid_displacement(problem, s0, omega, forward)
    # half the angle turned since the element touched down (eq. 6.3): w_z t / 2 with the time in
    # contact t = xi / (|omega| r) (eq. 6.5)
    half = problem.half_turn_rate / np.maximum(np.abs(omega) * problem.radius, 1e-12)
    fwd_plus, fwd_minus, entry_plus, entry_minus = problem.element_x
    xk = np.where(forward, fwd_plus, fwd_minus) - s0  # element now, relative to the turning centre
    xe = np.where(forward, entry_plus, entry_minus) - s0  # where it touched down
    jx, jy = chord_displacement(xk - xe, xe, problem.centre_offset, half)  # eq. 6.6
    if problem.path_law:  # soil's pivot band: the chord up to half a revolution, then the slip path
        blend = pivot_blend(half)
        if np.any(blend > 0):
            px, py, _ = _rigid_displacement(problem, s0, omega, forward)
            jx, jy = jx + blend * (px - jx), jy + blend * (py - jy)
    return jx, jy, xk


def _rigid_displacement(
    problem: Problem, s0: np.ndarray, omega: np.ndarray, forward: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`element_displacement` on rigid ground: :func:`~skidsteer_power.models.rigid_contact.
    slip_path_displacement` of every element, shapes (P, S, 2, G, N)."""
    from skidsteer_power.models.rigid_contact import slip_path_displacement

    fwd_plus, fwd_minus, entry_plus, entry_minus = problem.element_x
    xk = np.where(forward, fwd_plus, fwd_minus) - s0
    xe = np.where(forward, entry_plus, entry_minus) - s0
    along = problem.side_speed[:, None, :, None, None] - omega * problem.radius
    yaw = problem.yaw[:, None, None, None, None]
    rim = np.maximum(np.abs(omega) * problem.radius, 1e-12)
    jx, jy = slip_path_displacement(xk, xe, along, yaw, rim)
    return jx, jy, xk


def element_forces(problem: Problem, x: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per-element shear forces for trial states x (P, S, 3) = (s0, omega_left, omega_right).

    Returns (fx, fy, xk) with shapes (P, S, 2, G, N): the force on the vehicle per unit area [Pa]
    along x and y (eq. 6.7, against the displacement), and each element's x as in
    :func:`element_displacement`.
    """
    c = problem.contact
    jx, jy, xk = element_displacement(problem, x)
    if c.longitudinal != 1.0:  # a compliant belt: eq. 6.7 in the scaled displacement (j_x K / K_x, j_y)
        jx = jx * c.longitudinal
    j = np.hypot(jx, jy)
    # eq. 6.7; the fraction is 0 at j = 0, so dividing by 1 there gives the zero stress
    scale = c.tau_max[:, None] * shear_fraction(problem.terrain, j) / np.where(j > 0, j, 1.0)
    return -scale * jx, -scale * jy, xk


def residual(problem: Problem, x: np.ndarray) -> np.ndarray:
    """Equilibrium residuals (P, S, 3) of eq. 3.19 at trial states x (P, S, 3) [N, N, N m]."""
    return residual_and_forces(problem, x)[0]


def residual_and_forces(problem: Problem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`residual` and the longitudinal element forces fx (P, S, 2, G, N) [Pa] it summed (the
    one-point path takes the axle torque of the converged state from them)."""
    c = problem.contact
    fx, fy, xk = element_forces(problem, x)
    sum_axes = (-2, -1)
    # (P, S, 2) trapezoid sums; the array methods: np.sum's reduction without its Python wrapper
    fx_side = (fx * c.wx[:, None]).sum(axis=sum_axes)
    fy_side = (fy * c.wy[:, None]).sum(axis=sum_axes)
    mz_lat = (xk * fy * c.wy[:, None]).sum(axis=(-3, -2, -1))
    net = fx_side - problem.rolling[:, None, :]  # rolling resistance against each side's motion
    s0 = x[..., 0]
    cfx, cfy = centrifugal(problem.centrifugal_terms, s0)
    out = np.empty((*s0.shape, 3))
    out[..., 0] = net.sum(axis=-1) + cfx  # sum F_x = 0
    e2 = fy_side.sum(axis=-1) + cfy  # sum F_y = 0
    out[..., 2] = mz_lat - net @ problem.side_y - s0 * cfy  # sum M_z about the turning centre
    # straight running has no lateral force and s0 is free; the kernel runs these points at a tiny
    # yaw rate and the lateral balance is scaled up by 1/STRAIGHT_YAW, so s0 takes its limit as
    # R -> inf (continuous across w_z = 0 in a map) while torques differ by O(STRAIGHT_YAW^2).
    out[..., 1] = e2 * problem.lateral_scale[:, None]
    return out, fx


# --------------------------------------------------------------------------------------------------
# Batched damped Newton-Raphson (eqs. 3.20-3.22)
# --------------------------------------------------------------------------------------------------


def initial_guess(problem: Problem) -> np.ndarray:
    """x0 (P, 3): no-slip side speeds (eq. 3.21) and Steeds' s0 = V w_z l / (2 mu g) (eq. 3.7).

    mu = GUESS_FRICTION stands in for the unknown mu_t; s0 is kept inside a quarter of the contact span.
    """
    r = problem.radius
    omega = problem.side_speed / r
    if problem.terrain.is_rigid:  # a driving slip orients the friction (rigid_contact)
        from skidsteer_power.models.rigid_contact import straight_slip_guess

        omega = omega * (1.0 + straight_slip_guess(problem.vehicle, problem.terrain))
    s0 = steeds_s0(problem.speed, np.abs(problem.yaw), problem.contact.length_scale)
    return np.column_stack([s0, omega])


def _limit(problem: Problem, idx: np.ndarray, x: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Each Newton step (M, 3) of the points ``idx`` inside the trust region (:func:`~skidsteer_power.
    models.newton.trust_scale`)."""
    ref = problem.omega_ref[idx]
    scale = trust_scale(
        problem.contact.length_scale, ref, (x[:, 0], x[:, 1], x[:, 2]), (step[:, 0], step[:, 1], step[:, 2])
    )
    limited: np.ndarray = step / scale[:, None]
    return limited


def _steps(problem: Problem, x: np.ndarray) -> np.ndarray:
    """Finite-difference steps (P, 3) for the Jacobian of eq. 3.22 (:func:`~skidsteer_power.models.
    newton.fd_steps`)."""
    h = np.empty_like(x)
    h[:, 0], h[:, 1], h[:, 2] = fd_steps(problem.contact.length_scale, problem.omega_ref, x[:, 1], x[:, 2])
    return h


_UNKNOWNS = np.arange(3)
_PERTURBED = _UNKNOWNS + 1


def newton(
    problem: Problem, x0: np.ndarray, tol: float = FORCE_TOL_N, fixed: np.ndarray | None = None
) -> NewtonResult:
    """Damped Newton on all points at once (eqs. 3.20-3.22): the iteration of
    :func:`skidsteer_power.models.newton.newton_solve`, specialised to FESS's residual.

    Each iteration is ONE batched residual call over the points not yet converged, evaluating every
    state together with its three forward-difference perturbations (eq. 3.22). A step that does not
    reduce the largest residual is halved (backtracking) before the Jacobian is refreshed.
    """
    x = x0.astype(float).copy()
    p = len(x)
    done = np.zeros(p, dtype=bool) if fixed is None else fixed.copy()
    gave_up = np.zeros(p, dtype=bool)
    x_prev = x.copy()
    norm_prev = np.full(p, np.inf)
    step_prev = np.zeros_like(x)
    halvings = np.zeros(p, dtype=int)
    f = np.full_like(x, np.nan)
    iterations = np.zeros(p, dtype=int)
    for _ in range(MAX_ITERATIONS):
        act = np.flatnonzero(~(done | gave_up))
        if act.size == 0:
            break
        iterations[act] += 1
        whole = act.size == p  # no index bookkeeping while every point is still iterating
        sub = problem if whole else problem.take(act)
        xa = x[act]
        h = _steps(sub, xa)
        trial = np.repeat(xa[:, None, :], 4, axis=1)
        trial[:, _PERTURBED, _UNKNOWNS] += h  # state k+1 has unknown k perturbed (eq. 3.22)
        fall = residual(sub, trial)
        fa = fall[:, 0]
        f[act] = fa
        norm = np.max(np.abs(fa), axis=1)
        finite = norm < np.inf  # False for inf and nan
        norm = np.where(finite, norm, np.inf)
        ok = norm < tol
        worse = ~ok & (norm >= norm_prev[act])
        if ok.any():
            done[act[ok]] = True
        if worse.any():
            gave_up[act[worse & (halvings[act] >= MAX_HALVINGS)]] = True
            back = act[worse & (halvings[act] < MAX_HALVINGS)]  # backtrack: halve the last step
            step_prev[back] *= 0.5
            x[back] = x_prev[back] + step_prev[back]
            halvings[back] += 1
        good = ~ok & ~worse & finite
        if not good.any():
            continue
        sel = slice(None) if good.all() else good  # all: views, no copies (the common case)
        idx, fg, ng = act[sel], fa[sel], norm[sel]
        jac = (fall[sel, 1:] - fa[sel, None, :]).transpose(0, 2, 1) / h[sel, None, :]
        step = solve3(jac, -fg)
        xi = x[idx]
        step = _limit(problem, idx, xi, step)
        x_prev[idx] = xi
        norm_prev[idx] = ng
        step_prev[idx] = step
        halvings[idx] = 0
        x[idx] = xi + step
    return NewtonResult(x, f, done, iterations)


# --------------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------------


class FessSolver:
    """FESS for one vehicle and terrain, prepared once; :meth:`solve_twist` is the batched solve.

    ``n`` is the number of elements per contact (eq. 6.5). Holding a solver avoids re-checking the
    vehicle on every call and keeps the single-wheel table warm; :meth:`solve_point` is the lean
    single-point path for on-board use (about 0.3 ms for a track: benchmarks/bench_fess.py).
    """

    def __init__(
        self, vehicle: Vehicle, terrain: Terrain, n: int = DEFAULT_ELEMENTS, *, path_law: bool = False
    ) -> None:
        """``path_law``: the shear displacement of every element is its slip path along its slip
        velocity (:func:`~skidsteer_power.models.rigid_contact.slip_path_displacement`) instead of
        eq. 6.6's chord; always so on rigid ground; on soil the set-point solve's pivot band uses it
        (:mod:`~skidsteer_power.models.setpoint`)."""
        if not isinstance(n, (int, np.integer)) or n < 2:
            raise InputError(f'number of FESS elements must be an integer >= 2, got {n!r}')
        self.vehicle = vehicle
        self.terrain = terrain
        self.n = int(n)
        self.path_law = bool(path_law) or terrain.is_rigid

    def problem(self, speed: np.ndarray, yaw: np.ndarray) -> Problem:
        """Set up the batch (V >= 0 required here; :meth:`solve_twist` mirrors reverse points)."""
        return build_problem(self.vehicle, self.terrain, self.n, self.path_law, speed, yaw)

    def solve_twist(
        self, speed: ArrayLike, yaw_rate: ArrayLike, *, x0: np.ndarray | None = None, tol: float = FORCE_TOL_N
    ) -> TwistSolution:
        """Solve all (V [m/s], w_z [rad/s]) points at once (broadcast, flattened to P points).

        ``x0`` (P, 3) warm-starts the Newton iteration with (s0, omega_left, omega_right) of the
        forward-driving frame (e.g. :attr:`TwistSolution.state` of neighbours).
        """
        v, w = _twist_arrays(speed, yaw_rate)
        reverse = v < 0
        v_fwd = np.abs(v)
        w_fwd = np.where(reverse, -w, w)  # fore-aft mirror: (-V, w) == (V, -w) with omega negated
        prob = self.problem(v_fwd, w_fwd)
        guess = initial_guess(prob)
        if x0 is not None:
            x0 = np.where(reverse[:, None], -np.asarray(x0, dtype=float), x0)  # into the forward frame
            guess = np.where(np.isfinite(x0), x0, guess)
        standing = (v_fwd == 0) & (w_fwd == 0)  # at rest: nothing to solve, every output 0
        result = newton(prob, guess, tol, fixed=standing)
        for _ in range(RETRY_ROUNDS):
            if not self._retry_from_neighbours(prob, result, tol):
                break
        sol = _outputs(prob, result, standing)
        sol.yaw_rate = w_fwd
        return _mirror_reverse(sol, reverse, v, w)

    def solve_point(
        self, speed: float, yaw_rate: float, *, x0: np.ndarray | None = None, tol: float = FORCE_TOL_N
    ) -> PointSolution:
        """One operating point (V [m/s], w_z [rad/s]) on the lean path for on-board use.

        Same equations, solver and answers as :meth:`solve_twist` (test_fess_track.py compares
        them) for one point, without the neighbour retries (:mod:`~skidsteer_power.models.fess_point`).
        ``x0`` = (s0, omega_left, omega_right) warm-starts it, e.g. with the previous command's
        :attr:`PointSolution.state` (used where it can save steps: :func:`fess_point._warm_start
        <skidsteer_power.models.fess_point._warm_start>`; elsewhere the same work as a cold solve).
        """
        return fess_point.solve_point(self, speed, yaw_rate, x0, tol)

    @cached_property
    def straight_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(V [m/s], s0 [m], slip [-]) of straight running at 13 speeds from 0 to 1.2 x max_speed:
        one batched solve on first use, the first guess of :meth:`solve_point` (measured: cold solves
        of random commands take about half the Newton steps from it; benchmarks/bench_fess.py)."""
        top = 1.2 * float(getattr(self.vehicle, 'max_speed_m_s', 1.5) or 1.5)
        speeds = np.concatenate([[0.0], np.geomspace(0.01, top, 12)])
        sol = self.solve_twist(speeds[1:], 0.0)
        ok = sol.converged
        s0 = np.concatenate([[0.0], np.where(ok, sol.s0, np.nan)])
        slip = np.concatenate([[0.0], np.where(ok, sol.slip[:, 0], np.nan)])
        good = np.isfinite(s0) & np.isfinite(slip)
        return speeds[good], s0[good], slip[good]

    def _retry_from_neighbours(self, prob: Problem, result: NewtonResult, tol: float) -> bool:
        """Re-solve failed points warm-started from the nearest converged point (in V and w_z scaled
        by their spans): the warm start along the grid. Updates ``result``; False if nothing to do."""
        failed = np.flatnonzero(~result.converged)
        good = np.flatnonzero(result.converged)
        if len(failed) == 0 or len(good) == 0:
            return False
        span = np.array([np.ptp(prob.speed) or 1.0, np.ptp(prob.yaw) or 1.0])
        pts = np.column_stack([prob.speed, prob.yaw]) / span
        dist = np.linalg.norm(pts[failed, None, :] - pts[None, good, :], axis=2)
        x0 = result.x[good[np.argmin(dist, axis=1)]]
        sub = self.problem(
            prob.speed[failed], np.where(prob.lateral_scale[failed] > 1, 0.0, prob.yaw[failed])
        )
        again = newton(sub, x0, tol)
        fixed = again.converged
        if not np.any(fixed):
            return False
        result.x[failed[fixed]] = again.x[fixed]
        result.residual[failed[fixed]] = again.residual[fixed]
        result.converged[failed[fixed]] = True
        return True


def _twist_arrays(speed: ArrayLike, yaw_rate: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    v, w = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(yaw_rate, dtype=float))
    v, w = v.ravel().copy(), w.ravel().copy()
    if np.any(~np.isfinite(v)) or np.any(~np.isfinite(w)):
        raise InputError('speed and yaw rate must be finite numbers (m/s, rad/s)')
    return v, w


def _outputs(prob: Problem, result: NewtonResult, standing: np.ndarray) -> TwistSolution:
    c = prob.contact
    x = result.x
    fx, fy, _ = element_forces(prob, x[:, None, :])
    thrust = np.sum(fx * c.wx[:, None], axis=(-2, -1))[:, 0]
    lateral = np.sum(fy * c.wy[:, None], axis=(-2, -1))[:, 0]
    torque = prob.radius * np.sum(fx * c.wt[:, None], axis=(-2, -1))[:, 0]  # shear about the axle
    # F_max per side, eq. 2.12 (F_max = c A + W tan(phi) of eq. 2.2 summed over the side's contacts).
    # tau_max and wx describe ONE wheel (gear axis of size 1); the thrust above sums all G gears (fx
    # broadcasts over ``centre``), so the capacity must too, or a side with k wheels reports k times
    # the required / available ratio. ones_like(centre) spreads one wheel's strength over every axle.
    capacity = np.sum(c.tau_max * c.wx * np.ones_like(c.centre), axis=(-2, -1))
    with np.errstate(invalid='ignore', divide='ignore'):
        margin = 1.0 - np.max(np.abs(thrust) / capacity, axis=1)  # 1 - required / available thrust
    omega = x[:, 1:]
    slip = slip_ratio(prob.side_speed, omega * prob.radius)
    rest = standing[:, None]
    omega, torque, thrust, lateral, slip = (
        np.where(rest, 0.0, a) for a in (omega, torque, thrust, lateral, slip)
    )
    margin = np.where(standing, 1.0, margin)
    x = np.where(rest, 0.0, x)
    # a side spinning at |slip| > SLIP_LIMIT means its thrust saturated before the balance was met:
    # the residual then creeps below the tolerance only as omega runs away, which is no steady state
    physical = np.all(np.abs(slip) <= SLIP_LIMIT, axis=1)
    if prob.terrain.is_rigid:
        # on rigid ground a side may turn backwards while it moves forwards over the ground (|slip|
        # = 1: a tight turn's inner side, issue 36) and still hold a steady state; a runaway is a
        # side whose thrust has reached its friction ceiling (the margin's 0), not a slip ratio
        physical = margin > RIGID_MARGIN_MIN
    converged = (result.converged & physical | standing) & np.all(prob.loads > 0, axis=1)
    return TwistSolution(
        speed=prob.speed,
        yaw_rate=prob.yaw,
        s0=x[:, 0],
        omega=omega,
        torque=torque,
        thrust=thrust,
        lateral=lateral,
        slip=slip,
        sinkage=np.max(c.sinkage, axis=1),
        traction_margin=margin,
        converged=converged,
        residual=result.residual,
        iterations=result.iterations,
    )


def _mirror_reverse(sol: TwistSolution, reverse: np.ndarray, v: np.ndarray, w: np.ndarray) -> TwistSolution:
    """Map solutions of the mirrored forward problem back to reverse driving (see module doc)."""
    if not np.any(reverse):
        return sol
    flip = np.where(reverse, -1.0, 1.0)
    sol.speed, sol.yaw_rate = v, w
    sol.s0 = sol.s0 * flip
    sol.omega = sol.omega * flip[:, None]
    sol.torque = sol.torque * flip[:, None]
    sol.thrust = sol.thrust * flip[:, None]
    return sol


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: ArrayLike,
    turn_radius: ArrayLike,
    *,
    n: int = DEFAULT_ELEMENTS,
    raise_on_failure: bool | None = None,
    tol: float = FORCE_TOL_N,
    **options: object,
) -> SteadyState:
    """FESS steady state at forward speed V [m/s] and signed turning radius R [m] (inf = straight).

    Arrays broadcast; the whole batch is one Newton solve. A scalar call raises ConvergenceError
    naming (V, R) if it fails; a batch marks failures ``converged=False`` unless
    ``raise_on_failure=True`` - also when the contact cannot be set up at all (e.g. a wheel that
    cannot roll free on the soil: no root of eq. 2.29 for the free-wheel table). ``n`` is the
    number of contact elements per track or wheel.
    """
    if options:
        raise InputError(f'unknown FESS option(s): {", ".join(sorted(options))}')
    v, r = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(turn_radius, dtype=float))
    shape = v.shape
    v, r = v.ravel(), r.ravel()
    if np.any(~np.isfinite(v)) or np.any(np.isnan(r)) or np.any(r == 0):
        raise InputError('speed must be finite and the turning radius non-zero (inf = straight)')
    yaw = np.where(np.isinf(r), 0.0, v / np.where(np.isinf(r), 1.0, r))
    if raise_on_failure is None:
        raise_on_failure = shape == ()
    start = time.perf_counter()
    try:
        sol = FessSolver(vehicle, terrain, n).solve_twist(v, yaw, tol=tol)
    except ConvergenceError:
        if raise_on_failure:
            raise
        return reshape_state(SteadyState.unsolved(v, r, 'fess'), shape)
    elapsed = time.perf_counter() - start
    state = to_steady_state(sol, r, elapsed)
    if raise_on_failure and not np.all(state.converged):
        k = int(np.flatnonzero(~state.converged)[0])
        raise ConvergenceError(
            f'FESS did not converge at V = {v[k]:.6g} m/s, R = {r[k]:.6g} m on {terrain.name!r} '
            f'(residuals {np.array2string(sol.residual[k], precision=3)})'
        )
    return reshape_state(state, shape)
