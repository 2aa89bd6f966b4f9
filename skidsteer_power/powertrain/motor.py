"""Maxon EC-45 motor (Appendix B), the 12:1 reduction and the DES 70/10 amplifier (Appendix A, ch. 7.1).

Every constant is converted to SI at definition (rad/s, N m, A, V, ohm, H, kg m^2, kg) and keeps the
datasheet value and unit beside it, so a reader can check the conversion.

Amplifier model (4-quadrant, ch. 7.1.2: "4-Q ready ... can absorb power from the motor when the
vehicle is performing regenerative braking"): the DC bus power is the motor terminal power divided by
the amplifier efficiency when motoring, and the terminal power times the efficiency when the motor
generates. Appendix A gives only the *maximum* efficiency (92 %); using it at every operating point is
a stated simplification (it slightly flatters part-load operation). Regeneration can therefore only
return part of the mechanical braking power: it never creates energy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypeVar

from skidsteer_power.errors import ConfigError
from skidsteer_power.numeric import Real, by_sign, real

RPM = 2.0 * math.pi / 60.0
"""One revolution per minute in rad/s."""


@dataclass(frozen=True)
class MotorConstants:
    """Datasheet constants of a DC / EC motor, SI units.

    Attributes
    ----------
    name : motor designation
    nominal_voltage_V : nominal supply voltage [V]
    no_load_speed_rad_s : no-load speed at nominal voltage [rad/s]
    no_load_current_A : no-load current at nominal voltage [A]
    nominal_speed_rad_s : speed at nominal torque [rad/s]
    nominal_torque_Nm : max. continuous torque [N m]
    nominal_current_A : max. continuous current [A]
    stall_torque_Nm : stall torque [N m]
    starting_current_A : starting (stall) current [A]
    max_efficiency : maximum efficiency [-]
    terminal_resistance_ohm : terminal resistance phase to phase [ohm]
    terminal_inductance_H : terminal inductance phase to phase [H]
    torque_constant_Nm_A : torque constant Kt [N m / A]
    speed_constant_rad_s_V : speed constant Kn [rad/s / V] (its inverse is the back-EMF constant)
    speed_torque_gradient : speed / torque gradient [(rad/s) / (N m)]
    mechanical_time_constant_s : mechanical time constant [s]
    rotor_inertia_kg_m2 : rotor inertia [kg m^2]
    max_speed_rad_s : max. permissible speed [rad/s]
    pole_pairs : number of pole pairs [-]
    encoder_counts_per_turn : encoder pulses per revolution [-] (ch. 7.1.2: 2048)
    mass_kg : motor mass [kg]
    """

    name: str
    nominal_voltage_V: float
    no_load_speed_rad_s: float
    no_load_current_A: float
    nominal_speed_rad_s: float
    nominal_torque_Nm: float
    nominal_current_A: float
    stall_torque_Nm: float
    starting_current_A: float
    max_efficiency: float
    terminal_resistance_ohm: float
    terminal_inductance_H: float
    torque_constant_Nm_A: float
    speed_constant_rad_s_V: float
    speed_torque_gradient: float
    mechanical_time_constant_s: float
    rotor_inertia_kg_m2: float
    max_speed_rad_s: float
    pole_pairs: int
    encoder_counts_per_turn: int
    mass_kg: float

    @property
    def back_emf_constant_V_s(self) -> float:
        """Back-EMF constant 1 / Kn [V s / rad] (equal to Kt within datasheet rounding)."""
        return 1.0 / self.speed_constant_rad_s_V


EC45 = MotorConstants(
    name='maxon EC-4pole 45, 300 W, order no. 283150 (Appendix B)',
    nominal_voltage_V=48.0,  # line 1: 48.0 V
    no_load_speed_rad_s=4010 * RPM,  # line 2: 4010 rpm
    no_load_current_A=0.193,  # line 3: 193 mA
    nominal_speed_rad_s=3580 * RPM,  # line 4: 3580 rpm
    nominal_torque_Nm=0.635,  # line 5: 635 mNm
    nominal_current_A=5.61,  # line 6: 5.61 A
    stall_torque_Nm=7.690,  # line 7: 7690 mNm
    starting_current_A=67.6,  # line 8: 67.6 A
    max_efficiency=0.90,  # line 9: 90 %
    terminal_resistance_ohm=0.710,  # line 10: 0.710 ohm phase to phase
    terminal_inductance_H=0.677e-3,  # line 11: 0.677 mH
    torque_constant_Nm_A=0.114,  # line 12: 114 mNm / A
    speed_constant_rad_s_V=84.0 * RPM,  # line 13: 84.0 rpm / V
    speed_torque_gradient=0.524 * RPM / 1e-3,  # line 14: 0.524 rpm / mNm
    mechanical_time_constant_s=2.02e-3,  # line 15: 2.02 ms
    rotor_inertia_kg_m2=368e-7,  # line 16: 368 g cm^2
    max_speed_rad_s=10000 * RPM,  # line 23: 10000 rpm
    pole_pairs=2,  # line 29
    encoder_counts_per_turn=2048,  # ch. 7.1.2 and encoder data
    mass_kg=1.130,  # line 31: 1130 g
)
"""The test robot's drive motor, one per side (ch. 7.1.1, Appendix B)."""

