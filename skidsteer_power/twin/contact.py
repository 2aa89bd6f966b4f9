"""The twin's running-gear contact: what tracks and wheels share (see ``model.py``'s module doc).

A contact strategy (:class:`~skidsteer_power.twin.track_contact.TrackContact`,
:class:`~skidsteer_power.twin.wheel_contact.WheelContact`) owns the shear displacements of its
contact patches and the soil state under them. Each step the body asks it for the terrain's forces
at the present state (:meth:`Contact.forces`) and then lets it transport the shear over the step
with the new velocities (:meth:`Contact.advance`). SI units throughout; sides 0 = left, 1 = right.

The laws beyond the steady models of chapters 2-4 (``extended`` contact; ``classic`` switches them
off): slip-sinkage under wheels and tracks (Lyasko 2010, :func:`slip_sinkage_factor`), bulldozing of
a digging wheel's excavated step (Hegedus, as Ishigami et al. 2007 apply it,
:func:`bulldozing_coefficients`) and the track belt's longitudinal shear modulus
(``track_contact.TRACK_LONGITUDINAL_MODULUS``, fitted; docs/TWIN.md).
"""

from __future__ import annotations

import math

import numpy as np

from skidsteer_power.terramechanics import soil
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.twin.terrain_field import TerrainField

CONTACT_LAWS = ('classic', 'extended')
"""``classic``: the chapter 2-4 laws only; ``extended``: plus slip-sinkage and bulldozing."""
DIRECTION_SMOOTHING_M_S = 0.005
"""Ground speed over which the compaction resistance changes direction [m/s]."""
SOIL_REFRESH_STEPS = 10
"""Steps between refreshes of the load-dependent soil terms (pressure, compaction, sinkage, terrain
under the contact): loads change over tens of ms, not 1 ms [-]."""
SHEAR_DAMPING_S = 0.05
"""ASSUMED transient shear damping: a node adds c dj/dt (at the fixed node, i.e. zero in steady
state) with c = (tau_max / K) t_d, t_d = 0.05 s. Without it the Janosi-Hanamoto curve acts as an
undamped spring between body and soil (a real soil unloads along a stiffer, dissipative path) and
the 30 kg body surges at ~1.7 Hz; see docs/TWIN.md."""
SOIL_UNIT_WEIGHT_N_M3 = 15.7e3
"""ASSUMED unit weight of the soil gamma [N/m^3] in the bulldozing resistance, for every terrain
(the presets carry none): dry sand of 1600 kg/m^3, inside the 14-18 kN/m^3 that soil-mechanics
texts give for loose to dense dry sand. At the test robot's sinkages the cohesion term dominates
(dry sand, wheel sinkage 23 mm: c h = 23 N/m against 0.5 D2 gamma h^2 = 14 N/m)."""

Force = tuple[float, float, float]
"""Body force in the hull frame (F_x [N], F_y [N], M_z [N m])."""


def slip_sinkage_factor(slip: np.ndarray) -> np.ndarray:
    """Lyasko's slip-sinkage coefficient K_j = (1 + i) / (1 - 0.5 i) [-] at slip i (eq. 2.13):
    total sinkage = K_j x static sinkage (M. Lyasko, "Slip sinkage effect in soil-vehicle
    mechanics", J. Terramechanics 47 (2010) 21-31), for a driven wheel (i >= 0; 1 when braking)."""
    i = np.minimum(np.maximum(slip, 0.0), 1.0)
    factor: np.ndarray = (1.0 + i) / (1.0 - 0.5 * i)
    return factor


def bulldozing_coefficients(terrain: Terrain) -> tuple[float, float]:
    """(A [N/m^2], B [N/m^3]) of the bulldozing resistance per unit length of a contact's side wall,
    R_b(h) = A h + B h^2 [N/m] at depth h [m] below the surface (Hegedus 1960, as Ishigami et al.
    2007 apply it to the side of a wheel under side slip: J. Field Robotics 24(3), 233-250):

        R_b = D1 (c h + D2 gamma h^2 / 2),  D1 = cot X_c + tan(X_c + phi),
        D2 = cot X_c + cot^2 X_c / cot phi,  X_c = 45 deg - phi / 2

    with the terrain's c [Pa] and phi (eq. 2.2) and gamma = ``SOIL_UNIT_WEIGHT_N_M3``. The
    dissertation names bulldozing (ch. 2.3, "especially significant when sinkage is large") and
    neglects it for SUGVs; the twin applies it to the face of the step a digging wheel leaves (the
    side walls against lateral sliding: not applied, docs/TWIN.md)."""
    xc = 0.25 * math.pi - 0.5 * terrain.phi
    cot = 1.0 / math.tan(xc)
    d1 = cot + math.tan(xc + terrain.phi)
    d2 = cot + cot * cot * math.tan(terrain.phi)
    return d1 * terrain.c, 0.5 * d1 * d2 * SOIL_UNIT_WEIGHT_N_M3


