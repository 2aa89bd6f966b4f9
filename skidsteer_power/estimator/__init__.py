"""Pure on-board estimator core (no ROS import).

From what the robot is told (a forward speed and yaw-rate command) and what its motors report
(shaft speed and Kt * current), predict each side's torque and power with a FESS look-up map,
measure the motor power, and keep track of the battery. The rclpy node
(:mod:`skidsteer_power.nodes.power_estimator`) is a thin shell around :class:`EstimatorCore`.

SI units throughout: m/s, rad/s, N m, W, J, Wh (energy shown to operators), s.
"""

from __future__ import annotations

from skidsteer_power.estimator.core import EstimatorCore, EstimatorSettings
from skidsteer_power.estimator.energy import EnergyTracker
from skidsteer_power.estimator.inputs import Freshness, InputLimits, RejectCounter
from skidsteer_power.estimator.measured import MeasuredPower, measure_motor_power
from skidsteer_power.estimator.persistence import load_state, save_state
from skidsteer_power.estimator.prediction import MapPredictor, Prediction, Predictor

__all__ = [
    'EnergyTracker',
    'EstimatorCore',
    'EstimatorSettings',
    'Freshness',
    'InputLimits',
    'MapPredictor',
    'MeasuredPower',
    'Prediction',
    'Predictor',
    'RejectCounter',
    'load_state',
    'measure_motor_power',
    'save_state',
]
