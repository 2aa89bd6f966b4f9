"""The simple power models a robotics engineer would fit instead of FESS (issue 27), pure numpy.

All three predict the motor terminal (electrical) power of both sides together [W], the quantity
``validate`` measures from joint_states (K_t i and the motor speed through the powertrain's motor
model, :mod:`skidsteer_power.estimator.measured`), sample by sample; energy is the sample-and-hold
sum of power x each sample's hold [s], as ``validate`` integrates it (:func:`energy_J`).

* :class:`LinearPower`: P = a |V| + b |yaw rate| + c, least squares (``numpy.linalg.lstsq``) over the
  training samples, each weighted by its hold time; predicts from the command (V [m/s], yaw rate
  [rad/s]) as the estimator does.
* :class:`CmdVelConsumer`: the ``cmd_vel`` battery consumer of gazebo_ros_battery
  (ctu-vras/gazebo_ros_battery, ``src/cmd_vel_consumer.cpp``, ``CalculatePower``: the sum over the
  six twist components of |component| x ``power_load_rate_*``, at least ``consumer_idle_power``).
  For a planar robot: P = max(k_v |V| + k_w |yaw rate|, P_idle). Fitted as a user would set its
  parameters from a recording: P_idle = mean measured power while the command is zero (0 W if never),
  k_v and k_w by least squares through the origin over the moving samples. From the command.
* :class:`IcrRlsPower`: the closest published on-line estimator, Pentzer, Brennan and Reichard,
  "On-Line Estimation of Vehicle Motion and Power Model Parameters for Skid-Steer Robot Energy Use
  Prediction", ACC 2014 (read: the abstract only; the full text was not available here), with the ICR
  kinematics of Pentzer, Brennan and Reichard, "Model-based Prediction of Skid-steer Robot Kinematics
  Using Online Estimation of Track Instantaneous Centers of Rotation", J. Field Robotics 31(3), 2014
  (read: the abstract). The abstract says: an ICR kinematic model, ICR locations learned on line
  (there by an extended Kalman filter from position and heading), terrain-related power model
  parameters learned on line by recursive least squares, no prior terrain information. Implemented
  here as that documented structure, not the paper's equations: the lateral ICR positions y_l, y_r
  [m] of the two sides by scalar RLS from odometry (V - v_i = y_i yaw rate, v_i the side's sprocket
  surface speed: the definition of a side's ICR), the longitudinal ICR at the centre (x = 0, a
  centred load); power P = th_r (|v_l| + |v_r|) + th_s (S_l + S_r) + th_0 with the per-side sliding
  speed S_i = |yaw rate| x mean over the side's contact points x_j of sqrt((y_i - y_side)^2 + x_j^2)
  (the speed at which the ground slides under each contact point, Morales et al. 2009's friction
  power per unit friction force), th = (rolling resistance, sliding friction, idle) by RLS with
  exponential forgetting. At each sample it predicts from the measured sprocket speeds with the ICRs
  and parameters learned so far (the motion from the ICR model: yaw rate = (v_r - v_l) / (y_l - y_r)),
  then learns from the sample: one sample ahead, as on line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

ICR_MEMORY_S = 60.0  # forgetting time constant of the ICR and power RLS [s] (ASSUMED)
MIN_YAW_FOR_ICR = 0.02  # |yaw rate| [rad/s] below which a sample says nothing about the ICRs
P0_POWER = 1e4  # initial covariance of the power parameters (weak prior) [W^2 / regressor unit^2]
P0_ICR = 1.0  # initial covariance of an ICR position [m^2]


@dataclass(frozen=True)
class Samples:
    """Time-aligned samples of one or more bags (one row per joint_states reading with a command in
    force; see :func:`skidsteer_power.apps.compare.bag_samples`).

    weight_s : hold of each sample [s]; speed_cmd, yaw_cmd : the command in force [m/s, rad/s];
    power_W : measured terminal power of both sides [W]; side_speed : (n, 2) measured sprocket surface
    speeds left, right [m/s]; speed, yaw : measured body motion [m/s, rad/s] (NaN where unknown);
    bag : index of the bag each sample comes from.
    """

    weight_s: np.ndarray
    speed_cmd: np.ndarray
    yaw_cmd: np.ndarray
    power_W: np.ndarray
    side_speed: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    yaw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bag: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


def energy_J(power_W: np.ndarray, weight_s: np.ndarray) -> float:
    """Sample-and-hold energy [J] of powers [W] held ``weight_s`` [s] each."""
    return float(np.sum(power_W * weight_s))


class LinearPower:
    """P = a |V| + b |yaw rate| + c [W]; ``coef`` = (a [W s/m], b [W s/rad], c [W])."""

    name = 'linear |V|, |yaw rate|'

    def __init__(self) -> None:
        self.coef = np.zeros(3)

    @staticmethod
    def regressors(speed: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        return np.column_stack([np.abs(speed), np.abs(yaw), np.ones_like(speed)])

    def fit(self, s: Samples) -> LinearPower:
        """Weighted least squares (weights = hold times) over the training samples."""
        root = np.sqrt(s.weight_s)
        x = self.regressors(s.speed_cmd, s.yaw_cmd) * root[:, None]
        self.coef = np.linalg.lstsq(x, s.power_W * root, rcond=None)[0]
        return self

    def predict(self, s: Samples) -> np.ndarray:
        """Power [W] of every sample, from its command."""
        return self.regressors(s.speed_cmd, s.yaw_cmd) @ self.coef


class CmdVelConsumer:
    """gazebo_ros_battery's cmd_vel consumer: P = max(k_v |V| + k_w |yaw rate|, P_idle) [W]."""

    name = 'gazebo_ros_battery cmd_vel'

    def __init__(self) -> None:
        self.rate_speed = 0.0  # power_load_rate_x [W s/m]
        self.rate_yaw = 0.0  # power_load_rate_yaw [W s/rad]
        self.idle_W = 0.0  # consumer_idle_power [W]

    def fit(self, s: Samples) -> CmdVelConsumer:
        rest = (s.speed_cmd == 0) & (s.yaw_cmd == 0)
        if np.any(rest) and np.sum(s.weight_s[rest]) > 0:
            self.idle_W = max(0.0, float(np.average(s.power_W[rest], weights=s.weight_s[rest])))
        moving = ~rest
        if np.any(moving):
            root = np.sqrt(s.weight_s[moving])
            x = np.column_stack([np.abs(s.speed_cmd[moving]), np.abs(s.yaw_cmd[moving])]) * root[:, None]
            self.rate_speed, self.rate_yaw = np.linalg.lstsq(x, s.power_W[moving] * root, rcond=None)[0]
        return self

    def predict(self, s: Samples) -> np.ndarray:
        load = self.rate_speed * np.abs(s.speed_cmd) + self.rate_yaw * np.abs(s.yaw_cmd)
        power: np.ndarray = np.maximum(load, self.idle_W)
        return power