GEAR_RATIO = 12.0
"""Motor-to-axle reduction of the test robot: 4.8:1 planetary x 2.5:1 roller chain (ch. 7.1.1) [-]."""


@dataclass(frozen=True)
class AmplifierConstants:
    """Servo amplifier data, SI units.

    Attributes
    ----------
    name : designation
    min_supply_V, max_supply_V : operating supply voltage range V_CC [V]
    max_output_voltage_fraction : max. output voltage / V_CC [-]
    max_current_A : max. (peak) output current [A]
    continuous_current_A : continuous output current [A]
    efficiency : efficiency used for every operating point [-] (Appendix A: max. efficiency)
    four_quadrant : True if it can absorb regenerated power
    """

    name: str
    min_supply_V: float
    max_supply_V: float
    max_output_voltage_fraction: float
    max_current_A: float
    continuous_current_A: float
    efficiency: float
    four_quadrant: bool = True


DES_70_10 = AmplifierConstants(
    name='maxon DES 70/10 4-Q-EC servoamplifier, part no. 228597 (Appendix A)',
    min_supply_V=24.0,  # operating voltage 24 - 70 VDC
    max_supply_V=70.0,
    max_output_voltage_fraction=0.9,  # max. output voltage 0.9 x V_CC
    max_current_A=30.0,  # I_max 30 A
    continuous_current_A=10.0,  # I_cont 10 A
    efficiency=0.92,  # max. efficiency 92 %
    four_quadrant=True,
)
"""The test robot's amplifier, one per motor (ch. 7.1.2, Appendix A)."""

Preset = TypeVar('Preset', MotorConstants, AmplifierConstants)

EFFECTIVE_MOTOR = MotorConstants(
    name='effective: the axle itself (motor unknown; issue 35)',
    nominal_voltage_V=48.0,  # unused: the powertrain's bus_voltage_V is the bus
    no_load_speed_rad_s=1.0e4,  # no speed ceiling from a motor nobody knows [rad/s]
    no_load_current_A=1.0e-9,
    nominal_speed_rad_s=1.0e4,
    nominal_torque_Nm=1.0e9,
    nominal_current_A=1.0e9,
    stall_torque_Nm=1.0e9,
    starting_current_A=1.0e9,
    max_efficiency=1.0,
    # copper loss R i^2 = R (T / K_t)^2: with K_t = 1 N m/A the resistance IS the copper-loss
    # coefficient k_cu [W / (N m)^2] of the powertrain file's copper_loss_W_per_Nm2 (neutral: 0)
    terminal_resistance_ohm=0.0,
    terminal_inductance_H=1.0e-9,
    torque_constant_Nm_A=1.0,  # a 'current' of this motor is the axle torque in N m
    speed_constant_rad_s_V=1.0e4,  # no speed ceiling (the drive controller's own limits apply)
    speed_torque_gradient=1.0e-9,
    mechanical_time_constant_s=1.0e-3,
    rotor_inertia_kg_m2=1.0e-9,
    max_speed_rad_s=1.0e4,
    pole_pairs=1,
    encoder_counts_per_turn=1,
    mass_kg=1.0e-9,
)
"""The motor of an effective powertrain (``preset: effective``): the axle with gear ratio 1 and K_t
1 N m/A, so its torque and speed are the axle's and its copper loss is k_cu T^2 (every constant
but K_t and R is a placeholder that sets no limit)."""

MOTORS: dict[str, MotorConstants] = {'EC45': EC45, 'EFFECTIVE': EFFECTIVE_MOTOR}
"""Motor presets a powertrain file names (``motor: EC45``), each with its datasheet constants."""
EFFECTIVE_AMPLIFIER = AmplifierConstants(
    name='effective: lossless until calibrated (issue 35)',
    min_supply_V=0.0,
    max_supply_V=math.inf,
    max_output_voltage_fraction=1.0,
    max_current_A=math.inf,
    continuous_current_A=math.inf,
    efficiency=1.0,  # neutral: calibrate fits it (the powertrain file's amplifier.efficiency)
    four_quadrant=True,
)
"""The amplifier of an effective powertrain: efficiency 1 (neutral) and no current limit."""

