"""Wheel contact of the twin: Wong-Reece stresses on each wheel's contact arc with the rim's shear
displacement transported through it, and each wheel's sinkage relaxed towards the vertical balance
(see ``model.py``'s module doc, "wheels"). SI units; sides 0 = left, 1 = right; hull frame x forward."""

from __future__ import annotations

import math

import numpy as np

from skidsteer_power.terramechanics import soil
from skidsteer_power.terramechanics import wheel as single_wheel
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.twin.contact import (
    DIRECTION_SMOOTHING_M_S,
    SOIL_REFRESH_STEPS,
    Contact,
    Force,
    bulldozing_resistance,
    slip_sinkage_factor,
)
from skidsteer_power.twin.terrain_field import TerrainField
from skidsteer_power.vehicle import Vehicle

WHEEL_NODES = 24
"""Intervals along each wheel's contact arc [-]."""
SINKAGE_SETTLING_S = 0.5
"""Time constant of a standing wheel's sinkage towards the vertical balance [s] (ASSUMED)."""

SideKinematics = tuple[float, float, float, float, float]
"""Axle ground speed forward [m/s], the same in the rolling frame [m/s], |omega| [rad/s], rolling
direction (+-1), slip (eq. 2.13) [-]."""
Kinematics = tuple[list[SideKinematics], np.ndarray]
"""Per side :data:`SideKinematics`; per wheel the lateral ground speed [m/s]."""


