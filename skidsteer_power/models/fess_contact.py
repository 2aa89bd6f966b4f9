"""FESS contact description (chapter 6): element positions, normal and shear strength, and
integration weights of both sides' tracks (section 6.4) or flattened wheels (eqs. 6.8-6.11), over a
batch of operating points. Built once per batch before the Newton solve; split from
:mod:`skidsteer_power.models.fess` (the residual and solver), which re-exports these names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.models.newton import newton_solve
from skidsteer_power.terramechanics.track import compaction_resistance_unchecked, track_sinkage_unchecked
from skidsteer_power.terramechanics.wheel import (
    first_guess_unknowns,
    quadratic_stress_coefficients,
    sinkage_slip_from_unknowns,
    solve_wheel,
    solve_wheel_bracketed,
    wheel_angles,
    wheel_forces,
)

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle


@dataclass
class Contact:
    """Discretized contacts of both sides over a batch of P operating points.

    Arrays broadcast to (P, 2 sides, G gears per side, N elements); forward position of an element
    relative to its gear centre for forward rolling is ``fwd`` [m]; the entry point is ``entry`` [m];
    ``xi`` = entry - fwd is the distance behind the entry [m] (eq. 6.1). Weights [m^2] are trapezoidal
    area weights for the longitudinal force (``wx``, horizontal projection), the lateral force
    (``wy``) and the drive torque about the axle (``wt``, rim area; multiplied by r).
    """

    centre: np.ndarray  # (1, 1, G, 1) gear centre x from the CG [m]
    fwd: np.ndarray  # (P|1, 2|1, G, N)
    entry: np.ndarray  # (P|1, 2|1, G, 1)
    tau_max: np.ndarray  # (P, 2, G|1, N|1) shear strength c + sigma tan(phi) [Pa] (eq. 2.2)
    wx: np.ndarray
    wy: np.ndarray
    wt: np.ndarray
    resistance: np.ndarray  # (P, 2) compaction resistance magnitude of each side [N]
    sinkage: np.ndarray  # (P, 2) sinkage of each side [m]
    length_scale: float  # contact span used to scale s0 steps [m]
    longitudinal: float = 1.0  # K / K_x: weight of the displacement along the contact (tracks)

    @property
    def xi(self) -> np.ndarray:
        xi: np.ndarray = self.entry - self.fwd
        return xi

    def take(self, idx: np.ndarray) -> Contact:
        """The contacts of the operating points ``idx`` only."""
        out = dict(vars(self))
        for name, value in vars(self).items():
            if isinstance(value, np.ndarray) and name != 'centre' and value.shape[0] > 1:
                out[name] = value[idx]
        return Contact(**out)


def _trapezoid_weights(n: int) -> np.ndarray:
    """Trapezoid weights of n+1 equally spaced nodes on [0, 1] (sum 1)."""
    w = np.full(n + 1, 1.0 / n)
    w[[0, -1]] *= 0.5
    return w


@lru_cache(maxsize=64)
def _track_elements(length: float, width: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(forward position [m], area weight [m^2]) of a track's n + 1 element nodes, shapes (1, 1, 1, n+1):
    fixed per track, built once (the on-board point solve sets up a contact per command)."""
    s = np.linspace(0.0, 1.0, n + 1)
    fwd = (0.5 * length - s * length)[None, None, None, :]  # element k at l/2 - k l / n (eq. 6.6)
    area = width * length * _trapezoid_weights(n)[None, None, None, :]
    fwd.flags.writeable = area.flags.writeable = False
    return fwd, area


def track_contact(vehicle: Vehicle, terrain: Terrain, loads: np.ndarray, n: int) -> Contact:
    """Contact of two tracks with uniform pressure L_side / (b l) (section 6.4); loads (P, 2) [N].
    Rigid ground has its own contact (:func:`~skidsteer_power.models.rigid_contact.rigid_contact`)."""
    if terrain.is_rigid:
        raise InputError(f'{terrain.name!r} is rigid ground: its contact is rigid_contact.rigid_contact')
    tracks = vehicle.tracks()
    length, width = float(tracks.track_length_m), float(tracks.track_width_m)
    fwd, area = _track_elements(length, width, n)
    pressure = np.maximum(loads, 0.0) / (width * length)
    tau_max = (terrain.c + pressure * math.tan(terrain.phi))[:, :, None, None]  # eq. 2.2
    safe = np.maximum(loads, 0.0)
    return Contact(
        centre=np.zeros((1, 1, 1, 1)),
        fwd=fwd,
        entry=np.full((1, 1, 1, 1), 0.5 * length),
        tau_max=tau_max,
        wx=area,
        wy=area,
        wt=area,
        # eqs. 2.10, 2.6; loads >= 0 (above) and finite (side_loads of finite V, w_z), b and l
        # validated by the vehicle file
        resistance=compaction_resistance_unchecked(terrain, safe, width, length),
        sinkage=track_sinkage_unchecked(terrain, safe, width, length),
        length_scale=length,
        longitudinal=1.0 / float(tracks.track_longitudinal_shear_ratio),
    )


