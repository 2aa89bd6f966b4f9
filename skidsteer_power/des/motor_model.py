"""The DES simulator's motor and load: one motor shaft behind the amplifier's speed loop (SI units).

    J dw/dt = Kt i - T_load(w, t)                                   (Newton, motor shaft)
    i = clamp(PI(w_set - w), peak current, (+-0.9 V_supply - w/Kn) / R)   (speed mode)

with the motor constants of the vehicle's powertrain (Appendix B, EC-45 by default), the rotor
inertia plus the robot's inertia reflected through the reduction, and a pluggable load torque.
Split from :mod:`skidsteer_power.des.simulator` (the protocol server), which re-exports these names.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from skidsteer_power.powertrain.motor import DES_70_10, GEAR_RATIO, MotorConstants
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.powertrain.speed_loop import (
    SPEED_LOOP_BANDWIDTH_RAD_S,
    current_limits,
    pi_current,
    ramp_setpoint,
    reflected_inertia,
    speed_loop_gains,
)
from skidsteer_power.vehicle import load_vehicle

LoadTorque = float | Callable[[float, float], float]
"""Load torque at the motor shaft [N m]: a constant or ``f(omega_rad_s, t_s)``."""

DEFAULT_VEHICLE = 'test_robot_track'
"""The vehicle whose mass, drive radius and powertrain a :class:`MotorModel` drives by default."""


def default_motor() -> MotorConstants:
    """The motor of :data:`DEFAULT_VEHICLE`'s powertrain (the EC-45, Appendix B), read from its files."""
    return _vehicle_drive(DEFAULT_VEHICLE)[0]


def no_load_friction_Nm(motor: MotorConstants) -> float:
    """A motor's own no-load friction torque K_t I_0 [N m] (Appendix B lines 3 and 12)."""
    return motor.torque_constant_Nm_A * motor.no_load_current_A


@dataclass(frozen=True)
class ViscousCoulombLoad:
    """Default load torque [N m] = b w + c tanh(w / w_eps) (cf. eq. 7.1's b w + c).

    Defaults: Coulomb part c = Kt I0 of :func:`default_motor` (EC-45: 0.114 N m/A x 0.193 A =
    0.022 N m, Appendix B lines 3 and 12, the no-load friction of the motor); a small viscous part
    b = 1e-5 N m s/rad (assumed); tanh smoothing over w_eps = 1 rad/s keeps the explicit integration
    stable through zero speed.
    """

    viscous_Nm_s: float = 1e-5
    coulomb_Nm: float = field(default_factory=lambda: no_load_friction_Nm(default_motor()))
    smoothing_rad_s: float = 1.0

    def __call__(self, omega_rad_s: float, t_s: float) -> float:
        return self.viscous_Nm_s * omega_rad_s + self.coulomb_Nm * math.tanh(
            omega_rad_s / self.smoothing_rad_s
        )


@dataclass(frozen=True)
class AxleLoad:
    """Load torque at the motor shaft [N m] from an axle (sprocket/wheel) torque, e.g. a
    terramechanics steady state (``PowerMap.query(...).torque_left_Nm``) for an operating point.

    ``axle_torque_Nm`` [N m] is a number or ``f(axle_omega_rad_s, t_s)``; it resists rotation in
    either direction (its magnitude is used, with the sign of the speed, smoothed over
    ``smoothing_rad_s`` at the motor). The motor sees it divided by ``gear_ratio`` [-] and by the
    transmission ``efficiency`` [-], plus the motor's own ``friction`` (default
    :class:`ViscousCoulombLoad`; a :class:`MotorModel` gives it its motor's K_t I_0).
    """

    axle_torque_Nm: float | Callable[[float, float], float]
    gear_ratio: float = GEAR_RATIO
    efficiency: float = 1.0
    friction: Callable[[float, float], float] | None = None
    smoothing_rad_s: float = 1.0

    def __call__(self, omega_rad_s: float, t_s: float) -> float:
        axle = self.axle_torque_Nm
        axle_omega = omega_rad_s / self.gear_ratio
        torque = abs(float(axle(axle_omega, t_s) if callable(axle) else axle))
        friction = (self.friction or ViscousCoulombLoad())(omega_rad_s, t_s)
        direction = math.tanh(omega_rad_s / self.smoothing_rad_s)
        return friction + direction * torque / (self.gear_ratio * self.efficiency)


