"""Wong's general theory of skid steering for tracked vehicles (section 3.3, eqs. 3.8-3.22).

Unknowns x = (s0, omega_o, omega_i): offset of the turning centre ahead of the CG [m] and the two
sprocket speeds [rad/s]. The shear stress at every point of both contact patches follows the
Janosi-Hanamoto law (3.12) of its shear displacement (3.8-3.11), in the direction of that
displacement (3.13-3.15); the patch integrals (3.14, 3.16) are a 2-D Gauss-Legendre quadrature done
as one numpy array over (operating point, x, y). The three equilibrium equations (3.18) are solved
by Newton-Raphson (3.20) from the guess of eq. 3.21 with a forward-difference Jacobian (3.22), all
operating points iterating together, until every |residual| < 1e-3 (N, N, N m).

Kinematics, in the hull frame of ``models/base.py`` (x forward from the CG, y left, a left turn):
the turning centre O is at (s0, R). A track element touches down at x = l/2 and moves back along
the hull at r omega, so after t = (l/2 - x) / (r omega) the hull has turned by a = yaw_rate * t.
The element's displacement relative to the ground point it touched, in the *current* hull frame, is

    j = d(t) - Rot(-a) d(0),   d = (x - s0, y - R)                                   (cf. 3.8, 6.6)

Eq. 3.8 gives the same displacement in the frame the hull had at touchdown (its components are
those of j rotated by +a, and its y axis points away from O). The force components of 3.14 are
along the hull's current axes, so we rotate to the current frame, as FESS's eq. 6.6 does. The
terms sin(a)(R - y) and (1 - cos a)(R - y) are written as t (V - yaw y) sinc(a) and
t (V - yaw y)(1 - cos a)/a, exact and finite for R = inf (straight running).

Sign typo: eq. 3.19 writes the first residual with "- m v^2/R sin(beta)" inside the bracket;
eq. 3.18 (and the geometry: the centrifugal force at the CG points away from O, which lies ahead of
the CG) has "+". We use 3.18.

Straight running (R = inf): the lateral equation vanishes identically and s0 is undetermined; we
replace it by s0 = 0, the symmetric solution.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import roots_legendre

from skidsteer_power.errors import InputError
from skidsteer_power.models import loads
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.newton import MAX_ITERATIONS, TOLERANCE, NewtonResult, newton_solve
from skidsteer_power.terramechanics import track as single_track
from skidsteer_power.terramechanics.soil import shear_fraction, shear_strength
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import Vehicle

DEFAULT_RESOLUTION = (24, 3)  # Gauss-Legendre nodes along and across each track (benchmark study)


# ---------------------------------------------------------------------------------------------
# contact patch quadrature and shear displacement (eqs. 3.8-3.17)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackGrid:
    """Gauss-Legendre nodes over one track patch, relative to its centre (x along, eta across) [m]."""

    x: np.ndarray  # (nx, 1)
    eta: np.ndarray  # (1, ny)
    weight: np.ndarray  # (nx, ny) area weights [m^2], summing to b l


def track_grid(length: float, width: float, resolution: tuple[int, int]) -> TrackGrid:
    """Tensor Gauss-Legendre rule with resolution (nx, ny) over an l x b patch [m]."""
    nx, ny = (int(v) for v in resolution)
    if nx < 2 or ny < 1:
        raise InputError(f'integration resolution must be at least (2, 1), got {resolution!r}')
    tx, wx = roots_legendre(nx)
    ty, wy = roots_legendre(ny)
    return TrackGrid(
        x=(0.5 * length * tx)[:, None],
        eta=(0.5 * width * ty)[None, :],
        weight=np.outer(0.25 * length * width * wx, wy),
    )


def sinc_terms(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin(a)/a and (1 - cos a)/a, finite at a = 0."""
    return np.sinc(a / math.pi), np.sin(0.5 * a) * np.sinc(a / (2.0 * math.pi))


