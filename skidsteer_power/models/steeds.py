"""Steeds' skid-steering model (section 3.2, eqs. 3.2-3.7): closed form, Coulomb lateral friction.

Tracks: exactly eqs. 3.2-3.7. The lateral resistance is a uniform Coulomb friction mu_t per unit
load along the track (3.3), which fixes the turning-centre offset s0 = V^2 l / (2 R mu_t g) (3.7);
the moments of lateral resistance (3.6) and the compaction resistances (3.2 = 2.10) then give the
thrusts F_o, F_i (3.7) and the sprocket torques T = F r.

mu_t is a parameter (``mu_t=``, default 0.5). Table 3.1 (source [10]), coefficient of lateral
resistance: steel track 0.50-0.51 on concrete, 0.55-0.58 unpaved hard ground, 0.87-1.11 grass;
rubber track 0.90-0.91 concrete, 0.65-0.66 unpaved hard ground, 0.67-1.14 grass.

The model gives no sprocket speeds. To report them (and power) we invert the longitudinal
thrust-slip law Steeds keeps from Bekker (eq. 2.17, the track model of chapter 2) for each side's
thrust and load: omega = V_side / (r (1 - s)) driving, V_side (1 + s) / r braking (eq. 2.13).

Wheels (an extension; the text gives Steeds' model for tracks only): each wheel is a flat patch of
the chord length r (sin theta_f - sin theta_r) under it (eqs. 2.19, 2.20 at Bekker's sinkage of
eq. 2.32 for the straight-running wheel load), with uniform pressure, compaction resistance
b k z^(n+1)/(n+1) (the rut work of eq. 2.7 per unit length); s0 then solves the lateral balance of
eq. 3.4 by bisection, and the moment of eq. 3.6 is integrated over every patch.

Straight running (R = inf) has no turning: s0 = 0, no lateral resistance, F = R_c on each side.
Note the limit R -> inf of eq. 3.7 is not straight running: M_ro + M_ri -> mu_t W l / 4 for any
finite R, which is why Steeds' torques hardly change with R (Figure 3.3 text).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import elementwise

from skidsteer_power.errors import InputError
from skidsteer_power.models import loads
from skidsteer_power.models.base import SteadyState
from skidsteer_power.terramechanics import track as single_track
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import TrackGear, Vehicle

DEFAULT_MU_T = 0.5  # Table 3.1 (steel on concrete); Figure 3.3 plots several values


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: ArrayLike,
    turn_radius: ArrayLike,
    *,
    mu_t: float = DEFAULT_MU_T,
    raise_on_failure: bool | None = None,
) -> SteadyState:
    """Steeds' steady state (eqs. 3.2-3.7) for speed V [m/s] and signed radius R [m] (inf straight).

    mu_t : coefficient of lateral resistance [-] (Table 3.1). A point where the lateral friction
    cannot hold the vehicle (V^2/R > mu_t g), the inner side lifts, or a side's thrust exceeds the
    terrain's shear strength is reported with converged False (ConvergenceError for a single point).
    """
    if not mu_t > 0:
        raise InputError(f'mu_t must be > 0, got {mu_t!r}')
    points = loads.operating_points(speed, turn_radius)
    patches = contact_patches(vehicle, terrain, points)
    f_c = loads.centrifugal_force(vehicle, points)
    sliding = f_c >= mu_t * vehicle.weight_N
    s0 = lateral_offset(patches, points, f_c, mu_t)
    resist_moment = mu_t * patches.friction_moment(s0)  # eq. 3.6, M_ro + M_ri
    resist_moment = np.where(points.straight, 0.0, resist_moment)
    couple = (resist_moment - f_c * s0) / vehicle.tread_m  # eq. 3.7
    thrust_o, thrust_i = patches.resistance_o + couple, patches.resistance_i - couple
    mu_t_eq = resist_moment / (vehicle.weight_N * patches.length_for_mu_t)  # eq. 3.27: mu_t itself for tracks
    return finish(
        vehicle,
        terrain,
        points,
        patches,
        s0,
        (thrust_o, thrust_i),
        sliding,
        'steeds',
        raise_on_failure,
        extra={'mu_t': mu_t_eq, 'turning_moment_Nm': resist_moment},
    )


class Patches:
    """Flat rectangular contact patches of both sides (tracks: one per side; wheels: one per wheel).

    centres (k,) longitudinal centre of each patch on a side [m], lengths (N, k) [m]; loads of the
    outer and inner side (N,) [N] spread equally over a side's patches; compaction resistance of
    each side (N,) [N]; width b [m].
    """

    def __init__(
        self,
        centres: np.ndarray,
        lengths: np.ndarray,
        width: float,
        load_o: np.ndarray,
        load_i: np.ndarray,
        resistance_o: np.ndarray,
        resistance_i: np.ndarray,
        sinkage: np.ndarray,
        length_for_mu_t: float,
    ) -> None:
        self.centres = centres
        self.lengths = lengths
        self.width = width
        self.load_o, self.load_i = load_o, load_i
        self.resistance_o, self.resistance_i = resistance_o, resistance_i
        self.sinkage = sinkage
        self.length_for_mu_t = length_for_mu_t

    @property
    def count(self) -> int:
        return self.centres.size

    def lateral_fraction(self, s0: np.ndarray) -> np.ndarray:
        """Net lateral friction towards O per unit mu_t W: (behind - ahead of s0) load fraction [-]."""
        return lateral_fraction(self.centres, self.lengths, s0)

    def friction_moment(self, s0: np.ndarray) -> np.ndarray:
        """Sum over patches of (load / length) * integral |x - s0| dx [N m] (eq. 3.6 without mu_t)."""
        u1 = self.centres[None, :] - 0.5 * self.lengths - s0[:, None]
        u2 = u1 + self.lengths
        integral = 0.5 * (u2 * np.abs(u2) - u1 * np.abs(u1))
        load_per_patch = (self.load_o + self.load_i)[:, None] / self.count
        moment: np.ndarray = np.sum(load_per_patch / self.lengths * integral, axis=1)
        return moment


def contact_patches(vehicle: Vehicle, terrain: Terrain, points: loads.OperatingPoints) -> Patches:
    """The flat patches of the vehicle at the operating points (see module doc)."""
    load_o, load_i = loads.side_loads(vehicle, points)
    safe_i = np.maximum(load_i, 0.0)
    b = vehicle.contact_width_m
    gear = vehicle.gear
    if isinstance(gear, TrackGear):
        length = float(gear.track_length_m)
        rc_o = single_track.compaction_resistance(terrain, load_o, b, length)  # eq. 3.2
        rc_i = single_track.compaction_resistance(terrain, safe_i, b, length)
        sinkage = single_track.track_sinkage(terrain, load_o, b, length)
        return Patches(
            np.zeros(1),
            np.full((points.speed.size, 1), length),
            b,
            load_o,
            load_i,
            rc_o,
            rc_i,
            sinkage,
            length,
        )
    from skidsteer_power.terramechanics import wheel as single_wheel

    per_side = gear.wheels_per_side
    r = gear.wheel_radius_m
    k = terrain.k_eq(b)
    z_o = single_wheel.bekker_wheel_sinkage(terrain, load_o / per_side, r, b)  # eq. 2.32
    z_i = single_wheel.bekker_wheel_sinkage(terrain, safe_i / per_side, r, b)
    rut = per_side * b * k / (terrain.n + 1.0)  # eq. 2.7 per unit rut length, times wheels per side
    z_mean = 0.5 * (z_o + z_i)
    theta_f, _, theta_r = single_wheel.wheel_angles(terrain, z_mean, 0.0, r)
    chord = np.maximum(r * (np.sin(theta_f) - np.sin(theta_r)), 1e-6)
    centres = np.asarray(gear.axle_positions_m())
    lengths = np.repeat(chord[:, None], centres.size, axis=1)
    return Patches(
        centres,
        lengths,
        b,
        load_o,
        load_i,
        rut * z_o ** (terrain.n + 1.0),
        rut * z_i ** (terrain.n + 1.0),
        z_o,
        float(gear.wheelbase_m),
    )


def lateral_fraction(centres: np.ndarray, lengths: np.ndarray, s0: np.ndarray) -> np.ndarray:
    """Fraction of equally loaded patches (centres (k,), lengths (N, k) [m]) behind s0, minus ahead [-]."""
    start = centres[None, :] - 0.5 * lengths
    behind = np.clip((s0[:, None] - start) / lengths, 0.0, 1.0)
    fraction: np.ndarray = np.mean(2.0 * behind - 1.0, axis=1)
    return fraction


def lateral_offset(
    patches: Patches, points: loads.OperatingPoints, f_c: np.ndarray, mu_t: float
) -> np.ndarray:
    """Turning-centre offset s0 [m] with lateral friction = centrifugal force (eqs. 3.4, 3.5, 3.7)."""
    weight = patches.load_o + patches.load_i
    target = np.clip(f_c / (mu_t * weight), 0.0, 1.0)
    if patches.count == 1:  # track: closed form of eq. 3.7, s0 = V^2 l / (2 R mu_t g)
        length = patches.lengths[:, 0]
        return np.where(points.straight, 0.0, 0.5 * length * target)
    low = np.full(target.shape, float(patches.centres.min())) - patches.lengths.max(axis=1)
    high = np.full(target.shape, float(patches.centres.max())) + patches.lengths.max(axis=1)

    def residual(s0: np.ndarray, goal: np.ndarray, chord: np.ndarray) -> np.ndarray:
        # find_root hands over flat arrays; every patch of a vehicle has the same chord
        lengths = np.repeat(chord.reshape(-1, 1), patches.count, axis=1)
        gap: np.ndarray = lateral_fraction(patches.centres, lengths, s0.reshape(-1)).reshape(s0.shape) - goal
        return gap

    res = elementwise.find_root(residual, (low, high), args=(target, patches.lengths[:, 0]))
    return np.where(points.straight, 0.0, res.x)


def finish(
    vehicle: Vehicle,
    terrain: Terrain,
    points: loads.OperatingPoints,
    patches: Patches,
    s0: np.ndarray,
    thrust: tuple[np.ndarray, np.ndarray],
    sliding: np.ndarray,
    model: str,
    raise_on_failure: bool | None,
    extra: dict[str, np.ndarray],
) -> SteadyState:
    """Side speeds from the inverted thrust-slip law (2.17), torques F r, and the SteadyState."""
    r = vehicle.drive_radius_m
    speed_o, speed_i = points.side_speeds(vehicle.tread_m)
    slip_o, strength_o = thrust_slip(terrain, patches, patches.load_o, thrust[0])
    slip_i, strength_i = thrust_slip(terrain, patches, np.maximum(patches.load_i, 0.0), thrust[1])
    omega_o = loads.omega_for_slip(speed_o, slip_o, r)
    omega_i = loads.omega_for_slip(speed_i, slip_i, r)
    with np.errstate(divide='ignore', invalid='ignore'):
        margin = np.minimum(1.0 - np.abs(thrust[0]) / strength_o, 1.0 - np.abs(thrust[1]) / strength_i)
    tipping = patches.load_i <= 0
    no_grip = ~np.isfinite(slip_o) | ~np.isfinite(slip_i)
    failure = np.select([tipping, sliding, no_grip], [2, 3, 4], 0)
    state = loads.assemble_state(
        points,
        model,
        s0=s0,
        omega=(omega_o, omega_i),
        torque=(thrust[0] * r, thrust[1] * r),
        thrust=thrust,
        slip=(slip_o, slip_i),
        sinkage=patches.sinkage,
        traction_margin=margin,
        converged=failure == 0,
        extra={**extra, 'failure': failure.astype(float)},
    )
    loads.raise_if_failed(state, points, model, raise_on_failure)
    return state


def thrust_slip(
    terrain: Terrain, patches: Patches, side_load: np.ndarray, thrust: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slip s [-] at which a side's patches give ``thrust`` [N] by eq. 2.17; NaN beyond reach.

    Returns (slip, the largest thrust of that sign the side can give, at s = +1 or -1 [N]).
    """
    count, b = patches.count, patches.width
    length = patches.lengths[:, 0]
    load = side_load / count

    def effort(s: np.ndarray, load: np.ndarray, length: np.ndarray, thrust: np.ndarray) -> np.ndarray:
        surplus: np.ndarray = count * single_track.tractive_effort(terrain, load, b, length, s) - thrust
        return surplus

    lo, hi = -np.ones_like(thrust), np.ones_like(thrust)
    f_lo = effort(lo, load, length, thrust)
    f_hi = effort(hi, load, length, thrust)
    reachable = (f_lo <= 0) & (f_hi >= 0)
    slip = np.full(thrust.shape, np.nan)
    if np.any(reachable):
        args = (load[reachable], length[reachable], thrust[reachable])
        res = elementwise.find_root(effort, (lo[reachable], hi[reachable]), args=args)
        slip[reachable] = res.x
    available = np.where(thrust >= 0, f_hi + thrust, -(f_lo + thrust))
    return slip, available
