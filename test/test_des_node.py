"""des_driver node end to end: real rclpy and DDS, two simulated amplifiers on ptys."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
import uuid

import pytest

from skidsteer_power.des.protocol import DesErrorFlags, OpCode
from skidsteer_power.des.simulator import SimulatedPair

pytestmark = pytest.mark.ros

RPM = 2 * math.pi / 60
# Set points for v = 0.2 m/s, yaw rate 0.5 rad/s on the default vehicle file test_robot_track.yaml
# (tread 0.426 m, sprocket r = 0.1 m; its powertrain 12:1):
# v_left = 0.2 - 0.5 * 0.426 / 2 = 0.0935 m/s -> 0.0935 / 0.1 * 12 rad/s = 11.22 rad/s = 107.14 rpm;
# v_right = 0.3065 m/s -> 36.78 rad/s = 351.22 rpm. Right motor mirrored (polarity -1): -351.
LEFT_RPM, RIGHT_RPM = 107, -351


@pytest.fixture
def pair():
    with SimulatedPair(38400) as sims:
        yield sims


class Harness:
    """The driver node, a test node publishing cmd_vel and recording outputs, one executor."""

    def __init__(self, context, pair: SimulatedPair, activate: bool = True, **overrides) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import Twist, TwistStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.lifecycle import TransitionCallbackReturn
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger

        from skidsteer_power.nodes.des_driver import DesDriver

        ns = f'/t{uuid.uuid4().hex[:8]}'
        params = {
            'left_port': pair.left.port,
            'right_port': pair.right.port,
            'ack_timeout_s': 0.3,
            'reconnect_period_s': 0.2,
            'diagnostics_rate_hz': 10.0,
            **overrides,
        }
        self.driver = DesDriver(
            context=context,
            namespace=ns,
            parameter_overrides=[Parameter(k, value=v) for k, v in params.items()],
        )
        self.node = Node('des_test', namespace=ns, context=context)
        self.stamped = bool(overrides.get('twist_stamped', False))
        self.cmd_pub = self.node.create_publisher(
            TwistStamped if self.stamped else Twist, f'{ns}/cmd_vel', 10
        )
        self.clear_client = self.node.create_client(Trigger, f'{ns}/des_driver/clear_faults')
        self.joints: list[JointState] = []
        self.diags: list[DiagnosticArray] = []
        self.node.create_subscription(JointState, f'{ns}/joint_states', self.joints.append, 10)
        self.node.create_subscription(DiagnosticArray, f'{ns}/diagnostics', self.diags.append, 10)
        self.twist: tuple[float, float] | None = None
        self.node.create_timer(0.05, self._publish_cmd)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.driver)
        self.executor.add_node(self.node)
        if activate:
            assert self.driver.trigger_configure() == TransitionCallbackReturn.SUCCESS
            assert self.driver.trigger_activate() == TransitionCallbackReturn.SUCCESS

    def _publish_cmd(self) -> None:
        from geometry_msgs.msg import Twist, TwistStamped

        if self.twist is not None:
            msg = TwistStamped() if self.stamped else Twist()
            twist = msg.twist if self.stamped else msg
            twist.linear.x, twist.angular.z = self.twist
            self.cmd_pub.publish(msg)

    def spin_until(self, predicate, timeout_s: float = 8.0) -> bool:
        """Spin until ``predicate()`` holds or the deadline passes (a wait, not a timing assertion)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
            if predicate():
                return True
        return predicate()

    def call(self, client, request, timeout_s: float = 10.0):
        """Call a service through DDS and spin until the answer arrives."""
        assert client.wait_for_service(timeout_sec=timeout_s)
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout_s)
        return future.result()

    def side_diag(self, side: str):
        for array in reversed(self.diags):
            for status in array.status:
                if status.name == f'des_driver: {side} amplifier':
                    return status, {kv.key: kv.value for kv in status.values}
        return None, {}

    def close(self) -> None:
        self.driver.destroy_node()
        self.node.destroy_node()
        self.executor.shutdown()


