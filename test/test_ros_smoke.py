"""Day-one ROS check: two real nodes over DDS, a message crosses. Never skipped: CI must fail
if rclpy cannot be imported (issue 2)."""

from __future__ import annotations

import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String


def test_message_crosses_between_two_nodes(ros_context: Context) -> None:
    talker = rclpy.create_node('smoke_talker', context=ros_context)
    listener = rclpy.create_node('smoke_listener', context=ros_context)
    received: list[str] = []

    def on_chatter(m: String) -> None:
        received.append(m.data)

    listener.create_subscription(String, 'smoke_chatter', on_chatter, 10)
    publisher = talker.create_publisher(String, 'smoke_chatter', 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(talker)
    executor.add_node(listener)
    try:
        deadline = time.monotonic() + 10.0
        while not received and time.monotonic() < deadline:
            publisher.publish(String(data='hello skid steer'))
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        talker.destroy_node()
        listener.destroy_node()
    assert received and received[0] == 'hello skid steer'
