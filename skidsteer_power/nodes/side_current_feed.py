"""power_estimator's subscription to a vendor topic of per-side motor currents (the drivetrain's
``side_currents``, :mod:`skidsteer_power.estimator.side_currents`): each joint_states message takes
the latest currents as its effort; without fresh ones it is "no data" (NaN in every field)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from skidsteer_power.estimator.side_currents import SideCurrentSource, side_efforts

if TYPE_CHECKING:
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.qos import QoSProfile
    from rclpy.subscription import Subscription

    from skidsteer_power.estimator.inputs import JointMap


class FeedNode(Protocol):
    """What a vendor-topic feed uses of its node (the power_estimator): subscriptions, the logger
    and its ``now_s`` clock [s]."""

    def create_subscription(
        self, msg_type: type, topic: str, callback: Callable[[object], None], qos_profile: QoSProfile | int
    ) -> Subscription: ...
    def get_logger(self) -> RcutilsLogger: ...
    def now_s(self) -> float: ...


class SideCurrentFeed:
    """The latest (left, right) current [A] of the first ``side_currents`` source whose message
    package is installed; :meth:`joint_values` rewrites a joint_states reading with it."""

    def __init__(self, node: FeedNode, joint_map: JointMap, qos: QoSProfile | int) -> None:
        """``node``: the power_estimator (its subscriptions, logger and ``now_s`` clock [s])."""
        from skidsteer_power.bag_io._ros import message_class
        from skidsteer_power.errors import InputError

        self.map = joint_map
        self.source: SideCurrentSource | None = None
        self.currents = (math.nan, math.nan)
        self.received_s = -math.inf
        self.messages = 0
        self._now = node.now_s
        missing = []
        for source in joint_map.side_currents:
            try:
                msg_type = message_class(source.msgtype)
            except InputError as err:
                missing.append(str(err))
                continue
            self.source = source
            node.create_subscription(msg_type, source.topic, self._on_message, qos)
            node.get_logger().info(f'motor currents from {source.topic} ({source.left}, {source.right})')
            return
        node.get_logger().warning(
            'the drivetrain takes motor currents from a vendor topic, but no message package of them is '
            f'installed ({"; ".join(missing)}): no measured power'
        )

    def _on_message(self, msg: object) -> None:
        assert self.source is not None
        self.currents = self.source.read(msg)
        self.received_s = self._now()
        self.messages += 1

    def joint_values(
        self, names: list[str], position: list[float], velocity: list[float], now_s: float
    ) -> tuple[list[str], list[float], list[float], list[float]]:
        """(names, position, velocity, effort) of the mapped joints, the effort from the latest
        currents; all NaN ("no data") when none is fresh or a mapped joint is missing."""
        joints = list(self.map.joints)
        fresh = self.source is not None and now_s - self.received_s <= self.source.max_age_s
        index = {name: i for i, name in enumerate(names)}
        if fresh and all(j in index for j in joints):
            pick = [index[j] for j in joints]
            pos = [position[i] if i < len(position) else math.nan for i in pick]
            vel = [velocity[i] if i < len(velocity) else math.nan for i in pick]
            return joints, pos, vel, side_efforts(self.currents, len(self.map.left), len(joints))
        nan = [math.nan] * len(joints)
        return joints, nan, list(nan), list(nan)
