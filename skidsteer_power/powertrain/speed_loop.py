"""The DES 70/10's speed loop (ch. 7.1.2, Appendix A): one drive model for the twin
(``twin/motor_dynamics.py``, semi-implicit) and the simulated amplifier (``des/simulator.MotorModel``,
explicit Euler). SI units: rad/s at the motor shaft, A, V, s.

Per step: the set point ramps towards the target at the amplifier's ACCELERATION, a PI loop turns the
speed error into a wanted current (its integral clamped to the peak current), and the current is
limited by the peak current and by the voltage left above the back-EMF (0.9 V_bus, Appendix A).
The real gains (DES parameters 5 and 6) are in units the sources do not give, so the loop is designed
for an ASSUMED bandwidth on the rotor plus half the vehicle's mass at the drive radius.

Plain floats, not arrays: both callers step one side at a time, where numpy scalars cost more.
"""

from __future__ import annotations

from skidsteer_power.powertrain.motor import RPM

SPEED_LOOP_BANDWIDTH_RAD_S = 60.0
"""Speed-loop bandwidth of the PI controller [rad/s] (ASSUMED, see module doc)."""
SETPOINT_ACCEL_RAD_S2 = 10.0 * 1000.0 * RPM
"""Set-point ramp [rad/s^2 at the motor]: DES parameter ACCELERATION = 10 rpm/ms, as the driver
configures it (``des/simulator.default_parameters``)."""


def reflected_inertia(mass_kg: float, drive_radius_m: float, gear_ratio: float) -> float:
    """Half the vehicle's mass [kg] at the drive radius [m], seen at one motor through the reduction
    G [-]: m r^2 / (2 G^2) [kg m^2]."""
    return 0.5 * mass_kg * drive_radius_m**2 / gear_ratio**2


def speed_loop_gains(
    design_inertia_kg_m2: float,
    torque_constant_Nm_A: float,
    bandwidth_rad_s: float = SPEED_LOOP_BANDWIDTH_RAD_S,
) -> tuple[float, float]:
    """PI gains (kp [A s/rad], ki [A/rad]) for a loop of ``bandwidth_rad_s`` on an inertia [kg m^2]
    driven through K_t [N m/A]: kp = w_b J / K_t, ki = kp w_b / 4 (critically damped)."""
    kp = bandwidth_rad_s * design_inertia_kg_m2 / torque_constant_Nm_A
    return kp, kp * bandwidth_rad_s / 4.0


def ramp_setpoint(setpoint: float, target: float, max_step: float) -> float:
    """The set point [rad/s] moved towards the target [rad/s] by at most ``max_step`` [rad/s]."""
    return setpoint + min(max_step, max(-max_step, target - setpoint))


def pi_current(
    error: float, integral_A: float, kp_A_s: float, ki_A: float, dt_s: float, peak_A: float
) -> tuple[float, float]:
    """(wanted current [A], new integral [A]) for a speed error [rad/s] over ``dt_s`` [s]; the
    integral is clamped to +-``peak_A`` (anti-windup)."""
    integral = min(peak_A, max(-peak_A, integral_A + ki_A * error * dt_s))
    return kp_A_s * error + integral, integral


def current_limits(
    omega_rad_s: float, v_max_V: float, speed_constant_rad_s_V: float, resistance_ohm: float, peak_A: float
) -> tuple[float, float]:
    """(lower, upper) current [A] the amplifier can drive at motor speed [rad/s]: the peak current,
    and (+-v_max - EMF) / R with EMF = omega / K_n."""
    emf = omega_rad_s / speed_constant_rad_s_V
    upper = min(peak_A, (v_max_V - emf) / resistance_ohm)
    lower = max(-peak_A, (-v_max_V - emf) / resistance_ohm)
    return lower, upper
