"""FESS's one-point Newton for on-board use (:meth:`FessSolver.solve_point
<skidsteer_power.models.fess.FessSolver.solve_point>`), and its warm start.

The iteration is :func:`skidsteer_power.models.fess.newton`'s (eqs. 3.20-3.22), written for one
point without the batch bookkeeping: the residual of eq. 3.19 is :class:`PointKernel`'s, the same
equations as :func:`~skidsteer_power.models.fess.residual` laid out for one point, and the Newton
step, trust region and stopping rule are computed in Python floats.

Why a second layout of the same residual (issue 25, docs/PREDICTION.md "Speed"): one point's
arrays are tiny (2 sides x 41 elements for a track), so a residual call costs its number of numpy
operations, not its number of elements. The batched residual spends about 60 operations on 5-D
broadcasts; the kernel about 25 on (side, row, element) arrays. A row is one side at one (s0,
omega): a side's elements depend only on s0 and that side's own speed, so the state and its three
forward-difference perturbations of eq. 3.22 need three rows per side (not four states x two
sides), and everything that does not depend on the trial state (element positions, the half turn
rate of eq. 6.3, strength x area weights) is built once per command.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.models.fess_problem import (
    FORCE_TOL_N,
    SLIP_LIMIT,
    Problem,
    build_problem,
    centrifugal,
    chord_displacement,
    pivot_blend,
    rolling_direction,
    slip_ratio,
    steeds_s0,
)
from skidsteer_power.models.fess_steady import PointSolution
from skidsteer_power.models.newton import MAX_HALVINGS, MAX_ITERATIONS, fd_steps, solve3_floats, trust_scale
from skidsteer_power.models.rigid_contact import slip_path_displacement
from skidsteer_power.terramechanics.soil import shear_fraction_magnitude

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

STALL_ITERATIONS = 8  # newton_point: steps without STALL_GAIN progress before it gives up
STALL_GAIN = 1e-2  # relative decrease of the largest residual that counts as progress
WARM_MARGIN = 2.0  # _pick_start: a warm guess's scaled residual must be this much smaller
TIGHT_RATIO = 0.6  # _warm_start: a turn whose inner / outer side speed is below this is tight

State = tuple[float, float, float]  # (s0 [m], omega_left, omega_right [rad/s]) or residuals [N, N, N m]


class Solver(Protocol):
    """What the one-point path needs of :class:`~skidsteer_power.models.fess.FessSolver` (named
    here, so that this module does not import fess.py, which calls it)."""

    vehicle: Vehicle
    terrain: Terrain
    n: int
    path_law: bool

    @property
    def straight_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


class PointKernel:
    """The residual of eq. 3.19 at ONE operating point (a :class:`~skidsteer_power.models.fess.Problem`
    with P = 1), evaluated on rows: one row = one side's E elements (G gears x N nodes) at one trial
    (s0 [m], omega [rad/s]); arrays (2 sides, k rows, E). The same equations as
    :func:`~skidsteer_power.models.fess.residual` (eqs. 6.3-6.7 per element, trapezoid sums, eq.
    3.18's centrifugal force); the sums differ from it only by rounding (the same terms in another
    order)."""

    def __init__(self, problem: Problem) -> None:
        c = problem.contact
        gears, nodes = c.centre.shape[2], c.fwd.shape[-1]
        full = (1, 2, gears, nodes)
        per_side = (2, 1, gears * nodes)  # broadcasts against (2, k, E)
        # the trial-independent element arrays, each broadcast into its full shape by ``out=``
        geometry = np.empty((5, *full))
        np.subtract(c.entry, c.fwd, out=geometry[0])  # xi, distance behind the entry (eq. 6.1)
        geometry[0] *= 0.5 * float(problem.yaw[0])  # w_z xi / 2 (eqs. 6.3, 6.5)
        np.add(c.centre, c.fwd, out=geometry[1])  # element x from the CG [m], forward
        np.subtract(c.centre, c.fwd, out=geometry[2])  # ... mirrored (omega < 0: entry at the rear)
        np.add(c.centre, c.entry, out=geometry[3])  # its touch-down point, forward
        np.subtract(c.centre, c.entry, out=geometry[4])  # ... mirrored
        rows = geometry.reshape(5, *per_side)
        self._half_rate = rows[0]
        self._now, self._entry = (rows[1], rows[2]), (rows[3], rows[4])
        strength = np.empty((3, *full))  # -tau_max times the area weights [N]
        neg_tau = -c.tau_max
        np.multiply(neg_tau, c.wx, out=strength[0])
        np.multiply(neg_tau, c.wy, out=strength[1])
        np.multiply(neg_tau, c.wt, out=strength[2])
        self._strength = strength.reshape(3, *per_side)
        self._moment: dict[tuple[bool, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.problem = problem
        # the per-point terms of Problem's cached properties, in floats (fess.Problem)
        r = self.radius = float(problem.radius)
        self.longitudinal = float(c.longitudinal)
        v, w, half_tread = float(problem.speed[0]), float(problem.yaw[0]), float(problem.half_tread)
        self.side_y = (half_tread, -half_tread)  # fess.SIDE_Y_SIGN
        self.side_speed = (v - w * half_tread, v + w * half_tread)  # V - w_z y_side [m/s]
        # compaction (rolling) resistance against each side's motion over the ground [N], with the
        # pivot law's ramp at rest over the ground (fess_problem.rolling_direction)
        rolling_l, rolling_r = (c.resistance[0] * rolling_direction(problem)[0]).tolist()
        self.rolling = (float(rolling_l), float(rolling_r))
        turn_radius = v / w  # finite: straight points run at STRAIGHT_YAW
        self._offset = np.array(
            [[[half_tread - turn_radius]], [[-half_tread - turn_radius]]]
        )  # (2, 1, 1) [m]
        mass = float(problem.vehicle.mass_kg)
        self._centrifugal_terms = (v, w, abs(v), abs(w), -mass * abs(v * w), -mass * v * w)
        self.lateral_scale = float(problem.lateral_scale[0])
        self.rigid = problem.path_law and problem.terrain.is_rigid
        self.pivot_law = problem.path_law and not self.rigid  # soil's pivot band (fess_problem.pivot_blend)
        self._yaw = np.array(w)
        self.length = float(c.length_scale)
        self.omega_ref = max(abs(self.side_speed[0]), abs(self.side_speed[1]), 1e-3) / r
        self._last: tuple[State, np.ndarray, int] | None = None  # state x, q jx (2, k, E) of its rows

    def _positions(self, forward: list[bool], k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x now - x at touch-down and x at touch-down of the elements of every row [m], (2, 1|k, E),
        and the lateral force and moment weights (2, 2, 1|k, E) [N, N m]: a side turning backwards
        (omega < 0) enters the contact at the rear (the mirrored contact, module doc of fess.py)."""
        key = (True,) if all(forward) else tuple(forward)
        cached = self._moment.get(key)
        if cached is None:
            if key == (True,):
                now, entry = self._now[0], self._entry[0]
            else:
                mask = np.array(forward).reshape(2, k, 1)
                now = np.where(mask, self._now[0], self._now[1])
                entry = np.where(mask, self._entry[0], self._entry[1])
            lateral = self._strength[1]
            # sum M_z of the lateral forces: sum (x_now - s0) f_y w_y = sum x_now f_y w_y - s0 F_y
            weights = np.stack(np.broadcast_arrays(lateral, lateral * now))
            cached = self._moment[key] = (now - entry, entry, weights)
        return cached

    def rows(self, s0: list[float], omega: list[float], at: State | None = None) -> list[list[list[float]]]:
        """Force sums of 2k rows (k left, then k right) at trial (s0 [m], omega [rad/s]) per row:
        [F_x, F_y, M_z], each [left k floats, right k floats] [N, N, N m]; M_z is that of the lateral
        forces about the element x positions' origin (the CG); :meth:`combine` moves it to the
        turning centre. ``at``: the state whose rows are 0 and k (:meth:`torque` reuses them)."""
        k = len(omega) // 2
        r = self.radius
        trial = np.array([s0, [max(abs(o) * r, 1e-12) for o in omega]]).reshape(2, 2, k, 1)
        travel, entry, lateral = self._positions([o >= 0 for o in omega], k)
        # half the angle an element has turned since touch-down (eq. 6.3): w_z t / 2 with the time
        # in contact t = xi / (|omega| r) (eq. 6.5)
        half = self._half_rate / trial[1]
        xe = entry - trial[0]  # where the element touched down, relative to the turning centre
        if self.rigid:  # friction: the slip path, not eq. 6.6's chord (rigid_contact module doc)
            along = np.array(omega).reshape(2, k, 1) * -r + np.array(self.side_speed).reshape(2, 1, 1)
            jx, jy = slip_path_displacement(travel + xe, xe, along, self._yaw, trial[1])
        else:  # eq. 6.6; x_k - x_e (travel) does not depend on s0
            jx, jy = chord_displacement(travel, xe, self._offset, half)
            if self.pivot_law:  # the slip path past half a revolution (fess.element_displacement)
                blend = pivot_blend(half)
                along = np.array(omega).reshape(2, k, 1) * -r + np.array(self.side_speed).reshape(2, 1, 1)
                px, py = slip_path_displacement(travel + xe, xe, along, self._yaw, trial[1])
                jx, jy = jx + blend * (px - jx), jy + blend * (py - jy)
        if self.longitudinal != 1.0:  # a compliant belt: eq. 6.7 in the scaled displacement
            jx *= self.longitudinal
        j = np.hypot(jx, jy)
        # eq. 6.7 over |j|: the stress against the displacement; the fraction is 0 at j = 0
        q = shear_fraction_magnitude(self.problem.terrain, j) / np.maximum(j, 1e-300)
        qjx = q * jx
        fx: list[list[float]] = np.vecdot(qjx, self._strength[0]).tolist()
        fy, mz = np.vecdot(q * jy, lateral).tolist()
        self._last = None if at is None else (at, qjx, k)
        return [fx, fy, mz]

    def centrifugal(self, s0: float) -> tuple[float, float]:
        """:func:`~skidsteer_power.models.fess_problem.centrifugal` in floats: (x, y) force on the CG [N]."""
        return centrifugal(self._centrifugal_terms, s0)

    def combine(
        self,
        sums: list[list[list[float]]],
        s0: float,
        left: int,
        right: int,
        cf: tuple[float, float] | None = None,
    ) -> State:
        """Residuals of eq. 3.19 [N, N, N m] of the state at ``s0`` whose left side is row ``left``
        and right side row ``right`` of ``sums`` (:meth:`rows`); ``cf``: :meth:`centrifugal` at s0."""
        fx, fy, mz = sums
        net_l, net_r = fx[0][left] - self.rolling[0], fx[1][right] - self.rolling[1]
        lateral = fy[0][left] + fy[1][right]
        cfx, cfy = self.centrifugal(s0) if cf is None else cf
        y_l, y_r = self.side_y
        return (
            net_l + net_r + cfx,  # sum F_x = 0
            (lateral + cfy) * self.lateral_scale,  # sum F_y = 0 (scaled: fess.residual_and_forces)
            # sum M_z = 0 about the turning centre: the lateral forces' moment about it
            mz[0][left] + mz[1][right] - s0 * lateral - (net_l * y_l + net_r * y_r) - s0 * cfy,
        )

    def perturbed(self, x: State, h: State) -> list[State]:
        """Residuals at x and its three forward-difference perturbations (eq. 3.22), x + h_k e_k:
        three rows per side, (s0, omega), (s0 + h0, omega), (s0, omega + h)."""
        s0, wl, wr = x
        s1 = s0 + h[0]
        sums = self.rows([s0, s1, s0, s0, s1, s0], [wl, wl, wl + h[1], wr, wr, wr + h[2]], x)
        cf = self.centrifugal(s0)
        return [
            self.combine(sums, s0, 0, 0, cf),
            self.combine(sums, s1, 1, 1),
            self.combine(sums, s0, 2, 0, cf),
            self.combine(sums, s0, 0, 2, cf),
        ]

    def torque(self, x: State) -> np.ndarray:
        """(2,) axle torque [N m] of each side at state x: r times the elements' shear force about
        the axle (from the last evaluation if that was at x)."""
        if self._last is None or self._last[0] != x:
            self.rows([x[0], x[0]], [x[1], x[2]], x)
        assert self._last is not None
        qjx = self._last[1][:, 0]  # row 0 of each side: the state itself
        torque: np.ndarray = self.radius * np.vecdot(qjx, self._strength[2][:, 0])
        return torque


