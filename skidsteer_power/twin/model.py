"""The twin's dynamics: planar rigid body, two drivetrains with DES speed loops, terrain contact.

Fixed step dt (default 2 ms, 500 Hz), semi-implicit (symplectic) Euler: the forces of the current
state (shear displacements, sinkage) accelerate the motors and the body; the new velocities then
move the pose and advance the shear displacements. SI units throughout. Sides: index 0 = left
(y = +B/2), 1 = right (y = -B/2); hull frame x forward, y left, z up (REP 103).

Terrain contact (see docs/TWIN.md for where this agrees with and departs from the steady models):

* tracks: each patch is a grid of nodes, ``TRACK_NODES`` + 1 along (x = l/2 ... -l/2) times
  ``TRACK_ROWS`` Gauss-Legendre rows across. Every node carries the shear displacement j (2-D, in
  the current hull frame) of the belt element passing over it, relative to the soil it touched.
  A belt element moves back along the hull at r omega and slips over the ground at
  v_s = (v_x - yaw y - r omega, v_y + yaw x); in the rotating hull frame (Eulerian form)

      dj/dt + (-r omega) dj/dx = v_s - yaw e_z x j,          j = 0 where the belt touches down

  (first-order upwind, touchdown at the front for omega > 0, at the rear for omega < 0). Its steady
  state is the displacement of eqs. 3.8-3.11 / 6.6 (module doc of ``models/wong_track.py``), and
  for straight running eq. 2.15. Shear stress: Janosi-Hanamoto (eqs. 2.2-2.5, 3.12) at the node's
  uniform pressure (eq. 3.17) with lateral load transfer (eq. 3.1, from the instantaneous v_x yaw);
  it acts against j (3.13-3.15). Compaction resistance eq. 2.10 against the side's travel.
* wheels: each wheel's contact arc [theta_r, theta_f] (eqs. 2.19-2.22 at its sinkage and its
  instantaneous slip, eq. 2.13) carries ``WHEEL_NODES`` + 1 nodes in a normalised coordinate
  xi = (theta_f - theta) / (theta_f - theta_r); the rim element moves through them at omega /
  (theta_f - theta_r) and slips at u = (V_x cos(theta) - r omega, V_y) (eq. 4.3 without the
  r sin(theta) yaw term): the same transport equation, whose steady state is eq. 2.25 (and 4.4
  without yaw during contact). Wong-Reece normal stress (eq. 2.21), forces eq. 2.27 plus the
  lateral integral of eq. 4.9, axle torque eq. 2.34. The sinkage is a state relaxed each step
  towards the vertical balance Fz = W (eq. 2.29), with W from the lateral load transfer.

Drivetrain, per side (``powertrain``: Table 7.1 internal resistance, left/right asymmetric):
J dw_m/dt = K_t i - (b w_m + c tanh(w_m / 1 rad/s)) - T_axle / G, the current from the DES speed
loop (PI, the gains of ``des/simulator.MotorModel``, 10 A limit, voltage limit 0.9 V_bus - EMF),
with the PI and friction terms implicit so the stiff zero-speed friction stays stable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import roots_legendre

from skidsteer_power.des.kinematics import RPM, twist_to_motor_rpm
from skidsteer_power.errors import InputError
from skidsteer_power.powertrain import Battery, Powertrain
from skidsteer_power.terramechanics import soil
from skidsteer_power.terramechanics import track as single_track
from skidsteer_power.terramechanics import wheel as single_wheel
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.twin.terrain_field import Patch, TerrainField
from skidsteer_power.vehicle import Vehicle

DEFAULT_DT_S = 2e-3
"""Default fixed step [s] (500 Hz): the 1 ms step gives the same steady torques and speeds to 4
digits (measured on the three test-robot configurations) at half the speed."""
TRACK_NODES = 32
"""Intervals along each track patch [-] (nodes every l / 32; 1.4 cm on the test robot)."""
TRACK_ROWS = 2
"""Gauss-Legendre rows across each track [-]."""
WHEEL_NODES = 24
"""Intervals along each wheel's contact arc [-]."""
SPEED_LOOP_BANDWIDTH_RAD_S = 60.0
"""DES speed-loop bandwidth [rad/s], as ``des/simulator.MotorModel`` (ASSUMED there: the real gains
are in units the sources do not give)."""
SETPOINT_ACCEL_RAD_S2 = 10.0 * 1000.0 * RPM
"""Set-point ramp of the DES [rad/s^2 at the motor]: parameter ACCELERATION = 10 rpm/ms, as the
driver configures it (``des/simulator.default_parameters``)."""
MAX_MOTOR_RPM = 10000.0
"""Max. permissible EC-45 speed [rpm] (Appendix B), the driver's set-point limit."""
FRICTION_SMOOTHING_RAD_S = 1.0
"""Motor speed over which the Coulomb terms change sign (tanh) [rad/s], as nodes/suite.py."""
TRACK_ASSEMBLY_INERTIA_KG_M2 = 0.015
"""ASSUMED: one side's track belt (~1 kg at r = 0.1 m) and two sprockets (0.5 kg each) [kg m^2 at the
axle], scaled by (r / 0.1 m)^2 for other vehicles."""
WHEEL_INERTIA_KG_M2 = 0.0035
"""ASSUMED: one HPI Baja class wheel (~0.5 kg, mostly tyre, at r = 0.1 m): 0.7 m r^2 [kg m^2],
scaled by (r / 0.1 m)^2."""
DIRECTION_SMOOTHING_M_S = 0.005
"""Ground speed over which the compaction resistance changes direction [m/s]."""
BATTERY_STEP_S = 0.1
"""Interval at which the battery (state of charge, terminal voltage) is updated with the mean bus
power of the interval [s]; the bus voltage changes by < 0.1 V within it at the test robot's loads."""
SOIL_REFRESH_STEPS = 10
"""Steps between refreshes of the load-dependent soil terms (pressure, compaction, sinkage, terrain
under the contact): loads change over tens of ms, not 1 ms [-]."""
SHEAR_DAMPING_S = 0.05
"""ASSUMED transient shear damping: a node adds c dj/dt (at the fixed node, i.e. zero in steady
state) with c = (tau_max / K) t_d, t_d = 0.05 s. Without it the Janosi-Hanamoto curve acts as an
undamped spring between body and soil (a real soil unloads along a stiffer, dissipative path) and
the 30 kg body surges at ~1.7 Hz; see docs/TWIN.md."""
SINKAGE_SETTLING_S = 0.5
"""Time constant of a standing wheel's sinkage towards the vertical balance [s] (ASSUMED)."""
SOIL_UNIT_WEIGHT_N_M3 = 15.7e3
"""ASSUMED unit weight of the soil gamma [N/m^3] in the bulldozing resistance, for every terrain
(the presets carry none): dry sand of 1600 kg/m^3, inside the 14-18 kN/m^3 that soil-mechanics
texts give for loose to dense dry sand. At the test robot's sinkages the cohesion term dominates
(dry sand, wheel sinkage 23 mm: c h = 23 N/m against 0.5 D2 gamma h^2 = 14 N/m)."""


