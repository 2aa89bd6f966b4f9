"""Bag I/O: read (MCAP and sqlite3 rosbag2, with salvage of damaged files), write, record and replay.

The lowest layer that touches bags: it knows messages and files, not the physics. The twin writes
its recordings with it; validation (:mod:`skidsteer_power.validation`), calibration and the nodes read
with it. Reading needs no ROS graph; recording and replay use rclpy's raw (serialized)
subscriptions and ``publish(bytes)`` so messages pass through byte for byte.
"""

from __future__ import annotations

from skidsteer_power.bag_io.reader import BagMessage, BagReader, TopicInfo, load_msg_definitions, open_bag

__all__ = ['BagMessage', 'BagReader', 'TopicInfo', 'load_msg_definitions', 'open_bag']