@pytest.fixture
def harness(ros_context, pair):
    h = Harness(ros_context, pair)
    yield h
    h.close()


def test_cmd_vel_to_setpoints_to_joint_states(harness, pair):
    harness.twist = (0.2, 0.5)
    assert harness.spin_until(
        lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (LEFT_RPM, RIGHT_RPM)
    )
    assert pair.left.enabled and pair.right.enabled

    def settled():
        if not harness.joints:
            return False
        v = harness.joints[-1].velocity
        return abs(v[0] - LEFT_RPM * RPM) < 0.3 and abs(v[1] + RIGHT_RPM * RPM) < 0.3

    assert harness.spin_until(settled)
    msg = harness.joints[-1]
    assert list(msg.name) == ['left_motor', 'right_motor']
    # Both sides forward-positive; effort = Kt i with the simulator's friction load (> 0 forward).
    assert msg.velocity[1] > msg.velocity[0] > 0
    assert all(0 < e < 0.1 for e in msg.effort)
    assert msg.effort[0] == pytest.approx(0.114 * pair.left.model.mean_current_A, abs=0.005)
    # Position integrates velocity: over ~1 s of joint_states the encoder must agree with the speed.
    first = msg
    harness.spin_until(lambda: harness.joints[-1].header.stamp.sec > first.header.stamp.sec + 1, timeout_s=5)
    last = harness.joints[-1]
    dt = (last.header.stamp.sec - first.header.stamp.sec) + 1e-9 * (
        last.header.stamp.nanosec - first.header.stamp.nanosec
    )
    for i, rpm in enumerate((LEFT_RPM, -RIGHT_RPM)):
        moved = last.position[i] - first.position[i]
        assert moved == pytest.approx(rpm * RPM * dt, rel=0.1)


def test_twist_stamped_by_parameter(ros_context, pair):
    h = Harness(ros_context, pair, twist_stamped=True)
    try:
        h.twist = (0.2, 0.5)
        assert h.spin_until(
            lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (LEFT_RPM, RIGHT_RPM)
        )
    finally:
        h.close()


def test_watchdog_stops_the_motors(harness, pair):
    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    harness.twist = None  # cmd_vel stops
    assert harness.spin_until(
        lambda: pair.left.speed_setpoint_rpm == 0 and pair.right.speed_setpoint_rpm == 0
    )
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('watchdog_zero') == 'True')
    assert pair.left.enabled  # stopped, not disabled: the next cmd_vel drives again
    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)


def test_amplifier_error_stops_both_sides_until_cleared(harness, pair):
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_srvs.srv import Trigger

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.right.speed_setpoint_rpm < 0 and pair.left.speed_setpoint_rpm > 0)
    pair.left.raise_error(DesErrorFlags.OVER_CURRENT)
    assert harness.spin_until(
        lambda: pair.right.speed_setpoint_rpm == 0 and pair.left.speed_setpoint_rpm == 0
    )

    def fault_reported():
        status, values = harness.side_diag('left')
        return status is not None and 'OVER_CURRENT' in values['errors'] and values['fault_latched'] == 'True'

    assert harness.spin_until(fault_reported)
    assert harness.side_diag('left')[0].level == DiagnosticStatus.ERROR
    assert not pair.left.enabled
    # cmd_vel keeps coming, but the latch holds: still stopped after a while.
    harness.spin_until(lambda: False, timeout_s=0.5)
    assert pair.right.speed_setpoint_rpm == 0
    answer = harness.call(harness.clear_client, Trigger.Request())
    assert answer.success, answer.message
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    assert pair.left.errors == DesErrorFlags(0) and pair.left.enabled
    assert harness.spin_until(lambda: harness.side_diag('left')[0].level == DiagnosticStatus.OK)