class WheelContact(Contact):
    """Each wheel's contact arc [theta_r, theta_f] carries ``WHEEL_NODES`` + 1 rim nodes; j[0] is the
    tangential and j[1] the lateral shear displacement [m] (wheel, rim node)."""

    def __init__(self, vehicle: Vehicle, field: TerrainField, gear_ratio: float, *, extended: bool) -> None:
        super().__init__(field, vehicle.drive_radius_m, gear_ratio, 0.5 * vehicle.tread_m, extended=extended)
        self._weight_N = vehicle.weight_N
        self._patched = not field.uniform
        wheels = vehicle.wheels()
        nw = wheels.n_wheels
        axles = np.array(vehicle.axle_positions_m())
        self.wheel_side = np.repeat([0, 1], len(axles))
        self.wheel_x = np.tile(axles, 2)
        self.wheel_y = self.y_side[self.wheel_side]
        self.width = float(wheels.wheel_width_m)
        self.xi = np.linspace(0.0, 1.0, WHEEL_NODES + 1)
        trap = np.full(WHEEL_NODES + 1, 1.0 / WHEEL_NODES)
        trap[[0, -1]] *= 0.5
        self.xi_w = trap
        self._xi_pair = np.stack([self.xi, 1.0 - self.xi])  # (forces)
        self.n_wheels = nw
        self._wheels_per_side = nw // 2
        # sums over the wheels (forces): all, x-weighted, x^2-weighted, left side, right side
        left = (self.wheel_side == 0).astype(float)
        self._wheel_weights = np.stack([np.ones(nw), self.wheel_x, self.wheel_x**2, left, 1.0 - left], axis=1)
        self._sinkage_exponent = 1.0 / (self.field.base.n + 0.5)  # eq. 2.32: Fz ~ z^(n + 1/2)
        if field.uniform:
            self._soil(np.zeros(3))  # once (with patches: refreshed while stepping)

    def reset(self) -> None:
        w_wheel = self._weight_N / self.n_wheels
        z0 = float(single_wheel.bekker_wheel_sinkage(self.field.base, w_wheel, self.r, self.width))
        self.z = np.full(self.n_wheels, min(z0, 0.5 * self.r))
        self.dz = np.zeros(self.n_wheels)  # slip-sinkage: rut excavated below the wheel [m]
        self._deepest = float(self.z.max())  # deepest z + dz [m]
        self._sense = [1.0, 1.0]  # rolling sense of each side's wheels (+-1)
        self.j = np.zeros((2, self.n_wheels, WHEEL_NODES + 1))  # j_t, j_y [m] (wheel, rim node)
        nodes = (self.n_wheels, WHEEL_NODES + 1)
        self._rows = np.empty((6, *nodes))  # integrands (forces)
        self._rows_flat = self._rows.reshape(6 * self.n_wheels, -1)  # (views of the same memory)
        self._integrals = np.empty((6, self.n_wheels))
        self._integrals_flat = self._integrals.reshape(-1)
        self._angles = np.zeros((3, *nodes))  # (forces)
        self._trig = self._angles[:2]  # cos, sin of the node angles
        self._depth = np.empty(nodes)
        self._u_pair = np.empty((2, *nodes))
        self._u_pair_flat = self._u_pair.reshape(2 * self.n_wheels, -1)
        self._outer = np.zeros((2 * self.n_wheels, 2))
        self._spans, self._slope_spans = [0.0] * self.n_wheels, [0.0] * self.n_wheels
        self._per_wheel = np.zeros((6, self.n_wheels))  # contact integrals (forces)
        self._cell, self._change = np.zeros(nodes), np.empty((2, *nodes))  # (advance)
        self._damped = np.empty((2, *nodes))  # (forces)
        self._soil_age = 0
        self._loads = np.zeros(2)  # side loads of the last force step [N] (_relax_sinkage)
        self._geometry()
        self._face_sides = (0.0, 0.0)  # the excavated step's bulldozing per side [N] (_contact)
        self._contact_age = 1
        self._kinematics: Kinematics | None = None  # of the present velocities
        super().reset()

    def motor_speeds_changed(self) -> None:
        self._kinematics = None

    @property
    def deepest_m(self) -> float:
        """The deepest wheel's sinkage plus excavation z + dz [m]."""
        return self._deepest

    def _soil(self, pose: np.ndarray) -> None:
        """Per-wheel constants of the terrain under each wheel (uniform floor: once; with patches:
        every ``SOIL_REFRESH_STEPS``): Wong-Reece stress factor r^n (kc / b + kphi) [Pa] and exponent
        n (eq. 2.21), c [Pa] and tan(phi) (eq. 2.2), the angle coefficients a0, a1, b0, b1 (eqs.
        2.20, 2.22) as (n_wheels, 1) columns, and the shear law (None: type A with K [m], else the
        terrains per wheel for ``soil.shear_fraction``)."""
        index = self._terrain_index(self.wheel_x, self.wheel_y, pose)
        self._wheel_index = index
        field = self.field
        terrains = [field.base] * self.n_wheels if index is None else [field.terrains[i] for i in index]
        r, b = self.r, self.width

        def column(values: list[float]) -> np.ndarray:
            return np.array(values, dtype=float)[:, None]

        def spread(values: list[float]) -> np.ndarray:  # over the rim nodes (see _geometry)
            return np.repeat(column(values), WHEEL_NODES + 1, axis=1)

        self._wp_stress = spread([r**t.n * t.k_eq(b) for t in terrains])
        exponents = {t.n for t in terrains}
        self._wp_n: float | np.ndarray = (
            exponents.pop() if len(exponents) == 1 else spread([t.n for t in terrains])
        )
        self._wp_c = spread([t.c for t in terrains])
        self._wp_tan_phi = spread([math.tan(t.phi) for t in terrains])
        angles = [(t.a0, t.a1, t.b0, t.b1) for t in terrains]
        groups: dict[tuple[int, tuple[float, ...]], list[int]] = {}
        for wheel, coefficients in enumerate(angles):
            groups.setdefault((int(self.wheel_side[wheel]), coefficients), []).append(wheel)
        self._wp_groups = [(side, coefficients, wheels) for (side, coefficients), wheels in groups.items()]
        bull = [self._bulldozing(t) for t in terrains]
        self._wp_bull = (column([a for a, _ in bull]), column([b_ for _, b_ in bull]))
        if all(t.shear_type == 'A' for t in terrains):
            self._wp_inv_k: np.ndarray | None = spread([-1.0 / t.K for t in terrains])
            self._wp_terrains: list[Terrain] | None = None
        else:
            self._wp_inv_k, self._wp_terrains = None, terrains

    def _kinematics_of(self, vel: np.ndarray, omega_m: np.ndarray) -> Kinematics:
        """Per side (floats: the wheels of a side share them): axle ground speed forward [m/s],
        the same in the rolling frame [m/s], |omega| [rad/s], rolling direction (+-1), slip (eq.
        2.13) [-]; per wheel: lateral ground speed [m/s]. A side whose rolling sense changed
        mirrors its wheels' rim displacement first."""
        vx, vy, wz = vel.tolist()
        k = self._wheels_per_side
        r = self.r
        sides = []
        for side, w in enumerate(omega_m.tolist()):
            w /= self.G
            sense = 1.0 if w > 0 else (-1.0 if w < 0 or vx < 0 else 1.0)
            if sense != self._sense[side]:
                # a wheel that reverses keeps its soil: the rim nodes' order (entry <-> exit) and the
                # tangential displacement in the rolling frame mirror, so the stress on the rim does
                # not jump (without this a standing wheel chatters between the two senses every step)
                wheels = slice(side * k, (side + 1) * k)
                self.j[:, wheels] = self.j[:, wheels, ::-1]
                self.j[0, wheels] *= -1.0
                self._damped_rate[:, wheels] = 0.0
                self._sense[side] = sense
            vxa = vx - wz * self.half_tread * (1.0 - 2.0 * side)  # axle ground speed, forward
            vxm = sense * vxa  # mirrored so the wheel rolls forward
            om = abs(w)
            rw = r * om
            # eq. 2.13: (r w - V) / (r w) driving, (r w - V) / V braking: one denominator, max(r w, |V|)
            slip = min(1.0, max(-1.0, (rw - vxm) / max(rw, abs(vxm), 1e-12)))
            sides.append((vxa, vxm, om, sense, slip))
        return sides, vy + wz * self.wheel_x  # lateral [m/s]

    def _geometry(self) -> None:
        """Entry angle theta_f = arccos(1 - z / r) (eq. 2.19) of each wheel at its sinkage, as the
        pair (theta_f, theta_f - pi / 2) (one cosine call gives cos and sin of the node angles) and
        cos(theta_f), spread over the rim nodes (whole arrays: numpy is slower at broadcasting a
        column than at the arithmetic); with the sinkage, refreshed every ``SOIL_REFRESH_STEPS``."""
        tf = np.arccos(np.maximum(1.0 - self.z / self.r, -1.0))
        self._tf = tf.tolist()
        nodes = self._u_pair.shape[1:]
        self._tf_pair = np.broadcast_to(np.stack([tf, tf - 0.5 * math.pi])[:, :, None], (2, *nodes)).copy()
        self._cos_tf = np.broadcast_to(np.cos(tf)[:, None], nodes).copy()

    def forces(self, loads: np.ndarray, vel: np.ndarray, omega_m: np.ndarray, pose: np.ndarray
               ) -> tuple[Force, list[float], float, float]:  # fmt: skip
        """Body force (F_x, F_y, M_z), axle torques per side [N m], dissipation [W], sinkage [m].

        Shear displacement per rim node: j[0] tangential along the rim, j[1] lateral [m]. The
        contact integrals are weighted sums over the nodes (trapezoid in xi, times the arc
        r (theta_f - theta_r) and the width b), all six in one matrix product; their sums over the
        wheels (per side, and weighted by the wheels' positions) in a second one.
        """
        if self._patched:
            self._refresh_soil(pose)
        kin = self._kinematics if self._kinematics is not None else self._kinematics_of(vel, omega_m)
        sides, _ = kin
        self._arc_spans(sides)
        span = self._integrands()
        fx, fy, mz, axle, power = self._body_forces(sides, span)
        # dissipation = power of the contact stresses on the slip velocities = what the axles put in
        # minus what the body receives (F . v + M_z yaw rate)
        vx, vy, wz = vel.tolist()
        dissipation = power - (fx * vx + fy * vy + mz * wz)
        self._loads = loads
        return (fx, fy, mz), axle, dissipation, self._deepest

    def _refresh_soil(self, pose: np.ndarray) -> None:
        """With patches: the terrain under each wheel (_soil) every ``SOIL_REFRESH_STEPS`` steps."""
        if self._soil_age <= 0:
            self._soil(pose)
            self._soil_age = SOIL_REFRESH_STEPS
        else:
            self._soil_age -= 1

    def _arc_spans(self, sides: list[SideKinematics]) -> None:
        """Each wheel's arc theta_f - theta_r and its k (theta_f - theta_r) [rad] at its side's slip
        (into ``_spans``, ``_slope_spans``).

        Wong-Reece angles (eqs. 2.20, 2.22) at the side's slip i, as fractions of theta_f:
        theta_r = (b0 + b1 i) theta_f, theta_m = (a0 + a1 i) theta_f. The arc spans theta_f - theta_r;
        behind theta_m the equivalent front angle of eq. 2.22,
        theta_e = theta_f - (theta_f - theta_m) (theta - theta_r) / (theta_m - theta_r)
                = theta_f - k (span - u) (u = theta_f - theta), falls from theta_f to theta_m over
        [theta_r, theta_m] and continues below theta_m ahead of it, so the angle to use in eq. 2.21
        is max(theta, theta_e) = theta_f - min(u, k (span - u)) everywhere on the arc, with
        u = span xi and k (span - u) = k span (1 - xi): both in one matrix product (_integrands).
        """
        tfs = self._tf
        spans, slope_spans = self._spans, self._slope_spans  # theta_f - theta_r and k (theta_f - theta_r)
        for side, (a0, a1, b0, b1), wheels in self._wp_groups:  # wheels sharing a side and a soil
            i = sides[side][4]
            rear = 1.0 - b0 - b1 * i  # (theta_f - theta_r) / theta_f
            k = (1.0 - a0 - a1 * i) / max(a0 - b0 + (a1 - b1) * i, 1e-12)
            for wheel in wheels:
                spans[wheel] = arc = tfs[wheel] * rear
                slope_spans[wheel] = k * arc

    def _integrands(self) -> np.ndarray:
        """The six integrands of the contact integrals at the rim nodes into ``_rows`` [Pa]: sigma
        cos(theta), sigma sin(theta), tau_t cos(theta), tau_t sin(theta), tau_t, tau_y; returns the
        arc theta_f - theta_r per wheel [rad] (a view of ``_outer``)."""
        n = self.n_wheels
        outer = self._outer  # (2 n, 2): [span, 0] and [0, k span] rows
        outer[:n, 0] = self._spans
        span = outer[:n, 0]
        outer[n:, 1] = self._slope_spans
        np.dot(outer, self._xi_pair, out=self._u_pair_flat)
        u_pair = self._u_pair
        # u = theta_f - theta at the nodes, k (span - u) [rad] (_arc_spans)
        angles = self._angles  # theta, theta - pi / 2, max(theta, theta_e)
        np.subtract(self._tf_pair, u_pair[0], out=angles[:2])
        depth = np.minimum(u_pair[0], u_pair[1], out=angles[2])
        np.subtract(self._tf_pair[0], depth, out=depth)
        np.cos(angles, out=angles)  # cos(theta), sin(theta), cos(max(theta, theta_e))
        trig = angles[:2]
        depth -= self._cos_tf
        np.maximum(depth, 0.0, out=depth)
        sigma = np.power(depth, self._wp_n, out=self._depth)
        sigma *= self._wp_stress  # eq. 2.21
        strength = sigma * self._wp_tan_phi
        strength += self._wp_c  # eq. 2.2
        j = self.j
        mag = np.hypot(j[0], j[1])
        if self._wp_inv_k is not None:
            minus_fraction = np.expm1(mag * self._wp_inv_k)  # eq. 2.3 (tau / tau_max = -this)
        else:
            assert self._wp_terrains is not None  # set whenever _wp_inv_k is None
            pairs = zip(self._wp_terrains, mag, strict=True)
            minus_fraction = np.array([-soil.shear_fraction(t, m) for t, m in pairs])  # eqs. 2.4-2.5
        # tau_t, tau_y against the displacement (4.7, 4.8), plus the transient damping:
        # -(tau_max f / |j|) j - c dj/dt, both components at once (the sign folded into the gain)
        mag += 1e-300
        gain = np.multiply(strength, minus_fraction, out=minus_fraction)
        gain /= mag
        rows = self._rows  # (6, wheels, nodes): the integrands
        shear = rows[4:]
        np.multiply(gain, j, out=shear)
        shear -= np.multiply(strength, self._damped_rate, out=self._damped)
        np.multiply(sigma, trig, out=rows[:2])
        np.multiply(rows[4], trig, out=rows[2:4])
        return span

    def _body_forces(
        self, sides: list[SideKinematics], span: np.ndarray
    ) -> tuple[float, float, float, list[float], float]:
        """F_x, F_y [N], M_z [N m], the axle torques per side [N m] and the axles' power into the
        contact [W], from the integrands (_integrands) over the arcs ``span`` [rad]; sets
        ``body_damping`` (the slopes of the face bulldozing)."""
        r = self.r
        # per wheel [N]: s_cos, s_sin, t_cos, t_sin, t_sum, y_sum (arc x width per unit xi [m^2])
        per_wheel = self._per_wheel
        np.dot(self._rows_flat, self.xi_w, out=self._integrals_flat)
        np.multiply(self._integrals, (r * self.width) * span, out=per_wheel)
        # sums over the wheels: all, x-weighted, per side (_wheel_weights)
        (
            _,
            (_, _, _, s_sin_l, s_sin_r),
            (_, _, _, t_cos_l, t_cos_r),
            _,
            (_, _, _, t_sum_l, t_sum_r),
            (y_sum, y_sum_x, _, _, _),
        ) = per_wheel.dot(self._wheel_weights).tolist()
        # Per side (floats): the rut's resistance (-sigma sin(theta) of eq. 2.27) against travel (at
        # rest the stress is symmetric and it vanishes; smoothed like the track's compaction
        # resistance); the excavated step's face bulldozing against the axle's travel, its slope.
        fx = mz = c_x = c_x_y = c_x_yy = power = 0.0
        axle = []
        faces = self._face_sides
        for (vxa, vxm, om, sense, _slip), s_sin, t_cos, t_sum, face, y in zip(
            sides,
            (s_sin_l, s_sin_r),
            (t_cos_l, t_cos_r),
            (t_sum_l, t_sum_r),
            faces,
            self._side_y,
            strict=True,
        ):
            th_x = math.tanh(vxm / DIRECTION_SMOOTHING_M_S)
            pull = t_cos - s_sin * th_x
            th_a = math.tanh(vxa / DIRECTION_SMOOTHING_M_S)
            f = sense * pull - face * th_a  # eq. 2.27 (rolling frame, then mirrored back)
            fx += f
            mz -= y * f
            slope_x = face * (1.0 - th_a * th_a) / DIRECTION_SMOOTHING_M_S
            c_x += slope_x
            c_x_y += slope_x * y
            c_x_yy += slope_x * y * y
            torque = sense * r * t_sum  # eq. 2.34: the terrain's resisting torque
            axle.append(torque)
            power += sense * om * torque  # the axle's power into the contact
        fy = y_sum  # eq. 4.9
        mz += y_sum_x
        self.body_damping = (c_x, -c_x_y, 0.0, 0.0, c_x_yy)
        return fx, fy, mz, axle, power

    def advance(self, dt: float, vel: np.ndarray, omega_m: np.ndarray) -> None:
        """Transport the rim's shear displacement; every ``SOIL_REFRESH_STEPS`` also relax the sinkage
        and the excavation (see the module doc)."""
        spans = self._spans  # theta_f - theta_r per wheel [rad], as the last force step set them
        span = self._outer[: self.n_wheels, 0]  # the same as an array
        cos = self._trig[0]
        kin = self._kinematics_of(vel, omega_m)  # the new velocities (kept for the next step's forces)
        self._kinematics = kin
        sides, vya = kin
        k = self._wheels_per_side
        # per wheel: 0.5 dt x the rim's forward speed in the rolling frame, dt r omega, Courant number
        # (the wheels of a side share the first two)
        (_, vxm_left, om_left, _, _), (_, vxm_right, om_right, _, _) = sides
        scale = dt * WHEEL_NODES
        columns = np.array(
            [
                [0.5 * dt * vxm_left] * k + [0.5 * dt * vxm_right] * k,
                [dt * self.r * om_left] * k + [dt * self.r * om_right] * k,
                [min(om_left * scale / max(arc, 1e-6), 1.0) for arc in spans[:k]]
                + [min(om_right * scale / max(arc, 1e-6), 1.0) for arc in spans[k:]],
            ]
        )[:, :, None]
        # the rim element's slip velocity is (vxm cos(theta) - r om) along the rim and vya across; its
        # cell average (trapezoid) times dt (at node 0 the node's own value, needed only where the
        # wheel stands: a turning wheel's node 0 is a touchdown, below)
        cell = self._cell
        np.add(cos[:, 1:], cos[:, :-1], out=cell[:, 1:])
        if om_left <= 0.0 or om_right <= 0.0:
            np.multiply(cos[:, :1], 2.0, out=cell[:, :1])
        cell *= columns[0]
        cell -= columns[1]
        # node k takes the rim element from node k - 1 (upwind), plus the slip; node 0 of a turning
        # wheel is where the rim touches down, carrying no displacement (no shear yet)
        j = self.j
        change = self._change
        np.subtract(j[:, :, :-1], j[:, :, 1:], out=change[:, :, 1:])
        change[:, :, 1:] *= columns[2]
        change[:, :, 0] = 0.0
        change[0] += cell
        change[1] += (dt * vya)[:, None]
        if om_left > 0.0 and om_right > 0.0:
            np.negative(j[:, :, 0], out=change[:, :, 0])
        else:
            for side, om in enumerate((om_left, om_right)):
                if om > 0.0:
                    np.negative(
                        j[:, side * k : (side + 1) * k, 0], out=change[:, side * k : (side + 1) * k, 0]
                    )
        self.j = j + change
        self._damped_rate = change * (self._damping / dt)
        self._contact_age -= 1
        if self._contact_age <= 0:
            self._contact_age = SOIL_REFRESH_STEPS
            axle_speed = np.array([abs(sides[0][0])] * k + [abs(sides[1][0])] * k)  # [m/s]
            wheel_omega = np.array([sides[0][2]] * k + [sides[1][2]] * k)  # [rad/s]
            self._relax_sinkage(SOIL_REFRESH_STEPS * dt, span, j[0, :, -1], axle_speed, wheel_omega)
            self._contact()

    def _relax_sinkage(
        self, dt: float, span: np.ndarray, exit_j: np.ndarray, ground: np.ndarray, om: np.ndarray
    ) -> None:
        """Relax each wheel's sinkage z and excavation dz over dt [s] (every ``SOIL_REFRESH_STEPS``):
        span theta_f - theta_r [rad], exit_j the rim's tangential displacement at the exit [m],
        ground the axle's ground speed [m/s], om the wheel speed [rad/s]."""
        r = self.r
        loads = self._loads  # [N] per side
        per_wheel = self._per_wheel
        fz = per_wheel[0] + per_wheel[3]  # s_cos + t_sin of eq. 2.29 [N]
        # vertical balance Fz = W (eq. 2.29), Fz ~ z^(n + 1/2) (eq. 2.32). The rut deepens or
        # shallows only as soil passes under the wheel: relax over the rim's transit of the contact
        # (the same time scale as the shear), plus a slow settling at rest.
        ratio = (loads[self.wheel_side] / self._wheels_per_side) / np.maximum(fz, 1e-9)
        ratio = np.minimum(np.maximum(ratio, 0.5), 2.0)
        arc = np.maximum(r * span, 1e-6)  # [m]
        transits = (r * om + ground) / arc  # [1/s]
        if self.extended:  # slip-sinkage (Lyasko 2010): the excavation relaxes like the sinkage
            # at the slip the soil has felt: the steady slip whose displacement at the exit (eq. 2.25:
            # j_r = r [(theta_f - theta_r) - (1 - i)(sin(theta_f) - sin(theta_r))]) is the rim's j there
            # (= i in steady running; a wheel spinning up from rest has not yet sheared the soil; the
            # twin's j_t is -j_r: the rim slides backwards over the soil when driving)
            sin = self._trig[1]
            felt = 1.0 - (arc + exit_j) / (r * np.maximum(sin[:, 0] - sin[:, -1], 1e-9))
            target = (slip_sinkage_factor(felt) - 1.0) * self.z
            dig = np.minimum(transits * dt, 1.0)  # (only a moving wheel excavates: no settling term)
            self.dz = np.minimum(self.dz + dig * (target - self.dz), 0.95 * r - self.z)
        fraction = np.minimum((transits + 1.0 / SINKAGE_SETTLING_S) * dt, 1.0)
        z = self.z * ratio ** (fraction * self._sinkage_exponent)
        self.z = np.minimum(np.maximum(z, 1e-6), 0.95 * r)
        self._deepest = float((self.z + self.dz).max())

    def _contact(self) -> None:
        """The slow contact terms, every ``SOIL_REFRESH_STEPS``: the geometry at the sinkage
        (_geometry) and the bulldozing resistance [N] of the excavated step's face in front of each
        wheel, b R_b(dz) (Hegedus, as Ishigami et al. 2007 apply it), summed per side. (The side
        walls' bulldozing against lateral sliding is not applied: docs/TWIN.md.)"""
        self._geometry()
        bull_a, bull_b = self._wp_bull
        dz = self.dz
        face = (self.width * bulldozing_resistance(bull_a[:, 0], bull_b[:, 0], dz)).tolist()
        k = self._wheels_per_side
        self._face_sides = (sum(face[:k]), sum(face[k:]))
