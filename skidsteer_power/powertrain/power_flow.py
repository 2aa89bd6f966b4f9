"""One skid-steer powertrain: per side, internal resistance (eqs. 7.1-7.4), reduction, motor, amplifier.

Power flow of one side, from the terrain to the battery (SI units)::

    axle torque T_a, speed w_a          (the skid-steer model: terrain load at the sprocket / axle)
    motor speed   w_m = G w_a
    motor torque  T_m = T_a / G + T_int(w_m)      (eqs. 7.1-7.4, internal resistance at the motor shaft)
    current       i   = T_m / K_t
    terminal      P_t = T_m w_m + R i^2           (copper loss)
    amplifier     P_a = P_t / eta  or  P_t eta_regen when generating (4-quadrant DES 70/10)
    bus (battery) P_b = P_a + P_idle / 2          (the drive electronics' idle power, half per side)

The dissertation's "power consumption" (ch. 7.2, 8) is the mechanical part T_m w_m, which splits
exactly into terrain power T_a w_a and internal power T_int w_m; copper, amplifier and idle losses
come on top, each a named output of :class:`MotorPoint`, and the parts add up exactly:

    P_b = terrain + internal + copper + amplifier + idle                           [W]

An **effective** powertrain (``preset: effective``, config/powertrains/effective.yaml) is for a robot
whose motor nobody knows: the axle is the motor (gear ratio 1, K_t 1 N m/A), and the terms measured
battery power determines start neutral (no viscous/Coulomb loss, copper-loss coefficient
``copper_loss_W_per_Nm2`` 0, amplifier efficiency 1, ``idle_power_W`` 0) for calibration to fit
(docs/POWERTRAINS.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Generic

import numpy as np

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.numeric import Real, by_sign, real
from skidsteer_power.powertrain.config import merged, to_float
from skidsteer_power.powertrain.internal import SideResistance, side_from_config
from skidsteer_power.powertrain.motor import (
    AMPLIFIERS,
    DES_70_10,
    EFFECTIVE_MOTOR,
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
GENERIC_CELL_V = 3.7
"""Nominal voltage of a generic Li-ion cell [V] (config/batteries/generic_li_ion.yaml)."""


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
    copper_loss_W : winding loss R i^2 [W] (terminal - mechanical)
    amplifier_loss_W : amplifier loss [W] (bus - terminal - idle; >= 0 when regenerating too)
    idle_power_W : this side's half of the drive electronics' idle power [W]

    ``electrical_power_W`` = terrain + internal + copper + amplifier + idle, exactly.
    """

    motor_torque_Nm: Real
    motor_omega_rad_s: Real
    current_A: Real
    electrical_power_W: Real
    internal_power_W: Real
    terrain_power_W: Real
    mechanical_power_W: Real
    terminal_power_W: Real
    copper_loss_W: Real
    amplifier_loss_W: Real
    idle_power_W: Real


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
        limit, 10 A = its continuous current, Appendix A; the preset's ``current_limit_A``; inf: none)
    battery : battery preset name or mapping (for :meth:`Battery.from_config`), may be None
    source : provenance of the numbers
    bus_voltage_V : nominal DC bus (battery) voltage [V] (the preset's ``bus_voltage_V``; None: the
        battery's open-circuit voltage at half charge); what V x I uses when no voltage is measured
    idle_power_W : battery power the drive electronics draw at standstill, both sides [W]
    preset : the preset the file named ('effective': the motor is unknown, :meth:`is_effective`)
    """

    name: str
    running_gear: str
    motor: MotorConstants
    amplifier: AmplifierConstants
    gear_ratio: float
    left: SideResistance
    right: SideResistance
    regen_efficiency: float | None = None
    battery: str | Mapping[str, object] | None = None
    source: str = ''
    current_limit_A: float = DES_70_10.continuous_current_A
    bus_voltage_V: float | None = None
    idle_power_W: float = 0.0
    preset: str = ''

    @property
    def is_effective(self) -> bool:
        """True for an effective powertrain (motor unknown: its loss and idle terms are calibrated)."""
        return self.motor.name == EFFECTIVE_MOTOR.name

    @property
    def copper_loss_W_per_Nm2(self) -> float:
        """Copper-loss coefficient k_cu = R / K_t^2 [W / (N m)^2]: copper loss = k_cu T_m^2."""
        return self.motor.terminal_resistance_ohm / self.motor.torque_constant_Nm_A**2

    def nominal_bus_voltage_V(self) -> float:
        """The bus voltage [V] V x I uses when no voltage is measured: ``bus_voltage_V``, else the
        battery's open-circuit voltage at half charge, else the motor's nominal voltage."""
        if self.bus_voltage_V is not None:
            return self.bus_voltage_V
        from skidsteer_power.powertrain.battery import Battery

        try:
            return float(Battery.from_config(self.battery).config.ocv(0.5))
        except (ConfigError, InputError, OSError):
            return self.motor.nominal_voltage_V

    @classmethod
    def from_config(cls, config: Mapping[str, object] | None, running_gear: str = 'track') -> Powertrain:
        """Build from a config mapping (a vehicle's ``powertrain:`` section), ``preset`` expanded.

        An empty mapping means the test robot. Raises ConfigError for unknown or bad values.
        """
        preset = str((config or {}).get('preset', 'test_robot' if not config else ''))
        cfg = merged('powertrains', config or {'preset': 'test_robot'})
        _check_keys(cfg)
        motor = motor_from_config(cfg.get('motor'))
        if cfg.get('copper_loss_W_per_Nm2') is not None:  # k_cu = R / K_t^2 replaces the motor's R
            k_cu = _nonnegative(cfg['copper_loss_W_per_Nm2'], 'copper_loss_W_per_Nm2')
            motor = replace(motor, terminal_resistance_ohm=k_cu * motor.torque_constant_Nm_A**2)
        amplifier = amplifier_from_config(cfg.get('amplifier'))
        gear_ratio = _positive(cfg.get('gear_ratio', GEAR_RATIO), 'gear_ratio')
        internal = cfg.get('internal_resistance')
        if not isinstance(internal, Mapping) or not all(isinstance(internal.get(s), Mapping) for s in SIDES):
            raise ConfigError('powertrain: internal_resistance needs left and right sections')
        regen = cfg.get('regen_efficiency')
        if regen is not None and not (0.0 <= float(regen) <= 1.0):
            raise ConfigError(f'powertrain: regen_efficiency must be in [0, 1], not {regen}')
        kt = motor.torque_constant_Nm_A
        bus = None if cfg.get('bus_voltage_V') is None else _positive(cfg['bus_voltage_V'], 'bus_voltage_V')
        battery = cfg.get('battery')
        if battery is None and motor.name == EFFECTIVE_MOTOR.name:  # no battery named: a generic pack
            cells = max(1, round((bus or 24.0) / GENERIC_CELL_V))
            battery = {'preset': 'generic_li_ion', 'cells_in_series_per_pack': cells}
        return cls(
            name=str(cfg.get('name', 'custom')),
            running_gear=running_gear,
            motor=motor,
            amplifier=amplifier,
            gear_ratio=gear_ratio,
            left=side_from_config(internal['left'], kt, running_gear),
            right=side_from_config(internal['right'], kt, running_gear),
            regen_efficiency=None if regen is None else float(regen),
            battery=battery,
            source=str(cfg.get('source', '')),
            current_limit_A=_limit(cfg.get('current_limit_A', amplifier.continuous_current_A)),
            bus_voltage_V=bus,
            idle_power_W=_nonnegative(cfg.get('idle_power_W', 0.0), 'idle_power_W'),
            preset=preset,
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
        mechanical = torque_m * omega_m
        p_amplifier = bus_power(p_terminal, self.amplifier, self.regen_efficiency)
        idle = 0.5 * self.idle_power_W
        return MotorPoint(
            motor_torque_Nm=torque_m,
            motor_omega_rad_s=omega_m,
            current_A=motor_current(self.motor, torque_m),
            electrical_power_W=p_amplifier + idle,
            internal_power_W=internal_m * omega_m,
            terrain_power_W=torque_a * omega_a,
            mechanical_power_W=mechanical,
            terminal_power_W=p_terminal,
            copper_loss_W=p_terminal - mechanical,
            amplifier_loss_W=p_amplifier - p_terminal,
            idle_power_W=idle + 0.0 * omega_m,  # broadcast like the others
        )

    def terminal_from_bus(self, bus_W: Real) -> Real:
        """Invert the amplifier and idle terms of :meth:`motor_side` for one side: the motor terminal
        power [W] of a measured battery-side power ``bus_W`` [W] (float or array)."""
        amp = real(bus_W) - 0.5 * self.idle_power_W
        eta = self.amplifier.efficiency
        eta_regen = (
            (eta if self.amplifier.four_quadrant else 0.0)
            if self.regen_efficiency is None
            else self.regen_efficiency
        )
        regen = amp / eta_regen if eta_regen > 0 else 0.0 * amp
        return by_sign(amp, amp * eta, regen)

    def torque_from_terminal(self, terminal_W: Real, motor_omega_rad_s: Real) -> Real:
        """The motor torque T_m [N m] whose terminal power T_m w_m + k_cu T_m^2 is ``terminal_W`` [W] at
        motor speed [rad/s]: the root with T_m w_m >= 0 while motoring (2P / (w + sign(w) sqrt(w^2 +
        4 k P)), free of cancellation). Below the smallest power the quadratic reaches (generating
        more than the copper loss allows) the discriminant is taken as 0; at standstill without
        copper loss there is no torque to tell (0)."""
        p, w = np.asarray(terminal_W, dtype=float), np.asarray(motor_omega_rad_s, dtype=float)
        k = self.copper_loss_W_per_Nm2
        s = np.where(w >= 0.0, 1.0, -1.0)
        root = np.sqrt(np.maximum(w * w + 4.0 * k * p, 0.0))
        denominator = w + s * root
        with np.errstate(divide='ignore', invalid='ignore'):
            torque = np.where(np.abs(denominator) > 1e-12, 2.0 * p / denominator, 0.0)
        out: Real = torque if torque.ndim else float(torque)  # type: ignore[assignment]
        return out

    def axle_from_motor(self, side: str, motor_torque_Nm: Real, motor_omega_rad_s: Real) -> tuple[Real, Real]:
        """Invert :meth:`motor_side`: axle torque [N m] and speed [rad/s] from measured K_t i and w_m."""
        omega_m, torque_m = real(motor_omega_rad_s), real(motor_torque_Nm)
        torque_a = self.gear_ratio * (torque_m - self.resistance(side).torque(omega_m))
        return torque_a, omega_m / self.gear_ratio


KEYS = (
    'name', 'source', 'motor', 'amplifier', 'gear_ratio', 'current_limit_A', 'regen_efficiency',
    'internal_resistance', 'battery', 'bus_voltage_V', 'idle_power_W', 'copper_loss_W_per_Nm2',
    'sources', 'preset', 'calibration',
)  # fmt: skip
"""The keys of a powertrain file (docs/POWERTRAINS.md); ``sources`` maps a key to where its number
comes from (datasheet, manual, or ASSUMED); ``calibration`` is the record ``skidsteer-power calibrate``
writes (skidsteer_power/calibration/io.py), not read here."""


def _check_keys(cfg: Mapping[str, object]) -> None:
    unknown = sorted(set(cfg) - set(KEYS))
    if unknown:
        raise ConfigError(f'powertrain: unknown key(s) {", ".join(unknown)}; known: {", ".join(KEYS)}')


def _limit(value: object) -> float:
    """A current limit [A]: a number > 0, or null / inf for none."""
    if value is None:
        return float('inf')
    number = _nonnegative(value, 'current_limit_A')
    if number == 0:
        raise ConfigError('powertrain: current_limit_A must be > 0 (null: no limit)')
    return number


def _number(value: object, name: str) -> float:
    try:
        return to_float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'powertrain: {name} must be a number, not {value!r}') from None


def _nonnegative(value: object, name: str) -> float:
    number = _number(value, name)
    if np.isnan(number) or number < 0 or (np.isinf(number) and name != 'current_limit_A'):
        raise ConfigError(f'powertrain: {name} must be a finite number >= 0, not {value!r}')
    return number


def _positive(value: object, name: str) -> float:
    number = _number(value, name)
    if not np.isfinite(number) or number <= 0:
        raise ConfigError(f'powertrain: {name} must be > 0, not {value!r}')
    return number