AMPLIFIERS: dict[str, AmplifierConstants] = {'DES_70_10': DES_70_10, 'EFFECTIVE': EFFECTIVE_AMPLIFIER}
"""Amplifier presets a powertrain file names (``amplifier: DES_70_10``)."""


def motor_from_config(value: str | Mapping[str, object] | None) -> MotorConstants:
    """The motor of a powertrain file's ``motor:`` entry: a preset name (:data:`MOTORS`), or a mapping
    ``{preset: EC45, <field>: <SI value>, ...}`` whose fields (those of :class:`MotorConstants`, SI
    units) replace the preset's; without ``preset`` every field must be given. None = EC-45.
    Raises ConfigError for an unknown preset or field, or a non-positive number."""
    return _from_config(value, MOTORS, 'EC45', 'motor')


def amplifier_from_config(value: str | Mapping[str, object] | None) -> AmplifierConstants:
    """The amplifier of a powertrain file's ``amplifier:`` entry, as :func:`motor_from_config`."""
    return _from_config(value, AMPLIFIERS, 'DES_70_10', 'amplifier')


def _from_config(value: object, presets: Mapping[str, Preset], default: str, what: str) -> Preset:
    if value is None or isinstance(value, str):
        name = default if value is None else value
        if name not in presets:
            raise ConfigError(f'powertrain: unknown {what} {name!r} (presets: {", ".join(presets)})')
        return presets[name]
    if not isinstance(value, Mapping):
        raise ConfigError(f'powertrain: {what} must be a preset name or a mapping, not {value!r}')
    fields = {f.name for f in dataclasses.fields(next(iter(presets.values())))}
    values = dict(value)
    unknown = set(values) - set(fields) - {'preset'}
    if unknown:
        raise ConfigError(f'powertrain: unknown {what} fields {sorted(unknown)}')
    for key, number in values.items():
        if key in ('preset', 'name', 'four_quadrant'):
            continue
        if not isinstance(number, int | float) or isinstance(number, bool) or not number > 0:
            raise ConfigError(f'powertrain: {what}.{key} must be a number > 0, not {number!r}')
    preset = values.pop('preset', None)
    if preset is not None:
        return dataclasses.replace(_from_config(str(preset), presets, default, what), **values)
    missing = set(fields) - set(values) - {'four_quadrant'}
    if missing:
        raise ConfigError(f'powertrain: {what} without a preset needs {sorted(missing)}')
    return type(next(iter(presets.values())))(**values)


def motor_current(motor: MotorConstants, motor_torque_Nm: Real) -> Real:
    """Motor current i = T / Kt [A] for the total electromagnetic torque T [N m] (eq. 7.1: Kt i);
    a float or an array (:mod:`skidsteer_power.numeric`)."""
    return real(motor_torque_Nm) / motor.torque_constant_Nm_A


def terminal_power(motor: MotorConstants, motor_torque_Nm: Real, motor_omega_rad_s: Real) -> Real:
    """Electrical power at the motor terminals [W]: T omega + R i^2 (negative = generating).

    ``motor_torque_Nm`` is the electromagnetic torque Kt i [N m] (load plus internal resistance),
    ``motor_omega_rad_s`` the shaft speed [rad/s]; floats or arrays (:mod:`skidsteer_power.numeric`).
    R is the phase-to-phase terminal resistance, the datasheet's convention (starting current
    67.6 A = 48 V / 0.710 ohm).
    """
    torque = real(motor_torque_Nm)
    current = torque / motor.torque_constant_Nm_A
    power: Real = torque * real(motor_omega_rad_s) + motor.terminal_resistance_ohm * (current * current)
    return power


def bus_power(
    terminal_power_W: Real,
    amplifier: AmplifierConstants = DES_70_10,
    regen_efficiency: float | None = None,
) -> Real:
    """DC bus (battery-side) power of one amplifier [W], 4-quadrant.

    Motoring (terminal power > 0): P_bus = P_term / eta. Generating (< 0): P_bus = P_term * eta_regen,
    with eta_regen = ``regen_efficiency`` (default: the amplifier efficiency; 0 = no regeneration,
    e.g. a 2-quadrant amplifier or a full battery). |P_bus| <= |P_term| when generating, so braking
    never returns more than the motor gives back. A float or an array (:mod:`skidsteer_power.numeric`).
    """
    eta = amplifier.efficiency
    eta_regen = (eta if amplifier.four_quadrant else 0.0) if regen_efficiency is None else regen_efficiency
    if not (0.0 < eta <= 1.0) or not (0.0 <= eta_regen <= 1.0):
        raise ConfigError(f'amplifier efficiencies must be in (0, 1]: {eta}, {eta_regen}')
    p = real(terminal_power_W)
    return by_sign(p, p / eta, p * eta_regen)
