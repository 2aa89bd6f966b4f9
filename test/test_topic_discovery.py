"""The one topic discovery of the recorder and the Foxglove bridge (bag_io/_ros.discover_topics), on a
real ROS graph (rclpy + DDS): a publisher that appears is found with its type, exactly once; the
graph's own topics only when named; a topic with two types and one whose type is not installed are
skipped with the reason."""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Collection

import pytest
from rclpy.context import Context
from rclpy.node import Node

from skidsteer_power.bag_io._ros import GRAPH_TOPICS, absolute_topic, discover_topics
from skidsteer_power.errors import InputError

pytestmark = pytest.mark.ros


class Seen:
    """What discover_topics handed over: taken (name -> type) and skipped (name -> reason)."""

    def __init__(self, refuse: str = '') -> None:
        self.taken: dict[str, str] = {}
        self.skipped: dict[str, str] = {}
        self.refuse = refuse  # a type whose take raises InputError, as message_class does

    def known(self, name: str) -> bool:
        return name in self.taken or name in self.skipped

    def take(self, name: str, msgtype: str) -> None:
        if msgtype == self.refuse:
            raise InputError(f'message type {msgtype} is not installed for Python')
        assert name not in self.taken, f'{name} handed over twice'
        self.taken[name] = msgtype

    def skip(self, name: str, reason: str) -> None:
        self.skipped[name] = reason


def _discover_until(
    node: Node, wanted: Collection[str], seen: Seen, done: Callable[[], object], timeout_s: float = 20.0
) -> None:
    """Discover as the recorder's timer does, until ``done()`` (DDS discovery takes a moment)."""
    end = time.monotonic() + timeout_s
    while True:
        discover_topics(node, wanted, seen.known, seen.take, seen.skip)
        if done():
            return
        assert time.monotonic() < end, f'not discovered: taken {seen.taken}, skipped {seen.skipped}'
        time.sleep(0.05)


def _wait_for(predicate: Callable[[], object], timeout_s: float = 20.0) -> None:
    end = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < end, 'timed out waiting for the ROS graph'
        time.sleep(0.05)


def test_a_new_publisher_is_discovered_once_with_its_type(ros_context: Context) -> None:
    import rclpy
    from std_msgs.msg import Float64, String

    listener = rclpy.create_node('discovery_listener', context=ros_context)
    talker = rclpy.create_node('discovery_talker', context=ros_context)
    first, second = (f'/discovery_{uuid.uuid4().hex[:8]}_{k}' for k in ('first', 'second'))
    try:
        seen = Seen()
        talker.create_publisher(String, first, 10)
        _discover_until(listener, (), seen, lambda: first in seen.taken)
        assert seen.taken[first] == 'std_msgs/msg/String'
        assert not GRAPH_TOPICS & set(seen.taken), 'rosout / parameter_events taken without being named'

        talker.create_publisher(Float64, second, 10)  # appears later: the next call picks it up
        _discover_until(listener, (), seen, lambda: second in seen.taken)
        assert seen.taken[second] == 'std_msgs/msg/Float64'
        discover_topics(listener, (), seen.known, seen.take, seen.skip)  # Seen.take fails on a repeat
    finally:
        talker.destroy_node()
        listener.destroy_node()


def test_named_topics_only_and_graph_topics_when_named(ros_context: Context) -> None:
    import rclpy
    from std_msgs.msg import String

    node = rclpy.create_node('discovery_named', context=ros_context)
    wanted_name, other = (f'/discovery_{uuid.uuid4().hex[:8]}_{k}' for k in ('wanted', 'other'))
    try:
        node.create_publisher(String, wanted_name, 10)
        node.create_publisher(String, other, 10)
        seen = Seen()
        wanted = {wanted_name, '/rosout'}
        _discover_until(node, wanted, seen, lambda: wanted <= set(seen.taken))
        assert seen.taken == {wanted_name: 'std_msgs/msg/String', '/rosout': 'rcl_interfaces/msg/Log'}
    finally:
        node.destroy_node()


def test_two_types_on_one_topic_and_a_refused_type_are_skipped_with_the_reason(ros_context: Context) -> None:
    import rclpy
    from std_msgs.msg import Float64, String

    node = rclpy.create_node('discovery_skips', context=ros_context)
    from rclpy.context import Context

    # DDS takes one type per topic in a participant: the second type comes from another context
    other_context = Context()
    rclpy.init(context=other_context)
    other = rclpy.create_node('discovery_other_type', context=other_context)
    mixed, refused = (f'/discovery_{uuid.uuid4().hex[:8]}_{k}' for k in ('mixed', 'refused'))
    try:
        node.create_publisher(String, mixed, 10)
        other.create_publisher(Float64, mixed, 10)
        node.create_publisher(Float64, refused, 10)
        # the other participant's publisher is discovered later than the node's own: wait for both
        # types on the graph first, or the topic would be taken as String-only
        _wait_for(lambda: len(dict(node.get_topic_names_and_types()).get(mixed, [])) == 2)
        seen = Seen(refuse='std_msgs/msg/Float64')
        _discover_until(node, {mixed, refused}, seen, lambda: {mixed, refused} <= set(seen.skipped))
        assert 'several types' in seen.skipped[mixed]
        assert 'std_msgs/msg/String' in seen.skipped[mixed] and 'std_msgs/msg/Float64' in seen.skipped[mixed]
        assert 'not installed' in seen.skipped[refused]
        assert not seen.taken
    finally:
        other.destroy_node()
        rclpy.try_shutdown(context=other_context)
        node.destroy_node()


def test_absolute_topic_adds_the_root_slash_once() -> None:
    assert absolute_topic('cmd_vel') == '/cmd_vel'
    assert absolute_topic('/cmd_vel') == '/cmd_vel'
