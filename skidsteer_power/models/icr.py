"""Instantaneous-centre-of-rotation (ICR) skid-steering model (section 3.4, eqs. 3.23-3.26).

Every contact element carries a saturated Coulomb friction mu p dA opposite its slipping velocity
(3.24); the slipping velocity is the yaw rate times the distance to its side's ICR (3.25), and the
ICRs of both sides lie on the line x = s0 (3.23):

    ICR_side = (s0, Y_side),   v = yaw * (-(y - Y_side), x - s0),   omega_side = (V - yaw Y_side) / r

(hull frame of ``models/base.py``: x forward from the CG, y left, left turn; eq. 3.23 writes
y_ICR = (omega r - v_x)/yaw with its y axis pointing the other way). The direction of v does not
depend on the size of the yaw rate, so we solve for (s0, Y_o, Y_i), which stays well conditioned
from R = 1 m to R = 500 m. The forces (3.26) are integrated over both patches by Gauss-Legendre
quadrature and put into the same equilibrium as Wong's model (3.18, with the compaction resistance
of eq. 2.10), solved by the batched Newton-Raphson of ``wong_track`` from s0 = l/4 and ICRs just
outside the track centrelines.

Typo: eq. 3.26 writes F_x = b mu integral df cos(theta) dx; df of (3.24) already holds mu p dA, so
the extra mu (and b, when dA = b dx) would count twice. We integrate df over the patch area once.

mu is a parameter (``mu=``, default 1.12, the value of the text, ref. [49]).

Straight running (R = inf) has no slipping velocity to orient the friction: Coulomb friction is
then static, the tracks roll without slip (omega = V / r) and each side's thrust equals its
compaction resistance. The turning solution does not tend to this as R grows: the friction stays
saturated at every radius (section 3.4), which is the model's known weakness.

Wheels (an extension): each wheel is the flat patch of ``steeds.contact_patches``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import roots_legendre

from skidsteer_power.errors import InputError
from skidsteer_power.models import loads, steeds
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.newton import MAX_ITERATIONS, TOLERANCE, Residual, newton_solve
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import TrackGear, Vehicle

DEFAULT_MU = 1.12  # section 3.4, ref. [49]
DEFAULT_RESOLUTION = (32, 3)  # Gauss-Legendre nodes along and across each patch


class _Contact:
    """Quadrature nodes of one side's patches for every operating point.

    x (N, P, 1) longitudinal node positions [m], eta (1, 1, ny) lateral offsets from the side's
    centreline [m], area (N, P, ny) area weights [m^2] (summing to the side's contact area).
    """

    def __init__(self, patches: steeds.Patches, resolution: tuple[int, int]) -> None:
        nx, ny = (int(v) for v in resolution)
        if nx < 2 or ny < 1:
            raise InputError(f'integration resolution must be at least (2, 1), got {resolution!r}')
        tx, wx = roots_legendre(nx)
        ty, wy = roots_legendre(ny)
        half = 0.5 * patches.lengths[:, :, None]  # (N, k, 1)
        x = patches.centres[None, :, None] + half * tx  # (N, k, nx)
        wlen = half * wx  # (N, k, nx)
        n = patches.lengths.shape[0]
        self.x = x.reshape(n, -1)[:, :, None]
        self.eta = (0.5 * patches.width * ty)[None, None, :]
        self.area = wlen.reshape(n, -1)[:, :, None] * (0.5 * patches.width * wy)[None, None, :]
        self.total_area = self.area.sum(axis=(1, 2))


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: ArrayLike,
    turn_radius: ArrayLike,
    *,
    mu: float = DEFAULT_MU,
    resolution: tuple[int, int] = DEFAULT_RESOLUTION,
    tol: float = TOLERANCE,
    max_iter: int = MAX_ITERATIONS,
    raise_on_failure: bool | None = None,
) -> SteadyState:
    """ICR steady state (eqs. 3.23-3.26 with the equilibrium 3.18) for V [m/s] and signed R [m].

    mu : Coulomb friction coefficient [-] (1.12 in the text). ``resolution`` = (nodes along,
    nodes across) each patch. Failures as in every model: converged False in a batch,
    ConvergenceError for a single point or with ``raise_on_failure``.
    """
    if not mu > 0:
        raise InputError(f'mu must be > 0, got {mu!r}')
    points = loads.operating_points(speed, turn_radius)
    patches = steeds.contact_patches(vehicle, terrain, points)
    contact = _Contact(patches, resolution)
    f_c = loads.centrifugal_force(vehicle, points)
    half_b = 0.5 * vehicle.tread_m
    pressure = (patches.load_o / contact.total_area, np.maximum(patches.load_i, 0.0) / contact.total_area)
    forces = _friction_forces(contact, pressure, half_b, mu)
    equilibrium = _equilibrium(forces, points, patches, f_c, half_b)
    x0 = _first_guess(vehicle, patches, points.speed.size, half_b)
    x, converged, iterations, residual_max = _solve_turning(equilibrium, x0, ~points.straight, tol, max_iter)
    return _state(
        vehicle, points, patches, x, forces, converged, iterations, residual_max, mu, raise_on_failure
    )


Forces = Callable[[np.ndarray, np.ndarray, bool], tuple[np.ndarray, ...]]
"""forces(x, idx, outer) of :func:`_friction_forces`."""


def _friction_forces(
    contact: _Contact, pressure: tuple[np.ndarray, np.ndarray], half_b: float, mu: float
) -> Forces:
    """forces(x, idx, outer): one side's friction (outer or inner) at the unknowns x = (s0, Y_o,
    Y_i) [m] of the points ``idx``: F_x, F_y [N], the moment about the CG and the turning moment
    [N m], and the saturation |friction| / (mu p) [-] (eqs. 3.24-3.26); ``pressure`` [Pa] per side
    (outer, inner), ``half_b`` half the tread [m]."""

    def forces(x: np.ndarray, idx: np.ndarray, outer: bool) -> tuple[np.ndarray, ...]:
        s0 = x[:, 0, None, None]
        icr_y = x[:, 1 if outer else 2, None, None]
        y = (-half_b if outer else half_b) + contact.eta
        px = contact.x[idx]
        vx, vy = -(y - icr_y), px - s0  # slipping velocity / yaw rate (3.25)
        norm = np.hypot(vx, vy)
        p = (pressure[0] if outer else pressure[1])[idx, None, None]
        with np.errstate(invalid='ignore', divide='ignore'):
            scale = np.where(norm > 0, -mu * p * contact.area[idx] / norm, 0.0)  # (3.24)
        fx, fy = scale * vx, scale * vy
        arm = px - s0
        total = (1, 2)
        saturation = np.hypot(fx, fy).sum(axis=total) / (mu * p[:, 0, 0] * contact.area[idx].sum(axis=total))
        return (
            fx.sum(axis=total),
            fy.sum(axis=total),
            (arm * fy - y * fx).sum(axis=total),
            -(arm * fy).sum(axis=total),
            saturation,
        )

    return forces


def _equilibrium(
    forces: Forces,
    points: loads.OperatingPoints,
    patches: steeds.Patches,
    f_c: np.ndarray,
    half_b: float,
) -> Residual:
    """equilibrium(x, idx): the residuals of eq. 3.18 (longitudinal, lateral [N], yaw [N m]) with
    the compaction resistance and the centrifugal force ``f_c`` [N] of the points ``idx``."""

    def equilibrium(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
        fxo, fyo, mo, _, _ = forces(x, idx, True)
        fxi, fyi, mi, _, _ = forces(x, idx, False)
        s0 = x[:, 0]
        beta = np.arctan2(s0, points.radius[idx])
        rt_o, rt_i = patches.resistance_o[idx], patches.resistance_i[idx]
        longitudinal = fxo + fxi - (rt_o + rt_i) - f_c[idx] * np.sin(beta)  # eq. 3.18
        lateral = fyo + fyi - f_c[idx] * np.cos(beta)
        yaw = mo + mi - half_b * (rt_o - rt_i) + s0 * f_c[idx] * np.cos(beta)
        return np.stack([longitudinal, lateral, yaw], axis=1)

    return equilibrium


def _first_guess(vehicle: Vehicle, patches: steeds.Patches, n: int, half_b: float) -> np.ndarray:
    """(n, 3) start of the Newton solve: s0 = l / 4 ahead of the CG, each ICR just outside its
    side's centreline [m] (module doc)."""
    gear = vehicle.gear
    lead = 0.25 * (float(np.max(patches.lengths)) if isinstance(gear, TrackGear) else float(gear.wheelbase_m))
    return np.stack([np.full(n, lead), np.full(n, -1.1 * half_b), np.full(n, 1.1 * half_b)], axis=1)


