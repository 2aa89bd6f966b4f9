"""The fast computation skid-steering model for tracked vehicles (chapter 5, eqs. 5.1-5.3).

The computation-intensive part (shear displacement and stress over the contacts) is replaced by two
pre-generated maps, the coefficient of turning resistance mu_t = (M_To + M_Ti) / (m g L) (eq. 3.27)
and the turning-centre offset s0, both solved once by Wong's model (chapter 3) over a grid of
forward speed V and curvature 1/R (Figure 5.1). Each operating point is then closed form: the side
thrusts by eq. 5.2 and each side's slip by inverting the single-track thrust of eq. 5.3 (eq. 2.17).

Grid: V = 0.1 ... 1.5 m/s (8 values) x curvature 1/R for R = 1 ... 500 m (16 values, the text's
8 x 16 grid) plus straight running (1/R = 0); bilinear in (V, 1/R), clamped outside (the result's
``extra['clamped']`` says where). Tables are cached per (vehicle, terrain, source model) in the
process and on disk next to the power maps ($SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power).

Eq. 5.2 typo: A2 is printed with (R_to + R_ti) B/2; eq. 5.1 (and straight running, where A2 must be
0) give (R_to - R_ti) B/2. We use 5.1.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import elementwise

from skidsteer_power.cache import atomic_file
from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models.base import SteadyState
from skidsteer_power.models.loads import (
    OperatingPoints,
    omega_for_slip,
    operating_points,
    side_loads,
    sideslip_angle,
)
from skidsteer_power.terramechanics.track import compaction_resistance, track_sinkage, tractive_effort

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

TABLE_SPEEDS = np.linspace(0.1, 1.5, 8)  # [m/s]
TABLE_RADII = np.geomspace(1.0, 500.0, 16)  # [m]
SOURCES = ('wong', 'fess')


@dataclass(frozen=True)
class TurningTables:
    """mu_t [-] and s0 [m] on (speed [m/s] x curvature [1/m]) from ``source`` (Figure 5.1)."""

    speeds: np.ndarray
    curvatures: np.ndarray
    mu_t: np.ndarray
    s0: np.ndarray
    source: str

    def lookup(self, speed: np.ndarray, curvature: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear (mu_t, s0, clamped) at |V| [m/s] and |1/R| [1/m], clamped to the table."""
        from skidsteer_power.interpolation import Axis, BilinearGrid

        grid = BilinearGrid(
            Axis(self.speeds, 'speed'),
            Axis(self.curvatures, 'curvature'),
            np.stack([self.mu_t, self.s0], axis=-1),
        )
        values, clamped, _cell = grid(np.abs(speed), np.abs(curvature))
        return values[:, 0], values[:, 1], clamped


def generate_tables(vehicle: Vehicle, terrain: Terrain, source: str = 'wong') -> TurningTables:
    """Solve the source model over the table grid (one batched call) and extract mu_t and s0."""
    if source not in SOURCES:
        raise InputError(f'fast model tables come from {" or ".join(SOURCES)}, not {source!r}')
    from skidsteer_power import models

    radii = np.concatenate([[np.inf], TABLE_RADII[::-1]])  # curvature ascending: 0, 1/500 ... 1
    v, r = np.meshgrid(TABLE_SPEEDS, radii, indexing='ij')
    state = models.solve(vehicle, terrain, v, r, model=source, raise_on_failure=False)
    if not np.all(state.converged):
        k = np.unravel_index(np.argmin(state.converged), v.shape)
        raise ConvergenceError(
            f'{source} model did not converge at V = {v[k]:.6g} m/s, R = {r[k]:.6g} m while generating '
            f'the fast-model tables for {vehicle.name!r} on {terrain.name!r}'
        )
    mu_t = state.extra['mu_t'] if 'mu_t' in state.extra else _mu_t_from_balance(vehicle, terrain, state)
    return TurningTables(
        TABLE_SPEEDS.copy(), 1.0 / radii, np.asarray(mu_t, float), np.asarray(state.s0_m, float), source
    )


