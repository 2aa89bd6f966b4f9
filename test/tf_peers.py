"""The other processes of test_tf_replay.py, each with the genuine tf2_msgs/msg/TFMessage class:

- ``publish N``: a robot's tf, with tf2_ros' conventions (TransformBroadcaster: /tf, reliable,
  volatile, depth 100; StaticTransformBroadcaster: /tf_static, reliable, transient-local, depth 1):
  the static transforms once at start, then, once something subscribes to both topics, N /tf messages.
- ``listen N``: a late-joining tf listener (tf2_ros' TransformListener QoS: /tf reliable volatile
  depth 100, /tf_static reliable transient-local depth 100) that subscribes to /tf_static only after
  its 5th /tf message, so it receives the static transforms only if their publisher keeps them for
  late joiners. Prints one JSON line: the messages received, as :func:`as_dicts`, and what the graph
  says of the publishers (type name, RIHS01 type hash, durability).

Run as ``python test/tf_peers.py publish N`` or ``python test/tf_peers.py listen N [STATIC]``
(STATIC: /tf_static messages to wait for, 1 by default).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
STATIC_PUB_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
STATIC_SUB_QOS = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
LATE_AFTER = 5  # /tf messages the listener receives before it subscribes to /tf_static
START_SEC = 1_700_000_000  # stamp of the first /tf message [s]
PERIOD_NS = 50_000_000  # between /tf messages [ns] (20 Hz)
TIMEOUT_S = 60.0  # bound on every wait here (not a timing goal) [s]


def _transform(
    parent: str, child: str, sec: int, nanosec: int, xyz: tuple[float, float, float], yaw: float
) -> TransformStamped:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = xyz
    t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)  # about z
    return t


def static_message() -> TFMessage:
    """base_link -> laser (0.2 m ahead, 0.15 m up) and base_link -> imu_link (yawed 90 deg)."""
    return TFMessage(
        transforms=[
            _transform('base_link', 'laser', START_SEC, 0, (0.2, 0.0, 0.15), 0.0),
            _transform('base_link', 'imu_link', START_SEC, 0, (-0.05, 0.01, 0.1), math.pi / 2),
        ]
    )


def tf_message(k: int) -> TFMessage:
    """The k-th odom -> base_link: x = 0.01 k m, y = -0.002 k m, yaw = 0.02 k rad, 20 Hz stamps."""
    sec, nanosec = divmod(START_SEC * 1_000_000_000 + k * PERIOD_NS, 1_000_000_000)
    return TFMessage(
        transforms=[_transform('odom', 'base_link', sec, nanosec, (0.01 * k, -0.002 * k, 0.0), 0.02 * k)]
    )


def as_dicts(message: Any) -> list[dict[str, Any]]:
    """A TFMessage (rclpy's or rosbags') as plain values: frames, stamp, translation, rotation."""
    out = []
    for t in message.transforms:
        position, rotation = t.transform.translation, t.transform.rotation
        out.append(
            {
                'frame_id': t.header.frame_id,
                'child_frame_id': t.child_frame_id,
                'stamp': [t.header.stamp.sec, t.header.stamp.nanosec],
                'translation': [position.x, position.y, position.z],
                'rotation': [rotation.x, rotation.y, rotation.z, rotation.w],
            }
        )
    return out


def _spin_until(node: Node, done: Any) -> bool:
    end = time.monotonic() + TIMEOUT_S
    while not done() and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    return bool(done())


def publish(count: int) -> int:
    node = rclpy.create_node('tf_peer_robot')
    static = node.create_publisher(TFMessage, '/tf_static', STATIC_PUB_QOS)
    dynamic = node.create_publisher(TFMessage, '/tf', TF_QOS)
    static.publish(static_message())
    if not _spin_until(node, lambda: dynamic.get_subscription_count() and static.get_subscription_count()):
        print('no subscriber to /tf and /tf_static', file=sys.stderr)
        return 1
    time.sleep(1.0)  # discovery is two-sided: let the subscriber match this writer too
    for k in range(count):
        dynamic.publish(tf_message(k))
        time.sleep(PERIOD_NS / 1e9)
    wait = Duration(seconds=10)
    acked = dynamic.wait_for_all_acked(wait) and static.wait_for_all_acked(wait)
    node.destroy_node()
    return 0 if acked else 1


def listen(count: int, static_count: int) -> int:
    node = rclpy.create_node('tf_peer_listener')
    received: dict[str, list[list[dict[str, Any]]]] = {'/tf': [], '/tf_static': []}
    graph: dict[str, list[dict[str, str]]] = {}

    def on_tf(message: TFMessage) -> None:
        received['/tf'].append(as_dicts(message))

    def on_static(message: TFMessage) -> None:
        received['/tf_static'].append(as_dicts(message))

    node.create_subscription(TFMessage, '/tf', on_tf, TF_QOS)
    print('ready', flush=True)
    _spin_until(node, lambda: len(received['/tf']) >= LATE_AFTER)
    subscribed_after = len(received['/tf'])
    # the graph while the publisher is surely alive (it is still sending /tf)
    _spin_until(node, lambda: all(node.get_publishers_info_by_topic(t) for t in received))
    for topic in received:
        graph[topic] = [
            {
                'node': info.node_name,
                'type': info.topic_type,
                'type_hash': str(info.topic_type_hash),
                'durability': info.qos_profile.durability.name,
            }
            for info in node.get_publishers_info_by_topic(topic)
        ]
    node.create_subscription(TFMessage, '/tf_static', on_static, STATIC_SUB_QOS)
    _spin_until(node, lambda: len(received['/tf']) >= count and len(received['/tf_static']) >= static_count)
    print(json.dumps({'received': received, 'graph': graph, 'static_subscribed_after': subscribed_after}))
    node.destroy_node()
    return 0


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument('role', choices=('publish', 'listen'))
    parser.add_argument('count', type=int)
    parser.add_argument('static_count', type=int, nargs='?', default=1)
    args = parser.parse_args()
    rclpy.init()
    try:
        return publish(args.count) if args.role == 'publish' else listen(args.count, args.static_count)
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