class MotorModel:
    """A motor (the EC-45 by default) driven by a DES in speed or current mode; state in SI units.

    Parameters
    ----------
    motor : motor constants (default: the motor of :data:`DEFAULT_VEHICLE`'s powertrain, the EC-45)
    load_inertia_kg_m2 : inertia reflected to the motor shaft besides the rotor [kg m^2] (default:
        half of :data:`DEFAULT_VEHICLE`'s mass at its drive radius, :func:`reflected_inertia`)
    supply_voltage_V : amplifier supply [V] (default 44.4 V: two 6-cell LiPo packs in series at
        3.7 V/cell, ASSUMED; ch. 7.1.2 names the packs, not their wiring)
    load_torque : see :data:`LoadTorque` (default: :class:`ViscousCoulombLoad` with the motor's K_t I_0,
        also an :class:`AxleLoad`'s friction when it names none)
    bandwidth_rad_s : speed-loop bandwidth of the PI controller [rad/s] (ASSUMED, see
        :mod:`skidsteer_power.powertrain.speed_loop`, the drive model shared with the twin)
    mean_time_constant_s : low-pass behind the 'mean' speed and current readings [s] (assumed)
    """

    STEP_S = 0.0005

    def __init__(
        self,
        motor: MotorConstants | None = None,
        load_inertia_kg_m2: float | None = None,
        supply_voltage_V: float = 44.4,
        load_torque: LoadTorque | None = None,
        bandwidth_rad_s: float = SPEED_LOOP_BANDWIDTH_RAD_S,
        mean_time_constant_s: float = 0.01,
    ) -> None:
        if motor is None or load_inertia_kg_m2 is None:
            default_motor, default_load = _vehicle_drive(DEFAULT_VEHICLE)
            motor = default_motor if motor is None else motor
            load_inertia_kg_m2 = default_load if load_inertia_kg_m2 is None else load_inertia_kg_m2
        self.motor = motor
        self.inertia_kg_m2 = motor.rotor_inertia_kg_m2 + load_inertia_kg_m2
        self.supply_voltage_V = supply_voltage_V
        own_friction = ViscousCoulombLoad(coulomb_Nm=no_load_friction_Nm(motor))
        if load_torque is None:  # the motor's own no-load friction, K_t I_0
            load_torque = own_friction
        elif isinstance(load_torque, AxleLoad) and load_torque.friction is None:
            load_torque = dataclasses.replace(load_torque, friction=own_friction)
        self.load_torque: LoadTorque = load_torque
        self.kp_A_s, self.ki_A = speed_loop_gains(
            self.inertia_kg_m2, motor.torque_constant_Nm_A, bandwidth_rad_s
        )
        self.mean_time_constant_s = mean_time_constant_s
        self.omega_rad_s = 0.0
        self.theta_rad = 0.0
        self.current_A = 0.0
        self.mean_omega_rad_s = 0.0
        self.mean_current_A = 0.0
        self.ramped_setpoint_rad_s = 0.0
        self.current_limited = False
        self._integral_A = 0.0

    def load_at(self, omega_rad_s: float, t_s: float) -> float:
        """Load torque at the motor shaft [N m]."""
        load = self.load_torque
        return float(load(omega_rad_s, t_s)) if callable(load) else float(load)

    def holding_torque(self, t_s: float) -> float:
        """The load's torque at 1 rad/s [N m]: what holds a coasting motor at rest. A load that keeps
        state (the live twin, ``twin/live.TwinLoad``) gives it by ``holding_torque_Nm()`` instead, so
        asking it never moves anything (issue 37 item 9: asking the twin at 1 rad/s fed it that speed)."""
        holding = getattr(self.load_torque, 'holding_torque_Nm', None)
        return float(holding()) if callable(holding) else self.load_at(1.0, t_s)

    def step(
        self,
        dt_s: float,
        t_s: float,
        *,
        powered: bool,
        current_mode: bool,
        speed_setpoint_rad_s: float,
        current_setpoint_A: float,
        peak_current_A: float,
        acceleration_rad_s2: float,
    ) -> None:
        """Advance the state by ``dt_s`` [s] (explicit Euler)."""
        motor = self.motor
        self.ramped_setpoint_rad_s = ramp_setpoint(
            self.ramped_setpoint_rad_s, speed_setpoint_rad_s, acceleration_rad_s2 * dt_s
        )
        if not powered:
            wanted, self._integral_A = 0.0, 0.0
            self.ramped_setpoint_rad_s = self.omega_rad_s
        elif current_mode:
            wanted = current_setpoint_A
        else:
            error = self.ramped_setpoint_rad_s - self.omega_rad_s
            wanted, self._integral_A = pi_current(
                error, self._integral_A, self.kp_A_s, self.ki_A, dt_s, peak_current_A
            )
        lower, upper = current_limits(
            self.omega_rad_s,
            DES_70_10.max_output_voltage_fraction * self.supply_voltage_V,
            motor.speed_constant_rad_s_V,
            motor.terminal_resistance_ohm,
            peak_current_A,
        )
        current = min(upper, max(lower, wanted)) if powered else 0.0
        self.current_limited = powered and current != wanted
        self.current_A = current
        torque = motor.torque_constant_Nm_A * current - self.load_at(self.omega_rad_s, t_s)
        if not powered and abs(self.omega_rad_s) < 0.5 and abs(torque) < self.holding_torque(t_s):
            torque, self.omega_rad_s = 0.0, 0.0  # Coulomb friction holds a coasting motor at rest
        # a load that gives its slope d(load)/d(omega) [N m s/rad] is taken implicitly (as the twin's
        # drivetrain does): the live twin's Coulomb friction changes sign over 1 rad/s on a rotor of
        # 1.4e-4 kg m^2, c dt / (J w_s) = 2.7 > 2, and explicit Euler chattered at zero speed with a
        # non-zero mean, so the robot drifted at zero set points (issue 37 item 9)
        slope = getattr(self.load_torque, 'slope_Nm_s', None)
        implicit = float(slope(self.omega_rad_s)) * dt_s if callable(slope) else 0.0
        self.omega_rad_s += torque * dt_s / (self.inertia_kg_m2 + max(implicit, 0.0))
        self.theta_rad += self.omega_rad_s * dt_s
        alpha = dt_s / (self.mean_time_constant_s + dt_s)
        self.mean_omega_rad_s += alpha * (self.omega_rad_s - self.mean_omega_rad_s)
        self.mean_current_A += alpha * (current - self.mean_current_A)


@functools.cache
def _vehicle_drive(vehicle_name: str) -> tuple[MotorConstants, float]:
    """(motor, reflected inertia [kg m^2]) of a vehicle file and its powertrain."""
    vehicle = load_vehicle(vehicle_name)
    powertrain = Powertrain.for_vehicle(vehicle)
    inertia = reflected_inertia(vehicle.mass_kg, vehicle.drive_radius_m, powertrain.gear_ratio)
    return powertrain.motor, inertia