def slip_sinkage_factor(slip: np.ndarray) -> np.ndarray:
    """Lyasko's slip-sinkage coefficient K_j = (1 + i) / (1 - 0.5 i) [-] at slip i (eq. 2.13):
    total sinkage = K_j x static sinkage (M. Lyasko, "Slip sinkage effect in soil-vehicle
    mechanics", J. Terramechanics 47 (2010) 21-31), for a driven wheel (i >= 0; 1 when braking)."""
    i = np.clip(slip, 0.0, 1.0)
    return (1.0 + i) / (1.0 - 0.5 * i)


def bulldozing_coefficients(terrain: Terrain) -> tuple[float, float]:
    """(A [N/m^2], B [N/m^3]) of the bulldozing resistance per unit length of a contact's side wall,
    R_b(h) = A h + B h^2 [N/m] at depth h [m] below the surface (Hegedus 1960, as Ishigami et al.
    2007 apply it to the side of a wheel under side slip: J. Field Robotics 24(3), 233-250):

        R_b = D1 (c h + D2 gamma h^2 / 2),  D1 = cot X_c + tan(X_c + phi),
        D2 = cot X_c + cot^2 X_c / cot phi,  X_c = 45 deg - phi / 2

    with the terrain's c [Pa] and phi (eq. 2.2) and gamma = ``SOIL_UNIT_WEIGHT_N_M3``. The
    dissertation names bulldozing (ch. 2.3, "especially significant when sinkage is large") and
    neglects it for SUGVs; the twin applies it to the lateral sliding of wheels and track sides."""
    xc = 0.25 * math.pi - 0.5 * terrain.phi
    cot = 1.0 / math.tan(xc)
    d1 = cot + math.tan(xc + terrain.phi)
    d2 = cot + cot * cot * math.tan(terrain.phi)
    return d1 * terrain.c, 0.5 * d1 * d2 * SOIL_UNIT_WEIGHT_N_M3


@dataclass
class StepOutput:
    """Quantities of the last step (per side arrays [left, right]) for sensors and bookkeeping."""

    current_A: np.ndarray
    axle_torque_Nm: np.ndarray  # terrain's resisting torque at the sprocket / axle
    bus_power_W: np.ndarray
    terminal_power_W: np.ndarray
    sinkage_m: float


@dataclass
class EnergyLedger:
    """Accumulated energies since the start [J]."""

    bus_J: float = 0.0  # electrical energy drawn from the bus by both amplifiers
    amplifier_J: float = 0.0  # amplifier loss (bus - terminal)
    copper_J: float = 0.0  # R i^2
    friction_J: float = 0.0  # drivetrain internal resistance (eqs. 7.1-7.4)
    terrain_J: float = 0.0  # dissipated by soil shear and compaction
    kinetic0_J: float = 0.0


