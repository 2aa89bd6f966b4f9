"""Operating points and the lateral load transfer of a turning vehicle (eqs. 3.1 and 6.12).

Helpers every skid-steering model of this package shares: broadcasting (V, R) into flat arrays,
the yaw rate, the side speeds and the vertical load of each side.

Sign convention (``models/base.py``, REP 103): R > 0 is a left turn and the outer side is the right
side; R < 0 is the mirror image. The physics depends on |R| only, so the models work with |R| and
report outer/inner quantities; :class:`~skidsteer_power.models.base.SteadyState` maps them to
left/right. R = +-inf is straight running: yaw rate 0, no load transfer, no division by zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models.base import SteadyState
from skidsteer_power.vehicle import GRAVITY_M_S2, Vehicle


@dataclass(frozen=True)
class OperatingPoints:
    """Flattened operating points (all arrays shape (N,), SI units).

    speed : forward speed V of the vehicle centre [m/s]
    turn_radius : signed turning radius R [m] as given (inf = straight)
    radius : |R| [m]
    yaw_rate : |V / R| [rad/s] (0 for straight running)
    shape : broadcast shape of the inputs, to reshape results
    """

    speed: np.ndarray
    turn_radius: np.ndarray
    radius: np.ndarray
    yaw_rate: np.ndarray
    shape: tuple[int, ...]

    @property
    def straight(self) -> np.ndarray:
        """True where the vehicle runs straight (R = +-inf)."""
        straight: np.ndarray = np.isinf(self.radius)
        return straight

    @property
    def centripetal_accel(self) -> np.ndarray:
        """V^2 / R [m/s^2] (0 for straight running)."""
        accel: np.ndarray = self.speed * self.yaw_rate
        return accel

    def side_speeds(self, tread: float) -> tuple[np.ndarray, np.ndarray]:
        """Longitudinal speeds of the outer and inner side centrelines, (R +- B/2) yaw rate [m/s]."""
        half = 0.5 * tread * self.yaw_rate
        return self.speed + half, self.speed - half

    def label(self, index: int) -> str:
        """Human-readable 'V = .. m/s, R = .. m' of one point, for error messages."""
        return f'V = {self.speed[index]:.6g} m/s, R = {self.turn_radius[index]:.6g} m'


def operating_points(speed: ArrayLike, turn_radius: ArrayLike) -> OperatingPoints:
    """Broadcast speed V [m/s] and signed turning radius R [m] into flat :class:`OperatingPoints`.

    InputError for a non-finite or negative speed, a NaN or zero radius, or V = 0 (a turning radius
    needs forward motion; spinning in place is the map layer's business).
    """
    v, r = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(turn_radius, dtype=float))
    shape = v.shape
    v, r = v.ravel().copy(), r.ravel().copy()
    if np.any(~np.isfinite(v)) or np.any(v <= 0):
        raise InputError(f'speed must be finite and > 0 m/s, got {np.asarray(speed)!r}')
    if np.any(np.isnan(r)) or np.any(r == 0):
        raise InputError(f'turning radius must be non-zero (inf = straight), got {np.asarray(turn_radius)!r}')
    radius = np.abs(r)
    yaw = np.where(np.isinf(radius), 0.0, v / np.where(np.isinf(radius), 1.0, radius))
    return OperatingPoints(v, r, radius, yaw, shape)


def side_loads(vehicle: Vehicle, points: OperatingPoints) -> tuple[np.ndarray, np.ndarray]:
    """Vertical loads of the outer and inner side L_o, L_i [N] (eqs. 3.1 and 6.12).

    L_o,i = m g / 2 +- m V^2 h / (B R), with the CG at the geometric centre. An inner load <= 0 means
    the vehicle tips over; callers treat such points as failed.
    """
    half_weight = 0.5 * vehicle.mass_kg * GRAVITY_M_S2
    transfer = vehicle.mass_kg * points.centripetal_accel * vehicle.cg_height_m / vehicle.tread_m
    return half_weight + transfer, half_weight - transfer


def centrifugal_force(vehicle: Vehicle, points: OperatingPoints) -> np.ndarray:
    """Magnitude m V^2 / R of the centrifugal force [N] (0 for straight running)."""
    return vehicle.mass_kg * points.centripetal_accel


def sideslip_angle(s0: np.ndarray, points: OperatingPoints) -> np.ndarray:
    """Side slip angle beta = atan(s0 / R) [rad] (below eq. 3.18); 0 for straight running."""
    beta: np.ndarray = np.arctan2(s0, points.radius)
    return beta


def slip_ratio(side_speed: np.ndarray, omega: np.ndarray, drive_radius: float) -> np.ndarray:
    """Longitudinal slip (eq. 2.13) of a side: (r w - V)/(r w) driving, (r w - V)/V braking [-]."""
    rim = drive_radius * omega
    with np.errstate(divide='ignore', invalid='ignore'):
        driving = (rim - side_speed) / rim
        braking = (rim - side_speed) / side_speed
    slip: np.ndarray = np.where(rim >= side_speed, driving, braking)
    return slip


def omega_for_slip(side_speed: np.ndarray, slip: np.ndarray, drive_radius: float) -> np.ndarray:
    """Angular speed w [rad/s] giving slip s (inverse of eq. 2.13) at side speed V [m/s]."""
    with np.errstate(divide='ignore', invalid='ignore'):
        driving = side_speed / (drive_radius * (1.0 - slip))
    braking = side_speed * (1.0 + slip) / drive_radius
    return np.where(slip >= 0, driving, braking)


def assemble_state(
    points: OperatingPoints,
    model: str,
    *,
    s0: np.ndarray,
    omega: tuple[np.ndarray, np.ndarray],
    torque: tuple[np.ndarray, np.ndarray],
    thrust: tuple[np.ndarray, np.ndarray],
    slip: tuple[np.ndarray, np.ndarray],
    sinkage: np.ndarray,
    traction_margin: np.ndarray,
    converged: np.ndarray,
    extra: dict[str, np.ndarray] | None = None,
) -> SteadyState:
    """Build a :class:`SteadyState` from flat (N,) outer/inner arrays, reshaped to the input shape.

    Power of each side is torque * omega [W]. Points that did not converge keep their last iterate
    (NaN where none exists) and ``converged`` False: they are reported, never dropped.
    """

    def shaped(a: np.ndarray) -> np.ndarray:
        return np.asarray(a, dtype=float).reshape(points.shape)

    power = (torque[0] * omega[0], torque[1] * omega[1])
    return SteadyState(
        speed_m_s=shaped(points.speed),
        turn_radius_m=shaped(points.turn_radius),
        s0_m=shaped(s0),
        omega_outer_rad_s=shaped(omega[0]),
        omega_inner_rad_s=shaped(omega[1]),
        torque_outer_Nm=shaped(torque[0]),
        torque_inner_Nm=shaped(torque[1]),
        power_outer_W=shaped(power[0]),
        power_inner_W=shaped(power[1]),
        slip_outer=shaped(slip[0]),
        slip_inner=shaped(slip[1]),
        thrust_outer_N=shaped(thrust[0]),
        thrust_inner_N=shaped(thrust[1]),
        sinkage_m=shaped(sinkage),
        traction_margin=shaped(traction_margin),
        converged=np.asarray(converged, dtype=bool).reshape(points.shape),
        model=model,
        extra={k: shaped(v) for k, v in (extra or {}).items()},
    )


def raise_if_failed(
    state: SteadyState, points: OperatingPoints, model: str, raise_on_failure: bool | None
) -> None:
    """Raise ConvergenceError naming the first failed (V, R) for a scalar solve or on request.

    ``raise_on_failure`` None means: raise only when the input was a single operating point.
    """
    failed = ~np.asarray(state.converged).ravel()
    if not np.any(failed):
        return
    if raise_on_failure is None:
        raise_on_failure = points.speed.size == 1
    if raise_on_failure:
        index = int(np.flatnonzero(failed)[0])
        reason = ''
        if 'failure' in state.extra:
            reason = f' ({FAILURE_REASONS.get(int(state.extra["failure"].ravel()[index]), "unknown")})'
        raise ConvergenceError(
            f'{model} model: no steady state at {points.label(index)}{reason}; '
            f'{int(failed.sum())} of {failed.size} operating point(s) failed'
        )


# codes stored in SteadyState.extra['failure'] (0 = converged)
FAILURE_REASONS: dict[int, str] = {
    0: 'converged',
    1: 'Newton iteration did not reach the 1e-3 tolerance: no steady state near the start',
    2: 'the inner side is unloaded (the vehicle tips over)',
    3: 'the terrain cannot supply the lateral force (the vehicle slides out)',
    4: 'the required thrust exceeds what the terrain can give',
    5: 'turning radius within the half tread (the inner side would run backwards)',
}