def newton_point(
    problem: Problem,
    x0: np.ndarray,
    tol: float = FORCE_TOL_N,
    *,
    alternatives: np.ndarray | None = None,
    kernel: PointKernel | None = None,
) -> tuple[np.ndarray, np.ndarray, bool, int]:
    """FESS's :func:`~skidsteer_power.models.fess.newton` for ONE operating point, without the batch
    bookkeeping (the on-board path).

    The same iteration, step by step: one residual evaluation per iteration on the state and its
    three forward-difference perturbations (eq. 3.22), the trust region of
    :func:`~skidsteer_power.models.fess._limit`, and halving of the last step when the largest
    residual does not drop (at most MAX_HALVINGS times). Returns (x, residual, converged,
    iterations). Unlike :func:`~skidsteer_power.models.fess.newton` it stops a point whose largest
    residual has not fallen by STALL_GAIN in STALL_ITERATIONS steps: where FESS has no steady state
    (tight turns) that used to cost all MAX_ITERATIONS steps (a tenth of 200 random commands, half of
    all their Newton steps).

    ``alternatives`` (k, 3): other first guesses (a warm start). The first iteration evaluates every
    guess with the cold guess's perturbations in one kernel call and goes on from the one
    :func:`_pick_start` prefers. ``kernel``: the point's :class:`PointKernel` (built if not given;
    :meth:`PointKernel.torque` then reuses the converged evaluation).
    """
    kern = PointKernel(problem) if kernel is None else kernel
    s0, wl, wr = (float(v) for v in x0)
    x: State = (s0, wl, wr)
    length, omega_ref = kern.length, kern.omega_ref
    x_prev, step_prev = x, (0.0, 0.0, 0.0)
    norm_prev, halvings = math.inf, 0
    best, best_at = math.inf, 0
    f: State = (math.nan, math.nan, math.nan)
    for iteration in range(1, MAX_ITERATIONS + 1):
        h = fd_steps(length, omega_ref, x[1], x[2])
        if iteration == 1 and alternatives is not None and alternatives.size:
            x, h, fall = _pick_start(kern, x, h, alternatives)
        else:
            fall = kern.perturbed(x, h)
        f = fall[0]
        norm = _max_abs(f)
        if norm < tol:
            return np.array(x), np.array(f), True, iteration
        if norm < (1.0 - STALL_GAIN) * best:
            best, best_at = norm, iteration
        elif iteration - best_at >= STALL_ITERATIONS:  # no root here: stop (not converged)
            return np.array(x), np.array(f), False, iteration
        if norm >= norm_prev:  # backtrack: halve the last step
            if halvings >= MAX_HALVINGS:
                return np.array(x), np.array(f), False, iteration
            step_prev = (0.5 * step_prev[0], 0.5 * step_prev[1], 0.5 * step_prev[2])
            x = (x_prev[0] + step_prev[0], x_prev[1] + step_prev[1], x_prev[2] + step_prev[2])
            halvings += 1
            continue
        # eq. 3.22: jac[i][k] = (F_i(x + h_k e_k) - F_i(x)) / h_k
        jac = [[(fall[k + 1][i] - f[i]) / h[k] for k in range(3)] for i in range(3)]
        step = solve3_floats(jac, (-f[0], -f[1], -f[2]))
        scale = trust_scale(length, omega_ref, x, step)
        step = (step[0] / scale, step[1] / scale, step[2] / scale)
        x_prev, norm_prev, step_prev, halvings = x, norm, step, 0
        x = (x[0] + step[0], x[1] + step[1], x[2] + step[2])
    return np.array(x), np.array(f), False, MAX_ITERATIONS


