"""One skid-steer powertrain: per side, internal resistance (eqs. 7.1-7.4), reduction, motor, amplifier.

Power flow of one side, from the terrain to the battery (SI units)::

    axle torque T_a, speed w_a          (the skid-steer model: terrain load at the sprocket / axle)
    motor speed   w_m = G w_a
    motor torque  T_m = T_a / G + T_int(w_m)      (eqs. 7.1-7.4, internal resistance at the motor shaft)
    current       i   = T_m / K_t
    terminal      P_t = T_m w_m + R i^2           (copper loss)
    bus (battery) P_b = P_t / eta  or  P_t eta_regen when generating (4-quadrant DES 70/10)

The dissertation's "power consumption" (ch. 7.2, 8) is the mechanical part T_m w_m, which splits
exactly into terrain power T_a w_a and internal power T_int w_m; copper and amplifier losses come on
top and are reported separately.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic

import numpy as np

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.numeric import Real, real
from skidsteer_power.powertrain.config import merged
from skidsteer_power.powertrain.internal import SideResistance, side_from_config
from skidsteer_power.powertrain.motor import (
    AMPLIFIERS,
    DES_70_10,
    GEAR_RATIO,
    MOTORS,
    AmplifierConstants,
    MotorConstants,
    amplifier_from_config,
    bus_power,
    motor_current,
    motor_from_config,
    terminal_power,
)

if TYPE_CHECKING:
    from skidsteer_power.vehicle import Vehicle

__all__ = ['AMPLIFIERS', 'MOTORS', 'SIDES', 'MotorPoint', 'Powertrain']
SIDES = ('left', 'right')


@dataclass(frozen=True)
class MotorPoint(Generic[Real]):
    """Operating point of one side's motor and amplifier: floats for float inputs, arrays broadcast
    over array inputs (:mod:`skidsteer_power.numeric`).

    Attributes
    ----------
    motor_torque_Nm : electromagnetic torque K_t i [N m]
    motor_omega_rad_s : motor shaft speed [rad/s]
    current_A : motor current [A]
    electrical_power_W : power drawn from the DC bus / battery [W] (negative = regenerating)
    internal_power_W : power lost to the drivetrain's internal resistance [W] (eq. 7.2, >= 0)
    terrain_power_W : mechanical power delivered at the axle, T_a w_a [W]
    mechanical_power_W : T_m w_m = terrain + internal [W] (the dissertation's power consumption)
    terminal_power_W : electrical power at the motor terminals [W]
    """

    motor_torque_Nm: Real
    motor_omega_rad_s: Real
    current_A: Real
    electrical_power_W: Real
    internal_power_W: Real
    terrain_power_W: Real
    mechanical_power_W: Real
    terminal_power_W: Real


@dataclass(frozen=True)
class Powertrain:
    """Left and right drivetrains sharing motor type, reduction and amplifier type.

    Attributes
    ----------
    name : preset name
    running_gear : 'track' | 'wheel' (wheels have no track component, ch. 7.2.3)
    motor, amplifier : datasheet constants
    gear_ratio : motor speed / axle speed [-]
    left, right : internal resistance of each side at the motor shaft
    regen_efficiency : bus power / terminal power when generating [-] (None = amplifier efficiency)
    current_limit_A : largest motor current the amplifier delivers [A] (the DES 70/10's current
        limit, 10 A = its continuous current, Appendix A; the preset's ``current_limit_A``)
    battery : battery preset name or mapping (for :meth:`Battery.from_config`), may be None
    source : provenance of the numbers
    """

    name: str
    running_gear: str
    motor: MotorConstants
    amplifier: AmplifierConstants
    gear_ratio: float
    left: SideResistance
    right: SideResistance
    regen_efficiency: float | None = None
    battery: str | Mapping[str, Any] | None = None
    source: str = ''
    current_limit_A: float = DES_70_10.continuous_current_A

    @classmethod
    def from_config(cls, config: Mapping[str, Any] | None, running_gear: str = 'track') -> Powertrain:
        """Build from a config mapping (a vehicle's ``powertrain:`` section), ``preset`` expanded.

        An empty mapping means the test robot. Raises ConfigError for unknown or bad values.
        """
        cfg = merged('powertrains', config or {'preset': 'test_robot'})
        motor = motor_from_config(cfg.get('motor'))
        amplifier = amplifier_from_config(cfg.get('amplifier'))
        gear_ratio = _positive(cfg.get('gear_ratio', GEAR_RATIO), 'gear_ratio')
        internal = cfg.get('internal_resistance')
        if not isinstance(internal, Mapping) or not all(isinstance(internal.get(s), Mapping) for s in SIDES):
            raise ConfigError('powertrain: internal_resistance needs left and right sections')
        regen = cfg.get('regen_efficiency')
        if regen is not None and not (0.0 <= float(regen) <= 1.0):
            raise ConfigError(f'powertrain: regen_efficiency must be in [0, 1], not {regen}')
        kt = motor.torque_constant_Nm_A
        return cls(
            name=str(cfg.get('name', 'custom')),
            running_gear=running_gear,
            motor=motor,
            amplifier=amplifier,
            gear_ratio=gear_ratio,
            left=side_from_config(internal['left'], kt, running_gear),
            right=side_from_config(internal['right'], kt, running_gear),
            regen_efficiency=None if regen is None else float(regen),
            battery=cfg.get('battery'),
            source=str(cfg.get('source', '')),
            current_limit_A=_positive(
                cfg.get('current_limit_A', amplifier.continuous_current_A), 'current_limit_A'
            ),
        )

    @classmethod
    def default_test_robot(cls, running_gear: str = 'track') -> Powertrain:
        """The chapter 7 test robot's powertrain (config/powertrains/test_robot.yaml)."""
        return cls.from_config({'preset': 'test_robot'}, running_gear)

    @classmethod
    def for_vehicle(cls, vehicle: Vehicle) -> Powertrain:
        """The powertrain of a :class:`~skidsteer_power.vehicle.Vehicle` (its ``powertrain:`` section)."""
        return cls.from_config(getattr(vehicle, 'powertrain', None) or None, vehicle.running_gear)

    def resistance(self, side: str) -> SideResistance:
        if side not in SIDES:
            raise InputError(f"side must be 'left' or 'right', not {side!r}")
        return self.left if side == 'left' else self.right

    def internal_torque(self, side: str, axle_omega: Real) -> Real:
        """Internal resistance referred to the axle [N m] at axle speed [rad/s]: G T_int(G w_a)."""
        omega_m = self.gear_ratio * real(axle_omega)
        return self.gear_ratio * self.resistance(side).torque(omega_m)

    def motor_side(self, side: str, axle_torque_Nm: Real, axle_omega_rad_s: Real) -> MotorPoint[Real]:
        """Motor and amplifier operating point of one side for axle torque [N m] and speed [rad/s]:
        floats (one command, the estimator's per-message path) or arrays (broadcast).

        All four quadrants: a negative torque * speed (braking) makes the motor generate and the
        bus power negative, never larger in magnitude than the braking power the axle delivers.
        """
        torque_a, omega_a = real(axle_torque_Nm), real(axle_omega_rad_s)
        omega_m = self.gear_ratio * omega_a
        internal_m = self.resistance(side).torque(omega_m)  # eq. 7.1, at the motor shaft
        torque_m = torque_a / self.gear_ratio + internal_m
        p_terminal = terminal_power(self.motor, torque_m, omega_m)
        return MotorPoint(
            motor_torque_Nm=torque_m,
            motor_omega_rad_s=omega_m,
            current_A=motor_current(self.motor, torque_m),
            electrical_power_W=bus_power(p_terminal, self.amplifier, self.regen_efficiency),
            internal_power_W=internal_m * omega_m,
            terrain_power_W=torque_a * omega_a,
            mechanical_power_W=torque_m * omega_m,
            terminal_power_W=p_terminal,
        )

    def axle_from_motor(self, side: str, motor_torque_Nm: Real, motor_omega_rad_s: Real) -> tuple[Real, Real]:
        """Invert :meth:`motor_side`: axle torque [N m] and speed [rad/s] from measured K_t i and w_m."""
        omega_m, torque_m = real(motor_omega_rad_s), real(motor_torque_Nm)
        torque_a = self.gear_ratio * (torque_m - self.resistance(side).torque(omega_m))
        return torque_a, omega_m / self.gear_ratio


def _positive(value: Any, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'powertrain: {name} must be a number, not {value!r}') from None
    if not np.isfinite(number) or number <= 0:
        raise ConfigError(f'powertrain: {name} must be > 0, not {value!r}')
    return number
