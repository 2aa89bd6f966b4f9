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
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.fess_contact import Contact, track_contact, wheel_contact
from skidsteer_power.models.fess_contact import _free_wheel_table as _free_wheel_table
from skidsteer_power.models.fess_steady import reshape_state, to_steady_state
from skidsteer_power.models.loads import OperatingPoints, side_loads
from skidsteer_power.models.newton import MAX_ITERATIONS, TOLERANCE, NewtonResult
from skidsteer_power.terramechanics.soil import shear_fraction
from skidsteer_power.vehicle import GRAVITY_M_S2

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

GUESS_FRICTION = 0.5  # [-] mu standing in for the unknown mu_t in Steeds' s0 guess (eq. 3.7)
STEEDS_S0_SCALE = 1.0 / (2.0 * GUESS_FRICTION * GRAVITY_M_S2)  # [s^2/m]: s0 = V |w_z| l x this (eq. 3.7)
DEFAULT_ELEMENTS = 40  # elements per contact (eq. 6.5); see test_fess_track.py for the n study
FORCE_TOL_N = TOLERANCE  # stopping rule of section 3.3.1: |each equation of (3.19)| < 0.001 (N, N m)
MAX_HALVINGS = 12
RETRY_ROUNDS = 3  # warm-started re-solves of failed points from converged neighbours
SLIP_LIMIT = 0.95  # |slip| beyond this: the side cannot develop the thrust (no steady state)
RIGID_MARGIN_MIN = 0.01  # rigid ground: a side within 1 % of mu x its load has no steady state
STRAIGHT_YAW = 1e-9  # [rad/s] yaw rate at which straight-running points are solved (s0 limit)

SIDE_Y_SIGN = np.array([1.0, -1.0])  # left side at y = +B/2, right side at y = -B/2


# --------------------------------------------------------------------------------------------------
# The residual of eq. 3.18 over a batch of operating points and trial states
# --------------------------------------------------------------------------------------------------