def _max_abs(f: State) -> float:
    """Largest |f_i|; inf if any is NaN or inf (a failed evaluation never looks converged)."""
    a, b, c = abs(f[0]), abs(f[1]), abs(f[2])
    if not (a < math.inf and b < math.inf and c < math.inf):
        return math.inf
    return max(a, b, c)


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
    kernel: PointKernel, x: State, h: State, alternatives: np.ndarray
) -> tuple[State, State, list[State]]:
    """Evaluate ``x`` with its perturbations and every alternative (unperturbed) in ONE kernel call;
    keep the one with the smallest residual (forces over the weight, the moment over weight x contact
    span), an alternative only if that is under 1 / WARM_MARGIN of ``x``'s. Returns (x, steps,
    residuals of x and its perturbations).

    Only a chosen alternative's perturbations cost a second call: evaluating all of them up front
    made a warm start slower than a cold one at equal iterations (issue 25, docs/PREDICTION.md
    "Speed")."""
    alts: list[State] = [(float(a[0]), float(a[1]), float(a[2])) for a in alternatives]
    s0, wl, wr = x
    s1 = s0 + h[0]
    sums = kernel.rows(
        [s0, s1, s0, *(a[0] for a in alts), s0, s1, s0, *(a[0] for a in alts)],
        [wl, wl, wl + h[1], *(a[1] for a in alts), wr, wr, wr + h[2], *(a[2] for a in alts)],
        x,
    )
    fall = [
        kernel.combine(sums, s0, 0, 0),
        kernel.combine(sums, s1, 1, 1),
        kernel.combine(sums, s0, 2, 0),
        kernel.combine(sums, s0, 0, 2),
    ]
    weight = kernel.problem.vehicle.weight_N
    scale = (weight, weight * kernel.lateral_scale, weight * kernel.length)
    chosen, best = -1, _scaled_norm(fall[0], scale)
    for i, alt in enumerate(alts):
        # a warm guess must beat the physics guess clearly to be taken
        norm = _scaled_norm(kernel.combine(sums, alt[0], 3 + i, 3 + i), scale) * WARM_MARGIN
        if norm < best:
            chosen, best = i, norm
    if chosen < 0:
        return x, h, fall
    start = alts[chosen]
    omega_ref = kernel.omega_ref
    steps = fd_steps(kernel.length, omega_ref, start[1], start[2])
    return start, steps, kernel.perturbed(start, steps)


