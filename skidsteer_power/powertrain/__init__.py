"""Powertrain (eqs. 7.1-7.4, EC-45 motor, DES 70/10 amplifier) and battery (ch. 7.1.2).

``Powertrain.from_config(dict)`` / ``Powertrain.default_test_robot()``;
``Battery.from_config(dict)`` / ``Battery.default_test_robot()`` (docs/INTERFACES.md).
"""

from __future__ import annotations

from skidsteer_power.powertrain.battery import Battery, BatteryConfig, BatteryState
from skidsteer_power.powertrain.internal import InternalFit, Resistance, SideResistance, fit_internal
from skidsteer_power.powertrain.motor import DES_70_10, EC45, GEAR_RATIO, AmplifierConstants, MotorConstants
from skidsteer_power.powertrain.power_flow import MotorPoint, Powertrain

__all__ = [
    'DES_70_10',
    'EC45',
    'GEAR_RATIO',
    'AmplifierConstants',
    'Battery',
    'BatteryConfig',
    'BatteryState',
    'InternalFit',
    'MotorConstants',
    'MotorPoint',
    'Powertrain',
    'Resistance',
    'SideResistance',
    'fit_internal',
]