def _mu_t_from_balance(vehicle: Vehicle, terrain: Terrain, state: SteadyState) -> np.ndarray:
    """mu_t from the yaw balance of eq. 5.1 at a solved state (for sources without ``mu_t``)."""
    pts = operating_points(np.ravel(state.speed_m_s), np.ravel(state.turn_radius_m))
    rto, rti = _resistances(vehicle, terrain, pts)
    beta = sideslip_angle(np.ravel(state.s0_m), pts)
    fc = vehicle.mass_kg * pts.centripetal_accel
    half = 0.5 * vehicle.tread_m
    moment = (np.ravel(state.thrust_outer_N) - np.ravel(state.thrust_inner_N)) * half - (rto - rti) * half
    moment = moment + np.ravel(state.s0_m) * np.cos(beta) * fc
    mu_t: np.ndarray = moment / (vehicle.weight_N * float(vehicle.tracks().track_length_m))
    return mu_t.reshape(np.shape(state.s0_m))


def _resistances(vehicle: Vehicle, terrain: Terrain, pts: OperatingPoints) -> tuple[np.ndarray, np.ndarray]:
    lo, li = side_loads(vehicle, pts)
    tracks = vehicle.tracks()
    width, length = float(tracks.track_width_m), float(tracks.track_length_m)
    return (
        compaction_resistance(terrain, np.maximum(lo, 0), width, length),
        compaction_resistance(terrain, np.maximum(li, 0), width, length),
    )  # eq. 2.10


@lru_cache(maxsize=16)
def turning_tables(vehicle: Vehicle, terrain: Terrain, source: str = 'wong') -> TurningTables:
    """The cached tables: process memory, then the disk cache, else :func:`generate_tables`."""
    from skidsteer_power.cache import default_cache_dir, physics_digest
    from skidsteer_power.terramechanics.terrain import terrain_fingerprint
    from skidsteer_power.vehicle import vehicle_fingerprint

    key = f'{vehicle_fingerprint(vehicle)}_{terrain_fingerprint(terrain)}_{source}_{physics_digest()}'
    path = default_cache_dir() / f'fast_{key}.npz'
    if path.exists():
        try:
            with np.load(path, allow_pickle=False) as data:
                speeds, curvatures, mu_t, s0 = (
                    np.array(data[k]) for k in ('speeds', 'curvatures', 'mu_t', 's0')
                )
                return TurningTables(speeds, curvatures, mu_t, s0, source)
        except (OSError, KeyError, ValueError):
            pass  # damaged: regenerate
    tables = generate_tables(vehicle, terrain, source)
    _save(path, tables)
    return tables


def _save(path: Path, tables: TurningTables) -> None:
    try:
        with atomic_file(path) as tmp:
            np.savez(tmp, speeds=tables.speeds, curvatures=tables.curvatures, mu_t=tables.mu_t, s0=tables.s0)
    except OSError:
        pass  # a read-only cache only costs a regeneration next time