def bulldozing_resistance(a: float | np.ndarray, b: float | np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """R_b = (A + B h) h [N/m] per unit length of side wall at depth h [m], from
    :func:`bulldozing_coefficients` (A and B floats or arrays, broadcast against the depths)."""
    resistance: np.ndarray = (a + b * depth_m) * depth_m
    return resistance


class Contact:
    """What both running gears share: the terrain field, the geometry of the sides, the switch
    between the classic and the extended laws, the shear state and the body's implicit damping.

    Subclasses set ``j`` (shear displacements [m]) in :meth:`reset` and implement :meth:`forces`
    and :meth:`advance`.
    """

    j: np.ndarray

    def __init__(self, field: TerrainField, drive_radius_m: float, gear_ratio: float, half_tread_m: float,
                 *, extended: bool) -> None:  # fmt: skip
        self.field = field
        self.r = drive_radius_m
        self.G = gear_ratio
        self.half_tread = half_tread_m
        self.y_side = np.array([half_tread_m, -half_tread_m])
        self._side_y = (half_tread_m, -half_tread_m)  # (floats)
        self.extended = extended

    def reset(self) -> None:
        """Shear relaxed, static sinkage (subclasses extend it and set ``j`` before calling this)."""
        self.body_damping = (0.0, 0.0, 0.0, 0.0, 0.0)  # slopes (d_xx, d_xw, d_yy, d_yw, d_ww) (Twin._move)
        self._damped_rate = np.zeros_like(self.j)  # t_d / K dj/dt [-]: the damping stress / tau_max
        self._damping = SHEAR_DAMPING_S / self.field.base.K  # [s/m]: c = tau_max t_d / K

    def forces(self, loads: np.ndarray, vel: np.ndarray, omega_m: np.ndarray, pose: np.ndarray
               ) -> tuple[Force, list[float], float, float]:  # fmt: skip
        """Body force (F_x, F_y, M_z) [N, N, N m], the terrain's resisting axle torque per side
        [N m], the power dissipated in the soil [W] and the deepest sinkage [m], at the side loads
        [N], body velocity (v_x, v_y [m/s], yaw rate [rad/s]), motor speeds [rad/s] and pose."""
        raise NotImplementedError

    def advance(self, dt: float, vel: np.ndarray, omega_m: np.ndarray) -> None:
        """Transport the shear displacements over dt [s] at the new velocities."""
        raise NotImplementedError

    def motor_speeds_changed(self) -> None:
        """The motor speeds were set from outside (live coupling): drop what was derived from them."""

    def _bulldozing(self, terrain: Terrain) -> tuple[float, float]:
        """:func:`bulldozing_coefficients` of ``terrain``, (0, 0) with the classic laws."""
        return bulldozing_coefficients(terrain) if self.extended else (0.0, 0.0)

    def _terrain_index(self, hx: np.ndarray, hy: np.ndarray, pose: np.ndarray) -> np.ndarray | None:
        """Terrain index of hull points (hx, hy) [m] at ``pose``; None if the floor is uniform."""
        if self.field.uniform:
            return None
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        return self.field.index_at(x + c * hx - s * hy, y + s * hx + c * hy)

    def _shear_fraction(self, magnitude: np.ndarray, index: np.ndarray | None) -> np.ndarray:
        """tau / tau_max at |j| [m] per node (eqs. 2.3-2.5), by the node's terrain."""
        if index is None:
            return soil.shear_fraction(self.field.base, magnitude)
        out = np.zeros(magnitude.shape)
        for i in np.unique(index):
            mask = index == i
            out[mask] = soil.shear_fraction(self.field.terrains[i], magnitude[mask])
        return out
