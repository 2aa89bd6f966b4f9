"""Single rigid wheel on deformable terrain, Wong-Reece model (section 2.4, eqs. 2.19-2.34), and the
quadratic normal-stress approximation used by FESS (section 6.3.1, eqs. 6.8-6.10).

Angles are measured from the vertical through the wheel centre, positive towards the front [rad];
sinkage z [m], radius r [m], width b [m], slip s [-] (eq. 2.13), forces [N], torques [N m].
Everything broadcasts over numpy arrays of operating points.

Quadrature: the contact integrals (2.27, 2.34) use fixed-order Gauss-Legendre rules on the front
[theta_m, theta_f] and rear [theta_r, theta_m] panels, so a whole slip sweep is one array computation
(scipy.integrate.quad would be a Python loop of scalar integrals: measured ~8000x slower for a
201-point sweep, benchmarks/bench_terramechanics.py). The normal stress
vanishes like (theta_f - theta)^n at the entry (and likewise at the exit), which Gauss-Legendre
resolves poorly for n < 1; the substitution theta = theta_f - (theta_f - theta_m) t^2 (and its mirror
at the exit) turns that end point into a smooth t^(2n+1) one. With 24 nodes per panel the forces
agree with adaptive scipy.integrate.quad to ~1e-10 relative (tested to 1e-6, test_terra_wheel.py).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import elementwise, root
from scipy.special import roots_legendre

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.terramechanics.soil import FloatArray, check_length, shear_stress
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.terramechanics.track import check_load, check_slip

NODES_PER_PANEL = 24
BALANCE_TOL_N = 1e-3  # eq. 2.29 stopping rule: |each equation| < 0.001 N


@dataclass(frozen=True)
class WheelState:
    """Forces and geometry of one wheel at (sinkage, slip). Arrays broadcast over the inputs.

    My_Nm is eq. 2.34: the terrain's moment on the wheel (negative when driving);
    drive_torque_Nm = -My_Nm is the torque the axle must supply (positive when driving).
    """

    sinkage_m: FloatArray
    slip: FloatArray
    Fx_N: FloatArray  # eq. 2.27, = drawbar pull in steady state (2.28)
    Fz_N: FloatArray  # eq. 2.27, = wheel load in steady state
    My_Nm: FloatArray  # eq. 2.34
    theta_f: FloatArray  # entry angle, eq. 2.19
    theta_m: FloatArray  # angle of maximum normal stress, eq. 2.22
    theta_r: FloatArray  # exit angle, eq. 2.20

    @property
    def drive_torque_Nm(self) -> FloatArray:
        return -self.My_Nm

    @property
    def drawbar_pull_N(self) -> FloatArray:
        return self.Fx_N


def wheel_angles(
    terrain: Terrain, sinkage: ArrayLike, slip: ArrayLike, radius: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Entry, maximum-stress and exit angles (theta_f, theta_m, theta_r) [rad] (eqs. 2.19-2.22)."""
    z = np.asarray(sinkage, dtype=float)
    s = np.asarray(slip, dtype=float)
    r = np.asarray(radius, dtype=float)
    theta_f = np.arccos(np.clip(1.0 - z / r, -1.0, 1.0))  # eq. 2.19
    theta_m = (terrain.a0 + terrain.a1 * s) * theta_f  # eq. 2.22
    theta_r = (terrain.b0 + terrain.b1 * s) * theta_f  # eq. 2.20
    return theta_f, theta_m, theta_r


def normal_stress(
    terrain: Terrain,
    theta: ArrayLike,
    theta_f: ArrayLike,
    theta_m: ArrayLike,
    theta_r: ArrayLike,
    radius: ArrayLike,
    width: ArrayLike,
) -> FloatArray:
    """Wong-Reece normal stress sigma(theta) [Pa] (eq. 2.21); 0 outside [theta_r, theta_f]."""
    theta = np.asarray(theta, dtype=float)
    tf, tm, tr = (np.asarray(a, dtype=float) for a in (theta_f, theta_m, theta_r))
    r, b = np.asarray(radius, dtype=float), np.asarray(width, dtype=float)
    with np.errstate(invalid='ignore', divide='ignore'):
        theta_e = tf - (theta - tr) * (tf - tm) / (tm - tr)  # eq. 2.22, rear region
    equivalent = np.where(theta >= tm, theta, theta_e)
    depth = np.maximum(np.cos(equivalent) - np.cos(tf), 0.0)
    inside = (theta >= tr) & (theta <= tf)
    return np.where(inside, r**terrain.n * terrain.k_eq(b) * depth**terrain.n, 0.0)