class IcrRlsPower:
    """On-line ICR kinematic power model with RLS-learned parameters (module doc).

    ``tread_m`` : tread B [m] (the sides' centre lines at y = +-B/2); ``contact_x_m`` : longitudinal
    positions of one side's contact points [m] (a track: points along its contact length; wheels: the
    axles); ``memory_s`` : forgetting time constant [s].
    """

    name = 'ICR + RLS on line (Pentzer 2014)'

    def __init__(self, tread_m: float, contact_x_m: np.ndarray, memory_s: float = ICR_MEMORY_S) -> None:
        self.half_tread = 0.5 * tread_m
        self.contact_x = np.asarray(contact_x_m, dtype=float)
        self.memory_s = memory_s
        self.icr = np.array([self.half_tread, -self.half_tread])  # y_l, y_r [m]: no slip to start
        self.icr_p = np.full(2, P0_ICR)
        self.theta = np.zeros(3)
        self.theta_p = np.eye(3) * P0_POWER

    def regressor(self, v_left: float, v_right: float) -> np.ndarray:
        """(|v_l| + |v_r| [m/s], S_l + S_r [m/s], 1) at side speeds [m/s] with the current ICRs."""
        y_l, y_r = self.icr
        yaw = (v_right - v_left) / (y_l - y_r)
        sliding = 0.0
        for y_icr, y_side in ((y_l, self.half_tread), (y_r, -self.half_tread)):
            sliding += abs(yaw) * float(np.mean(np.hypot(y_icr - y_side, self.contact_x)))
        return np.array([abs(v_left) + abs(v_right), sliding, 1.0])

    def step(
        self, v_left: float, v_right: float, power_W: float, speed: float, yaw: float, dt_s: float
    ) -> float:
        """Predict the power [W] of one sample (side speeds [m/s]) from what was learned so far, then
        learn from its measured power [W] and body motion (V [m/s], yaw rate [rad/s]; NaN: unknown)."""
        phi = self.regressor(v_left, v_right)
        predicted = float(phi @ self.theta)
        lam = math.exp(-max(dt_s, 0.0) / self.memory_s)
        # power parameters: RLS with forgetting factor lam
        p_phi = self.theta_p @ phi
        gain = p_phi / (lam + phi @ p_phi)
        self.theta = self.theta + gain * (power_W - predicted)
        self.theta_p = (self.theta_p - np.outer(gain, p_phi)) / lam
        trace = float(np.trace(self.theta_p))
        if trace > 3 * P0_POWER:  # no wind-up under a constant command: cap at the initial trace
            self.theta_p *= 3 * P0_POWER / trace
        # ICRs: V - v_i = y_i yaw (scalar RLS per side), only while turning
        if math.isfinite(speed) and math.isfinite(yaw) and abs(yaw) >= MIN_YAW_FOR_ICR:
            for i, v_side in enumerate((v_left, v_right)):
                innovation = (speed - v_side) - self.icr[i] * yaw
                g = self.icr_p[i] * yaw / (lam + yaw * self.icr_p[i] * yaw)
                self.icr[i] += g * innovation
                self.icr_p[i] = min((self.icr_p[i] - g * yaw * self.icr_p[i]) / lam, P0_ICR)
            if self.icr[0] - self.icr[1] < 0.1 * self.half_tread:  # keep the model's yaw rate finite
                mid = 0.5 * (self.icr[0] + self.icr[1])
                self.icr = np.array([mid + 0.05 * self.half_tread, mid - 0.05 * self.half_tread])
        return predicted

    def run(self, s: Samples) -> np.ndarray:
        """Step through ``s`` in order; the one-sample-ahead predicted power of every sample [W]."""
        out = np.empty(s.weight_s.size)
        for k in range(out.size):
            out[k] = self.step(
                float(s.side_speed[k, 0]),
                float(s.side_speed[k, 1]),
                float(s.power_W[k]),
                float(s.speed[k]),
                float(s.yaw[k]),
                float(s.weight_s[k]),
            )
        return out

    def fit(self, s: Samples) -> IcrRlsPower:
        """Learn on line over the training samples (the state carries on into :meth:`predict`)."""
        self.run(s)
        return self

    def predict(self, s: Samples) -> np.ndarray:
        """On line over ``s``: predicted before each sample is learned [W]."""
        return self.run(s)