def _scaled_norm(f: State, scale: State) -> float:
    """max |f_i| / scale_i; inf if any is NaN or inf (never chosen)."""
    a, b, c = abs(f[0]) / scale[0], abs(f[1]) / scale[1], abs(f[2]) / scale[2]
    if not (a < math.inf and b < math.inf and c < math.inf):
        return math.inf
    return max(a, b, c)


# --------------------------------------------------------------------------------------------------
# The one-point solve: FessSolver.solve_point
# --------------------------------------------------------------------------------------------------


def point_problem(solver: Solver, v: float, w: float) -> Problem:
    """:meth:`FessSolver.problem <skidsteer_power.models.fess.FessSolver.problem>` for ONE point
    (V >= 0 [m/s], w_z [rad/s]): :func:`~skidsteer_power.models.fess_problem.build_problem` with P = 1."""
    return build_problem(
        solver.vehicle, solver.terrain, solver.n, solver.path_law, np.array([v]), np.array([w])
    )


def first_guess(solver: Solver, kernel: PointKernel) -> State:
    """(s0, omega_left, omega_right) to start the point's Newton from: no-slip side speeds (eq.
    3.21) raised by the straight-running slip at this speed, and s0 of straight running faded by
    V^2 / (V^2 + (w_z l / 2)^2) towards 0 for a spin (s0 = 0 by symmetry), both from
    :attr:`FessSolver.straight_table <skidsteer_power.models.fess.FessSolver.straight_table>`
    (measured: cold solves of random commands take about half the Newton steps from it); without
    the table Steeds' s0 = V w_z l / (2 mu g) (eq. 3.7, mu = 0.5) as
    :func:`~skidsteer_power.models.fess.initial_guess`."""
    v, w, _, abs_w, _, _ = kernel._centrifugal_terms
    length, r = kernel.length, kernel.radius
    omega_l, omega_r = kernel.side_speed[0] / r, kernel.side_speed[1] / r
    speeds, s0_table, slip_table = solver.straight_table
    if speeds.size < 2:
        return (steeds_s0(v, abs_w, length), omega_l, omega_r)
    half_span = 0.5 * length * w
    fade = v * v / (v * v + half_span * half_span) if v != 0 else 0.0
    raise_by = 1.0 - min(float(np.interp(v, speeds, slip_table)), 0.9)
    return (float(np.interp(v, speeds, s0_table)) * fade, omega_l / raise_by, omega_r / raise_by)


