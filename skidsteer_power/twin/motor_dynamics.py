"""The twin's motor dynamics, per side: the DES 70/10 speed loop and current limit, the EC-45 motor and
the gearbox's internal resistance (Table 7.1, eqs. 7.1-7.4), integrated with the PI and friction terms
implicit so the stiff zero-speed friction stays stable. SI units; sides 0 = left, 1 = right.

J dw_m/dt = K_t i - (b w_m + c tanh(w_m / 1 rad/s)) - T_axle / G, the current from the DES speed
loop (``powertrain/speed_loop.py``, shared with ``des/simulator.MotorModel``: PI, 10 A limit,
voltage limit 0.9 V_bus - EMF).
"""

from __future__ import annotations

import math

import numpy as np

from skidsteer_power.powertrain import Powertrain
from skidsteer_power.powertrain.speed_loop import (
    SETPOINT_ACCEL_RAD_S2,
    current_limits,
    pi_current,
    ramp_setpoint,
    reflected_inertia,
    speed_loop_gains,
)
from skidsteer_power.vehicle import Vehicle

FRICTION_SMOOTHING_RAD_S = 1.0
"""Motor speed over which the Coulomb terms change sign (tanh) [rad/s], as nodes/suite.py."""
TRACK_ASSEMBLY_INERTIA_KG_M2 = 0.015
"""ASSUMED: one side's track belt (~1 kg at r = 0.1 m) and two sprockets (0.5 kg each) [kg m^2 at the
axle], scaled by (r / 0.1 m)^2 for other vehicles."""
WHEEL_INERTIA_KG_M2 = 0.0035
"""ASSUMED: one HPI Baja class wheel (~0.5 kg, mostly tyre, at r = 0.1 m): 0.7 m r^2 [kg m^2],
scaled by (r / 0.1 m)^2."""

SideFigures = tuple[list[float], list[float], list[float], list[float], float]
"""New motor speeds [rad/s], currents [A], terminal powers [W], bus powers [W] per side, and the
mean power of the internal resistance over the step [W]."""


class MotorDynamics:
    """Both sides' amplifier, motor and gearbox (``powertrain``: Table 7.1 internal resistance,
    left/right asymmetric); the state is the ramped set point and the PI integral per side."""

    def __init__(self, vehicle: Vehicle, powertrain: Powertrain) -> None:
        pt, motor = powertrain, powertrain.motor
        self.G = pt.gear_ratio
        r = vehicle.drive_radius_m
        self.kt = motor.torque_constant_Nm_A
        self.R = motor.terminal_resistance_ohm
        self.kn = motor.speed_constant_rad_s_V
        self.peak_A = pt.amplifier.continuous_current_A
        self.v_fraction = pt.amplifier.max_output_voltage_fraction
        self.friction_b = np.array([pt.left.total.viscous_Nm_s, pt.right.total.viscous_Nm_s])
        self.friction_c = np.array([pt.left.total.coulomb_Nm, pt.right.total.coulomb_Nm])
        self._friction_b, self._friction_c = self.friction_b.tolist(), self.friction_c.tolist()
        scale = (r / 0.1) ** 2
        if vehicle.is_tracked:
            axle_inertia = TRACK_ASSEMBLY_INERTIA_KG_M2 * scale
        else:
            axle_inertia = vehicle.wheels_per_side * WHEEL_INERTIA_KG_M2 * scale
        self.J = motor.rotor_inertia_kg_m2 + axle_inertia / self.G**2
        # PI gains as des/simulator.MotorModel: designed on the rotor + half the robot's mass at r
        j_design = motor.rotor_inertia_kg_m2 + reflected_inertia(vehicle.mass_kg, r, self.G)
        self.kp, self.ki = speed_loop_gains(j_design, self.kt)
        amp = powertrain.amplifier
        self._eta = amp.efficiency
        regen = powertrain.regen_efficiency
        self._eta_regen = (amp.efficiency if amp.four_quadrant else 0.0) if regen is None else regen
        self.reset()

    def reset(self) -> None:
        """Set points and integrals at zero."""
        self.integral_A = np.zeros(2)
        self.setpoint = np.zeros(2)  # ramped speed set point [rad/s]

    def step(self, dt: float, omega_m: np.ndarray, targets: list[float], axle_Nm: list[float],
             bus_voltage_V: float) -> SideFigures:  # fmt: skip
        """One step of dt [s] from the motor speeds [rad/s] towards the target speeds [rad/s] against
        the terrain's axle torques [N m] at the bus voltage [V] (see :data:`SideFigures`).

        Per side, in plain floats (two-element numpy arrays cost more than they save here).
        Amplifier: ramped set point, PI speed loop, current and voltage limits (powertrain/speed_loop)."""
        ramp = SETPOINT_ACCEL_RAD_S2 * dt
        v_max = self.v_fraction * bus_voltage_V
        kp, ki, kt, res, peak, inertia, gear = self.kp, self.ki, self.kt, self.R, self.peak_A, self.J, self.G
        kn = self.kn
        omegas, setpoints, integrals = omega_m.tolist(), self.setpoint.tolist(), self.integral_A.tolist()
        friction_b, friction_c = self._friction_b, self._friction_c
        currents, p_terms, p_buses = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
        friction_power = 0.0
        eta, eta_regen = self._eta, self._eta_regen
        for k in (0, 1):
            omega = omegas[k]
            set_k = setpoints[k] = ramp_setpoint(setpoints[k], targets[k], ramp)
            error = set_k - omega
            wanted, integrals[k] = pi_current(error, integrals[k], kp, ki, dt, peak)
            lower, upper = current_limits(omega, v_max, kn, res, peak)
            current = min(upper, max(lower, wanted))
            free = lower < wanted < upper
            # implicit in omega: the PI proportional part (where not limited) and the friction slope
            th = math.tanh(omega / FRICTION_SMOOTHING_RAD_S)
            b, c = friction_b[k], friction_c[k]
            friction = b * omega + c * th
            slope = b + c * (1.0 - th * th) / FRICTION_SMOOTHING_RAD_S
            drive = kt * current - friction - axle_Nm[k] / gear
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
        return omegas, currents, p_terms, p_buses, friction_power