class Twin:
    """Dynamic twin of a skid-steered robot on its own terrain (see the module doc).

    vehicle, terrain (the truth), powertrain (default: the vehicle's), ``patches`` (other terrains
    in polygons), ``seed`` (sensor noise, used by :mod:`skidsteer_power.twin.sensors`), ``dt`` [s].
    """

    def __init__(
        self,
        vehicle: Vehicle,
        terrain: Terrain,
        powertrain: Powertrain | None = None,
        *,
        patches: list[Patch] | None = None,
        seed: int = 0,
        dt: float = DEFAULT_DT_S,
        bulldozing: bool = True,
    ) -> None:
        if not (0 < dt <= DEFAULT_DT_S):
            raise InputError(f'dt must be in (0, 2 ms] (>= 500 Hz), got {dt}')
        self.vehicle = vehicle
        self.field = TerrainField(terrain, patches or ())
        self.powertrain = powertrain or Powertrain.for_vehicle(vehicle)
        self.battery = Battery.from_config(self.powertrain.battery)
        self.seed = seed
        self.dt = dt
        self.bulldozing = bulldozing  # False: the steady models' contact (no side-wall resistance)
        pt, motor = self.powertrain, self.powertrain.motor
        self.G = pt.gear_ratio
        self.r = vehicle.drive_radius_m
        self.half_tread = 0.5 * vehicle.tread_m
        self.y_side = np.array([self.half_tread, -self.half_tread])
        self.kt = motor.torque_constant_Nm_A
        self.R = motor.terminal_resistance_ohm
        self.kn = motor.speed_constant_rad_s_V
        self.peak_A = pt.amplifier.continuous_current_A
        self.v_fraction = pt.amplifier.max_output_voltage_fraction
        self.friction_b = np.array([pt.left.total.viscous_Nm_s, pt.right.total.viscous_Nm_s])
        self.friction_c = np.array([pt.left.total.coulomb_Nm, pt.right.total.coulomb_Nm])
        self._friction_b, self._friction_c = self.friction_b.tolist(), self.friction_c.tolist()
        scale = (self.r / 0.1) ** 2
        if vehicle.is_tracked:
            axle_inertia = TRACK_ASSEMBLY_INERTIA_KG_M2 * scale
        else:
            axle_inertia = vehicle.wheels_per_side * WHEEL_INERTIA_KG_M2 * scale
        self.J = motor.rotor_inertia_kg_m2 + axle_inertia / self.G**2
        # PI gains of des/simulator.MotorModel: designed on the rotor + half the robot's mass at r
        j_design = motor.rotor_inertia_kg_m2 + 0.5 * vehicle.mass_kg * self.r**2 / self.G**2
        self.kp = SPEED_LOOP_BANDWIDTH_RAD_S * j_design / self.kt
        self.ki = self.kp * SPEED_LOOP_BANDWIDTH_RAD_S / 4.0
        self.mass = vehicle.mass_kg
        self._transfer_coefficient = vehicle.mass_kg * vehicle.cg_height_m / vehicle.tread_m  # eq. 3.1
        self._half_weight = 0.5 * vehicle.weight_N
        amp = self.powertrain.amplifier
        self._eta = amp.efficiency
        regen = self.powertrain.regen_efficiency
        self._eta_regen = (amp.efficiency if amp.four_quadrant else 0.0) if regen is None else regen
        self.Iz = vehicle.yaw_inertia
        self._tracked = vehicle.is_tracked
        self._init_contact()
        self.reset()

    # ------------------------------------------------------------------ set-up
    def _init_contact(self) -> None:
        v = self.vehicle
        if v.is_tracked:
            length, b = float(v.track_length_m), float(v.track_width_m)  # type: ignore[arg-type]
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
        else:
            nw = int(v.n_wheels)  # type: ignore[arg-type]
            axles = np.array(v.axle_positions_m())
            self.wheel_side = np.repeat([0, 1], len(axles))
            self.wheel_x = np.tile(axles, 2)
            self.wheel_y = self.y_side[self.wheel_side]
            self.width = float(v.wheel_width_m)  # type: ignore[arg-type]
            self.xi = np.linspace(0.0, 1.0, WHEEL_NODES + 1)
            trap = np.full(WHEEL_NODES + 1, 1.0 / WHEEL_NODES)
            trap[[0, -1]] *= 0.5
            self.xi_w = trap
            self.n_wheels = nw
            self._wheels_per_side = nw // 2
            self._sinkage_exponent = 1.0 / (self.field.base.n + 0.5)  # eq. 2.32: Fz ~ z^(n + 1/2)
            if self.field.uniform:
                self._wheel_soil()  # once (with patches: refreshed while stepping)

    def reset(self) -> None:
        """Rest at the origin, heading +x, shear relaxed, static sinkage, full battery."""
        self.t = 0.0
        self.pose = np.zeros(3)  # x, y [m], yaw [rad] (world)
        self.vel = np.zeros(3)  # v_x, v_y [m/s] (hull), yaw rate [rad/s]
        self.omega_m = np.zeros(2)  # motor speeds, forward positive [rad/s]
        self.theta_m = np.zeros(2)  # motor angles [rad]
        self.integral_A = np.zeros(2)
        self.setpoint = np.zeros(2)  # ramped speed set point [rad/s]
        self.command = (0.0, 0.0)
        self.energy = EnergyLedger()
        self.battery = Battery.from_config(self.powertrain.battery)
        self.bus_voltage_V = self.battery.state.voltage_V
        self._battery_pending = [0.0, 0.0]  # energy [J], time [s] not yet given to the battery
        self.bus_current_A = 0.0
        self.max_sinkage_m = 0.0
        v = self.vehicle
        if v.is_tracked:
            self.j = np.zeros(self.node_x.shape, dtype=complex)  # j_x + i j_y [m] (side, along, across)
            self._soil_age = 0
        else:
            w_wheel = v.weight_N / self.n_wheels
            z0 = float(single_wheel.bekker_wheel_sinkage(self.field.base, w_wheel, self.r, self.width))
            self.z = np.full(self.n_wheels, min(z0, 0.5 * self.r))
            self.dz = np.zeros(self.n_wheels)  # slip-sinkage: rut excavated below the wheel [m]
            self._direction = np.ones(self.n_wheels)  # rolling sense of each wheel (+-1)
            self.j = np.zeros((2, self.n_wheels, WHEEL_NODES + 1))  # j_t, j_y [m] (wheel, rim node)
            self._rows = np.empty((7, self.n_wheels, WHEEL_NODES + 1))  # integrands (_wheel_forces)
            self._trig = np.empty((2, self.n_wheels, WHEEL_NODES + 1))  # cos, sin of the node angles
            self._padded = np.zeros((3, self.n_wheels, WHEEL_NODES + 2))  # (_advance_wheels)
            self._soil_age = 0
        self.last = StepOutput(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), 0.0)
        self._kinematics: tuple[np.ndarray, ...] | None = None  # wheels: of the present velocities
        self._body_damping = (0.0, 0.0, 0.0, 0.0, 0.0)  # (_move)
        self._j_rate = np.zeros_like(self.j)
        self._damping = SHEAR_DAMPING_S / self.field.base.K  # [s/m]: c = tau_max t_d / K

    # ------------------------------------------------------------------ terrain
    def _side_loads(self) -> np.ndarray:
        """Vertical load of each side [N] with lateral load transfer (eq. 3.1, instantaneous)."""
        transfer = self._transfer_coefficient * float(self.vel[0]) * float(self.vel[2])
        half = self._half_weight
        return np.array([max(half - transfer, 0.0), max(half + transfer, 0.0)])

    def _terrain_index(self, hx: np.ndarray, hy: np.ndarray) -> np.ndarray | None:
        """Terrain index of hull points (hx, hy) [m]; None if the floor is uniform."""
        if self.field.uniform:
            return None
        x, y, yaw = self.pose
        c, s = math.cos(yaw), math.sin(yaw)
        return self.field.index_at(x + c * hx - s * hy, y + s * hx + c * hy)

    def _by_terrain(self, index: np.ndarray | None, shape: tuple[int, ...], fn) -> np.ndarray:
        """Evaluate ``fn(terrain, mask)`` per terrain present; mask None = everywhere."""
        if index is None:
            return fn(self.field.base, None)
        out = np.zeros(shape)
        for i in np.unique(index):
            mask = index == i
            out[mask] = fn(self.field.terrains[i], mask)
        return out

    def _track_soil(self, loads: np.ndarray) -> None:
        """Per-node shear strength [Pa x m^2], per-side compaction resistance [N] and sinkage [m]
        at the side loads [N] (eqs. 2.2, 2.6, 2.10, 3.17); refreshed every ``SOIL_REFRESH_STEPS``."""
        b, length = self.width, self.track_length
        pressure = loads / (b * length)  # eq. 3.17
        index = self._terrain_index(self.node_x, self.node_y)
        self._track_index = index
        if index is None:
            t = self.field.base
            self._tau_max_w = soil.shear_strength(t, pressure)[:, None, None] * self.node_w  # eq. 2.2
            self._rc = single_track.compaction_resistance(t, loads, b, length)  # eq. 2.10
            sinkage = single_track.track_sinkage(t, loads, b, length)  # eq. 2.6
            self._sinkage = float(np.max(sinkage))
            bull_a, bull_b = bulldozing_coefficients(t)
            side_wall = (bull_a + bull_b * sinkage) * sinkage  # R_b [N/m] per side
            self._bull_w = side_wall[:, None] * self.track_dx * (1.0 if self.bulldozing else 0.0)
            return
        p = np.broadcast_to(pressure[:, None, None], self.node_x.shape)
        strength = np.zeros(p.shape)
        rc = np.zeros(p.shape)
        sink = np.zeros(p.shape)
        side_wall = np.zeros(p.shape)
        for i in np.unique(index):
            mask = index == i
            t = self.field.terrains[i]
            strength[mask] = soil.shear_strength(t, p[mask])
            rc[mask] = single_track.compaction_resistance(t, p[mask] * b * length, b, length)
            sink[mask] = soil.sinkage_for_pressure(t, p[mask], b)
            bull_a, bull_b = bulldozing_coefficients(t)
            side_wall[mask] = (bull_a + bull_b * sink[mask]) * sink[mask]
        self._bull_w = side_wall.mean(axis=2) * self.track_dx * (1.0 if self.bulldozing else 0.0)
        share = self.node_w / (b * length)  # each node's share of the rut
        self._tau_max_w = strength * self.node_w
        self._rc = (rc * share).sum(axis=(1, 2))
        self._sinkage = float(sink.max())

    def _shear_fraction(self, magnitude: np.ndarray, index: np.ndarray | None) -> np.ndarray:
        """tau / tau_max at |j| [m] per node (eqs. 2.3-2.5), by the node's terrain."""
        if index is None:
            return soil.shear_fraction(self.field.base, magnitude)
        out = np.zeros(magnitude.shape)
        for i in np.unique(index):
            mask = index == i
            out[mask] = soil.shear_fraction(self.field.terrains[i], magnitude[mask])
        return out

    def _track_forces(self, loads: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Body force (F_x, F_y, M_z) [N, N, N m], axle torques [N m], dissipation [W], sinkage [m].

        Vectors in the hull plane are complex numbers x + i y (j, forces, velocities).
        """
        if self._soil_age <= 0:
            self._track_soil(loads)
            self._soil_age = SOIL_REFRESH_STEPS
        self._soil_age -= 1
        vx, vy, wz = self.vel
        j = self.j
        mag = np.abs(j)
        tau_w = self._tau_max_w * self._shear_fraction(mag, self._track_index)  # eq. 3.12
        safe = np.where(mag > 0, mag, 1.0)
        f = -tau_w * j / safe  # eqs. 3.13-3.15: against the displacement
        f -= self._damping * self._tau_max_w * self._j_rate  # transient damping, 0 in steady state
        belt = self.r * self.omega_m / self.G  # belt speed relative to the hull [m/s]
        side_speed = vx - wz * self.y_side
        fc = -self._rc * np.tanh(side_speed / DIRECTION_SMOOTHING_M_S)  # eq. 2.10, against travel
        f_side = f.sum(axis=(1, 2))
        total = f_side.sum()
        # bulldozing on the track's side walls (Ishigami et al. 2007) against the lateral motion
        lateral = vy + wz * self.track_x  # [m/s] along the track
        th = np.tanh(lateral * (1.0 / DIRECTION_SMOOTHING_M_S))
        fb = -self._bull_w * th  # (side, along) [N]
        c_y = (self._bull_w * (1.0 - th * th)).sum(axis=0)  # slope for the implicit body step (_move)
        x = self.track_x
        self._body_damping = (0.0, 0.0, float(c_y.sum()), float(c_y @ x), float(c_y @ (x * x)))
        force = np.array(
            [
                total.real + fc.sum(),
                total.imag + fb.sum(),
                float((self.node_p.conjugate() * f).imag.sum())
                - float((self.y_side * fc).sum())
                + float((fb @ self.track_x).sum()),
            ]
        )
        axle = self.r * f_side.real  # the ground's pull on the belt resists the sprocket
        slip = (vx + 1j * vy) + 1j * wz * self.node_p - belt[:, None, None]
        dissipation = float(
            -(f.conjugate() * slip).real.sum() - (fc * side_speed).sum() - (fb @ lateral).sum()
        )
        return force, axle, dissipation, self._sinkage

    def _advance_tracks(self, dt: float) -> None:
        """Transport the shear displacement with the belt and add the slip (see the module doc)."""
        vx, vy, wz = self.vel
        j = self.j
        belt = self.r * self.omega_m / self.G
        source = (vx + 1j * vy) + 1j * wz * (self.node_p - j) - belt[:, None, None]  # - yaw e_z x j
        courant = np.minimum(np.abs(belt) * dt / self.node_dx, 1.0)
        new = j.copy()
        half = 0.5 * dt
        for side in (0, 1):
            c, jj, ss, nn = float(courant[side]), j[side], source[side], new[side]
            if belt[side] >= 0:  # touchdown at the front (node 0): node k takes the belt from k - 1
                nn[1:] += half * (ss[1:] + ss[:-1]) + c * (jj[:-1] - jj[1:])
                nn[0] += dt * ss[0] - c * jj[0]
                if belt[side] > 0:
                    nn[0] = 0.0
            else:  # reversing: touchdown at the rear
                nn[:-1] += half * (ss[:-1] + ss[1:]) + c * (jj[1:] - jj[:-1])
                nn[-1] = 0.0
        # (the slip source is averaged over each cell, trapezoid: the steady state integrates the
        # slip velocity along the patch to second order)
        j = new
        self._j_rate = (j - self.j) / dt
        self.j = j

    def _wheel_soil(self) -> None:
        """Per-wheel constants of the terrain under each wheel (uniform floor: once; with patches:
        every ``SOIL_REFRESH_STEPS``): Wong-Reece stress factor r^n (kc / b + kphi) [Pa] and exponent
        n (eq. 2.21), c [Pa] and tan(phi) (eq. 2.2), the angle coefficients a0, a1, b0, b1 (eqs.
        2.20, 2.22) as (n_wheels, 1) columns, and the shear law (None: type A with K [m], else the
        terrains per wheel for ``soil.shear_fraction``)."""
        index = self._terrain_index(self.wheel_x, self.wheel_y)
        self._wheel_index = index
        field = self.field
        terrains = [field.base] * self.n_wheels if index is None else [field.terrains[i] for i in index]
        r, b = self.r, self.width

        def column(values: list[float]) -> np.ndarray:
            return np.array(values, dtype=float)[:, None]

        self._wp_stress = column([r**t.n * (t.kc / b + t.kphi) for t in terrains])
        self._wp_n = column([t.n for t in terrains])
        self._wp_c = column([t.c for t in terrains])
        self._wp_tan_phi = column([math.tan(t.phi) for t in terrains])
        self._wp_a = (column([t.a0 for t in terrains])[:, 0], column([t.a1 for t in terrains])[:, 0])
        self._wp_b = (column([t.b0 for t in terrains])[:, 0], column([t.b1 for t in terrains])[:, 0])
        on = 1.0 if self.bulldozing else 0.0
        bull = [bulldozing_coefficients(t) for t in terrains]
        self._wp_bull = (column([on * a for a, _ in bull]), column([on * b_ for _, b_ in bull]))
        if all(t.shear_type == 'A' for t in terrains):
            self._wp_inv_k: np.ndarray | None = column([-1.0 / t.K for t in terrains])
            self._wp_terrains: list[Terrain] | None = None
        else:
            self._wp_inv_k, self._wp_terrains = None, terrains

    def _wheel_kinematics(self) -> tuple[np.ndarray, ...]:
        """Per wheel: axle ground speed forward and lateral [m/s], |omega| [rad/s], rolling direction
        (+-1), forward speed in the rolling frame [m/s] and slip (eq. 2.13) [-]."""
        vx, vy, wz = self.vel.tolist()
        vxa = vx - wz * self.wheel_y  # axle ground speed, forward [m/s]
        vya = vy + wz * self.wheel_x  # lateral [m/s]
        per_side = []
        for w in self.omega_m.tolist():
            w /= self.G
            per_side.append((1.0 if w > 0 else (-1.0 if w < 0 or vx < 0 else 1.0), abs(w)))
        k = self._wheels_per_side
        direction = np.array([per_side[0][0]] * k + [per_side[1][0]] * k)
        flipped = direction != self._direction
        if flipped.any():
            # a wheel that reverses keeps its soil: the rim nodes' order (entry <-> exit) and the
            # tangential displacement in the rolling frame mirror, so the stress on the rim does not
            # jump (without this a standing wheel chatters between the two senses every step)
            self.j[:, flipped] = self.j[:, flipped, ::-1]
            self.j[0, flipped] *= -1.0
            self._j_rate[:, flipped] = 0.0
            self._direction = direction
        om = np.array([per_side[0][1]] * k + [per_side[1][1]] * k)
        vxm = direction * vxa  # mirrored so the wheel rolls forward
        rw = self.r * om
        # eq. 2.13: (r w - V) / (r w) driving, (r w - V) / V braking: one denominator, max(r w, |V|)
        slip = (rw - vxm) / np.maximum(np.maximum(rw, np.abs(vxm)), 1e-12)
        return vxa, vya, om, direction, vxm, np.minimum(np.maximum(slip, -1.0), 1.0)

    def _wheel_forces(self, loads: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Body force (F_x, F_y, M_z), axle torques per side [N m], dissipation [W], sinkage [m].

        Shear displacement per rim node: j[0] tangential along the rim, j[1] lateral [m]. The
        contact integrals are weighted sums over the nodes (trapezoid in xi, times the arc
        r (theta_f - theta_r) and the width b), all six in one matrix product.
        """
        if not self.field.uniform:
            if self._soil_age <= 0:
                self._wheel_soil()
                self._soil_age = SOIL_REFRESH_STEPS
            else:
                self._soil_age -= 1
        kin = self._kinematics if self._kinematics is not None else self._wheel_kinematics()
        vxa, vya, om, direction, vxm, slip = kin
        r = self.r
        z = self.z
        a0, a1 = self._wp_a
        b0, b1 = self._wp_b
        tf = np.arccos(np.maximum(1.0 - z / r, -1.0))  # eq. 2.19 (z > 0)
        tm = (a0 + a1 * slip) * tf  # eq. 2.22
        tr = (b0 + b1 * slip) * tf  # eq. 2.20
        span = tf - tr
        tf_c, span_c = tf[:, None], span[:, None]
        u = self.xi * span_c  # theta_f - theta at the nodes [rad]
        theta = np.subtract(tf_c, u)
        # Wong-Reece normal stress (eq. 2.21); behind theta_m the equivalent front angle of eq. 2.22,
        # theta_e = theta_f - (theta - theta_r) (theta_f - theta_m) / (theta_m - theta_r), falls from
        # theta_f to theta_m over [theta_r, theta_m] and continues below theta_m ahead of it, so the
        # angle to use is max(theta, theta_e) everywhere on the arc
        theta_e = np.subtract(span_c, u, out=u)  # (u no longer needed)
        theta_e *= ((tf - tm) / np.maximum(tm - tr, 1e-12))[:, None]
        np.subtract(tf_c, theta_e, out=theta_e)
        depth = np.maximum(theta, theta_e, out=theta_e)
        np.cos(depth, out=depth)
        depth -= np.cos(tf_c)
        np.maximum(depth, 0.0, out=depth)
        sigma = np.power(depth, self._wp_n, out=depth)
        sigma *= self._wp_stress
        strength = sigma * self._wp_tan_phi
        strength += self._wp_c  # eq. 2.2
        j = self.j
        mag = np.hypot(j[0], j[1])
        if self._wp_inv_k is not None:
            minus_fraction = np.expm1(mag * self._wp_inv_k)  # eq. 2.3 (tau / tau_max = -this)
        else:
            pairs = zip(self._wp_terrains, mag, strict=True)
            minus_fraction = np.array([-soil.shear_fraction(t, m) for t, m in pairs])  # eqs. 2.4-2.5
        # tau_t, tau_y against the displacement (4.7, 4.8), plus the transient damping:
        # -(tau_max f / |j|) j - c dj/dt, both components at once (the sign folded into the gain)
        mag += 1e-300
        gain = np.multiply(strength, minus_fraction, out=minus_fraction)
        gain /= mag
        rows = self._rows  # (6, wheels, nodes): the integrands
        trig = self._trig  # cos(theta), sin(theta)
        np.cos(theta, out=trig[0])
        np.sin(theta, out=trig[1])
        shear = rows[4:6]
        np.multiply(gain, j, out=shear)
        strength *= self._damping
        shear -= strength * self._j_rate
        tau = rows[4]
        np.multiply(sigma, trig, out=rows[:2])
        np.multiply(tau, trig, out=rows[2:4])
        cos = trig[0]
        # bulldozing on the side wall (Ishigami et al. 2007): R_b(h) per unit length along x = r sin(theta)
        # at the rim's depth below the surface h = r (cos(theta) - cos(theta_f)) + the excavated dz,
        # dx = r cos(theta) d(theta)
        h = rows[6]
        np.subtract(cos, np.cos(tf_c), out=h)
        h *= r
        np.maximum(h, 0.0, out=h)
        dz = self.dz[:, None]
        h += dz
        bull_a, bull_b = self._wp_bull
        rb = bull_b * h
        rb += bull_a
        np.multiply(rb, h, out=h)
        h *= cos
        area = (r * self.width) * span  # the contact's arc times width per unit xi [m^2]
        s_cos, s_sin, t_cos, t_sin, t_sum, y_sum, bull = (rows @ self.xi_w) * area  # [N] (bull: [N m / m^2])
        # the rut's resistance (-sigma sin(theta) of eq. 2.27) acts against travel; at rest the
        # stress is symmetric and it vanishes (smoothed like the track's compaction resistance)
        normal = s_sin * np.tanh(vxm / DIRECTION_SMOOTHING_M_S)
        pull = t_cos - normal
        # the face of the excavated step (depth dz, width b) bulldozes against the axle's travel
        dz = self.dz
        face = self.width * (bull_a[:, 0] + bull_b[:, 0] * dz) * dz  # [N]
        th_x = np.tanh(vxa * (1.0 / DIRECTION_SMOOTHING_M_S))
        front = face * th_x
        fx = direction * pull - front  # eq. 2.27 (rolling frame, then mirrored back)
        fz = s_cos + t_sin
        # eq. 4.9, lateral shear; the side wall's bulldozing against the axle's lateral motion
        side = bull / self.width  # [N]
        th_y = np.tanh(vya * (1.0 / DIRECTION_SMOOTHING_M_S))
        fy = y_sum - side * th_y
        # the bulldozing's slope in the body velocities, for the implicit body step (_move)
        c_x = face * (1.0 - th_x * th_x)
        c_y = side * (1.0 - th_y * th_y)
        x, y = self.wheel_x, self.wheel_y
        self._body_damping = (
            float(c_x.sum()),
            -float(c_x @ y),
            float(c_y.sum()),
            float(c_y @ x),
            float(c_x @ (y * y) + c_y @ (x * x)),
        )
        torque = direction * (r * t_sum)  # eq. 2.34: the terrain's resisting torque
        force = np.array([sum(fx.tolist()), sum(fy.tolist()), float(self.wheel_x @ fy - self.wheel_y @ fx)])
        # power of the contact stresses on the slip velocity (vxm cos(theta) - r om, vya), and the rut's
        dissipation = float((r * om) @ t_sum - vxm @ pull - vya @ fy + vxa @ front)
        self._wheel_state = (cos, span, fz, loads[self.wheel_side] / self._wheels_per_side)
        half = self._wheels_per_side
        torques = torque.tolist()
        axle = np.array([sum(torques[:half]), sum(torques[half:])])
        return force, axle, dissipation, float((z + dz).max())

    def _advance_wheels(self, dt: float) -> None:
        """Transport the rim's shear displacement and relax the sinkage (see the module doc)."""
        cos, span, fz, w_wheel = self._wheel_state
        kin = self._wheel_kinematics()  # the new velocities (kept for the next step's forces)
        self._kinematics = kin
        vxa, vya, om, _direction, vxm, _ = kin
        # slip velocity of the rim element: (vxm cos(theta) - r om) along the rim, vya across
        # (padded by one node in front: the rim element arriving at node 0 carries no displacement,
        # and the slip source's cell average there is its value at node 0)
        padded = self._padded  # (3, wheels, 1 + nodes): 0 then j_t, j_y; source at node 0 then all
        source = padded[2]
        np.multiply(vxm[:, None], cos, out=source[:, 1:])
        source[:, 1:] -= (self.r * om)[:, None]
        source[:, 0] = source[:, 1]
        courant = np.minimum(om / np.maximum(span, 1e-6) * (dt * WHEEL_NODES), 1.0)[:, None]
        j = self.j
        padded[:2, :, 1:] = j
        # node k takes the rim element from node k - 1, plus the cell-averaged slip source
        shift = padded[:2, :, :-1] - j
        shift *= courant
        new = j + shift
        source_sum = source[:, 1:] + source[:, :-1]
        source_sum *= 0.5 * dt
        new[0] += source_sum
        new[1] += (dt * vya)[:, None]
        np.copyto(new[:, :, 0], 0.0, where=om > 0)  # touchdown: no shear yet
        rate = new - j
        rate *= 1.0 / dt
        self._j_rate = rate
        self.j = new
        # vertical balance Fz = W (eq. 2.29), Fz ~ z^(n + 1/2) (eq. 2.32). The rut deepens or
        # shallows only as soil passes under the wheel: relax over the rim's transit of the contact
        # (the same time scale as the shear), plus a slow settling at rest.
        ratio = np.maximum(fz, 1e-9, out=fz)  # (in place: these per-wheel arrays are this step's)
        np.divide(w_wheel, ratio, out=ratio)
        np.maximum(ratio, 0.5, out=ratio)
        np.minimum(ratio, 2.0, out=ratio)
        travel = self.r * om
        travel += np.abs(vxa)
        span *= self.r
        travel /= np.maximum(span, 1e-6, out=span)
        if self.bulldozing:  # slip-sinkage (Lyasko 2010): the excavation relaxes like the sinkage
            # at the slip the soil has felt: the steady slip whose displacement at the exit (eq. 2.25:
            # j_r = r [(theta_f - theta_r) - (1 - i)(sin(theta_f) - sin(theta_r))]) is the rim's j there
            # (= i in steady running; a wheel spinning up from rest has not yet sheared the soil);
            # span is r (theta_f - theta_r) [m] here
            sin = self._trig[1]
            # (the twin's j_t is -j_r of eq. 2.25: the rim slides backwards over the soil when driving)
            felt = 1.0 - (span + j[0, :, -1]) / (self.r * np.maximum(sin[:, 0] - sin[:, -1], 1e-9))
            target = (slip_sinkage_factor(felt) - 1.0) * self.z
            dig = np.minimum(travel * dt, 1.0)  # (only a moving wheel excavates: no settling term)
            self.dz = np.minimum(self.dz + dig * (target - self.dz), 0.95 * self.r - self.z)
        travel += 1.0 / SINKAGE_SETTLING_S
        travel *= dt
        fraction = np.minimum(travel, 1.0, out=travel)
        fraction *= self._sinkage_exponent
        np.power(ratio, fraction, out=ratio)
        z = ratio
        z *= self.z
        np.maximum(z, 1e-6, out=z)
        self.z = np.minimum(z, 0.95 * self.r, out=z)

    # ------------------------------------------------------------------ stepping
    def kinetic_energy(self) -> float:
        """Kinetic energy of body and drivetrains [J]."""
        vx, vy, wz = self.vel
        return float(
            0.5 * self.mass * (vx * vx + vy * vy)
            + 0.5 * self.Iz * wz * wz
            + 0.5 * self.J * (self.omega_m**2).sum()
        )

    def set_command(self, speed_m_s: float, yaw_rate_rad_s: float) -> None:
        """Hold forward speed [m/s] and yaw rate [rad/s] until the next command."""
        self.command = (float(speed_m_s), float(yaw_rate_rad_s))
        rpm = twist_to_motor_rpm(
            self.command[0],
            self.command[1],
            tread_m=self.vehicle.tread_m,
            drive_radius_m=self.r,
            gear_ratio=self.G,
            max_rpm=MAX_MOTOR_RPM,
        )
        self._target = np.array(rpm) * RPM

    def step(
        self, cmd_speed: float | None = None, cmd_yaw_rate: float | None = None, n_steps: int = 1
    ) -> None:
        """Advance ``n_steps`` steps of dt, holding the command (or the given new one)."""
        if cmd_speed is not None or cmd_yaw_rate is not None:
            self.set_command(cmd_speed or 0.0, cmd_yaw_rate or 0.0)
        elif not hasattr(self, '_target'):
            self.set_command(0.0, 0.0)
        for _ in range(n_steps):
            self._step()

    def _move(self, force: np.ndarray, omega_m: np.ndarray) -> float:
        """Body (hull frame: m (dv/dt + yaw x v) = F, Iz dyaw/dt = M), motor angles, pose and the
        contact's shear transport over one step, with the new motor speeds [rad/s]. The bulldozing
        (stiff where the body nearly stands) is implicit: (M + dt D) dv = dt (F + m v x yaw) with D
        its slope in (v_x, v_y, yaw rate) (``_body_damping``). Returns the power its implicit part
        adds to the dissipation [W] (-dF . v, dF = -D dv)."""
        dt = self.dt
        m = self.mass
        vx, vy, wz = self.vel.tolist()
        fx, fy, mz = force.tolist()
        dxx, dxw, dyy, dyw, dww = self._body_damping
        rx, ry, rw = dt * (fx + m * wz * vy), dt * (fy - m * wz * vx), dt * mz
        a, b, c, p, q = m + dt * dxx, m + dt * dyy, self.Iz + dt * dww, dt * dxw, dt * dyw
        d_w = (rw - p * rx / a - q * ry / b) / (c - p * p / a - q * q / b)
        d_x, d_y = (rx - p * d_w) / a, (ry - q * d_w) / b
        extra = (dxx * d_x + dxw * d_w) * vx + (dyy * d_y + dyw * d_w) * vy
        extra += (dxw * d_x + dyw * d_y + dww * d_w) * wz
        vx, vy, wz = vx + d_x, vy + d_y, wz + d_w
        self.vel = np.array([vx, vy, wz])
        self.omega_m = omega_m
        self.theta_m = self.theta_m + dt * omega_m
        x, y, yaw = self.pose.tolist()
        c, s = math.cos(yaw), math.sin(yaw)
        self.pose = np.array([x + dt * (c * vx - s * vy), y + dt * (s * vx + c * vy), yaw + dt * wz])
        if self._tracked:
            self._advance_tracks(dt)
        else:
            self._advance_wheels(dt)
        return extra

    def step_with_motor_speeds(self, omega_m: np.ndarray) -> np.ndarray:
        """One step with the motor speeds [rad/s, forward positive] imposed from outside (the live
        suite's simulated amplifiers integrate the motors); returns the terrain's resisting axle
        torque of each side [N m]. The energy ledger then holds only the terrain work."""
        omega_m = np.asarray(omega_m, dtype=float)
        self.omega_m = omega_m
        self._kinematics = None  # the motor speeds changed from outside
        loads = self._side_loads()
        if self._tracked:
            force, axle, dissipation, sinkage = self._track_forces(loads)
        else:
            force, axle, dissipation, sinkage = self._wheel_forces(loads)
        self.max_sinkage_m = max(self.max_sinkage_m, sinkage)
        dissipation += self._move(force, omega_m)
        self.energy.terrain_J += dissipation * self.dt
        self.t += self.dt
        return axle

    def _step(self) -> None:
        dt = self.dt
        loads = self._side_loads()
        if self._tracked:
            force, axle, dissipation, sinkage = self._track_forces(loads)
        else:
            force, axle, dissipation, sinkage = self._wheel_forces(loads)
        if sinkage > self.max_sinkage_m:
            self.max_sinkage_m = sinkage
        # Per side, in plain floats (two-element numpy arrays cost more than they save here).
        # Amplifier: ramped set point, PI speed loop, current and voltage limits (des/simulator).
        ramp = SETPOINT_ACCEL_RAD_S2 * dt
        v_max = self.v_fraction * self.bus_voltage_V
        kp, ki, kt, res, peak, inertia, gear = self.kp, self.ki, self.kt, self.R, self.peak_A, self.J, self.G
        kn = self.kn
        omegas, setpoints, integrals = self.omega_m.tolist(), self.setpoint.tolist(), self.integral_A.tolist()
        targets, axles = self._target.tolist(), axle.tolist()
        friction_b, friction_c = self._friction_b, self._friction_c
        currents, p_terms, p_buses = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
        friction_power = 0.0
        eta, eta_regen = self._eta, self._eta_regen
        for k in (0, 1):
            omega = omegas[k]
            set_k = setpoints[k]
            set_k += min(ramp, max(-ramp, targets[k] - set_k))
            setpoints[k] = set_k
            error = set_k - omega
            integral = min(peak, max(-peak, integrals[k] + ki * error * dt))
            integrals[k] = integral
            wanted = kp * error + integral
            emf = omega / kn
            upper = min(peak, (v_max - emf) / res)
            lower = max(-peak, (-v_max - emf) / res)
            current = min(upper, max(lower, wanted))
            free = lower < wanted < upper
            # implicit in omega: the PI proportional part (where not limited) and the friction slope
            th = math.tanh(omega / FRICTION_SMOOTHING_RAD_S)
            b, c = friction_b[k], friction_c[k]
            friction = b * omega + c * th
            slope = b + c * (1.0 - th * th) / FRICTION_SMOOTHING_RAD_S
            drive = kt * current - friction - axles[k] / gear
            if free:
                d_omega = dt * drive / (inertia + dt * (slope + kt * kp))
                current -= kp * d_omega
            else:
                d_omega = dt * drive / (inertia + dt * slope)
            new = omega + d_omega
            mid = 0.5 * (omega + new)
            friction_power += (friction + slope * d_omega) * mid
            p_term = kt * current * mid + res * current * current
            p_bus = p_term / eta if p_term >= 0.0 else p_term * eta_regen  # = motor.bus_power (4-Q)
            currents[k], omegas[k], p_terms[k], p_buses[k] = current, new, p_term, p_bus
        self.setpoint = np.array(setpoints)
        self.integral_A = np.array(integrals)
        dissipation += self._move(force, np.array(omegas))
        # electrical side and energy ledger
        e = self.energy
        total = p_buses[0] + p_buses[1]
        e.bus_J += total * dt
        e.amplifier_J += (total - p_terms[0] - p_terms[1]) * dt
        e.copper_J += res * (currents[0] ** 2 + currents[1] ** 2) * dt
        e.friction_J += friction_power * dt
        e.terrain_J += dissipation * dt
        self.bus_current_A = total / self.bus_voltage_V
        pending = self._battery_pending
        pending[0] += total * dt
        pending[1] += dt
        if pending[1] >= BATTERY_STEP_S - 1e-12:  # the battery changes slowly: step it every 0.1 s
            self.battery.step(pending[0] / pending[1], pending[1])
            self.bus_voltage_V = self.battery.state.voltage_V
            pending[0] = pending[1] = 0.0
        self.t += dt
        self.last = StepOutput(np.array(currents), axle, np.array(p_buses), np.array(p_terms), sinkage)
