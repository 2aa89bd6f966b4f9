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
  lateral integral of eq. 4.9, axle torque eq. 2.34. The sinkage is a state relaxed towards the
  vertical balance Fz = W (eq. 2.29), with W from the lateral load transfer, every
  ``SOIL_REFRESH_STEPS``.
* beyond the steady models (``dig_and_bulldoze=False`` switches both off): slip-sinkage, an excavated
  rut under each wheel (Lyasko 2010, :func:`slip_sinkage_factor`), and bulldozing of the contacts'
  side walls against their lateral motion and of the excavated step against travel (Hegedus, as
  Ishigami et al. 2007 apply it, :func:`bulldozing_coefficients`).

Drivetrain, per side (``powertrain``: Table 7.1 internal resistance, left/right asymmetric):
J dw_m/dt = K_t i - (b w_m + c tanh(w_m / 1 rad/s)) - T_axle / G, the current from the DES speed
loop (PI, the gains of ``des/simulator.MotorModel``, 10 A limit, voltage limit 0.9 V_bus - EMF),
with the PI and friction terms implicit so the stiff zero-speed friction stays stable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

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
    i = np.minimum(np.maximum(slip, 0.0), 1.0)
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


def bulldozing_resistance(a: Any, b: Any, depth_m: Any) -> Any:
    """R_b = (A + B h) h [N/m] per unit length of side wall at depth h [m], from
    :func:`bulldozing_coefficients` (floats or arrays, broadcast)."""
    return (a + b * depth_m) * depth_m


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
        dig_and_bulldoze: bool = True,
    ) -> None:
        if not (0 < dt <= DEFAULT_DT_S):
            raise InputError(f'dt must be in (0, 2 ms] (>= 500 Hz), got {dt}')
        self.vehicle = vehicle
        self.field = TerrainField(terrain, patches or ())
        self._patched = not self.field.uniform
        self.powertrain = powertrain or Powertrain.for_vehicle(vehicle)
        self.battery = Battery.from_config(self.powertrain.battery)
        self.seed = seed
        self.dt = dt
        # False: the steady models' contact (no slip-sinkage, no side-wall or step-face bulldozing)
        self.dig_and_bulldoze = dig_and_bulldoze
        pt, motor = self.powertrain, self.powertrain.motor
        self.G = pt.gear_ratio
        self.r = vehicle.drive_radius_m
        self.half_tread = 0.5 * vehicle.tread_m
        self.y_side = np.array([self.half_tread, -self.half_tread])
        self._side_y = (self.half_tread, -self.half_tread)  # (floats)
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
            self._xi_pair = np.stack([self.xi, 1.0 - self.xi])  # (_wheel_forces)
            self.n_wheels = nw
            self._wheels_per_side = nw // 2
            # sums over the wheels (_wheel_forces): all, x-weighted, x^2-weighted, left side, right side
            left = (self.wheel_side == 0).astype(float)
            self._wheel_weights = np.stack(
                [np.ones(nw), self.wheel_x, self.wheel_x**2, left, 1.0 - left], axis=1
            )
            self._sinkage_exponent = 1.0 / (self.field.base.n + 0.5)  # eq. 2.32: Fz ~ z^(n + 1/2)
            if self.field.uniform:
                self._wheel_soil()  # once (with patches: refreshed while stepping)

    def reset(self) -> None:
        """Rest at the origin, heading +x, shear relaxed, static sinkage, full battery."""
        self.t = 0.0
        # sensor noise (twin/sensors.py): one stream per run from rest, so a drive split into pieces
        # gets fresh noise in every piece, not the same draws again
        self.sensor_rng = np.random.default_rng(self.seed)
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
            self._th = np.empty((2, TRACK_NODES + 1))  # (_track_forces)
            self._side_column = np.zeros((2, 1, 1), dtype=complex)  # (_advance_tracks)
            self._courant = np.zeros((2, 1, 1))
        else:
            w_wheel = v.weight_N / self.n_wheels
            z0 = float(single_wheel.bekker_wheel_sinkage(self.field.base, w_wheel, self.r, self.width))
            self.z = np.full(self.n_wheels, min(z0, 0.5 * self.r))
            self.dz = np.zeros(self.n_wheels)  # slip-sinkage: rut excavated below the wheel [m]
            self._deepest = float(self.z.max())  # deepest z + dz [m]
            self._sense = [1.0, 1.0]  # rolling sense of each side's wheels (+-1)
            self.j = np.zeros((2, self.n_wheels, WHEEL_NODES + 1))  # j_t, j_y [m] (wheel, rim node)
            nodes = (self.n_wheels, WHEEL_NODES + 1)
            self._rows = np.empty((6, *nodes))  # integrands (_wheel_forces)
            self._rows_flat = self._rows.reshape(6 * self.n_wheels, -1)  # (views of the same memory)
            self._integrals = np.empty((6, self.n_wheels))
            self._integrals_flat = self._integrals.reshape(-1)
            self._angles = np.zeros((3, *nodes))  # (_wheel_forces)
            self._trig = self._angles[:2]  # cos, sin of the node angles
            self._depth = np.empty(nodes)
            self._u_pair = np.empty((2, *nodes))
            self._u_pair_flat = self._u_pair.reshape(2 * self.n_wheels, -1)
            self._outer = np.zeros((2 * self.n_wheels, 2))
            self._spans, self._slope_spans = [0.0] * self.n_wheels, [0.0] * self.n_wheels
            self._per_wheel = np.zeros((8, self.n_wheels))  # contact integrals, bulldozing (_wheel_forces)
            self._cell, self._change = np.zeros(nodes), np.empty((2, *nodes))  # (_advance_wheels)
            self._damped = np.empty((2, *nodes))  # (_wheel_forces)
            self._soil_age = 0
            zeros = np.zeros(self.n_wheels)
            self._loads = np.zeros(2)  # side loads of the last force step [N] (_relax_sinkage)
            self._wheel_geometry()
            self._side, self._face_sides = zeros, (0.0, 0.0)  # bulldozing [N] (_wheel_contact)
            self._side_slope = zeros
            self._contact_age = 1
        self.current_A = [0.0, 0.0]  # motor currents of the last step [A] (left, right)
        self._last: tuple = (np.zeros(2), [0.0, 0.0], [0.0, 0.0], 0.0)  # (last)
        self._kinematics: tuple | None = None  # wheels: of the present velocities
        self._body_damping = (0.0, 0.0, 0.0, 0.0, 0.0)  # (_move)
        self._damped_rate = np.zeros_like(self.j)  # t_d / K dj/dt [-]: the damping stress / tau_max
        self._damping = SHEAR_DAMPING_S / self.field.base.K  # [s/m]: c = tau_max t_d / K

    @property
    def last(self) -> StepOutput:
        """The last step's per-side quantities (built when asked: the step keeps plain floats)."""
        axle, p_buses, p_terms, sinkage = self._last
        return StepOutput(
            np.array(self.current_A), np.array(axle), np.array(p_buses), np.array(p_terms), sinkage
        )

    # ------------------------------------------------------------------ terrain
    def _side_loads(self) -> np.ndarray:
        """Vertical load of each side [N] with lateral load transfer (eq. 3.1, instantaneous)."""
        transfer = self._transfer_coefficient * float(self.vel[0]) * float(self.vel[2])
        half = self._half_weight
        return np.array([max(half - transfer, 0.0), max(half + transfer, 0.0)])

    def _bulldozing(self, terrain: Terrain) -> tuple[float, float]:
        """:func:`bulldozing_coefficients` of ``terrain``, (0, 0) with ``dig_and_bulldoze`` off."""
        return bulldozing_coefficients(terrain) if self.dig_and_bulldoze else (0.0, 0.0)

    def _terrain_index(self, hx: np.ndarray, hy: np.ndarray) -> np.ndarray | None:
        """Terrain index of hull points (hx, hy) [m]; None if the floor is uniform."""
        if self.field.uniform:
            return None
        x, y, yaw = self.pose
        c, s = math.cos(yaw), math.sin(yaw)
        return self.field.index_at(x + c * hx - s * hy, y + s * hx + c * hy)

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
            side_wall = bulldozing_resistance(*self._bulldozing(t), sinkage)  # [N/m] per side
            self._bull_w = side_wall[:, None] * self.track_dx
            self._track_moments()
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
            side_wall[mask] = bulldozing_resistance(*self._bulldozing(t), sink[mask])
        self._bull_w = side_wall.mean(axis=2) * self.track_dx
        share = self.node_w / (b * length)  # each node's share of the rut
        self._tau_max_w = strength * self.node_w
        self._rc = (rc * share).sum(axis=(1, 2))
        self._sinkage = float(sink.max())
        self._track_moments()

    def _track_moments(self) -> None:
        """After a soil refresh: the side walls' bulldozing moments along the track, bw x^k (k = 0, 1,
        2) per node, and their sums."""
        bw = self._bull_w.sum(axis=0)  # both sides [N]
        x = self.track_x
        self._bull_moments = np.stack([bw, bw * x, bw * x * x])
        self._bull_sums = self._bull_moments.sum(axis=1).tolist()

    def _shear_fraction(self, magnitude: np.ndarray, index: np.ndarray | None) -> np.ndarray:
        """tau / tau_max at |j| [m] per node (eqs. 2.3-2.5), by the node's terrain."""
        if index is None:
            return soil.shear_fraction(self.field.base, magnitude)
        out = np.zeros(magnitude.shape)
        for i in np.unique(index):
            mask = index == i
            out[mask] = soil.shear_fraction(self.field.terrains[i], magnitude[mask])
        return out

    def _track_forces(
        self, loads: np.ndarray
    ) -> tuple[tuple[float, float, float], list[float], float, float]:
        """Body force (F_x, F_y, M_z) [N, N, N m], axle torques [N m], dissipation [W], sinkage [m].

        Vectors in the hull plane are complex numbers x + i y (j, forces, velocities).
        """
        if self._soil_age <= 0:
            self._track_soil(loads)
            self._soil_age = SOIL_REFRESH_STEPS
        self._soil_age -= 1
        vx, vy, wz = self.vel.tolist()
        j = self.j
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
        belts = (self.omega_m * (self.r / self.G)).tolist()  # belt speed relative to the hull [m/s]
        dissipation = belts[0] * f_side[0].real + belts[1] * f_side[1].real - (fx * vx + fy * vy + mz * wz)
        # compaction resistance (eq. 2.10) against each side's travel
        for rc, y in zip(self._rc.tolist(), self._side_y, strict=True):
            speed = vx - wz * y
            fc = -rc * math.tanh(speed / DIRECTION_SMOOTHING_M_S)
            fx += fc
            mz -= y * fc
            dissipation -= fc * speed
        # bulldozing on the track's side walls (Ishigami et al. 2007) against the lateral motion
        # vy + yaw x: sums of bw th, bw x th, bw x^2 th and of th^2 (bw the side walls' resistance
        # per node along, _track_soil) in one product
        th = self._th
        np.multiply(self.track_x, wz / DIRECTION_SMOOTHING_M_S, out=th[0])
        th[0] += vy / DIRECTION_SMOOTHING_M_S
        np.tanh(th[0], out=th[0])
        np.multiply(th[0], th[0], out=th[1])
        (b_th, b_th2), (bx_th, bx_th2), (_, bxx_th2) = self._bull_moments.dot(th.T).tolist()
        s0, s1, s2 = self._bull_sums
        fy -= b_th
        mz -= bx_th
        dissipation += vy * b_th + wz * bx_th
        # slopes in (vy, yaw rate) for the implicit body step (_move): d/dv of bw tanh(v / s)
        inv = 1.0 / DIRECTION_SMOOTHING_M_S
        self._body_damping = (0.0, 0.0, (s0 - b_th2) * inv, (s1 - bx_th2) * inv, (s2 - bxx_th2) * inv)
        return (fx, fy, mz), axle, dissipation, self._sinkage

    def _advance_tracks(self, dt: float) -> None:
        """Transport the shear displacement with the belt and add the slip (see the module doc)."""
        vx, vy, wz = self.vel.tolist()
        j = self.j
        belts = (self.omega_m * (self.r / self.G)).tolist()
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

        def spread(values: list[float]) -> np.ndarray:  # over the rim nodes (see _wheel_geometry)
            return np.repeat(column(values), WHEEL_NODES + 1, axis=1)

        self._wp_stress = spread([r**t.n * (t.kc / b + t.kphi) for t in terrains])
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

    def _wheel_kinematics(self) -> tuple[list[tuple[float, float, float, float, float]], np.ndarray]:
        """Per side (floats: the wheels of a side share them): axle ground speed forward [m/s],
        the same in the rolling frame [m/s], |omega| [rad/s], rolling direction (+-1), slip (eq.
        2.13) [-]; per wheel: lateral ground speed [m/s]. A side whose rolling sense changed
        mirrors its wheels' rim displacement first."""
        vx, vy, wz = self.vel.tolist()
        k = self._wheels_per_side
        r = self.r
        sides = []
        for side, w in enumerate(self.omega_m.tolist()):
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

    def _wheel_geometry(self) -> None:
        """Entry angle theta_f = arccos(1 - z / r) (eq. 2.19) of each wheel at its sinkage, as the
        pair (theta_f, theta_f - pi / 2) (one cosine call gives cos and sin of the node angles) and
        cos(theta_f), spread over the rim nodes (whole arrays: numpy is slower at broadcasting a
        column than at the arithmetic); with the sinkage, refreshed every ``SOIL_REFRESH_STEPS``."""
        tf = np.arccos(np.maximum(1.0 - self.z / self.r, -1.0))
        self._tf = tf.tolist()
        nodes = self._u_pair.shape[1:]
        self._tf_pair = np.broadcast_to(np.stack([tf, tf - 0.5 * math.pi])[:, :, None], (2, *nodes)).copy()
        self._cos_tf = np.broadcast_to(np.cos(tf)[:, None], nodes).copy()

    def _wheel_forces(
        self, loads: np.ndarray
    ) -> tuple[tuple[float, float, float], list[float], float, float]:
        """Body force (F_x, F_y, M_z), axle torques per side [N m], dissipation [W], sinkage [m].

        Shear displacement per rim node: j[0] tangential along the rim, j[1] lateral [m]. The
        contact integrals are weighted sums over the nodes (trapezoid in xi, times the arc
        r (theta_f - theta_r) and the width b), all six in one matrix product; their sums over the
        wheels (per side, and weighted by the wheels' positions) in a second one.
        """
        if self._patched:
            if self._soil_age <= 0:
                self._wheel_soil()
                self._soil_age = SOIL_REFRESH_STEPS
            else:
                self._soil_age -= 1
        kin = self._kinematics if self._kinematics is not None else self._wheel_kinematics()
        sides, vya = kin
        r = self.r
        # Wong-Reece angles (eqs. 2.20, 2.22) at the side's slip i, as fractions of theta_f:
        # theta_r = (b0 + b1 i) theta_f, theta_m = (a0 + a1 i) theta_f. The arc spans theta_f - theta_r;
        # behind theta_m the equivalent front angle of eq. 2.22,
        # theta_e = theta_f - (theta_f - theta_m) (theta - theta_r) / (theta_m - theta_r)
        #         = theta_f - k (span - u) (u = theta_f - theta), falls from theta_f to theta_m over
        # [theta_r, theta_m] and continues below theta_m ahead of it, so the angle to use in eq. 2.21
        # is max(theta, theta_e) = theta_f - min(u, k (span - u)) everywhere on the arc, with
        # u = span xi and k (span - u) = k span (1 - xi): both in one matrix product.
        tfs = self._tf
        spans, slope_spans = self._spans, self._slope_spans  # theta_f - theta_r and k (theta_f - theta_r)
        for side, (a0, a1, b0, b1), wheels in self._wp_groups:  # wheels sharing a side and a soil
            i = sides[side][4]
            rear = 1.0 - b0 - b1 * i  # (theta_f - theta_r) / theta_f
            k = (1.0 - a0 - a1 * i) / max(a0 - b0 + (a1 - b1) * i, 1e-12)
            for wheel in wheels:
                spans[wheel] = arc = tfs[wheel] * rear
                slope_spans[wheel] = k * arc
        n = self.n_wheels
        outer = self._outer  # (2 n, 2): [span, 0] and [0, k span] rows
        outer[:n, 0] = spans
        span = outer[:n, 0]
        outer[n:, 1] = slope_spans
        np.dot(outer, self._xi_pair, out=self._u_pair_flat)
        u_pair = self._u_pair
        # u = theta_f - theta at the nodes, k (span - u) [rad]
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
        # per wheel [N]: s_cos, s_sin, t_cos, t_sin, t_sum, y_sum (arc x width per unit xi [m^2]),
        # then the side wall's bulldozing against the axle's lateral motion (magnitude from
        # _wheel_contact) and its slope in that motion (for the implicit step, _move)
        per_wheel = self._per_wheel
        np.dot(self._rows_flat, self.xi_w, out=self._integrals_flat)
        integrals = self._integrals
        np.multiply(integrals, (r * self.width) * span, out=per_wheel[:6])
        th = np.multiply(vya, 1.0 / DIRECTION_SMOOTHING_M_S, out=per_wheel[6])
        np.tanh(th, out=th)
        slope = np.multiply(th, th, out=per_wheel[7])
        th *= self._side
        slope *= self._side_slope
        np.subtract(self._side_slope, slope, out=slope)  # side / s (1 - th^2)
        # sums over the wheels: all, x-weighted, per side (_wheel_weights)
        (
            _,
            (_, _, _, s_sin_l, s_sin_r),
            (_, _, _, t_cos_l, t_cos_r),
            _,
            (_, _, _, t_sum_l, t_sum_r),
            (y_sum, y_sum_x, _, _, _),
            (bull_y, bull_y_x, _, _, _),
            (c_y, c_y_x, c_y_xx, _, _),
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
        fy = y_sum - bull_y  # eq. 4.9 and the side wall
        mz += y_sum_x - bull_y_x
        self._body_damping = (c_x, -c_x_y, c_y, c_y_x, c_x_yy + c_y_xx)
        # dissipation = power of the contact stresses on the slip velocities = what the axles put in
        # minus what the body receives (F . v + M_z yaw rate)
        vx, vy, wz = self.vel.tolist()
        dissipation = power - (fx * vx + fy * vy + mz * wz)
        self._loads = loads
        return (fx, fy, mz), axle, dissipation, self._deepest

    def _advance_wheels(self, dt: float) -> None:
        """Transport the rim's shear displacement; every ``SOIL_REFRESH_STEPS`` also relax the sinkage
        and the excavation (see the module doc)."""
        spans = self._spans  # theta_f - theta_r per wheel [rad], as the last force step set them
        span = self._outer[: self.n_wheels, 0]  # the same as an array
        cos = self._trig[0]
        kin = self._wheel_kinematics()  # the new velocities (kept for the next step's forces)
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
            self._wheel_contact()

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
        if self.dig_and_bulldoze:  # slip-sinkage (Lyasko 2010): the excavation relaxes like the sinkage
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

    def _wheel_contact(self) -> None:
        """The slow contact terms, every ``SOIL_REFRESH_STEPS``: the geometry at the sinkage
        (_wheel_geometry) and the bulldozing magnitudes [N] (Ishigami et al. 2007) of each wheel's
        side wall, int R_b(h) dx over the contact at the rim's depth below the surface
        h = r (cos(theta) - cos(theta_f)) + dz, dx = r cos(theta) d(theta) (trapezoid over the rim
        nodes of the last step), and of the excavated step's face, b R_b(dz), summed per side."""
        self._wheel_geometry()
        bull_a, bull_b = self._wp_bull
        cos = self._trig[0]
        h = cos - self._cos_tf
        h *= self.r
        np.maximum(h, 0.0, out=h)
        h += self.dz[:, None]
        integrand = bulldozing_resistance(bull_a, bull_b, h) * cos
        self._side = (integrand @ self.xi_w) * (self.r * self._outer[: self.n_wheels, 0])
        self._side_slope = self._side * (1.0 / DIRECTION_SMOOTHING_M_S)
        dz = self.dz
        face = (self.width * bulldozing_resistance(bull_a[:, 0], bull_b[:, 0], dz)).tolist()
        k = self._wheels_per_side
        self._face_sides = (sum(face[:k]), sum(face[k:]))

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
        self._targets = self._target.tolist()

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

    def _move(self, force: tuple[float, float, float], omega_m: np.ndarray) -> float:
        """Body (hull frame: m (dv/dt + yaw x v) = F, Iz dyaw/dt = M), motor angles, pose and the
        contact's shear transport over one step, with the new motor speeds [rad/s]. The bulldozing
        (stiff where the body nearly stands) is implicit: (M + dt D) dv = dt (F + m v x yaw) with D
        its slope in (v_x, v_y, yaw rate) (``_body_damping``). Returns the power its implicit part
        adds to the dissipation [W] (-dF . v, dF = -D dv)."""
        dt = self.dt
        m = self.mass
        vx, vy, wz = self.vel.tolist()
        fx, fy, mz = force
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
        return np.array(axle)

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
        targets, axles = self._targets, axle
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
        self.current_A = currents
        self._last = (axle, p_buses, p_terms, sinkage)
