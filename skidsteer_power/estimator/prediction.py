"""Predicted per-side torque and power for a (V, yaw rate) command, from a FESS look-up map.

A :class:`Predictor` turns a command into a :class:`Prediction`. :class:`MapPredictor` is the real
one: the map (chapter 5/6, built with the FESS model) gives each side's axle speed, the torque the
terrain needs and the traction margin; the powertrain adds the internal resistance (eqs. 7.1-7.4),
the 12:1 reduction, the EC-45 winding loss and the DES 70/10 amplifier.

Reverse driving (V < 0) and spinning in place (V = 0, r != 0) are answered by the map
(:mod:`skidsteer_power.maps.power_map`, whose module docstring gives the reasoning):

* reverse at (-V, r) is the forward solution at (V, r) seen from a frame turned 180 degrees about the
  vertical: left and right swap, each side's speed and torque change sign, power and traction margin
  do not (valid for a CG midway along the contact, which all vehicles here have, 7.1.1);
* turns tighter than the map's small-radius limit (twice the tread), spinning in place included, take
  the turning resistance of the tightest reliable turn at the same yaw rate (section 3.4: the soil
  fails and the shear force saturates), with each side's speed following its own ground speed; both
  sides then run in opposite directions, their torques opposite but not equal in size;
* at rest (V = r = 0) every torque is zero, so the prediction is the powertrain at standstill.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache, partial
from typing import TYPE_CHECKING, Protocol

import numpy as np

from skidsteer_power.seams import PowerMapLike, PowertrainLike

if TYPE_CHECKING:
    from skidsteer_power.maps.power_map import MapQuery
    from skidsteer_power.maps.setpoint_map import SetpointMap
    from skidsteer_power.powertrain.power_flow import MotorPoint

Pair = tuple[float, float]


@dataclass(frozen=True)
class Prediction:
    """Predicted steady state for one command, per side (left, right), SI units.

    speed_m_s, yaw_rate_rad_s : the command [m/s], [rad/s]
    axle_omega_rad_s : axle (sprocket / wheel) speed [rad/s]
    terrain_torque_Nm : axle torque the terrain needs [N m]
    terrain_W : terrain (running-gear / soil) power, torque x axle speed [W]
    internal_W : powertrain internal-resistance power, eqs. 7.1-7.4 [W]
    motor_omega_rad_s, motor_torque_Nm : at the motor shaft (comparable with joint_states) [rad/s], [N m]
    current_A : motor current [A]
    electrical_W : motor terminal power with winding loss [W]
    bus_W : battery-side power through the amplifier [W]
    traction_margin : 1 - required / available thrust (<= 0: about to get stuck) [-]
    clamped : the command lay outside the map's command envelope and was answered at its edge
    limited : a physics limit (a turn tighter than the map's small-radius limit, or no steady state)
    achieved_speed_m_s, achieved_yaw_rate_rad_s : the motion the model expects [m/s], [rad/s]: at the
        command's wheel speed set points (:class:`SetpointPredictor`), or the command itself when the
        command is taken as the motion (:class:`MapPredictor`, ``kinematics='twist'``)
    """

    speed_m_s: float
    yaw_rate_rad_s: float
    axle_omega_rad_s: Pair
    terrain_torque_Nm: Pair
    terrain_W: Pair
    internal_W: Pair
    motor_omega_rad_s: Pair
    motor_torque_Nm: Pair
    current_A: Pair
    electrical_W: Pair
    bus_W: Pair
    traction_margin: float
    clamped: bool
    limited: bool = False
    achieved_speed_m_s: float = math.nan
    achieved_yaw_rate_rad_s: float = math.nan

    @property
    def bus_total_W(self) -> float:
        """Battery power of both sides [W]."""
        return self.bus_W[0] + self.bus_W[1]

    @property
    def terrain_total_W(self) -> float:
        return self.terrain_W[0] + self.terrain_W[1]

    @property
    def internal_total_W(self) -> float:
        return self.internal_W[0] + self.internal_W[1]

    @property
    def terrain_share(self) -> float:
        """Terrain share of the mechanical power at the axles [-] (nan when both are zero)."""
        total = self.terrain_total_W + self.internal_total_W
        return self.terrain_total_W / total if abs(total) > 1e-12 else float('nan')


class Predictor(Protocol):
    """Anything that predicts a :class:`Prediction` for a command (V [m/s], yaw rate [rad/s])."""

    description: str

    def predict(self, speed_m_s: float, yaw_rate_rad_s: float) -> Prediction: ...


def _scalar(value: float | np.ndarray) -> float:
    """A Python float from a number, a 0-d array or the first element of a 1-d one (per message:
    the plain ``float`` path first, as most values here are floats or 0-d arrays)."""
    if isinstance(value, np.ndarray) and value.ndim:
        return float(value.reshape(-1)[0])
    return float(value)


def _pair(left: float | np.ndarray, right: float | np.ndarray) -> Pair:
    return _scalar(left), _scalar(right)


class MapPredictor:
    """Prediction from a :class:`skidsteer_power.maps.PowerMap` and a powertrain.

    ``powertrain`` is a :class:`skidsteer_power.powertrain.Powertrain`, whose ``motor_side`` adds the
    internal resistance, reduction, motor and amplifier to the map's axle torque and speed.
    Repeated commands (teleoperation repeats the last one) are answered from a small cache.
    ``path_scale``: how the drive controller slows a planned path's twists (V [m/s], w_z [rad/s]) ->
    factor in (0, 1] (:meth:`~skidsteer_power.drive.DriveController.path_scale` at the wheel speed
    ceiling; path energy, :mod:`skidsteer_power.estimator.path_energy`); None: paths driven as asked.
    """

    def __init__(
        self,
        power_map: PowerMapLike,
        powertrain: PowertrainLike,
        *,
        description: str = '',
        cache_size: int = 256,
        path_scale: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.power_map = power_map
        self.powertrain = powertrain
        self.path_scale = path_scale
        self.description = description or 'power map'
        self.predict = lru_cache(maxsize=cache_size)(self._predict)

    def _predict(self, speed_m_s: float, yaw_rate_rad_s: float) -> Prediction:
        q = self.power_map.query(speed_m_s, yaw_rate_rad_s)
        omega = _pair(q.omega_left_rad_s, q.omega_right_rad_s)
        torque = _pair(q.torque_left_Nm, q.torque_right_Nm)
        return self._with_powertrain(speed_m_s, yaw_rate_rad_s, omega, torque, q)

    def _with_powertrain(
        self, speed: float, yaw_rate: float, omega: Pair, torque: Pair, q: MapQuery
    ) -> Prediction:
        # floats, one side at a time: ~20x faster than numpy on two values (skidsteer_power.numeric)
        left = self.powertrain.motor_side('left', torque[0], omega[0])
        right = self.powertrain.motor_side('right', torque[1], omega[1])
        flags = (_scalar(q.traction_margin), bool(_scalar(q.clamped)), bool(_scalar(q.limited)))
        return _prediction(speed, yaw_rate, omega, torque, (left, right), flags, (speed, yaw_rate))


class SetpointPredictor:
    """Prediction at the command's wheel speed set points, from a
    :class:`skidsteer_power.maps.setpoint_map.SetpointMap` (issue 25; DESIGN.md: a command is a pair
    of set points, the terrain decides the motion). Each side turns at its set point with the torque
    FESS finds for the motion those set points produce (current limit applied); the achieved motion
    is in ``achieved_speed_m_s`` / ``achieved_yaw_rate_rad_s``. Repeated commands come from a cache.

    ``power_map`` is the (V, yaw rate) map of the same vehicle and terrain, for what starts from a
    motion rather than a command (path energy: a route's (V, R) is the achieved motion, and its
    side speeds are the set points that produce it). ``motion_map`` loads it on first use.
    """

    def __init__(
        self,
        setpoint_map: SetpointMap,
        powertrain: PowertrainLike,
        *,
        description: str = '',
        cache_size: int = 256,
        motion_map: Callable[[], PowerMapLike] | None = None,
    ) -> None:
        self.setpoint_map = setpoint_map
        self.powertrain = powertrain
        command = setpoint_map.predictor  # its drive controller and wheel speed ceiling
        self.path_scale = partial(command.controller.path_scale, ceiling_rad_s=command.max_axle_rad_s)
        """How this predictor's drive controller slows a planned path (:class:`MapPredictor`)."""
        self.description = description or 'set-point map'
        self.predict = lru_cache(maxsize=cache_size)(self._predict)
        self._motion_map = motion_map
        self._power_map: PowerMapLike | None = None

    @property
    def power_map(self) -> PowerMapLike | None:
        """The (V, yaw rate) power map (loaded or built on first use), or None if none was given."""
        if self._power_map is None and self._motion_map is not None:
            self._power_map = self._motion_map()
        return self._power_map

    def _predict(self, speed_m_s: float, yaw_rate_rad_s: float) -> Prediction:
        q = self.setpoint_map.query(speed_m_s, yaw_rate_rad_s)
        omega = (q.setpoint_left_rad_s, q.setpoint_right_rad_s)
        torque = (q.torque_left_Nm, q.torque_right_Nm)
        left, right = q.motors  # the map's powertrain is this one (factory.map_predictor)
        if left is None or right is None:
            left = self.powertrain.motor_side('left', torque[0], omega[0])
            right = self.powertrain.motor_side('right', torque[1], omega[1])
        flags = (q.traction_margin, q.clamped, q.limited)
        achieved = (q.speed_m_s, q.yaw_rate_rad_s)
        return _prediction(speed_m_s, yaw_rate_rad_s, omega, torque, (left, right), flags, achieved)


def _prediction(
    speed: float,
    yaw_rate: float,
    omega: Pair,
    torque: Pair,
    sides: tuple[MotorPoint[float], MotorPoint[float]],
    flags: tuple[float, bool, bool],
    achieved: Pair,
) -> Prediction:
    """A :class:`Prediction` from the command, the axle speeds [rad/s] and torques [N m], the two
    sides' motor operating points, (traction margin, clamped, limited) and the achieved (V [m/s],
    yaw rate [rad/s]): one assembly for the (V, yaw rate) map and the set-point map."""
    left, right = sides
    return Prediction(
        speed_m_s=speed,
        yaw_rate_rad_s=yaw_rate,
        axle_omega_rad_s=omega,
        terrain_torque_Nm=torque,
        terrain_W=(left.terrain_power_W, right.terrain_power_W),
        internal_W=(left.internal_power_W, right.internal_power_W),
        motor_omega_rad_s=(left.motor_omega_rad_s, right.motor_omega_rad_s),
        motor_torque_Nm=(left.motor_torque_Nm, right.motor_torque_Nm),
        current_A=(left.current_A, right.current_A),
        electrical_W=(left.terminal_power_W, right.terminal_power_W),
        bus_W=(left.electrical_power_W, right.electrical_power_W),
        traction_margin=flags[0],
        clamped=flags[1],
        limited=flags[2],
        achieved_speed_m_s=achieved[0],
        achieved_yaw_rate_rad_s=achieved[1],
    )