def solve_point(
    solver: Solver, speed: float, yaw_rate: float, x0: np.ndarray | None, tol: float
) -> PointSolution:
    """:meth:`FessSolver.solve_point <skidsteer_power.models.fess.FessSolver.solve_point>`: one
    operating point (V [m/s], w_z [rad/s]) on the lean path."""
    v, w = float(speed), float(yaw_rate)
    if not (math.isfinite(v) and math.isfinite(w)):
        raise InputError('speed and yaw rate must be finite numbers (m/s, rad/s)')
    flip = -1.0 if v < 0 else 1.0  # reverse: the fore-aft mirror image (module doc of fess.py)
    v, w = abs(v), w * flip
    if v == 0 and w == 0:
        zero = np.zeros(2)
        return PointSolution(0.0, zero, zero.copy(), True, 0)
    problem = point_problem(solver, v, w)
    kernel = PointKernel(problem)
    guess = np.array(first_guess(solver, kernel))
    others = None if x0 is None else _warm_start(kernel, guess, np.asarray(x0, dtype=float) * flip)
    x, _, converged, iterations = newton_point(problem, guess, tol, alternatives=others, kernel=kernel)
    s0, omega_l, omega_r = x.tolist()
    torque = kernel.torque((s0, omega_l, omega_r))
    r = kernel.radius
    slips = (slip_ratio(kernel.side_speed[0], omega_l * r), slip_ratio(kernel.side_speed[1], omega_r * r))
    physical = all(abs(s) <= SLIP_LIMIT for s in slips)  # NaN slip: not physical (eq. 2.13)
    ok = converged and physical and bool((problem.loads > 0).all())
    return PointSolution(s0 * flip, x[1:] * flip, torque * flip, ok, iterations)


