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
* beyond the steady models (``contact='extended'``, the default; ``'classic'`` switches them off):
  slip-sinkage, an excavated rut under each wheel and a deeper rut under each track (Lyasko 2010,
  ``contact.slip_sinkage_factor``), bulldozing of a wheel's excavated step against travel
  (Hegedus, as Ishigami et al. 2007 apply it, ``contact.bulldozing_coefficients``), and the track
  belt's longitudinal shear modulus 4 K (``track_contact.TRACK_LONGITUDINAL_MODULUS``, fitted to
  the track's Appendix D radii at 0.1 m/s).

The contacts are strategies (``track_contact.TrackContact``, ``wheel_contact.WheelContact``, their
shared part in ``contact.py``); the motors, amplifiers and gearboxes are ``motor_dynamics.MotorDynamics``.

Motor dynamics, per side (``motor_dynamics.py``, ``powertrain``: Table 7.1 internal resistance, left/right
asymmetric): J dw_m/dt = K_t i - (b w_m + c tanh(w_m / 1 rad/s)) - T_axle / G, the current from the
DES speed loop (PI, 10 A limit, voltage limit 0.9 V_bus - EMF).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skidsteer_power.drive.controller import DriveController, Ramp, controller_for_vehicle
from skidsteer_power.errors import InputError
from skidsteer_power.powertrain import Battery, Powertrain
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.twin.contact import CONTACT_LAWS, Contact
from skidsteer_power.twin.motor_dynamics import MotorDynamics
from skidsteer_power.twin.terrain_field import Patch, TerrainField
from skidsteer_power.twin.track_contact import TrackContact
from skidsteer_power.twin.wheel_contact import WheelContact
from skidsteer_power.vehicle import Vehicle