def slip_for_thrust(
    terrain: Terrain, load: np.ndarray, width: float, length: float, thrust: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slip s [-] at which a track develops ``thrust`` [N] (eq. 5.3 / 2.17 inverted); (slip, ok).

    ok is False where |thrust| exceeds what the soil can give (A c + W tan(phi), eq. 2.11).
    Vectorized bracketed root finding (Chandrupatla) on s in [-1, 1].
    """
    f_max = width * length * terrain.c + load * math.tan(terrain.phi)
    ok = np.abs(thrust) < f_max
    target = np.where(ok, thrust, 0.0)

    def residual(s: np.ndarray, w: np.ndarray, f: np.ndarray) -> np.ndarray:
        surplus: np.ndarray = tractive_effort(terrain, w, width, length, np.clip(s, -1.0, 1.0)) - f
        return surplus

    res = elementwise.find_root(
        residual,
        (np.full(load.shape, -1.0), np.full(load.shape, 1.0)),
        args=(load, target),
        tolerances={'xatol': 1e-12, 'xrtol': 1e-12},
    )
    return np.where(ok, res.x, np.sign(thrust)), ok & np.asarray(res.success)


def solve(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: ArrayLike,
    turn_radius: ArrayLike,
    *,
    source: str = 'wong',
    tables: TurningTables | None = None,
    raise_on_failure: bool | None = None,
    **options: object,
) -> SteadyState:
    """Chapter 5 fast model at forward speed V [m/s] and signed turning radius R [m] (inf straight).

    ``source`` names the model the mu_t / s0 tables come from ('wong', as in the text, or 'fess');
    ``tables`` passes prepared :class:`TurningTables`. Tracked vehicles only.
    """
    if options:
        raise InputError(f'unknown fast-model option(s): {", ".join(sorted(options))}')
    if not vehicle.is_tracked:
        raise InputError(f'the chapter 5 fast model is for tracked vehicles; {vehicle.name!r} has wheels')
    scalar = np.ndim(speed) == 0 and np.ndim(turn_radius) == 0
    pts = operating_points(speed, turn_radius)
    table = tables if tables is not None else turning_tables(vehicle, terrain, source)
    start = time.perf_counter()
    curvature = np.where(np.isinf(pts.radius), 0.0, 1.0 / pts.radius)
    mu_t, s0, clamped = table.lookup(pts.speed, curvature)
    lo, li = side_loads(vehicle, pts)
    rto, rti = _resistances(vehicle, terrain, pts)
    fc = vehicle.mass_kg * pts.centripetal_accel  # m V^2 / R
    beta = sideslip_angle(s0, pts)
    half = 0.5 * vehicle.tread_m
    tracks = vehicle.tracks()
    length, width = float(tracks.track_length_m), float(tracks.track_width_m)
    a1 = fc * np.sin(beta) + rto + rti  # eq. 5.2
    a2 = (vehicle.weight_N * length * mu_t + (rto - rti) * half - s0 * np.cos(beta) * fc) / half  # 5.2 (5.1)
    f_o, f_i = 0.5 * (a1 + a2), 0.5 * (a1 - a2)
    slip_o, ok_o = slip_for_thrust(terrain, np.maximum(lo, 0), width, length, f_o)  # eq. 5.3
    slip_i, ok_i = slip_for_thrust(terrain, np.maximum(li, 0), width, length, f_i)
    v_o, v_i = pts.side_speeds(vehicle.tread_m)
    r = vehicle.drive_radius_m
    w_o, w_i = omega_for_slip(v_o, slip_o, r), omega_for_slip(v_i, slip_i, r)
    f_max_o = width * length * terrain.c + np.maximum(lo, 0) * math.tan(terrain.phi)
    f_max_i = width * length * terrain.c + np.maximum(li, 0) * math.tan(terrain.phi)
    converged = ok_o & ok_i & (li > 0)
    elapsed = time.perf_counter() - start
    state = SteadyState(
        speed_m_s=pts.speed,
        turn_radius_m=pts.turn_radius,
        s0_m=s0,
        omega_outer_rad_s=w_o,
        omega_inner_rad_s=w_i,
        torque_outer_Nm=f_o * r,
        torque_inner_Nm=f_i * r,
        power_outer_W=f_o * r * w_o,
        power_inner_W=f_i * r * w_i,
        slip_outer=slip_o,
        slip_inner=slip_i,
        thrust_outer_N=f_o,
        thrust_inner_N=f_i,
        sinkage_m=track_sinkage(terrain, np.maximum(lo, 0), width, length),
        traction_margin=np.minimum(1 - np.abs(f_o) / f_max_o, 1 - np.abs(f_i) / f_max_i),
        converged=converged,
        model='fast',
        extra={'mu_t': mu_t, 'clamped': clamped.astype(float), 'solve_time_s': np.full(len(s0), elapsed)},
    )
    if raise_on_failure is None:
        raise_on_failure = scalar
    if raise_on_failure and not np.all(converged):
        k = int(np.flatnonzero(~converged)[0])
        raise ConvergenceError(f'fast model: the tracks cannot develop the thrust needed at {pts.label(k)}')
    for name, value in list(vars(state).items()):
        if isinstance(value, np.ndarray):
            setattr(state, name, value.reshape(pts.shape))
    state.extra = {k: v.reshape(pts.shape) for k, v in state.extra.items()}
    return state