@dataclass
class Problem:
    """Everything fixed for a batch of P operating points (forward speed V >= 0)."""

    vehicle: Vehicle
    terrain: Terrain
    speed: np.ndarray  # (P,) V >= 0 [m/s]
    yaw: np.ndarray  # (P,) signed yaw rate [rad/s]; straight points carry STRAIGHT_YAW (see residual)
    loads: np.ndarray  # (P, 2) left, right [N]
    contact: Contact
    radius: float  # drive radius r [m]
    half_tread: float  # B / 2 [m]
    lateral_scale: np.ndarray  # (P,) 1, or 1 / STRAIGHT_YAW [s] for straight points
    # the slip path (rigid_contact) for the shear displacement: on rigid ground everywhere, on soil
    # past half a revolution of an element (pivot_blend; the pivot band); else eq. 6.6's chord
    path_law: bool = False

    def take(self, idx: np.ndarray) -> Problem:
        """The sub-problem of the operating points ``idx``."""
        return Problem(
            self.vehicle,
            self.terrain,
            self.speed[idx],
            self.yaw[idx],
            self.loads[idx],
            self.contact.take(idx),
            self.radius,
            self.half_tread,
            self.lateral_scale[idx],
            self.path_law,
        )

    # fixed per batch and read on every residual call: computed once (cached_property)
    @cached_property
    def turn_radius(self) -> np.ndarray:
        """(P,) signed R = V / w_z [m] (0 when spinning in place)."""
        radius: np.ndarray = self.speed / self.yaw
        return radius

    @cached_property
    def side_speed(self) -> np.ndarray:
        """(P, 2) ground speed of each side's centreline along x, V - w_z y_side [m/s]."""
        ground_speed: np.ndarray = self.speed[:, None] - self.yaw[:, None] * SIDE_Y_SIGN * self.half_tread
        return ground_speed

    @cached_property
    def rolling(self) -> np.ndarray:
        """(P, 2) compaction resistance of each side, signed against its motion over the ground [N]."""
        resistance: np.ndarray = self.contact.resistance * rolling_direction(self)
        return resistance

    @cached_property
    def side_y(self) -> np.ndarray:
        """(2,) lateral position of each side's centreline, +B/2 (left), -B/2 (right) [m]."""
        return SIDE_Y_SIGN * self.half_tread

    @cached_property
    def centre_offset(self) -> np.ndarray:
        """(P, 1, 2, 1, 1) lateral distance of each side's centreline from the turning centre O = (0, R)
        [m]; R = V / w_z is finite because straight points run at STRAIGHT_YAW, 0 spinning in place."""
        radius = self.turn_radius[:, None, None, None, None]
        offset: np.ndarray = self.side_y[None, None, :, None, None] - radius
        return offset

    @cached_property
    def half_turn_rate(self) -> np.ndarray:
        """(P, 1, 2|1, G, N) w_z xi / 2 [m rad/s]: divided by the rim speed |omega| r it is half the
        angle an element has turned since it touched down (eqs. 6.3, 6.5)."""
        rate: np.ndarray = (0.5 * self.yaw[:, None, None, None] * self.contact.xi)[:, None]
        return rate

    @cached_property
    def element_x(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each element's x now and at touch-down from the CG [m], forward (omega >= 0) and mirrored:
        (centre + fwd, centre - fwd, centre + entry, centre - entry), each (P|1, 1, 2|1, G, N|1).
        :func:`element_displacement` picks per side (the same sums, built once per batch)."""
        c = self.contact
        fwd, entry = c.fwd[:, None], c.entry[:, None]
        return c.centre + fwd, c.centre + -1.0 * fwd, c.centre + entry, c.centre + -1.0 * entry

    @cached_property
    def centrifugal_terms(self) -> tuple[np.ndarray, ...]:
        """(P, 1) V, w_z, |V|, |w_z| and -m |V w_z|, -m V w_z [N]: the parts of eq. 3.18 that do not
        depend on the trial state (:func:`_centrifugal`)."""
        v, w = self.speed[:, None], self.yaw[:, None]
        mass = self.vehicle.mass_kg
        return v, w, np.abs(v), np.abs(w), -mass * np.abs(v * w), -mass * v * w

    @cached_property
    def omega_ref(self) -> np.ndarray:
        """(P,) reference wheel speed [rad/s]: the faster side's no-slip speed, at least 1 mm/s / r
        (scales the Newton steps and their trust region)."""
        reference: np.ndarray = np.maximum(np.max(np.abs(self.side_speed), axis=1), 1e-3) / self.radius
        return reference


# The pivot band's shear law on soil (``FessSolver(path_law=True)``, docs/PREDICTION.md "The pivot
# band"): an element keeps eq. 6.6's chord until it has turned half a revolution since touch-down
# (eq. 6.3: w_z t = pi, where the chord is longest), then its displacement blends linearly into its
# slip path (rigid_contact.slip_path_displacement) over the next PIVOT_BLEND_REV of a revolution.
PIVOT_BLEND_REV = 0.125


PIVOT_REST_SPEED_M_S = 1e-3


def rolling_direction(problem: Problem) -> np.ndarray:
    """(P, 2) the compaction resistance's direction factor per side [-]: sign(v_side) (against the
    motion over the ground); in the pivot law on soil clip(v_side / PIVOT_REST_SPEED_M_S, -1, 1),
    because a side at rest over the ground (a pivot's inner side, its ground speed crossing 0) holds
    any resistance in [-R_c, R_c], as static friction does, and the sign's jump left a gap of set
    points without a root (docs/PREDICTION.md, "The pivot band")."""
    v = problem.side_speed
    if problem.path_law and not problem.terrain.is_rigid:
        ramp: np.ndarray = np.clip(v / PIVOT_REST_SPEED_M_S, -1.0, 1.0)
        return ramp
    direction: np.ndarray = np.sign(v)
    return direction


def pivot_blend(half: np.ndarray) -> np.ndarray:
    """The slip path's weight in an element's shear displacement (0: eq. 6.6's chord, 1: the slip
    path), from ``half`` = w_z t / 2 [rad], half the angle it turned since touch-down (eq. 6.3):
    0 up to half a revolution, 1 from 0.5 + PIVOT_BLEND_REV rev on."""
    weight: np.ndarray = np.clip((np.abs(half) - 0.5 * np.pi) / (np.pi * PIVOT_BLEND_REV), 0.0, 1.0)
    return weight


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
    dy = problem.centre_offset
    sh, ch = np.sin(half), np.cos(half)
    twice_sh = 2.0 * sh
    sin, one_minus_cos = twice_sh * ch, twice_sh * sh
    fwd_plus, fwd_minus, entry_plus, entry_minus = problem.element_x
    xk = np.where(forward, fwd_plus, fwd_minus) - s0  # element now, relative to the turning centre
    xe = np.where(forward, entry_plus, entry_minus) - s0  # where it touched down
    # eq. 6.6: J = p_k - Rot(-theta) p_e with p = (x, dy); 1 - cos written as 2 sin^2 (no cancellation)
    jx = xk - xe + one_minus_cos * xe - dy * sin
    jy = dy * one_minus_cos + xe * sin
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


def _centrifugal(problem: Problem, s0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centrifugal force components (x, y) on the CG [N], eq. 3.18: m V^2/R (-sin beta, -cos beta)."""
    v, w, abs_v, abs_w, force_x, force_y = problem.centrifugal_terms
    q = np.hypot(v, w * s0)
    # beta = atan(s0 / R); at q = 0 (V = 0) both forces vanish whatever beta
    safe = np.where(q > 0, q, 1.0)
    sin_b = s0 * abs_w / safe
    cos_b = abs_v / safe
    return force_x * sin_b, force_y * cos_b


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
    cfx, cfy = _centrifugal(problem, s0)
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
    s0 = problem.speed * np.abs(problem.yaw) * problem.contact.length_scale * STEEDS_S0_SCALE
    s0 = np.minimum(s0, 0.25 * problem.contact.length_scale)
    return np.column_stack([s0, omega])


def _steps(problem: Problem, x: np.ndarray) -> np.ndarray:
    """Finite-difference steps (P, 3) for the Jacobian of eq. 3.22."""
    h = np.empty_like(x)
    h[:, 0] = 1e-7 * problem.contact.length_scale
    h[:, 1:] = 1e-7 * np.maximum(np.abs(x[:, 1:]), problem.omega_ref[:, None])
    return h


def _solve3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve the batched 3x3 systems a x = b; x = 0 where a is singular (|det| below 1e-14 of the
    product of its row norms)."""
    det = np.linalg.det(a)
    ok = np.abs(det) > 1e-14 * np.prod(np.linalg.norm(a, axis=2), axis=1)
    if ok.all():
        return np.linalg.solve(a, b[..., None])[..., 0]
    out = np.zeros_like(b)
    if ok.any():
        out[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    return out


def _limit(problem: Problem, idx: np.ndarray, x: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Scale each Newton step so s0 moves < 20 % of the contact span and omega < 50 % (trust region)."""
    caps = np.empty_like(x)
    caps[:, 0] = 0.2 * problem.contact.length_scale
    caps[:, 1:] = 0.5 * np.maximum(np.abs(x[:, 1:]), problem.omega_ref[idx, None])
    ratio = np.max(np.abs(step) / caps, axis=1)
    limited: np.ndarray = step / np.maximum(ratio, 1.0)[:, None]
    return limited


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
        step = _solve3(jac, -fg)
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


@dataclass
class TwistSolution:
    """FESS steady state over a batch of (V, yaw rate) points, per side (left, right), SI units."""

    speed: np.ndarray  # V [m/s]
    yaw_rate: np.ndarray  # w_z [rad/s]
    s0: np.ndarray  # turning-centre offset along x, ahead of the CG [m] (negative in reverse)
    omega: np.ndarray  # (P, 2) [rad/s]
    torque: np.ndarray  # (P, 2) drive torque [N m]
    thrust: np.ndarray  # (P, 2) longitudinal shear force [N]
    lateral: np.ndarray  # (P, 2) lateral shear force [N]
    slip: np.ndarray  # (P, 2) [-] eq. 2.13
    sinkage: np.ndarray  # (P,) largest sinkage [m]
    traction_margin: np.ndarray  # (P,) [-]
    converged: np.ndarray  # (P,)
    residual: np.ndarray  # (P, 3)
    iterations: np.ndarray  # (P,) Newton steps per point

    @property
    def power(self) -> np.ndarray:
        """(P, 2) mechanical power torque * omega [W]."""
        power: np.ndarray = self.torque * self.omega
        return power

    @property
    def state(self) -> np.ndarray:
        """(P, 3) solver state (s0, omega_left, omega_right), forward-driving frame, for warm starts."""
        return np.column_stack([self.s0, self.omega])


@dataclass
class PointSolution:
    """One FESS steady state (left, right sides), SI units; see :meth:`FessSolver.solve_point`."""

    s0: float  # [m]
    omega: np.ndarray  # (2,) [rad/s]
    torque: np.ndarray  # (2,) [N m]
    converged: bool
    iterations: int

    @property
    def power(self) -> np.ndarray:
        """(2,) torque * omega [W]."""
        power: np.ndarray = self.torque * self.omega
        return power

    @property
    def state(self) -> np.ndarray:
        """(s0, omega_left, omega_right), to warm-start the next call."""
        return np.array([self.s0, *self.omega])


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
        veh = self.vehicle
        pts = OperatingPoints(
            speed, np.full_like(speed, np.inf), np.full_like(speed, np.inf), np.abs(yaw), speed.shape
        )
        outer, inner = side_loads(veh, pts)  # eq. 6.12 with m V^2/R = m V |w_z|
        left_outer = yaw < 0
        loads = np.column_stack([np.where(left_outer, outer, inner), np.where(left_outer, inner, outer)])
        build = track_contact if veh.is_tracked else wheel_contact
        contact = build(veh, self.terrain, loads, self.n)
        straight = yaw == 0
        kin_yaw = np.where(straight, STRAIGHT_YAW, yaw)
        scale = np.where(straight, 1.0 / STRAIGHT_YAW, 1.0)
        return Problem(
            veh,
            self.terrain,
            speed,
            kin_yaw,
            loads,
            contact,
            veh.drive_radius_m,
            0.5 * veh.tread_m,
            scale,
            self.path_law,
        )

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
        from skidsteer_power.models.fess_point import solve_point

        return solve_point(self, speed, yaw_rate, x0, tol)

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
    slip = _slip(prob.side_speed, omega * prob.radius)
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


def _slip(side_speed: np.ndarray, rim_speed: np.ndarray) -> np.ndarray:
    """Slip of eq. 2.13 for either direction of travel (computed in the side's own direction)."""
    d = np.where(side_speed < 0, -1.0, 1.0)
    v, rim = side_speed * d, rim_speed * d
    with np.errstate(invalid='ignore', divide='ignore'):
        s = np.where(rim >= v, np.where(rim != 0, (rim - v) / rim, 0.0), (rim - v) / v)
    return np.clip(s, -1.0, 1.0)


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
    **options: Any,
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
