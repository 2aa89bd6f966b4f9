"""Track contact of the twin: the shear displacement transported along each track patch (see
``model.py``'s module doc, "tracks"). SI units; sides 0 = left, 1 = right; hull frame x forward."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import roots_legendre

from skidsteer_power.terramechanics import soil
from skidsteer_power.terramechanics import track as single_track
from skidsteer_power.twin.contact import (
    DIRECTION_SMOOTHING_M_S,
    SOIL_REFRESH_STEPS,
    Contact,
    Force,
    slip_sinkage_factor,
)
from skidsteer_power.twin.terrain_field import TerrainField
from skidsteer_power.vehicle import Vehicle

TRACK_NODES = 32
"""Intervals along each track patch [-] (nodes every l / 32; 1.4 cm on the test robot)."""
TRACK_ROWS = 2
"""Gauss-Legendre rows across each track [-]."""
TRACK_LONGITUDINAL_MODULUS = 4.0
"""K_x / K [-] of a track (extended contact): the longitudinal shear-displacement modulus of the belt
against the soil is 4 K; laterally it stays K (eqs. 2.3, 3.12-3.15 in the scaled displacement
(j_x K / K_x, j_y)). Wong's track theory takes the belt as inextensible and rigidly driven; the test
robot's belt is neither (ch. 7.3.4: "repeated bending of the tracks ... oscillation of the track
tension ... sand got into the gaps between the tracks and the sprockets"), a compliance in series
with the soil's shear along the track. FITTED to the track's seven 0.1 m/s Appendix D radii
(docs/TWIN.md); the check: the track's 0.2 m/s and the 6-wheel radii, Table 7.3, and chapter 7.3's
torques (FESS at the measured motion matched the real track's torques; it matches this twin's too,
while a stiffer lateral law that fits the same radii doubles the torques)."""


class TrackContact(Contact):
    """Each patch is a grid of nodes, ``TRACK_NODES`` + 1 along (x = l/2 ... -l/2) times
    ``TRACK_ROWS`` Gauss-Legendre rows across; every node carries the 2-D shear displacement j
    (complex x + i y, hull frame) of the belt element passing over it."""

    def __init__(self, vehicle: Vehicle, field: TerrainField, gear_ratio: float, *, extended: bool) -> None:
        super().__init__(field, vehicle.drive_radius_m, gear_ratio, 0.5 * vehicle.tread_m, extended=extended)
        self._longitudinal = 1.0 / TRACK_LONGITUDINAL_MODULUS if extended else 1.0  # K / K_x
        tracks = vehicle.tracks()
        length, b = float(tracks.track_length_m), float(tracks.track_width_m)
        n = TRACK_NODES
        dx = length / n
        x = 0.5 * length - dx * np.arange(n + 1)
        t, w = roots_legendre(TRACK_ROWS)
        eta = 0.5 * b * t
        trap = np.full(n + 1, dx)
        trap[[0, -1]] *= 0.5
        self.node_x = np.broadcast_to(x[None, :, None], (2, n + 1, TRACK_ROWS)).copy()
        self.node_y = (self.y_side[:, None, None] + eta[None, None, :]) * np.ones_like(self.node_x)
        self.node_w = np.broadcast_to(trap[:, None] * (0.5 * b * w)[None, :], self.node_x.shape).copy()
        self.node_p = self.node_x + 1j * self.node_y  # hull positions as x + i y [m]
        self.node_dx = dx
        self.track_x, self.track_dx = x, trap  # positions [m] and trapezoid weights [m] along
        self.track_length, self.width = length, b

    def reset(self) -> None:
        self.j = np.zeros(self.node_x.shape, dtype=complex)  # j_x + i j_y [m] (side, along, across)
        self._soil_age = 0
        self._side_column = np.zeros((2, 1, 1), dtype=complex)  # (advance)
        self._courant = np.zeros((2, 1, 1))
        self._dig = np.ones(2)  # slip-sinkage factor of each side (Lyasko 2010) [-]
        self._step_s = 0.0  # the last step [s] (advance)
        super().reset()

    def _slip_sinkage(self, vel: np.ndarray, omega_m: np.ndarray) -> np.ndarray:
        """Each side's slip-sinkage factor K_j (Lyasko 2010, as under a wheel) at the side's slip
        (eq. 2.13), relaxed over the belt's transit of the patch; 1 with the classic laws [-]."""
        if not self.extended:
            return self._dig
        belts = omega_m * (self.r / self.G)  # [m/s]
        ground = vel[0] - vel[2] * self.y_side  # each side's ground speed forward [m/s]
        slip = np.clip(
            (belts - ground) / np.maximum(np.maximum(np.abs(belts), np.abs(ground)), 1e-12), -1.0, 1.0
        )
        dt = SOIL_REFRESH_STEPS * self._step_s
        transits = np.minimum((np.abs(belts) + np.abs(ground)) / self.track_length * dt, 1.0)
        self._dig = self._dig + transits * (slip_sinkage_factor(slip) - self._dig)
        return self._dig

    def _soil(self, loads: np.ndarray, pose: np.ndarray, dig: np.ndarray) -> None:
        """Per-node shear strength [Pa x m^2], per-side compaction resistance [N] and sinkage [m]
        at the side loads [N] (eqs. 2.2, 2.6, 2.10, 3.17) and each side's slip-sinkage factor dig
        (sinkage x dig, compaction resistance x dig^(n + 1) by eq. 2.10); refreshed every
        ``SOIL_REFRESH_STEPS``."""
        b, length = self.width, self.track_length
        pressure = loads / (b * length)  # eq. 3.17
        index = self._terrain_index(self.node_x, self.node_y, pose)
        self._track_index = index
        if index is None:
            t = self.field.base
            self._tau_max_w = soil.shear_strength(t, pressure)[:, None, None] * self.node_w  # eq. 2.2
            self._rc = single_track.compaction_resistance(t, loads, b, length) * dig ** (
                t.n + 1.0
            )  # eq. 2.10
            sinkage = single_track.track_sinkage(t, loads, b, length) * dig  # eq. 2.6
            self._sinkage = float(np.max(sinkage))
            return
        p = np.broadcast_to(pressure[:, None, None], self.node_x.shape)
        strength = np.zeros(p.shape)
        rc = np.zeros(p.shape)
        sink = np.zeros(p.shape)
        deeper = np.broadcast_to(dig[:, None, None], p.shape)
        for i in np.unique(index):
            mask = index == i
            t = self.field.terrains[i]
            strength[mask] = soil.shear_strength(t, p[mask])
            rc[mask] = single_track.compaction_resistance(t, p[mask] * b * length, b, length) * deeper[
                mask
            ] ** (t.n + 1.0)
            sink[mask] = soil.sinkage_for_pressure(t, p[mask], b) * deeper[mask]
        share = self.node_w / (b * length)  # each node's share of the rut
        self._tau_max_w = strength * self.node_w
        self._rc = (rc * share).sum(axis=(1, 2))
        self._sinkage = float(sink.max())

    def forces(self, loads: np.ndarray, vel: np.ndarray, omega_m: np.ndarray, pose: np.ndarray
               ) -> tuple[Force, list[float], float, float]:  # fmt: skip
        """Vectors in the hull plane are complex numbers x + i y (j, forces, velocities)."""
        if self._soil_age <= 0:
            self._soil(loads, pose, self._slip_sinkage(vel, omega_m))
            self._soil_age = SOIL_REFRESH_STEPS
        self._soil_age -= 1
        vx, vy, wz = vel.tolist()
        j = self.j
        if self._longitudinal != 1.0:  # the belt's longitudinal displacement counts K / K_x
            j = j.real * self._longitudinal + 1j * j.imag
        mag = np.abs(j)
        if self._track_index is None and self.field.base.shear_type == 'A':
            minus_fraction = np.multiply(mag, -1.0 / self.field.base.K)
            np.expm1(minus_fraction, out=minus_fraction)  # eq. 2.3 (tau / tau_max = -this)
        else:
            minus_fraction = -self._shear_fraction(mag, self._track_index)  # eqs. 2.3-2.5
        # eqs. 3.12-3.15: tau_max f against the displacement, plus the transient damping (0 in steady
        # state): -(tau_max f / |j|) j - c tau_max dj/dt
        gain = np.multiply(minus_fraction, self._tau_max_w, out=minus_fraction)
        mag += 1e-300
        gain /= mag
        f = gain * j
        f -= self._tau_max_w * self._damped_rate
        f_side = f.sum(axis=(1, 2)).tolist()  # [N] per side (complex)
        moment = np.vdot(self.node_p, f).imag  # sum of x f_y - y f_x [N m]
        axle = [self.r * f_side[0].real, self.r * f_side[1].real]  # the belt's pull resists the sprocket
        total = f_side[0] + f_side[1]
        fx, fy, mz = total.real, total.imag, moment
        # the soil takes the power of the shear stresses on the slip velocity v + yaw e_z x p - belt:
        # what the belts put in minus what the body receives
        belts = (omega_m * (self.r / self.G)).tolist()  # belt speed relative to the hull [m/s]
        dissipation = belts[0] * f_side[0].real + belts[1] * f_side[1].real - (fx * vx + fy * vy + mz * wz)
        # compaction resistance (eq. 2.10) against each side's travel
        for rc, y in zip(self._rc.tolist(), self._side_y, strict=True):
            speed = vx - wz * y
            fc = -rc * math.tanh(speed / DIRECTION_SMOOTHING_M_S)
            fx += fc
            mz -= y * fc
            dissipation -= fc * speed
        return (fx, fy, mz), axle, dissipation, self._sinkage

    def advance(self, dt: float, vel: np.ndarray, omega_m: np.ndarray) -> None:
        """Transport the shear displacement with the belt and add the slip (see the module doc)."""
        self._step_s = dt
        vx, vy, wz = vel.tolist()
        j = self.j
        belts = (omega_m * (self.r / self.G)).tolist()
        # slip velocity of the belt element at each node, - yaw e_z x j (rotating frame)
        source = np.subtract(self.node_p, j)
        source *= 1j * wz
        offset = self._side_column  # (side, 1, 1): each side's slip velocity offset (complex)
        offset[:, 0, 0] = ((vx + 1j * vy) - belts[0], (vx + 1j * vy) - belts[1])
        source += offset
        courant = [min(abs(b) * dt / self.node_dx, 1.0) for b in belts]
        new = j.copy()
        half = 0.5 * dt
        if belts[0] > 0 and belts[1] > 0:  # both sides forward (the usual case): in one go
            c = self._courant  # (side, 1, 1)
            c[:, 0, 0] = courant
            new[:, 1:] += half * (source[:, 1:] + source[:, :-1]) + c * (j[:, :-1] - j[:, 1:])
            new[:, 0] = 0.0  # touchdown at the front
        else:
            for side in (0, 1):
                c, jj, ss, nn = courant[side], j[side], source[side], new[side]
                if belts[side] >= 0:  # touchdown at the front (node 0): node k takes the belt from k - 1
                    nn[1:] += half * (ss[1:] + ss[:-1]) + c * (jj[:-1] - jj[1:])
                    nn[0] += dt * ss[0] - c * jj[0]
                    if belts[side] > 0:
                        nn[0] = 0.0
                else:  # reversing: touchdown at the rear
                    nn[:-1] += half * (ss[:-1] + ss[1:]) + c * (jj[1:] - jj[:-1])
                    nn[-1] = 0.0
        # (the slip source is averaged over each cell, trapezoid: the steady state integrates the
        # slip velocity along the patch to second order)
        rate = new - j
        rate *= self._damping / dt
        self._damped_rate = rate
        self.j = new