def shear_displacement(
    theta: ArrayLike, theta_f: ArrayLike, slip: ArrayLike, radius: ArrayLike
) -> FloatArray:
    """Shear displacement j(theta) [m] (eq. 2.25); -inf for a locked wheel (s = -1) behind the entry."""
    theta = np.asarray(theta, dtype=float)
    s = np.asarray(slip, dtype=float)
    # driving: (1 - s); braking: 1/(1 + s) (eq. 2.25); both are V/(r w), the travel per wheel turn
    with np.errstate(divide='ignore'):
        ratio = np.where(s >= 0, 1.0 - s, 1.0 / np.where(s > -1.0, 1.0 + s, 0.0))
    chord = np.sin(theta_f) - np.sin(theta)
    with np.errstate(invalid='ignore'):
        j = np.asarray(radius) * ((theta_f - theta) - ratio * chord)
    return np.where(np.isnan(j), 0.0, j)


_T, _W = roots_legendre(NODES_PER_PANEL)
_T = 0.5 * (_T + 1.0)  # nodes on (0, 1)
_W = 0.5 * _W


def _panels(tf: FloatArray, tm: FloatArray, tr: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Quadrature nodes theta [...,2N] and weights dtheta [...,2N] over [theta_r, theta_f]."""
    tf, tm, tr = (a[..., None] for a in (tf, tm, tr))
    front = tf - (tf - tm) * _T**2  # theta_f - theta ~ t^2: smooths the (theta_f - theta)^n end
    front_w = 2.0 * (tf - tm) * _T * _W
    rear = tr + (tm - tr) * _T**2
    rear_w = 2.0 * (tm - tr) * _T * _W
    return np.concatenate([front, rear], axis=-1), np.concatenate([front_w, rear_w], axis=-1)


def wheel_forces(
    terrain: Terrain, sinkage: ArrayLike, slip: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> WheelState:
    """Fx, Fz [N] (eq. 2.27) and My [N m] (eq. 2.34) of a wheel at sinkage z [m] and slip s [-].

    radius r and width b [m]. The shear stress acts along the shear displacement j(theta): eq. 2.26
    writes sign(s) |...|, identical wherever sign(j) = sign(s), i.e. everywhere when driving and for
    braking beyond s = cos(theta_f) - 1. Between, at small braking slips, the front of the patch
    still shears forwards (j > 0), and sign(s) would flip the whole shear stress in a jump at s = 0.
    """
    s = check_slip(slip)
    r, b = check_length(radius, 'radius'), check_length(width, 'width')
    z = np.asarray(sinkage, dtype=float)
    if np.any(~np.isfinite(z)) or np.any(z < 0) or np.any(z > r):
        raise InputError(f'sinkage must lie in [0, radius] m, got {sinkage!r}')
    z, s, r, b = np.broadcast_arrays(z, s, r, b)
    tf, tm, tr = wheel_angles(terrain, z, s, r)
    theta, dtheta = _panels(tf, tm, tr)
    rr, bb, ss = r[..., None], b[..., None], s[..., None]
    sigma = normal_stress(terrain, theta, tf[..., None], tm[..., None], tr[..., None], rr, bb)
    tau = shear_stress(terrain, sigma, shear_displacement(theta, tf[..., None], ss, rr))  # eq. 2.26
    fx = r * b * np.sum((-sigma * np.sin(theta) + tau * np.cos(theta)) * dtheta, axis=-1)
    fz = r * b * np.sum((sigma * np.cos(theta) + tau * np.sin(theta)) * dtheta, axis=-1)
    my = -(r**2) * b * np.sum(tau * dtheta, axis=-1)
    return WheelState(z, s, fx, fz, my, tf, tm, tr)


def bekker_wheel_sinkage(
    terrain: Terrain, load: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> FloatArray:
    """Bekker's first guess of wheel sinkage z0 [m] (eq. 2.32); load W [N], r and b [m].

    Valid for n < 3 (the (3 - n) factor); the presets all have n < 3.
    """
    w = check_load(load)
    r, b = check_length(radius, 'radius'), check_length(width, 'width')
    n = terrain.n
    if n >= 3:
        raise InputError(f'eq. 2.32 needs a sinkage exponent n < 3, terrain {terrain.name!r} has {n:g}')
    k = terrain.k_eq(b)
    sinkage: FloatArray = (3.0 * w / (b * (3.0 - n) * k * np.sqrt(2.0 * r))) ** (2.0 / (2.0 * n + 1.0))
    return sinkage


def sinkage_at_slip(
    terrain: Terrain, load: ArrayLike, slip: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> FloatArray:
    """Sinkage z [m] with Fz(z, s) = W (vertical balance of eq. 2.28) at the given slip s [-].

    Vectorized bracketed root finding (scipy.optimize.elementwise.find_root, Chandrupatla) on
    z in [0, r]: guaranteed convergence with no starting-point tuning, all points in one array call.
    ConvergenceError if some load cannot be carried with sinkage up to the radius.
    """
    w, s = check_load(load), check_slip(slip)
    r, b = check_length(radius, 'radius'), check_length(width, 'width')
    w, s, r, b = np.broadcast_arrays(w, s, r, b)

    def residual(z: FloatArray, w: FloatArray, s: FloatArray, r: FloatArray, b: FloatArray) -> FloatArray:
        return wheel_forces(terrain, z, s, r, b).Fz_N - w

    capacity = wheel_forces(terrain, r, s, r, b).Fz_N
    too_heavy = w > capacity
    if np.any(too_heavy):
        i = np.flatnonzero(too_heavy.ravel())[0]
        raise ConvergenceError(
            f'wheel on {terrain.name!r} cannot carry load {w.ravel()[i]:.6g} N at slip {s.ravel()[i]:.6g} '
            f'(r = {r.ravel()[i]:.6g} m, b = {b.ravel()[i]:.6g} m): it would sink deeper than its radius'
        )
    loaded = w > 0
    z = np.zeros(w.shape)
    if np.any(loaded):
        args = tuple(a[loaded] for a in (w, s, r, b))
        res = elementwise.find_root(
            residual,
            (np.zeros(args[0].shape), args[2]),
            args=args,
            tolerances={'xatol': 1e-12, 'xrtol': 1e-12, 'fatol': 0.1 * BALANCE_TOL_N, 'frtol': 0.0},
        )
        _check_root(terrain, res, args)
        z[loaded] = res.x
    return z


class _RootResult(Protocol):
    """What :func:`_check_root` reads of the result of scipy's ``elementwise.find_root`` (untyped)."""

    @property
    def success(self) -> ArrayLike: ...

    @property
    def f_x(self) -> ArrayLike: ...


def _check_root(terrain: Terrain, res: _RootResult, args: tuple[FloatArray, ...]) -> None:
    """``res``: the result of scipy's ``elementwise.find_root`` (untyped)."""
    bad = ~np.asarray(res.success) | ~(np.abs(np.asarray(res.f_x)) < BALANCE_TOL_N)
    if np.any(bad):
        i = np.flatnonzero(bad)[0]
        w, s, r, b = (a[i] for a in args)
        raise ConvergenceError(
            f'vertical wheel balance did not converge on {terrain.name!r}: load {w:.6g} N, slip {s:.6g}, '
            f'r = {r:.6g} m, b = {b:.6g} m'
        )


def wheel_at_slip(
    terrain: Terrain, load: ArrayLike, slip: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> WheelState:
    """Wheel state at load W [N] and slip s [-]: sinkage from the vertical balance, then Fx and My.

    The drawbar pull is Fx (compaction and bulldozing are inside eq. 2.27). This is the slip sweep
    of Figure 2.13; one array call for all points.
    """
    z = sinkage_at_slip(terrain, load, slip, radius, width)
    return wheel_forces(terrain, z, slip, radius, width)


def solve_wheel(
    terrain: Terrain,
    load: float,
    drawbar_pull: float,
    radius: float,
    width: float,
    *,
    method: str = 'hybr',
) -> WheelState:
    """Sinkage and slip (z, s) with Fx = F_d and Fz = W (eqs. 2.28-2.29) for one wheel.

    load W [N] > 0, drawbar pull F_d [N], radius r and width b [m].

    method='hybr' (default) starts from x0 = [z0, 0.2] (eqs. 2.31-2.32) and solves with MINPACK's
    hybrid Powell method (scipy.optimize.root): Newton-Raphson with a finite-difference Jacobian, as
    in eqs. 2.30 and 2.33, plus a dogleg trust region that keeps the steps from overshooting where
    plain Newton diverges. The unknowns are mapped to z = r (1 - cos theta_f), theta_f in (0, pi/2),
    and s = tanh(u), so no iterate leaves the physical range. From s = 0.2 it still misses some
    braking points (about 1 in 10 on dry sand, where F_x(s) is flat); then it falls back to
    method='bracket' (:func:`solve_wheel_bracketed`), which cannot miss a bracketed root.
    Either way the result meets both balances to 0.001 N (the dissertation's stopping rule), or
    ConvergenceError names the inputs. F_x(s) is not always monotonic (heavy loads on dry sand lose
    pull at large slip), so one pull can have two slips: 'hybr' returns the one its iteration
    reaches, 'bracket' the one with the smallest |s|.
    """
    w = float(check_load(load))
    r, b = float(check_length(radius, 'radius')), float(check_length(width, 'width'))
    fd = float(drawbar_pull)
    if not math.isfinite(fd):
        raise InputError(f'drawbar pull must be finite, got {drawbar_pull!r}')
    if w == 0:
        raise InputError('load must be > 0 N to solve for sinkage and slip')
    if method not in ('hybr', 'bracket'):
        raise InputError(f"method must be 'hybr' or 'bracket', got {method!r}")
    if method == 'hybr':
        state = _solve_hybr(terrain, w, fd, r, b)
        if state is not None:
            return state
    return solve_wheel_bracketed(terrain, w, fd, r, b)


def _solve_hybr(terrain: Terrain, w: float, fd: float, r: float, b: float) -> WheelState | None:
    if terrain.n >= 3:  # no eq. 2.32 first guess
        return None

    def residual(x: np.ndarray) -> np.ndarray:
        z, s = sinkage_slip_from_unknowns(x, r)
        state = wheel_forces(terrain, z, s, r, b)
        return np.array([float(state.Fx_N) - fd, float(state.Fz_N) - w])  # eq. 2.29

    x0 = first_guess_unknowns(terrain, w, r, b)
    sol = root(residual, x0, method='hybr', options={'xtol': 1e-13})
    if not np.all(np.abs(residual(sol.x)) < BALANCE_TOL_N):
        return None
    z, s = sinkage_slip_from_unknowns(sol.x, r)
    return wheel_forces(terrain, z, s, r, b)


def sinkage_slip_from_unknowns(x: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Sinkage z [m] and slip s [-] from :func:`solve_wheel`'s unknowns x (..., 2): z = r (1 - cos
    theta_f) with theta_f = (pi / 2) logistic(x_0) in (0, pi/2), and s = tanh(x_1), so no iterate
    leaves the physical range."""
    theta_f = 0.5 * math.pi / (1.0 + np.exp(-np.clip(x[..., 0], -50.0, 50.0)))
    return radius * (1.0 - np.cos(theta_f)), np.tanh(np.clip(x[..., 1], -20.0, 20.0))


def first_guess_unknowns(terrain: Terrain, load: ArrayLike, radius: float, width: float) -> np.ndarray:
    """:func:`solve_wheel`'s first guess in its unknowns (..., 2): Bekker's sinkage z0 (eq. 2.32, at
    most 0.9 r; needs n < 3) and s = 0.2 (eq. 2.31)."""
    z0 = np.minimum(bekker_wheel_sinkage(terrain, load, radius, width), 0.9 * radius)
    theta0 = np.arccos(1.0 - z0 / radius)
    return np.stack([-np.log(0.5 * math.pi / theta0 - 1.0), np.full_like(theta0, math.atanh(0.2))], axis=-1)


SLIP_SCAN = np.linspace(-1.0, 1.0, 41)


def solve_wheel_bracketed(
    terrain: Terrain, load: ArrayLike, drawbar_pull: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> WheelState:
    """(z, s) with Fx = F_d and Fz = W (eq. 2.29), vectorized, by two nested bracketed solves.

    The vertical balance gives z(s) (:func:`sinkage_at_slip`); F_x(z(s), s) - F_d is scanned on 41
    slips in [-1, 1] and its sign change nearest s = 0 is refined with Chandrupatla's method
    (scipy.optimize.elementwise.find_root). Where F_x(s) is not monotonic (dry sand near s = -1)
    this picks the smallest |s|: the first operating point reached as the axle torque grows from
    free rolling. ConvergenceError names the first point whose pull no slip in [-1, 1] provides.
    """
    w = check_load(load)
    fd = np.asarray(drawbar_pull, dtype=float)
    r, b = check_length(radius, 'radius'), check_length(width, 'width')
    if np.any(w <= 0) or np.any(~np.isfinite(fd)):
        raise InputError('load must be > 0 N and drawbar pull finite to solve for sinkage and slip')
    w, fd, r, b = (a.ravel() for a in np.broadcast_arrays(w, fd, r, b))
    shape = np.broadcast_shapes(np.shape(load), np.shape(drawbar_pull), np.shape(radius), np.shape(width))
    scan = _pull_scan(terrain, w, r, b) - fd[:, None]
    lo = _nearest_sign_change(scan)
    if np.any(lo < 0):
        i = int(np.flatnonzero(lo < 0)[0])
        raise ConvergenceError(
            f'no slip in [-1, 1] gives drawbar pull {fd[i]:.6g} N on {terrain.name!r}: load {w[i]:.6g} N, '
            f'r = {r[i]:.6g} m, b = {b[i]:.6g} m (reachable {np.nanmin(scan[i]) + fd[i]:.4g} to '
            f'{np.nanmax(scan[i]) + fd[i]:.4g} N)'
        )

    def pull_residual(
        s: FloatArray, w: FloatArray, fd: FloatArray, r: FloatArray, b: FloatArray
    ) -> FloatArray:
        return wheel_at_slip(terrain, w, np.clip(s, -1.0, 1.0), r, b).Fx_N - fd

    res = elementwise.find_root(
        pull_residual,
        (SLIP_SCAN[lo], SLIP_SCAN[lo + 1]),
        args=(w, fd, r, b),
        tolerances={'xatol': 1e-13, 'xrtol': 1e-13, 'fatol': 0.1 * BALANCE_TOL_N, 'frtol': 0.0},
    )
    state = wheel_at_slip(terrain, w, np.clip(res.x, -1.0, 1.0), r, b)
    bad = ~res.success | ~(np.abs(state.Fx_N - fd) < BALANCE_TOL_N)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ConvergenceError(
            f'wheel (sinkage, slip) solve did not converge on {terrain.name!r}: load {w[i]:.6g} N, '
            f'drawbar pull {fd[i]:.6g} N, r = {r[i]:.6g} m, b = {b[i]:.6g} m'
        )
    return WheelState(*(np.reshape(getattr(state, f.name), shape) for f in dataclasses.fields(WheelState)))


def _pull_scan(terrain: Terrain, w: FloatArray, r: FloatArray, b: FloatArray) -> FloatArray:
    """(P, len(SLIP_SCAN)) F_x [N] at the scanned slips, NaN where the wheel would sink deeper than
    its radius at that slip (slip sinkage, eq. 2.33: a deep-slip scan point of a soft ground such as
    snow). Those points are no operating point, and the bracket is sought among the others;
    ConvergenceError if the wheel carries its load at no scanned slip."""
    slips = np.broadcast_to(SLIP_SCAN, (w.size, SLIP_SCAN.size))
    wide = [np.broadcast_to(a[:, None], slips.shape) for a in (w, r, b)]
    carried = wheel_forces(terrain, wide[1], slips, wide[1], wide[2]).Fz_N >= wide[0]
    if not np.all(np.any(carried, axis=1)):
        i = int(np.flatnonzero(~np.any(carried, axis=1))[0])
        sinkage_at_slip(terrain, w[i], 0.0, r[i], b[i])  # raises its ConvergenceError
    scan = np.full(slips.shape, np.nan)
    scan[carried] = wheel_at_slip(
        terrain, wide[0][carried], slips[carried], wide[1][carried], wide[2][carried]
    ).Fx_N
    return scan


def _nearest_sign_change(scan: FloatArray) -> np.ndarray:
    """Per row, index k of the scan interval [k, k+1] with a sign change closest to s = 0; -1 if none."""
    change = scan[:, :-1] * scan[:, 1:] <= 0
    distance = np.minimum(np.abs(SLIP_SCAN[:-1]), np.abs(SLIP_SCAN[1:]))
    distance = np.where(change, distance, np.inf)
    best = np.argmin(distance, axis=1)
    return np.where(np.isfinite(distance[np.arange(scan.shape[0]), best]), best, -1)


def quadratic_stress_coefficients(
    terrain: Terrain, sinkage: ArrayLike, slip: ArrayLike, radius: ArrayLike, width: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Coefficients (a_i, b_i, c_i) of the quadratic normal stress (eqs. 6.8-6.10).

    Returns (front, rear), each [..., 3] in Pa/rad^2, Pa/rad, Pa; front holds on [theta_m, theta_f],
    rear on [theta_r, theta_m]. Each parabola passes through sigma_m at theta_m, the exact stress at
    the mid angle theta_im (6.8) and 0 at the end angle theta_i, i.e. it solves the 3x3 system of
    eq. 6.10 (done with a stacked np.linalg.solve).
    """
    z = np.asarray(sinkage, dtype=float)
    s = check_slip(slip)
    r, b = check_length(radius, 'radius'), check_length(width, 'width')
    z, s, r, b = np.broadcast_arrays(z, s, r, b)
    tf, tm, tr = wheel_angles(terrain, z, s, r)

    def fit(end: FloatArray) -> FloatArray:
        mid = 0.5 * (end + tm)  # eq. 6.8
        angles = np.stack([tm, mid, end], axis=-1)
        sig = normal_stress(
            terrain, angles, tf[..., None], tm[..., None], tr[..., None], r[..., None], b[..., None]
        )
        vander = np.stack([angles**2, angles, np.ones_like(angles)], axis=-1)
        degenerate = np.abs(end - tm) < 1e-12  # no contact: stress identically 0
        vander = np.where(degenerate[..., None, None], np.eye(3), vander)
        return np.linalg.solve(vander, np.where(degenerate[..., None], 0.0, sig)[..., None])[..., 0]  # 6.10

    return fit(tf), fit(tr)


def quadratic_normal_stress(
    terrain: Terrain,
    theta: ArrayLike,
    sinkage: ArrayLike,
    slip: ArrayLike,
    radius: ArrayLike,
    width: ArrayLike,
) -> FloatArray:
    """Quadratic approximation of the normal stress sigma~(theta) [Pa] (eq. 6.9); 0 off the contact.

    theta [rad] broadcasts against the operating point (sinkage z [m], slip s [-], r and b [m]).
    """
    theta = np.asarray(theta, dtype=float)
    front, rear = quadratic_stress_coefficients(terrain, sinkage, slip, radius, width)
    tf, tm, tr = wheel_angles(terrain, sinkage, slip, radius)
    coef = np.where((theta >= tm)[..., None], front, rear)
    value = (coef[..., 0] * theta + coef[..., 1]) * theta + coef[..., 2]
    return np.where((theta >= tr) & (theta <= tf), np.maximum(value, 0.0), 0.0)
