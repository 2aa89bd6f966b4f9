"""Bags: read (MCAP and sqlite3 rosbag2), record, replay and validate against the estimator.

Reading needs no ROS graph; recording and replay use rclpy's raw (serialized) subscriptions and
``publish(bytes)`` so messages pass through byte for byte.
"""

from __future__ import annotations

from skidsteer_power.bags.reader import BagMessage, BagReader, TopicInfo, load_msg_definitions, open_bag

__all__ = ['BagMessage', 'BagReader', 'TopicInfo', 'load_msg_definitions', 'open_bag']
