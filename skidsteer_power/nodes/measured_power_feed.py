"""power_estimator's subscriptions to the topics of a vehicle file's ``measured_power:``
(:mod:`skidsteer_power.estimator.measured`): each joint_states message takes, as its effort, the
sides' latest measured V x I [W] (``current_is: battery``) or motor current [A] (``motor``); without a
fresh current (or a declared voltage) it is "no data" (NaN in every field), as with side_currents."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.estimator.measured import MeasuredPowerSource, Signal, side_values

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

    from skidsteer_power.estimator.inputs import InputLimits, JointMap
    from skidsteer_power.nodes.parameters import PowerEstimatorParameters
    from skidsteer_power.nodes.side_current_feed import FeedNode, SideCurrentFeed
    from skidsteer_power.vehicle import Vehicle


class MeasuredPowerFeed:
    """The latest value of every signal of the first ``measured_power`` source whose message packages
    are installed; :meth:`joint_values` rewrites a joint_states reading with the side values."""

    def __init__(self, node: FeedNode, joint_map: JointMap, qos: QoSProfile | int) -> None:
        """``node``: the power_estimator (its subscriptions, logger and ``now_s`` clock [s])."""
        from skidsteer_power.bag_io._ros import message_class
        from skidsteer_power.errors import InputError

        self.map = joint_map
        self.source: MeasuredPowerSource | None = None
        self.latest: dict[Signal, tuple[float, float]] = {}  # signal -> (value, received [s])
        self.messages = 0
        self._now = node.now_s
        missing = []
        for source in joint_map.measured_power:
            try:
                classes = {topic: message_class(msgtype) for topic, msgtype in source.topics().items()}
            except InputError as err:
                missing.append(str(err))
                continue
            self.source = source
            for topic, msg_type in classes.items():
                signals = [s for s in source.signals if s.topic == topic]
                node.create_subscription(msg_type, topic, self._on_message(signals), qos)
            node.get_logger().info(source.describe())
            return
        node.get_logger().warning(
            'the vehicle file declares measured_power, but no message package of its topics is installed '
            f'({"; ".join(missing)}): no measured power'
        )

    def _on_message(self, signals: list[Signal]) -> Callable[[object], None]:
        def callback(msg: object) -> None:
            now = self._now()
            for signal in signals:
                self.latest[signal] = (signal.read(msg), now)
            self.messages += 1

        return callback

    def _value(self, signal: Signal | None, max_age_s: float, now_s: float) -> float | None:
        if signal is None:
            return None
        value, received = self.latest.get(signal, (math.nan, -math.inf))
        return value if now_s - received <= max_age_s else math.nan

    def joint_values(
        self, names: list[str], position: list[float], velocity: list[float], now_s: float
    ) -> tuple[list[str], list[float], list[float], list[float]]:
        """(names, position, velocity, effort) of the mapped joints, the effort from the latest
        measured values; all NaN ("no data") when one is stale or a mapped joint is missing."""
        joints = list(self.map.joints)
        index = {name: i for i, name in enumerate(names)}
        nan = [math.nan] * len(joints)
        if self.source is None or not all(j in index for j in joints):
            return joints, nan, list(nan), list(nan)
        pick = [index[j] for j in joints]
        pos = [position[i] if i < len(position) else math.nan for i in pick]
        vel = [velocity[i] if i < len(velocity) else math.nan for i in pick]
        channels = self.source.channels
        currents = [np.array([self._value(c.current, c.max_age_s, now_s)]) for c in channels]
        voltages: list[np.ndarray | None] = []
        for c in channels:
            v = self._value(c.voltage, c.max_age_s, now_s)
            voltages.append(None if v is None else np.array([v]))
        n_left = len(self.map.left)
        sign = [-1.0 if j in self.map.inverted else 1.0 for j in joints]
        signed = [x * s if math.isfinite(x) else 0.0 for x, s in zip(vel, sign, strict=True)]
        side_speed = np.array([[sum(signed[:n_left]), sum(signed[n_left:])]])
        values = side_values(
            self.source, currents, voltages, side_speed, float(self.map.bus_voltage_V or math.nan)
        )
        if not np.all(np.isfinite(values)):
            return joints, nan, list(nan), list(nan)
        effort = [0.0] * len(joints)
        effort[0], effort[n_left] = float(values[0, 0]) * sign[0], float(values[0, 1]) * sign[n_left]
        return joints, pos, vel, effort


def vehicle_limits(limits: InputLimits, vehicle: Vehicle, p: PowerEstimatorParameters) -> InputLimits:
    """The node's input limits: the vehicle's own motor and driver's
    (:meth:`~skidsteer_power.estimator.inputs.InputLimits.for_powertrain`, issue 35) where the
    ``max_motor_speed_rad_s`` / ``max_motor_torque_Nm`` parameters are left at their defaults (the
    test robot's 1200 rad/s and 5 N m), the parameter where one is set to another value."""
    import dataclasses

    from skidsteer_power.estimator.inputs import InputLimits
    from skidsteer_power.powertrain import Powertrain

    own = InputLimits.for_powertrain(Powertrain.for_vehicle(vehicle))
    defaults = InputLimits()
    changes = {
        name: getattr(own, name)
        for name in ('max_motor_speed_rad_s', 'max_motor_torque_Nm')
        if getattr(p, name) == getattr(defaults, name)
    }
    return dataclasses.replace(limits, max_side_power_W=own.max_side_power_W, **changes)


def vendor_feed(
    node: FeedNode, joint_map: JointMap, qos: QoSProfile | int
) -> MeasuredPowerFeed | SideCurrentFeed | None:
    """The feed of the joint map's vendor topics: measured_power, side_currents, or None."""
    if joint_map.measured_power:
        return MeasuredPowerFeed(node, joint_map, qos)
    if joint_map.side_currents:
        from skidsteer_power.nodes.side_current_feed import SideCurrentFeed

        return SideCurrentFeed(node, joint_map, qos)
    return None