def track_shear_displacement(
    x: np.ndarray,
    y: np.ndarray,
    s0: np.ndarray | float,
    omega: np.ndarray | float,
    speed: np.ndarray | float,
    yaw: np.ndarray | float,
    length: float,
    radius: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Shear displacement (j_x, j_y) [m] of track points at hull position (x, y) [m] (see module doc).

    s0 [m], sprocket speed omega [rad/s], vehicle speed V [m/s], yaw rate [rad/s] broadcast against
    x, y; l = contact length, r = sprocket radius [m]. Positive j_x: the track slid forward over
    the ground (braking); driving gives j_x < 0.
    """
    t = (0.5 * length - x) / (radius * omega)  # time since touchdown [s]
    a = yaw * t
    sinc, versinc = sinc_terms(a)
    local_speed = speed - yaw * y  # ground speed of the hull at lateral position y, = yaw (R - y)
    front = 0.5 * length - s0
    jx = -radius * omega * t + t * local_speed * sinc + a * versinc * front
    jy = -t * local_speed * versinc + a * sinc * front
    return jx, jy


def patch_forces(
    terrain: Terrain, pressure: np.ndarray, jx: np.ndarray, jy: np.ndarray, weight: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground force density on the hull -tau j/|j| (3.12-3.15): returns (f_x, f_y, w tau_max) [N].

    f_x, f_y are per-node forces (stress times area weight) [N]; the third array is the shear
    strength times the weight, for saturation checks. ``pressure`` [Pa] broadcasts against j.
    """
    j = np.hypot(jx, jy)
    tau = shear_strength(terrain, pressure) * shear_fraction(terrain, j)  # eq. 3.12
    with np.errstate(invalid='ignore', divide='ignore'):
        scale = np.where(j > 0, -tau * weight / j, 0.0)
    return scale * jx, scale * jy, shear_strength(terrain, pressure) * weight


# ---------------------------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Setup:
    vehicle: Vehicle
    terrain: Terrain
    points: loads.OperatingPoints
    grid: TrackGrid
    load_o: np.ndarray
    load_i: np.ndarray
    pressure_o: np.ndarray
    pressure_i: np.ndarray
    rt_o: np.ndarray  # compaction resistance (eq. 2.10)
    rt_i: np.ndarray
    f_c: np.ndarray  # m V^2 / R


def _setup(
    vehicle: Vehicle, terrain: Terrain, points: loads.OperatingPoints, resolution: tuple[int, int]
) -> _Setup:
    tracks = vehicle.tracks()
    length, b = float(tracks.track_length_m), float(tracks.track_width_m)
    load_o, load_i = loads.side_loads(vehicle, points)
    safe_i = np.maximum(load_i, 0.0)
    return _Setup(
        vehicle=vehicle,
        terrain=terrain,
        points=points,
        grid=track_grid(length, b, resolution),
        load_o=load_o,
        load_i=load_i,
        pressure_o=load_o / (b * length),  # eq. 3.17
        pressure_i=safe_i / (b * length),
        rt_o=single_track.compaction_resistance(terrain, load_o, b, length),
        rt_i=single_track.compaction_resistance(terrain, safe_i, b, length),
        f_c=loads.centrifugal_force(vehicle, points),
    )


@dataclass
class SideForces:
    fx: np.ndarray  # longitudinal ground force on the track [N] (thrust when > 0)
    fy: np.ndarray  # lateral ground force, + towards O [N]
    moment: np.ndarray  # yaw moment of the patch forces about (s0, 0) [N m]
    turning_moment: np.ndarray  # moment of turning resistance, -sum (x - s0) f_y [N m]
    strength: np.ndarray  # integral of tau_max over the patch [N]
    mobilised: np.ndarray  # integral of |tau| over the patch [N]


def side_forces(setup: _Setup, x: np.ndarray, idx: np.ndarray, outer: bool) -> SideForces:
    """Integrate the shear stress over one track (3.14, 3.16) for the iterates x (M, 3)."""
    v, grid, pts = setup.vehicle, setup.grid, setup.points
    length, r, tread = float(v.tracks().track_length_m), v.drive_radius_m, v.tread_m
    s0 = x[:, 0, None, None]
    omega = x[:, 1 if outer else 2, None, None]
    speed, yaw = pts.speed[idx, None, None], pts.yaw_rate[idx, None, None]
    y = (-0.5 * tread if outer else 0.5 * tread) + grid.eta
    pressure = (setup.pressure_o if outer else setup.pressure_i)[idx, None, None]
    jx, jy = track_shear_displacement(grid.x, y, s0, omega, speed, yaw, length, r)
    fx, fy, strength = patch_forces(setup.terrain, pressure, jx, jy, grid.weight)
    lateral_arm = grid.x - s0
    sum_ = (1, 2)
    return SideForces(
        fx=fx.sum(axis=sum_),
        fy=fy.sum(axis=sum_),
        moment=(lateral_arm * fy - y * fx).sum(axis=sum_),
        turning_moment=-(lateral_arm * fy).sum(axis=sum_),
        strength=np.broadcast_to(strength, fx.shape).sum(axis=sum_),
        mobilised=np.hypot(fx, fy).sum(axis=sum_),
    )


def equilibrium(setup: _Setup, x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Residuals of eq. 3.18 (longitudinal N, lateral N, yaw N m about (s0, 0)) for iterates x (M, 3)."""
    pts = setup.points
    outer, inner = side_forces(setup, x, idx, True), side_forces(setup, x, idx, False)
    s0 = x[:, 0]
    beta = np.arctan2(s0, pts.radius[idx])
    f_c, half_b = setup.f_c[idx], 0.5 * setup.vehicle.tread_m
    rt_o, rt_i = setup.rt_o[idx], setup.rt_i[idx]
    longitudinal = outer.fx + inner.fx - (rt_o + rt_i) - f_c * np.sin(beta)
    lateral = outer.fy + inner.fy - f_c * np.cos(beta)
    lateral = np.where(pts.straight[idx], s0, lateral)  # R = inf: fix the undetermined s0 at 0
    yaw = outer.moment + inner.moment - half_b * (rt_o - rt_i) + s0 * f_c * np.cos(beta)
    return np.stack([longitudinal, lateral, yaw], axis=1)


def initial_guess(vehicle: Vehicle, points: loads.OperatingPoints) -> np.ndarray:
    """x0 of eq. 3.21: s0 = l/4 (0 when straight), omega = (R +- B/2) yaw / r (no-slip speeds)."""
    v_o, v_i = points.side_speeds(vehicle.tread_m)
    s0 = np.where(points.straight, 0.0, 0.25 * float(vehicle.tracks().track_length_m))
    r = vehicle.drive_radius_m
    return np.stack([s0, v_o / r, v_i / r], axis=1)


def _limit_step(vehicle: Vehicle) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Keep sprocket speeds positive (the contact time t needs omega > 0) and |ds0| <= l/4."""
    quarter = 0.25 * float(vehicle.tracks().track_length_m)

    def limit(x: np.ndarray, dx: np.ndarray, idx: np.ndarray) -> np.ndarray:
        alpha = np.ones(x.shape[0])
        for col in (1, 2):
            shrinking = dx[:, col] < -0.8 * x[:, col]
            alpha = np.where(shrinking, np.minimum(alpha, -0.8 * x[:, col] / dx[:, col]), alpha)
        step = np.maximum(np.abs(dx[:, 0]), quarter)
        scale: np.ndarray = np.minimum(alpha, quarter / step)
        return scale

    return limit


def check_vehicle(vehicle: Vehicle, model: str) -> None:
    if not vehicle.is_tracked:
        raise InputError(f'{model} track model needs a tracked vehicle; {vehicle.name!r} has wheels')


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: ArrayLike,
    turn_radius: ArrayLike,
    *,
    resolution: tuple[int, int] = DEFAULT_RESOLUTION,
    tol: float = TOLERANCE,
    max_iter: int = MAX_ITERATIONS,
    raise_on_failure: bool | None = None,
) -> SteadyState:
    """Steady skid-steering state of a tracked vehicle by Wong's theory (eqs. 3.8-3.22).

    speed V [m/s] and signed turning radius R [m] (inf = straight) broadcast. ``resolution`` =
    (nodes along, nodes across) each track. A single operating point that fails raises
    ConvergenceError naming (V, R); a batch reports ``converged`` False for failed points (and
    ``extra['failure']`` codes, see ``loads.FAILURE_REASONS``) unless ``raise_on_failure``.
    Torque of a side = its longitudinal ground force F_x times the sprocket radius [N m].
    """
    check_vehicle(vehicle, 'wong')
    points = loads.operating_points(speed, turn_radius)
    if np.any(points.radius <= 0.5 * vehicle.tread_m):
        raise InputError(
            f'wong model needs |R| > B/2 = {0.5 * vehicle.tread_m:g} m '
            '(the inner track would run backwards); spinning in place is handled by the map layer'
        )
    setup = _setup(vehicle, terrain, points, resolution)
    tipping = setup.load_i <= 0
    result = newton_solve(
        lambda x, idx: equilibrium(setup, x, idx),
        initial_guess(vehicle, points),
        steps=np.array([1e-7, 1e-7, 1e-7]),
        tol=tol,
        max_iter=max_iter,
        limit_step=_limit_step(vehicle),
    )
    converged = result.converged & ~tipping
    failure = np.where(tipping, 2, np.where(result.converged, 0, 1))
    state = _state(setup, result, converged, failure)
    loads.raise_if_failed(state, points, 'wong', raise_on_failure)
    return state


def _state(setup: _Setup, result: NewtonResult, converged: np.ndarray, failure: np.ndarray) -> SteadyState:
    v, pts, x = setup.vehicle, setup.points, result.x
    idx = np.arange(x.shape[0])
    outer, inner = side_forces(setup, x, idx, True), side_forces(setup, x, idx, False)
    r = v.drive_radius_m
    speed_o, speed_i = pts.side_speeds(v.tread_m)
    tracks = v.tracks()
    length, b = float(tracks.track_length_m), float(tracks.track_width_m)
    sinkage = single_track.track_sinkage(setup.terrain, setup.load_o, b, length)
    margin = np.minimum(1.0 - np.abs(outer.fx) / outer.strength, 1.0 - np.abs(inner.fx) / inner.strength)
    turning = outer.turning_moment + inner.turning_moment
    return loads.assemble_state(
        pts,
        'wong',
        s0=x[:, 0],
        omega=(x[:, 1], x[:, 2]),
        torque=(outer.fx * r, inner.fx * r),
        thrust=(outer.fx, inner.fx),
        slip=(loads.slip_ratio(speed_o, x[:, 1], r), loads.slip_ratio(speed_i, x[:, 2], r)),
        sinkage=sinkage,
        traction_margin=margin,
        converged=converged,
        extra={
            'mu_t': turning / (v.weight_N * length),  # eq. 3.27
            # share of the shear strength the soil develops (1 = saturated everywhere, section 3.4)
            'saturation': (outer.mobilised + inner.mobilised) / (outer.strength + inner.strength),
            'turning_moment_Nm': turning,
            'lateral_outer_N': outer.fy,
            'lateral_inner_N': inner.fy,
            'residual_max': np.max(np.abs(result.residual), axis=1),
            'iterations': result.iterations.astype(float),
            'failure': failure.astype(float),
        },
    )