def _solve_turning(
    equilibrium: Residual, x0: np.ndarray, turning: np.ndarray, tol: float, max_iter: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Newton-Raphson on the ``turning`` points (straight ones keep x = 0: no slipping velocity,
    module doc): x (n, 3) [m], converged, iterations and the largest residual per point."""
    n = x0.shape[0]
    x = np.zeros((n, 3))
    converged = np.ones(n, dtype=bool)
    iterations = np.zeros(n)
    residual_max = np.zeros(n)
    if np.any(turning):
        sub = np.flatnonzero(turning)

        def sub_equilibrium(xs: np.ndarray, idx: np.ndarray) -> np.ndarray:
            return equilibrium(xs, sub[idx])

        result = newton_solve(sub_equilibrium, x0[sub], steps=np.full(3, 1e-7), tol=tol, max_iter=max_iter)
        x[sub], converged[sub], iterations[sub] = result.x, result.converged, result.iterations
        residual_max[sub] = np.max(np.abs(result.residual), axis=1)
    return x, converged, iterations, residual_max


def _state(
    vehicle: Vehicle,
    points: loads.OperatingPoints,
    patches: steeds.Patches,
    x: np.ndarray,
    forces: Callable[..., tuple[np.ndarray, ...]],
    converged: np.ndarray,
    iterations: np.ndarray,
    residual_max: np.ndarray,
    mu: float,
    raise_on_failure: bool | None,
) -> SteadyState:
    idx = np.arange(points.speed.size)
    r, straight = vehicle.drive_radius_m, points.straight
    fxo, _, _, mto, sat_o = forces(x, idx, True)
    fxi, _, _, mti, sat_i = forces(x, idx, False)
    fxo = np.where(straight, patches.resistance_o, fxo)  # static friction when straight (module doc)
    fxi = np.where(straight, patches.resistance_i, fxi)
    turning_moment = np.where(straight, 0.0, mto + mti)
    speed_o, speed_i = points.side_speeds(vehicle.tread_m)
    omega_o = np.where(straight, points.speed / r, (points.speed - points.yaw_rate * x[:, 1]) / r)  # eq. 3.23
    omega_i = np.where(straight, points.speed / r, (points.speed - points.yaw_rate * x[:, 2]) / r)
    load_i = np.maximum(patches.load_i, 0.0)
    with np.errstate(divide='ignore', invalid='ignore'):
        margin = np.minimum(1.0 - np.abs(fxo) / (mu * patches.load_o), 1.0 - np.abs(fxi) / (mu * load_i))
    tipping = patches.load_i <= 0
    failure = np.select([tipping, ~converged], [2, 1], 0)
    gear = vehicle.gear
    length = float(np.max(patches.lengths)) if isinstance(gear, TrackGear) else float(gear.wheelbase_m)
    state = loads.assemble_state(
        points,
        'icr',
        s0=x[:, 0],
        omega=(omega_o, omega_i),
        torque=(fxo * r, fxi * r),
        thrust=(fxo, fxi),
        slip=(loads.slip_ratio(speed_o, omega_o, r), loads.slip_ratio(speed_i, omega_i, r)),
        sinkage=patches.sinkage,
        traction_margin=margin,
        converged=failure == 0,
        extra={
            'mu_t': turning_moment / (vehicle.weight_N * length),  # eq. 3.27
            # |friction| / (mu p) averaged over the contact: 1 whenever the vehicle turns (section 3.4)
            'saturation': np.where(straight, np.nan, 0.5 * (sat_o + sat_i)),
            'turning_moment_Nm': turning_moment,
            'icr_outer_y_m': np.where(straight, np.nan, x[:, 1]),
            'icr_inner_y_m': np.where(straight, np.nan, x[:, 2]),
            'residual_max': residual_max,
            'iterations': iterations,
            'failure': failure.astype(float),
        },
    )
    loads.raise_if_failed(state, points, 'icr', raise_on_failure)
    return state
