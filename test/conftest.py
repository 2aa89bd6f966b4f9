"""Shared test set-up.

Every pytest process gets its own ROS domain (unless ROS_DOMAIN_ID is already set) and DDS discovery
is confined to this host, so parallel test runs on one machine never see each other's topics.
"""

from __future__ import annotations

import os
import random

os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 100)))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import pytest


@pytest.fixture
def ros_context():
    """An initialised rclpy context of its own, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