FREE_WHEEL_TOL_N = 1e-7
"""Balance tolerance of the free-wheel table [N]: far inside eq. 2.29's 0.001 N, so the table is the
scalar solve's (:func:`~skidsteer_power.terramechanics.wheel.solve_wheel`) to about 1e-8."""


@lru_cache(maxsize=32)
def _free_wheel_table(
    terrain: Terrain, radius: float, width: float, nominal_load: float
) -> tuple[np.ndarray, ...]:
    """Sinkage and slip of a self-propelled wheel (F_x = 0, eq. 2.28) over a range of wheel loads.

    Section 6.3 decouples slip and sinkage: each wheel's contact geometry comes from the single-wheel
    model at its load (eq. 2.28 with zero drawbar pull). The (z, s) solve is done once per
    (terrain, wheel) at 25 loads from 2 % to 200 % of the nominal wheel load and interpolated in
    log(load): a batch of operating points then needs no per-point Newton solve. The 25 loads are
    one batched Newton (:func:`~skidsteer_power.models.newton.newton_solve`, eqs. 2.29-2.33) from
    solve_wheel's first guess and in its unknowns (theta_f through a logistic, s = tanh u); a load it
    does not converge falls back to :func:`~skidsteer_power.terramechanics.wheel.solve_wheel`.
    """
    loads = nominal_load * np.geomspace(0.02, 2.0, 25)
    if terrain.n >= 3:  # no eq. 2.32 first guess: solve_wheel's own fallback, the bracketed solve
        state = solve_wheel_bracketed(terrain, loads, 0.0, radius, width)
        return np.log(loads), np.asarray(state.sinkage_m, dtype=float), np.asarray(state.slip, dtype=float)
    x0 = first_guess_unknowns(terrain, loads, radius, width)

    def balance(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
        z, s = sinkage_slip_from_unknowns(x, radius)
        state = wheel_forces(terrain, z, s, radius, width)
        return np.column_stack([state.Fx_N, state.Fz_N - loads[idx]])  # eq. 2.29, F_d = 0

    result = newton_solve(balance, x0, steps=np.array([1e-7, 1e-7]), tol=FREE_WHEEL_TOL_N)
    sink, slip = sinkage_slip_from_unknowns(result.x, radius)
    for k in np.flatnonzero(~result.converged):
        state = solve_wheel(terrain, float(loads[k]), 0.0, radius, width)
        sink[k], slip[k] = float(state.sinkage_m), float(state.slip)
    return np.log(loads), sink, slip


def wheel_contact(vehicle: Vehicle, terrain: Terrain, loads: np.ndarray, n: int) -> Contact:
    """Flattened wheel contacts with quadratic normal stress (eqs. 6.8-6.11); side loads (P, 2) [N].
    Rigid ground has its own contact (:func:`~skidsteer_power.models.rigid_contact.rigid_contact`)."""
    if terrain.is_rigid:
        raise InputError(f'{terrain.name!r} is rigid ground: its contact is rigid_contact.rigid_contact')
    wheels = vehicle.wheels()
    r, b = float(wheels.wheel_radius_m), float(wheels.wheel_width_m)
    per_side = vehicle.wheels_per_side
    nominal = vehicle.weight_N / (2 * per_side)
    log_w, sink_tab, slip_tab = _free_wheel_table(terrain, r, b, nominal)
    wheel_load = np.maximum(loads, 1e-9 * nominal) / per_side  # (P, 2)
    lw = np.log(wheel_load)
    z = np.interp(lw, log_w, sink_tab)
    s = np.interp(lw, log_w, slip_tab)
    tf, tm, tr = wheel_angles(terrain, z, s, r)
    front, rear = quadratic_stress_coefficients(terrain, z, s, r, b)  # eq. 6.10, (P, 2, 3)
    u = np.linspace(0.0, 1.0, n + 1)
    theta = tf[..., None] - (tf - tr)[..., None] * u  # nodes from entry to exit, (P, 2, N)
    coef = np.where((theta >= tm[..., None])[..., None], front[..., None, :], rear[..., None, :])
    sigma = np.maximum((coef[..., 0] * theta + coef[..., 1]) * theta + coef[..., 2], 0.0)  # eq. 6.9
    dtheta = ((tf - tr)[..., None] * _trapezoid_weights(n)) * r * b  # rim area weights (P, 2, N)
    rim = dtheta[:, :, None, :]
    centre = np.array(vehicle.axle_positions_m())[None, None, :, None]
    resistance = per_side * np.sum(sigma * np.sin(theta) * dtheta, axis=-1)  # rb int sigma sin (2.27)
    return Contact(
        centre=centre,
        fwd=(r * np.sin(theta))[:, :, None, :],  # flat contact: x = r sin(theta) (eq. 6.11)
        entry=(r * np.sin(tf))[:, :, None, None],
        tau_max=(terrain.c + sigma * math.tan(terrain.phi))[:, :, None, :],
        wx=rim * np.cos(theta)[:, :, None, :],
        wy=rim,
        wt=rim,
        resistance=resistance,
        sinkage=np.where(loads > 0, z, 0.0),
        length_scale=float(wheels.wheelbase_m) + 2 * r,
    )
