"""cmd_vel as Twist or TwistStamped, stamps checked, slow streams reported (issue 37 items 1-2,
issue 34 item 5): real rclpy publishers in a context of their own (another DDS participant, as another
process), the real power_estimator and des_driver (on the simulated DES 70/10)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from des_harness import Harness
from geometry_msgs.msg import TwistStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from test_estimator_core import FixedPowerPredictor

from skidsteer_power.des.simulator import SimulatedPair
from skidsteer_power.nodes.cmd_vel_input import CommandGaps, StampCheck
from skidsteer_power.nodes.power_estimator import PowerEstimator

HOUR_S = 3600.0


def test_stamp_check_refuses_old_and_future_stamps_and_takes_zero_as_unstamped() -> None:
    check = StampCheck(timeout_s=0.5, tolerance_s=0.2)
    now = 1_000_000.0
    assert check.check(0, 0, now) == 'zero'
    assert 'stale' in check.check(int(now - HOUR_S), 0, now)  # 1 h old
    assert 'future' in check.check(int(now + HOUR_S), 0, now)  # 1 h ahead
    assert check.check(int(now), 0, now + 0.1) == ''  # 0.1 s old: within the 0.5 s watchdog
    assert check.check(int(now), 150_000_000, now) == ''  # 0.15 s ahead: within the 0.2 s tolerance
    assert 'future' in check.check(int(now), 300_000_000, now)  # 0.3 s ahead
    assert (check.zero_stamps, check.refused_stale, check.refused_future) == (1, 1, 2)


def test_command_gaps_count_a_1_hz_stream_against_a_half_second_watchdog() -> None:
    gaps = CommandGaps(timeout_s=0.5)
    found = [gaps.note(float(t), moving=True) for t in range(5)]  # Foxglove Teleop's default 1 Hz
    assert found == [None, 1.0, 1.0, 1.0, 1.0] and gaps.slow_gaps == 4
    fast = CommandGaps(timeout_s=0.5)
    assert all(fast.note(t * 0.1, moving=True) is None for t in range(20))  # 10 Hz: never
    idle = CommandGaps(timeout_s=0.5)
    assert all(idle.note(float(t), moving=False) is None for t in range(5))  # zeros hold the robot anyway


class Graph:
    """A power_estimator in one context and a publisher node in another (another participant)."""

    def __init__(self, node_context: Context, tmp_path: Path, **params: Any) -> None:
        self.client_context = Context()
        rclpy.init(context=self.client_context)
        self.namespace = f'/cv{time.monotonic_ns() % 10**9}'
        overrides = {'state_file': str(tmp_path / 'e.json'), 'publish_period_s': 0.05, **params}
        try:
            self.node = PowerEstimator(
                predictor=FixedPowerPredictor(40.0),
                context=node_context,
                namespace=self.namespace,
                parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
            )
        except BaseException:  # a refused parameter: leave no second context behind for later tests
            rclpy.try_shutdown(context=self.client_context)
            raise
        self.client = Node('teleop', namespace=self.namespace, context=self.client_context)
        self.predicted: list[JointState] = []
        self.client.create_subscription(JointState, 'power/predicted', self.predicted.append, 100)
        self.executors = [
            SingleThreadedExecutor(context=node_context),
            SingleThreadedExecutor(context=self.client_context),
        ]
        self.executors[0].add_node(self.node)
        self.executors[1].add_node(self.client)

    def spin_until(self, predicate: Callable[[], object], timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for executor in self.executors:
                executor.spin_once(timeout_sec=0.01)
            if predicate():
                return True
        return bool(predicate())

    def close(self) -> None:
        self.node.destroy_node()
        self.client.destroy_node()
        for executor in self.executors:
            executor.shutdown()
        rclpy.try_shutdown(context=self.client_context)


@pytest.fixture
def graph(ros_context: Context, tmp_path: Path) -> Iterator[Graph]:
    g = Graph(ros_context, tmp_path)
    yield g
    g.close()


def stamped(node: Node, offset_s: float, speed: float = 0.3) -> TwistStamped:
    msg = TwistStamped()
    now = node.get_clock().now().nanoseconds + int(offset_s * 1e9)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
    msg.twist.linear.x = speed
    return msg


def test_auto_follows_a_twist_stamped_publisher_and_refuses_bad_stamps(graph: Graph) -> None:
    assert graph.node.cmd_input.current == 'twist'  # nothing on the graph yet: Twist
    publisher = graph.client.create_publisher(TwistStamped, 'cmd_vel', 10)
    assert graph.spin_until(lambda: graph.node.cmd_input.current == 'twist_stamped')

    def delivered(offset_s: float) -> int:
        """Publish stamped commands until one prediction comes back (or 2 s): how many came."""
        before = len(graph.predicted)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and len(graph.predicted) == before:
            publisher.publish(stamped(graph.client, offset_s))
            graph.spin_until(lambda: len(graph.predicted) > before, 0.1)
        return len(graph.predicted) - before

    assert delivered(0.0) > 0  # a fresh stamp drives the prediction
    stamps = graph.node.cmd_input.stamps
    assert delivered(-HOUR_S) == 0 and stamps.refused_stale > 0  # 1 h old: refused
    assert delivered(+HOUR_S) == 0 and stamps.refused_future > 0  # 1 h ahead: refused
    zero = TwistStamped()
    zero.twist.linear.x = 0.3
    before = len(graph.predicted)

    def zero_delivered() -> bool:
        publisher.publish(zero)
        return len(graph.predicted) > before

    assert graph.spin_until(zero_delivered)
    assert stamps.zero_stamps > 0  # a zero stamp: taken as unstamped
    values = graph.node.cmd_input.diagnostics()
    assert values['cmd_vel_type'] == 'geometry_msgs/msg/TwistStamped (auto)'
    assert int(values['cmd_vel_refused_stale_stamp']) == stamps.refused_stale


def test_a_pinned_type_names_the_publisher_it_refuses(ros_context: Context, tmp_path: Path) -> None:
    g = Graph(ros_context, tmp_path, cmd_vel_type='twist')
    try:
        publisher = g.client.create_publisher(TwistStamped, 'cmd_vel', 10)
        name = f'{g.namespace}/teleop'
        assert g.spin_until(lambda: name in g.node.cmd_input.refused_publishers)
        assert g.node.cmd_input.refused_publishers[name] == 'geometry_msgs/msg/TwistStamped'
        assert g.node.cmd_input.current == 'twist'
        before = len(g.predicted)
        for _ in range(10):
            publisher.publish(stamped(g.client, 0.0))
            g.spin_until(lambda: False, 0.05)
        assert len(g.predicted) == before  # DDS does not match the other type: nothing predicted
    finally:
        g.close()


def test_deprecated_alias_and_unknown_type(ros_context: Context, tmp_path: Path) -> None:
    from skidsteer_power.errors import ConfigError

    g = Graph(ros_context, tmp_path, cmd_vel_stamped=True)
    try:
        assert g.node.cmd_input.mode == 'twist_stamped'
    finally:
        g.close()
    with pytest.raises(ConfigError, match='cmd_vel_type must be one of auto, twist, twist_stamped'):
        Graph(ros_context, tmp_path, cmd_vel_type='Twist3')


def test_driver_refuses_stale_and_future_stamps(ros_context: Context) -> None:
    """des_driver on the simulated DES 70/10: a TwistStamped 1 h old or 1 h ahead leaves the motors
    at zero; a fresh one drives; a zero stamp drives (taken as unstamped)."""
    with SimulatedPair(38400) as pair:
        h = Harness(ros_context, pair, twist_stamped=True)
        try:
            for offset in (-HOUR_S, +HOUR_S):
                for _ in range(20):
                    h.cmd_pub.publish(stamped(h.node, offset, 0.2))
                    h.spin_until(lambda: False, 0.05)
                assert pair.left.speed_setpoint_rpm == 0 and pair.right.speed_setpoint_rpm == 0
            cmd_input = h.driver.cmd_input
            assert cmd_input is not None
            assert cmd_input.stamps.refused_stale > 0 and cmd_input.stamps.refused_future > 0

            last_sent = [-1.0]

            def fresh_drives() -> bool:  # at 20 Hz, a teleop's rate (every spin: ~5 kHz, 38 000 in 8 s)
                if time.monotonic() - last_sent[0] >= 0.05:
                    last_sent[0] = time.monotonic()
                    h.cmd_pub.publish(stamped(h.node, 0.0, 0.2))
                return pair.left.speed_setpoint_rpm > 0

            assert h.spin_until(fresh_drives)

            def refused_in_diagnostics() -> bool:
                values = h.diag('des_driver: command')[1]
                return int(values.get('cmd_vel_refused_stale_stamp', '0')) > 0

            assert h.spin_until(refused_in_diagnostics)
        finally:
            h.close()
