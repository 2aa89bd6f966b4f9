"""What the parts need of each other where they meet (typing.Protocol): a battery, a power map and a
powertrain. The concrete classes are :class:`skidsteer_power.powertrain.Battery`,
:class:`skidsteer_power.maps.PowerMap` (scalar and array queries) and
:class:`skidsteer_power.powertrain.Powertrain`; anything
with these members fits (a test double, a direct FESS map, another vehicle's drivetrain), and mypy
checks each use against the protocol instead of ``Any``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from skidsteer_power.numeric import Real

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.maps.power_map import MapQuery
    from skidsteer_power.powertrain.battery import BatteryConfig, BatteryState
    from skidsteer_power.powertrain.motor import AmplifierConstants, MotorConstants
    from skidsteer_power.powertrain.power_flow import MotorPoint

__all__ = ['ArrayPowerMapLike', 'BatteryModel', 'PowerMapLike', 'PowertrainLike']


class BatteryModel(Protocol):
    """A battery the estimator steps with battery-side power (ch. 7.1.2; SI units, energy in W h)."""

    @property
    def config(self) -> BatteryConfig: ...

    @property
    def state(self) -> BatteryState: ...

    @property
    def soc(self) -> float: ...

    @property
    def remaining_wh(self) -> float: ...

    def step(self, power_W: float, dt_s: float) -> None: ...

    def time_to_empty_s(self, power_W: float) -> float: ...

    def max_power_W(self) -> float:
        """Largest terminal power [W] it can deliver at any state of charge."""
        ...

    def current_for_power(self, power_W: float, soc: float | None = None) -> float: ...

    def with_state(self, state: BatteryState) -> BatteryModel:
        """The same battery (configuration) in another state (a restart restores the tallies)."""
        ...


class PowerMapLike(Protocol):
    """A steady-state map from a command (V [m/s], yaw rate [rad/s]) to axle torques and speeds."""

    def query(self, speed: float, yaw_rate: float, /) -> MapQuery: ...


class ArrayPowerMapLike(Protocol):
    """A power map asked about many commands at once (arrays of V [m/s] and yaw rate [rad/s],
    broadcast): a mission's or a planned path's segments."""

    def query(self, speed: ArrayLike, yaw_rate: ArrayLike, /) -> MapQuery: ...


class PowertrainLike(Protocol):
    """A skid-steer powertrain: reduction, motor, amplifier and the per-side power flow (eqs. 7.1-7.4),
    forward (:meth:`motor_side`) and back from a measured battery-side power (V x I readings)."""

    @property
    def gear_ratio(self) -> float: ...

    @property
    def motor(self) -> MotorConstants: ...

    @property
    def amplifier(self) -> AmplifierConstants: ...

    @property
    def regen_efficiency(self) -> float | None: ...

    def motor_side(self, side: str, axle_torque_Nm: Real, axle_omega_rad_s: Real) -> MotorPoint[Real]: ...

    def terminal_from_bus(self, bus_W: Real) -> Real:
        """Motor terminal power [W] of one side's measured battery-side power [W]."""
        ...

    def torque_from_terminal(self, terminal_W: Real, motor_omega_rad_s: Real) -> Real:
        """Motor torque [N m] whose terminal power is ``terminal_W`` [W] at motor speed [rad/s]."""
        ...


if TYPE_CHECKING:
    from skidsteer_power.maps.power_map import PowerMap
    from skidsteer_power.powertrain.battery import Battery
    from skidsteer_power.powertrain.power_flow import Powertrain

    def _concrete_classes_fit(
        battery: Battery, power_map: PowerMap, powertrain: Powertrain
    ) -> tuple[BatteryModel, PowerMapLike, ArrayPowerMapLike, PowertrainLike]:
        """Never called: mypy (``make lint``) checks here that the package's classes fit."""
        return battery, power_map, power_map, powertrain
