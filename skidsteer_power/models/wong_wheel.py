"""Wong's skid-steering theory extended to wheeled vehicles (chapter 4, eqs. 4.1-4.14).

Unknowns x = (omega_o, omega_i, z_o, z_i, s0): the axle speeds of the two sides [rad/s] (all wheels
of a side turn together), the sinkage of each side's wheels [m] and the turning-centre offset [m].
Every wheel carries the Wong-Reece normal stress of chapter 2 (eqs. 2.19-2.22, from
``terramechanics.wheel``) at its side's sinkage and slip, and a shear stress whose size follows the
Janosi-Hanamoto law of the shear displacement (4.7, 4.8) and whose direction is that displacement's.
The five balances of eq. 4.10 (longitudinal, lateral, vertical, roll, yaw) are solved by batched
Newton-Raphson with a forward-difference Jacobian (4.13, 4.14) until every |residual| < 1e-3.

Shear displacement (4.1-4.6), in the hull frame of ``models/base.py`` (x forward from the CG, y
left, left turn, turning centre O at (s0, R)). A rim element touches the soil at theta_f and is at
theta after psi = theta_f - theta of wheel rotation, time psi / omega. Its slipping velocity in the
wheel's shear frame (tangential forward, lateral) is (4.2, 4.3)

    u = (V_y cos(theta) - r omega,  yaw (x_axle + r sin(theta) - s0)),   V_y = V - yaw y_side

(eq. 4.3's "wb/2 - s0" is the axle position relative to O; 6.11 gives x = r sin(theta) -+ wb/2 - s0),
and the hull has turned by a = yaw psi / omega since touchdown: eq. 4.5 writes phi = yaw theta /
omega, which is the angle turned from theta = 0; the angle since touchdown is yaw (theta_f -
theta)/omega. The displacement is u integrated in the ground frame and read in the current hull
frame, as for tracks (``wong_track``):

    j(theta) = Rot(-a(theta)) integral_theta^theta_f Rot(a(theta')) u(theta') dtheta' / omega   (4.4, 4.6)

done with a nested Gauss-Legendre rule at every quadrature node. Without yaw this is exactly the
Wong-Reece displacement of eq. 2.25. Eq. 4.4's matrix also flips the sign of the lateral axis (the
text's Y points away from O); we keep the hull's axes.

Forces of each wheel (4.9) plus its lateral force and torque:
    F_x = r b int(-sigma sin + tau_x cos), F_z = r b int(sigma cos + tau_x sin), F_y = r b int tau_y,
    T = r^2 b int tau_x  (the axle torque, = -M_y of eq. 2.34).

Eq. 4.10's lateral balance has "-m V^2/R cos(beta)" because of the text's lateral axis; here the
lateral ground force points towards O. Its yaw balance puts every wheel's lateral force at its axle;
we integrate the moment over the contact (x = x_axle + r sin(theta)).

Start (4.12): the single wheel of chapter 2 at load W / n_wheels, zero drawbar pull, gives
(z~, s~); the text starts both sides at the same omega~, we start each side at
V_side / (r (1 - s~)), the no-slip speeds of eq. 3.21 with that slip, and s0 = wb/4 (0 straight).
Straight running: the lateral balance is replaced by s0 = 0 (s0 is otherwise undetermined).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import roots_legendre

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import loads
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.newton import MAX_ITERATIONS, TOLERANCE, NewtonResult, newton_solve
from skidsteer_power.terramechanics import wheel as single_wheel
from skidsteer_power.terramechanics.soil import shear_fraction, shear_strength
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import Vehicle

DEFAULT_RESOLUTION = (12, 6)  # (Gauss nodes per stress panel, nested nodes for the displacement)


@dataclass(frozen=True)
class _Rules:
    t: np.ndarray  # panel nodes on (0, 1)
    w: np.ndarray
    inner_t: np.ndarray  # nested rule nodes on (0, 1)
    inner_w: np.ndarray


def _rules(resolution: tuple[int, int]) -> _Rules:
    n_panel, n_inner = (int(v) for v in resolution)
    if n_panel < 2 or n_inner < 2:
        raise InputError(f'integration resolution must be at least (2, 2), got {resolution!r}')
    t, w = roots_legendre(n_panel)
    ti, wi = roots_legendre(n_inner)
    return _Rules(0.5 * (t + 1.0), 0.5 * w, 0.5 * (ti + 1.0), 0.5 * wi)


def _contact_nodes(
    rules: _Rules, tf: np.ndarray, tm: np.ndarray, tr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes theta and weights dtheta [rad] (..., 2 n) over [theta_r, theta_f].

    Two panels split at theta_m; theta = theta_f - (theta_f - theta_m) t^2 (and the mirror at the
    exit) smooths the (theta_f - theta)^n behaviour of the normal stress at the ends.
    """
    tf, tm, tr = tf[..., None], tm[..., None], tr[..., None]
    front = tf - (tf - tm) * rules.t**2
    front_w = 2.0 * (tf - tm) * rules.t * rules.w
    rear = tr + (tm - tr) * rules.t**2
    rear_w = 2.0 * (tm - tr) * rules.t * rules.w
    return np.concatenate([front, rear], axis=-1), np.concatenate([front_w, rear_w], axis=-1)


