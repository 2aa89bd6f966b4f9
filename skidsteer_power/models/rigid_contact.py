"""FESS's contact on rigid ground (issue 35): Coulomb friction and rolling resistance over the same
discretised contact patch as on soil (chapter 6), so the same residual, Newton solve, set-point
solve and maps apply unchanged.

On ground that does not deform (asphalt, concrete, indoor flooring, ice) Bekker's pressure-sinkage
law and the compaction resistance of eq. 2.10 are not the physics. What remains is the regime of
the ICR model (section 3.4, eqs. 3.24-3.26): every contact element carries friction mu p dA against
its slip. Saturated Coulomb friction has no steady state at small slip (straight running is
indeterminate and the turning solution does not tend to it as R grows, section 3.4); here the
friction is mobilised with the element's shear displacement j exactly like soil shear of type A,

    tau = p (1 - exp(-|j| / K)) (mu_x j_x, mu_y j_y) / |j|          (eq. 6.7 with eq. 2.3's form)

so a steady state exists at every slip and turning is well-posed; K [m] is the slip modulus (a few
mm for a tyre: the brush model's slip stiffness). mu_x (``mu_longitudinal``) acts along the running
gear, mu_y (``mu_lateral``) across it (Steeds' mu_t, Table 3.1); the resultant lies between them.
In FESS's kernel the stress is tau_max f(|j|) j / |j| with tau_max = mu_x p (eq. 2.2 with c = 0,
tan(phi) = mu_x), and the lateral component carries mu_y / mu_x in its area weight ``wy``.

The displacement j of friction (:func:`slip_path_displacement`): friction opposes the element's
*current* slip velocity v = (V - w_z y_side - omega r, w_z (x - s0)) (eq. 3.25's velocity, the ICR
model's direction), and is mobilised by the *length of the slip path* since the element touched
down, |j| = int |v| dt (eq. 6.5's time in contact, dt = dx / (|omega| r)). On soil FESS takes j as
the chord from the gripped ground point (eq. 6.6), which is the same for straight running (the
path is straight) but not in a turn: there the chord's direction lags behind the slip velocity, in a
spin the sideways chord grows from the entry to the exit without changing sign at the centre, and a
track on Coulomb ground would spin against almost no moment (0.13 N m where Steeds' closed form,
eq. 3.6, gives 21 N m for test_robot_track on asphalt). With the path law a saturated contact is
the ICR model's Coulomb contact (section 3.4), and a side that stands still (omega = 0: the pivot
turn's inner side) is an ordinary, fully sliding contact rather than a singular one.

Each side's rolling resistance is f_r times its vertical load (eq. 3.2's place), against its
motion over the ground; sinkage is 0.

Tracks: uniform pressure over the track's contact length (section 6.4), as on soil. Wheels: a flat
tyre patch of length 2 r sqrt(1 - (1 - d)^2) at a tyre deflection d = :data:`TYRE_DEFLECTION`
(ASSUMED) of the radius, uniform pressure, centred under each axle (eq. 6.11's placement). A wheeled
vehicle's turning resistance comes from its wheelbase, the patch length matters little.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.models.fess_contact import Contact

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

TYRE_DEFLECTION = 0.05
"""ASSUMED tyre deflection on rigid ground as a fraction of the wheel radius [-] (a pneumatic or
solid robot tyre under its static load: 3-8 % typical); it sets the patch length only."""


def patch_length_m(radius_m: float) -> float:
    """Flat tyre patch length [m] of a wheel of radius r [m] at :data:`TYRE_DEFLECTION`: the chord
    2 sqrt(r^2 - (r - d r)^2) of the deflected tyre."""
    return 2.0 * radius_m * math.sqrt(1.0 - (1.0 - TYRE_DEFLECTION) ** 2)


@lru_cache(maxsize=64)
def _patch(length: float, width: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(forward position [m], area weight [m^2]) of a patch's n + 1 nodes, shapes (1, 1, 1, n+1):
    node k at l/2 - k l / n (eq. 6.6), trapezoid weights (sum b l)."""
    s = np.linspace(0.0, 1.0, n + 1)
    weights = np.full(n + 1, 1.0 / n)
    weights[[0, -1]] *= 0.5
    fwd = (0.5 * length - s * length)[None, None, None, :]
    area = width * length * weights[None, None, None, :]
    fwd.flags.writeable = area.flags.writeable = False
    return fwd, area