def test_lost_port_is_reported_and_reopened(harness, pair):
    from diagnostic_msgs.msg import DiagnosticStatus

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: bool(harness.joints) and not math.isnan(harness.joints[-1].velocity[0]))
    pair.left.close_port()
    assert harness.spin_until(
        lambda: 'port lost' in (harness.side_diag('left')[0].message if harness.diags else '')
    )
    status, values = harness.side_diag('left')
    assert status.level == DiagnosticStatus.ERROR and values['connected'] == 'False'
    assert harness.spin_until(lambda: math.isnan(harness.joints[-1].velocity[0]))
    assert not math.isnan(harness.joints[-1].velocity[1])  # the other side keeps reporting
    set_before = len(pair.left.commands_of(OpCode.SET_VELOCITY))
    pair.left.reopen_port()
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('connected') == 'True')
    assert harness.spin_until(lambda: not math.isnan(harness.joints[-1].velocity[0]))
    assert len(pair.left.commands_of(OpCode.SET_VELOCITY)) > set_before
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)


def test_silent_amplifier_is_reported_and_reconnected(harness, pair):
    from skidsteer_power.des.simulator import Fault

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.right.speed_setpoint_rpm < 0)
    pair.right.inject(Fault.SILENT, count=-1)
    assert harness.spin_until(
        lambda: 'not answering' in (harness.side_diag('right')[0].message if harness.diags else '')
    )
    assert harness.side_diag('right')[1]['connected'] == 'False'
    assert harness.spin_until(lambda: math.isnan(harness.joints[-1].velocity[1]))
    pair.right.clear_faults()
    assert harness.spin_until(lambda: harness.side_diag('right')[1].get('connected') == 'True')
    assert harness.spin_until(lambda: not math.isnan(harness.joints[-1].velocity[1]))


def test_sigterm_zeroes_speed_then_disables(ros_context, pair):
    from geometry_msgs.msg import Twist
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    ns = f'/t{uuid.uuid4().hex[:8]}'
    proc = subprocess.Popen(
        [
            sys.executable, '-m', 'skidsteer_power.nodes.des_driver', '--ros-args', '-r', f'__ns:={ns}',
            '-p', f'left_port:={pair.left.port}', '-p', f'right_port:={pair.right.port}',
            '-p', 'ack_timeout_s:=0.3', '-p', 'cmd_timeout_s:=5.0', '-p', 'autostart:=true',
        ],
        env=os.environ.copy(),
    )  # fmt: skip
    node = Node('des_sigterm_test', namespace=ns, context=ros_context)
    pub = node.create_publisher(Twist, f'{ns}/cmd_vel', 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        msg = Twist()
        msg.linear.x = 0.2
        deadline = time.monotonic() + 30
        while pair.left.speed_setpoint_rpm == 0 and time.monotonic() < deadline:
            pub.publish(msg)
            executor.spin_once(timeout_sec=0.05)
        assert pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 0
        for sim in (pair.left, pair.right):
            assert sim.speed_setpoint_rpm == 0 and not sim.enabled
            log = [c for c in sim.commands if c.opcode in (OpCode.SET_VELOCITY, OpCode.ENABLE)]
            assert [(c.opcode, c.words) for c in log[-2:]] == [
                (OpCode.SET_VELOCITY, (0,)),
                (OpCode.ENABLE, (0,)),
            ]
    finally:
        proc.kill()
        proc.wait()
        node.destroy_node()
        executor.shutdown()


def test_bad_parameters_are_one_clear_error(ros_context, pair):
    from rclpy.parameter import Parameter

    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes.des_driver import DesDriver

    with pytest.raises(ConfigError, match='left_polarity must be'):
        DesDriver(
            context=ros_context,
            parameter_overrides=[
                Parameter('left_port', value=pair.left.port),
                Parameter('right_port', value=pair.right.port),
                Parameter('left_polarity', value=2),
            ],
        )