@dataclass
class WheelForces:
    fx: np.ndarray  # longitudinal force on the wheel [N]
    fy: np.ndarray  # lateral force, + towards O [N]
    fz: np.ndarray  # vertical force [N]
    torque: np.ndarray  # axle torque [N m]
    moment: np.ndarray  # yaw moment of the contact forces about (s0, 0) [N m]
    turning_moment: np.ndarray  # -int (x - s0) dF_y [N m]
    strength: np.ndarray  # r b int tau_max dtheta [N]
    shear_thrust: np.ndarray  # r b int tau_x cos(theta) dtheta, the gross tractive effort [N]
    mobilised: np.ndarray  # r b int |tau| dtheta [N]


def wheel_forces(
    terrain: Terrain,
    rules: _Rules,
    vehicle: Vehicle,
    *,
    omega: np.ndarray,
    sinkage: np.ndarray,
    s0: np.ndarray,
    speed: np.ndarray,
    yaw: np.ndarray,
    y_side: float,
    x_axle: float,
) -> WheelForces:
    """Forces of one wheel per operating point (arrays (M,)) for the given unknowns (see module doc)."""
    r, b = vehicle.drive_radius_m, vehicle.contact_width_m
    side_speed = speed - yaw * y_side
    slip = np.clip(loads.slip_ratio(side_speed, omega, r), -1.0, 1.0)  # eq. 2.13
    z = np.clip(sinkage, 1e-9, r)
    tf, tm, tr = single_wheel.wheel_angles(terrain, z, slip, r)  # eqs. 2.19-2.22
    theta, dtheta = _contact_nodes(rules, tf, tm, tr)  # (M, P)
    sigma = single_wheel.normal_stress(
        terrain, theta, tf[:, None], tm[:, None], tr[:, None], r, b
    )  # eq. 2.21
    jx, jy = _displacement(rules, theta, tf, omega, side_speed, yaw, s0, x_axle, r)
    j = np.hypot(jx, jy)
    tau_max = shear_strength(terrain, sigma)
    tau = tau_max * shear_fraction(terrain, j)  # eqs. 4.7, 4.8
    with np.errstate(invalid='ignore', divide='ignore'):
        tau_x = np.where(j > 0, -tau * jx / j, 0.0)
        tau_y = np.where(j > 0, -tau * jy / j, 0.0)
    sin, cos = np.sin(theta), np.cos(theta)
    rb = r * b
    fx = rb * np.sum((-sigma * sin + tau_x * cos) * dtheta, axis=-1)  # eq. 4.9
    fz = rb * np.sum((sigma * cos + tau_x * sin) * dtheta, axis=-1)
    dfy = rb * tau_y * dtheta
    arm = x_axle + r * sin - s0[:, None]  # eq. 6.11
    fy = dfy.sum(axis=-1)
    return WheelForces(
        fx=fx,
        fy=fy,
        fz=fz,
        torque=r * rb * np.sum(tau_x * dtheta, axis=-1),  # -(eq. 2.34)
        moment=(arm * dfy).sum(axis=-1) - y_side * fx,
        turning_moment=-(arm * dfy).sum(axis=-1),
        strength=rb * np.sum(tau_max * dtheta, axis=-1),
        shear_thrust=rb * np.sum(tau_x * cos * dtheta, axis=-1),
        mobilised=rb * np.sum(np.abs(tau) * dtheta, axis=-1),
    )