def straight_slip_guess(vehicle: Vehicle, terrain: Terrain) -> float:
    """First guess of the driving slip of straight running on rigid ground [-]: the brush model's
    small-slip thrust F = mu W s l / (2 K) (uniform pressure, f = 1 - exp(-s xi / K) ~ s xi / K)
    set equal to the rolling resistance f_r W, s = 2 K f_r / (mu l), with l the patch (track)
    length; at least 1e-4 (the Newton iteration needs a slip to orient the friction)."""
    assert terrain.rolling_resistance is not None  # rigid: validated
    length = (
        float(vehicle.tracks().track_length_m)
        if vehicle.is_tracked
        else patch_length_m(float(vehicle.wheels().wheel_radius_m))
    )
    guess = 2.0 * terrain.K * float(terrain.rolling_resistance) / (terrain.mu_longitudinal * length)
    return float(min(max(guess, 1e-4), 0.5))


def rigid_contact(vehicle: Vehicle, terrain: Terrain, loads: np.ndarray, n: int) -> Contact:
    """Contact of both sides on rigid ground for side loads (P, 2) [N] (module doc)."""
    assert terrain.mu_lateral is not None and terrain.rolling_resistance is not None  # rigid: validated
    safe = np.maximum(loads, 0.0)
    mu_x = terrain.mu_longitudinal
    ratio = float(terrain.mu_lateral) / mu_x
    if vehicle.is_tracked:
        tracks = vehicle.tracks()
        length, width = float(tracks.track_length_m), float(tracks.track_width_m)
        per_side = 1
        centre = np.zeros((1, 1, 1, 1))
        span = length
        longitudinal = 1.0 / float(tracks.track_longitudinal_shear_ratio)
    else:
        wheels = vehicle.wheels()
        r = float(wheels.wheel_radius_m)
        length, width = patch_length_m(r), float(wheels.wheel_width_m)
        per_side = vehicle.wheels_per_side
        centre = np.array(vehicle.axle_positions_m())[None, None, :, None]
        span = float(wheels.wheelbase_m) + 2 * r  # as on soil (fess_contact.wheel_contact)
        longitudinal = 1.0
    fwd, area = _patch(length, width, n)
    pressure = safe / (per_side * width * length)  # one element's pressure [Pa]
    return Contact(
        centre=centre,
        fwd=fwd,
        entry=np.full((1, 1, 1, 1), 0.5 * length),
        tau_max=(mu_x * pressure)[:, :, None, None],  # eq. 2.2 with c = 0, tan(phi) = mu_x
        wx=area,
        wy=area * ratio,  # the lateral stress's mu_y / mu_x (module doc)
        wt=area,
        resistance=float(terrain.rolling_resistance) * safe,  # f_r x side load [N]
        sinkage=np.zeros_like(safe),
        length_scale=span,
        longitudinal=longitudinal,
    )


def _arc(u: np.ndarray, a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Antiderivative in u of sqrt(a^2 + w^2 u^2): (u q + (a^2 / |w|) asinh(|w| u / |a|)) / 2 with
    q = sqrt(a^2 + w^2 u^2), written as (u q + |a| u asinh(z) / z) / 2, z = |w u / a|, which stays
    finite for a = 0 (then |w| u |u| / 2) and for w = 0 (then |a| u) [m^2/s]."""
    abs_a, abs_wu = np.abs(a), np.abs(w * u)
    q = np.hypot(a, abs_wu)
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        z = np.minimum(abs_wu / abs_a, 1e300)
        ratio = np.where(z > 1e-8, np.arcsinh(z) / np.where(z > 0, z, 1.0), 1.0)  # asinh(z) / z
    arc: np.ndarray = 0.5 * u * (q + np.where(abs_a > 0, abs_a * ratio, 0.0))
    return arc


def slip_path_displacement(
    u: np.ndarray, u_entry: np.ndarray, along: np.ndarray, yaw: np.ndarray, rim: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Friction's displacement (j_x, j_y) [m] of contact elements (module doc): the slip path length
    since touch-down along the current slip velocity.

    u : element x relative to the turning centre's projection, x - s0 [m]; u_entry : the same at its
    touch-down point [m]; along : its side's longitudinal slip velocity V - w_z y_side - omega r
    [m/s]; yaw : w_z [rad/s] (the lateral slip velocity is w_z u, eq. 3.25); rim : |omega| r [m/s],
    > 0 (the element's speed through the contact). Broadcast arrays."""
    lateral = yaw * u
    speed = np.hypot(along, lateral)
    path = np.abs(_arc(u, along, yaw) - _arc(u_entry, along, yaw)) / rim  # int |v| dx / (|omega| r)
    with np.errstate(divide='ignore', invalid='ignore'):
        gain = np.where(speed > 0, path / np.where(speed > 0, speed, 1.0), 0.0)
    jx: np.ndarray = gain * along
    jy: np.ndarray = gain * lateral
    return jx, jy