def _warm_start(kernel: PointKernel, cold: np.ndarray, warm: np.ndarray) -> np.ndarray | None:
    """The warm alternatives (:func:`warm_alternatives`) worth evaluating for this point, or None.

    Only for wheels, and only when this command AND the previous state are tight turns the same way
    (inner / outer side speed below TIGHT_RATIO). Elsewhere the physics guess starts Newton as well
    as the previous state does (3-4 residual calls from either), so evaluating the alternatives
    would only cost time (issue 25: a warm start never costs more than a cold one). Measured on
    200-command random walks (docs/PREDICTION.md, "Speed"): in consecutive tight turns, where a cold
    solve takes 10-30 steps, the previous state cut packbot_4wheel's steps from 12.4 to 9.2 per
    command and test_robot_6wheel's from 5.75 to 5.53, but raised both tracks' cost in residual
    rows by 1-4 % (test_robot_track's steps 5.26 -> 5.34): a track's tight turns lie next to the
    pivot band, where the previous state is often on the other branch."""
    if kernel.problem.vehicle.is_tracked:
        return None
    ss_l, ss_r = kernel.side_speed
    wl, wr = float(warm[1]), float(warm[2])
    if not (
        min(ss_l, ss_r) < TIGHT_RATIO * max(abs(ss_l), abs(ss_r))
        and min(wl, wr) < TIGHT_RATIO * max(abs(wl), abs(wr))
        and (wr - wl) * (ss_r - ss_l) > 0
    ):
        return None
    return warm_alternatives(cold, warm)