def _displacement(
    rules: _Rules,
    theta: np.ndarray,
    tf: np.ndarray,
    omega: np.ndarray,
    side_speed: np.ndarray,
    yaw: np.ndarray,
    s0: np.ndarray,
    x_axle: float,
    r: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Shear displacement (j_x, j_y) [m] at nodes theta (M, P) (eqs. 4.3-4.6, see module doc)."""
    psi = tf[:, None] - theta  # rotation since touchdown at each node (M, P)
    inner = psi[..., None] * rules.inner_t  # (M, P, m) rotation at the nested nodes
    theta_in = tf[:, None, None] - inner
    om, vs, yw, s = (a[:, None, None] for a in (omega, side_speed, yaw, s0))
    ux = vs * np.cos(theta_in) - r * om  # eq. 4.3, tangential
    uy = yw * (x_axle + r * np.sin(theta_in) - s)  # eq. 4.3, lateral
    kappa = yw / om  # heading change per radian of wheel rotation
    rel = kappa * (inner - psi[..., None])  # a(theta') - a(theta), rotate into the current frame
    c, sn = np.cos(rel), np.sin(rel)
    weight = (psi[..., None] * rules.inner_w) / om
    jx = np.sum((c * ux - sn * uy) * weight, axis=-1)
    jy = np.sum((sn * ux + c * uy) * weight, axis=-1)
    return jx, jy


@dataclass(frozen=True)
class _Setup:
    vehicle: Vehicle
    terrain: Terrain
    points: loads.OperatingPoints
    rules: _Rules
    f_c: np.ndarray


@dataclass
class SideTotals:
    fx: np.ndarray
    fy: np.ndarray
    fz: np.ndarray
    torque: np.ndarray
    moment: np.ndarray
    turning_moment: np.ndarray
    strength: np.ndarray
    shear_thrust: np.ndarray
    mobilised: np.ndarray


def side_totals(setup: _Setup, x: np.ndarray, idx: np.ndarray, outer: bool) -> SideTotals:
    """Sum the forces of one side's wheels for iterates x (M, 5) = (w_o, w_i, z_o, z_i, s0)."""
    v, pts = setup.vehicle, setup.points
    y_side = -0.5 * v.tread_m if outer else 0.5 * v.tread_m
    parts = [
        wheel_forces(
            setup.terrain,
            setup.rules,
            v,
            omega=x[:, 0 if outer else 1],
            sinkage=x[:, 2 if outer else 3],
            s0=x[:, 4],
            speed=pts.speed[idx],
            yaw=pts.yaw_rate[idx],
            y_side=y_side,
            x_axle=x_axle,
        )
        for x_axle in v.axle_positions_m()
    ]
    return SideTotals(*(sum(getattr(p, name) for p in parts) for name in SideTotals.__dataclass_fields__))


def equilibrium(setup: _Setup, x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Residuals of eq. 4.10 (N, N, N, N m, N m) for iterates x (M, 5)."""
    v, pts = setup.vehicle, setup.points
    o, i = side_totals(setup, x, idx, True), side_totals(setup, x, idx, False)
    s0 = x[:, 4]
    beta = np.arctan2(s0, pts.radius[idx])
    f_c, half_b = setup.f_c[idx], 0.5 * v.tread_m
    longitudinal = o.fx + i.fx - f_c * np.sin(beta)
    lateral = np.where(pts.straight[idx], s0, o.fy + i.fy - f_c * np.cos(beta))
    vertical = o.fz + i.fz - v.weight_N
    roll = (o.fz - i.fz) * half_b - f_c * v.cg_height_m
    yaw = o.moment + i.moment + s0 * f_c * np.cos(beta)
    return np.stack([longitudinal, lateral, vertical, roll, yaw], axis=1)


def initial_guess(vehicle: Vehicle, terrain: Terrain, points: loads.OperatingPoints) -> np.ndarray:
    """x0 of eq. 4.12 from the straight single-wheel solution (see module doc)."""
    wheels = vehicle.wheels()
    r, b = wheels.wheel_radius_m, wheels.wheel_width_m
    try:
        single = single_wheel.solve_wheel(terrain, vehicle.weight_N / wheels.n_wheels, 0.0, r, b)
        z0, s_0 = float(single.sinkage_m), float(single.slip)
    except ConvergenceError:
        z0 = min(
            float(single_wheel.bekker_wheel_sinkage(terrain, vehicle.weight_N / wheels.n_wheels, r, b)),
            0.5 * r,
        )
        s_0 = 0.2  # eqs. 2.31, 2.32
    v_o, v_i = points.side_speeds(vehicle.tread_m)
    n = points.speed.size
    s0 = np.where(points.straight, 0.0, 0.25 * float(wheels.wheelbase_m))
    scale = 1.0 / (r * (1.0 - s_0))
    return np.stack([v_o * scale, v_i * scale, np.full(n, z0), np.full(n, z0), s0], axis=1)


def _limit_step(vehicle: Vehicle) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Keep axle speeds and sinkages positive, sinkages below 0.95 r, and |ds0| <= wb/4."""
    r = vehicle.drive_radius_m
    quarter = 0.25 * float(vehicle.wheels().wheelbase_m)

    def limit(x: np.ndarray, dx: np.ndarray, idx: np.ndarray) -> np.ndarray:
        alpha = np.ones(x.shape[0])
        for col in (0, 1, 2, 3):  # keep omega and sinkage positive
            shrinking = dx[:, col] < -0.8 * x[:, col]
            alpha = np.where(shrinking, np.minimum(alpha, -0.8 * x[:, col] / dx[:, col]), alpha)
        for col in (2, 3):  # and the sinkage below the radius
            room = 0.95 * r - x[:, col]
            growing = dx[:, col] > 0.8 * room
            alpha = np.where(growing, np.minimum(alpha, 0.8 * room / dx[:, col]), alpha)
        scale: np.ndarray = np.minimum(alpha, quarter / np.maximum(np.abs(dx[:, 4]), quarter))
        return scale

    return limit


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
    """Steady skid-steering state of a 4- or 6-wheel vehicle (eqs. 4.1-4.14).

    speed V [m/s], signed radius R [m] (inf straight) broadcast; ``resolution`` = (Gauss nodes per
    normal-stress panel, nested nodes for the shear displacement). Per-side torque is the sum of
    the axle torques of that side's wheels [N m]. Failures: converged False in a batch,
    ConvergenceError naming (V, R) for a single point or with ``raise_on_failure``.
    """
    if vehicle.is_tracked:
        raise InputError(f'the wheeled wong model needs a wheeled vehicle; {vehicle.name!r} has tracks')
    points = loads.operating_points(speed, turn_radius)
    if np.any(points.radius <= 0.5 * vehicle.tread_m):
        raise InputError(
            f'wong model needs |R| > B/2 = {0.5 * vehicle.tread_m:g} m '
            '(the inner wheels would run backwards); spinning in place is handled by the map layer'
        )
    setup = _Setup(vehicle, terrain, points, _rules(resolution), loads.centrifugal_force(vehicle, points))
    _, load_i = loads.side_loads(vehicle, points)
    result = newton_solve(
        lambda x, idx: equilibrium(setup, x, idx),
        initial_guess(vehicle, terrain, points),
        steps=np.array([1e-7, 1e-7, 1e-9, 1e-9, 1e-7]),
        tol=tol,
        max_iter=max_iter,
        limit_step=_limit_step(vehicle),
    )
    tipping = load_i <= 0
    failure = np.where(tipping, 2, np.where(result.converged, 0, 1))
    state = _state(setup, result.x, result, failure)
    loads.raise_if_failed(state, points, 'wong', raise_on_failure)
    return state


def _state(setup: _Setup, x: np.ndarray, result: NewtonResult, failure: np.ndarray) -> SteadyState:
    v, pts = setup.vehicle, setup.points
    idx = np.arange(x.shape[0])
    o, i = side_totals(setup, x, idx, True), side_totals(setup, x, idx, False)
    r = v.drive_radius_m
    speed_o, speed_i = pts.side_speeds(v.tread_m)
    margin = np.minimum(1.0 - np.abs(o.shear_thrust) / o.strength, 1.0 - np.abs(i.shear_thrust) / i.strength)
    turning = o.turning_moment + i.turning_moment
    return loads.assemble_state(
        pts,
        'wong',
        s0=x[:, 4],
        omega=(x[:, 0], x[:, 1]),
        torque=(o.torque, i.torque),
        thrust=(o.shear_thrust, i.shear_thrust),
        slip=(loads.slip_ratio(speed_o, x[:, 0], r), loads.slip_ratio(speed_i, x[:, 1], r)),
        sinkage=np.maximum(x[:, 2], x[:, 3]),
        traction_margin=margin,
        converged=failure == 0,
        extra={
            'sinkage_outer_m': x[:, 2],
            'sinkage_inner_m': x[:, 3],
            'mu_t': turning / (v.weight_N * float(v.wheels().wheelbase_m)),  # eq. 3.27 with L = wheelbase
            'turning_moment_Nm': turning,
            'saturation': (o.mobilised + i.mobilised) / (o.strength + i.strength),
            'longitudinal_outer_N': o.fx,
            'longitudinal_inner_N': i.fx,
            'vertical_outer_N': o.fz,
            'vertical_inner_N': i.fz,
            'lateral_outer_N': o.fy,
            'lateral_inner_N': i.fy,
            'residual_max': np.max(np.abs(result.residual), axis=1),
            'iterations': result.iterations.astype(float),
            'failure': failure.astype(float),
        },
    )