DEFAULT_DT_S = 2e-3
"""Default fixed step [s] (500 Hz): the 1 ms step gives the same steady torques and speeds to 4
digits (measured on the three test-robot configurations) at half the speed."""
BATTERY_STEP_S = 0.1
"""Interval at which the battery (state of charge, terminal voltage) is updated with the mean bus
power of the interval [s]; the bus voltage changes by < 0.1 V within it at the test robot's loads."""


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
    in polygons), ``seed`` (sensor noise, used by :mod:`skidsteer_power.twin.sensors`), ``dt`` [s],
    ``contact``: ``'classic'`` (the chapter 2-4 laws only) or ``'extended'`` (docs/TWIN.md).
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
        contact: str = 'extended',
        controller: DriveController | None = None,
    ) -> None:
        if not (0 < dt <= DEFAULT_DT_S):
            raise InputError(f'dt must be in (0, 2 ms] (>= 500 Hz), got {dt}')
        if contact not in CONTACT_LAWS:
            raise InputError(f'contact must be one of {", ".join(CONTACT_LAWS)}, got {contact!r}')
        self.vehicle = vehicle
        self.field = TerrainField(terrain, patches or ())
        self.powertrain = powertrain or Powertrain.for_vehicle(vehicle)
        # the robot's drive controller makes the set points (skidsteer_power.drive): the vehicle's
        self.controller = controller or controller_for_vehicle(vehicle, self.powertrain)
        self._ramp = Ramp(self.controller)
        self.battery = Battery.from_config(self.powertrain.battery)
        self.seed = seed
        self.dt = dt
        # 'classic': the chapter 2-4 laws only (no slip-sinkage, bulldozing or belt compliance)
        self.contact_laws = contact
        self.motor_dynamics = MotorDynamics(vehicle, self.powertrain)
        d = self.motor_dynamics
        self.G, self.kt, self.R, self.peak_A, self.J, self.kp, self.ki = (
            d.G,
            d.kt,
            d.R,
            d.peak_A,
            d.J,
            d.kp,
            d.ki,
        )
        self.r = vehicle.drive_radius_m
        self.half_tread = 0.5 * vehicle.tread_m
        self.mass = vehicle.mass_kg
        self._transfer_coefficient = vehicle.mass_kg * vehicle.cg_height_m / vehicle.tread_m  # eq. 3.1
        self._half_weight = 0.5 * vehicle.weight_N
        self.Iz = vehicle.yaw_inertia
        gear: type[TrackContact] | type[WheelContact] = TrackContact if vehicle.is_tracked else WheelContact
        self.contact: Contact = gear(vehicle, self.field, self.G, extended=contact == 'extended')
        self.reset()

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
        self.motor_dynamics.reset()
        self._ramp.reset()
        self.command = (0.0, 0.0)
        self.energy = EnergyLedger()
        self.battery = Battery.from_config(self.powertrain.battery)
        self.bus_voltage_V = self.battery.state.voltage_V
        self._battery_pending = [0.0, 0.0]  # energy [J], time [s] not yet given to the battery
        self.bus_current_A = 0.0
        self.max_sinkage_m = 0.0
        self.contact.reset()
        self.current_A = [0.0, 0.0]  # motor currents of the last step [A] (left, right)
        # (last): axle torques [N m], bus and terminal powers [W] per side, sinkage [m]
        self._last: tuple[list[float], list[float], list[float], float] = (
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            0.0,
        )

    @property
    def last(self) -> StepOutput:
        """The last step's per-side quantities (built when asked: the step keeps plain floats)."""
        axle, p_buses, p_terms, sinkage = self._last
        return StepOutput(
            np.array(self.current_A), np.array(axle), np.array(p_buses), np.array(p_terms), sinkage
        )

    def _side_loads(self) -> np.ndarray:
        """Vertical load of each side [N] with lateral load transfer (eq. 3.1, instantaneous)."""
        transfer = self._transfer_coefficient * float(self.vel[0]) * float(self.vel[2])
        half = self._half_weight
        return np.array([max(half - transfer, 0.0), max(half + transfer, 0.0)])

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
        if self.controller.has_ramps:  # the set points follow the ramps step by step (_step)
            left, right, _ = self._ramp.step(*self.command, 0.0)
        else:
            left, right, _ = self.controller.apply_one(*self.command)
        self._target = np.array([left, right]) * self.G  # motor speed set points [rad/s]
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
        dxx, dxw, dyy, dyw, dww = self.contact.body_damping
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
        self.contact.advance(dt, self.vel, omega_m)
        return extra

    def step_with_motor_speeds(self, omega_m: np.ndarray) -> np.ndarray:
        """One step with the motor speeds [rad/s, forward positive] imposed from outside (the live
        suite's simulated amplifiers integrate the motors); returns the terrain's resisting axle
        torque of each side [N m]. The energy ledger then holds only the terrain work."""
        omega_m = np.asarray(omega_m, dtype=float)
        self.omega_m = omega_m
        self.contact.motor_speeds_changed()
        force, axle, dissipation, sinkage = self.contact.forces(
            self._side_loads(), self.vel, omega_m, self.pose
        )
        self.max_sinkage_m = max(self.max_sinkage_m, sinkage)
        dissipation += self._move(force, omega_m)
        self.energy.terrain_J += dissipation * self.dt
        self.t += self.dt
        return np.array(axle)

    def _step(self) -> None:
        dt = self.dt
        if self.controller.has_ramps:  # the controller's acceleration / jerk limits, per step
            left, right, _ = self._ramp.step(*self.command, dt)
            self._targets = [left * self.G, right * self.G]
        force, axle, dissipation, sinkage = self.contact.forces(
            self._side_loads(), self.vel, self.omega_m, self.pose
        )
        if sinkage > self.max_sinkage_m:
            self.max_sinkage_m = sinkage
        omegas, currents, p_terms, p_buses, friction_power = self.motor_dynamics.step(
            dt, self.omega_m, self._targets, axle, self.bus_voltage_V
        )
        dissipation += self._move(force, np.array(omegas))
        # electrical side and energy ledger
        e = self.energy
        total = p_buses[0] + p_buses[1]
        e.bus_J += total * dt
        e.amplifier_J += (total - p_terms[0] - p_terms[1]) * dt
        e.copper_J += self.R * (currents[0] ** 2 + currents[1] ** 2) * dt
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
