"""A des_driver node and a test node on one executor, against simulated amplifiers (for the DES tests).

Real rclpy and DDS: the test node publishes cmd_vel, calls the driver's services and records its
joint_states and diagnostics, all through the middleware.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from skidsteer_power.des.simulator import SimulatedDes, SimulatedPair

if TYPE_CHECKING:
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.client import Client
    from rclpy.context import Context

    from skidsteer_power.des.poller import DriveCommand


class Clock:
    """A clock the test steps [s] (DriveCommand's ``clock``): no sleeps, the same result on any load."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def enabled(sim: SimulatedDes) -> bool:
    """``sim.enabled``, read through a call: the driver changes it while the test spins, which mypy's
    narrowing of the attribute after an earlier ``assert not sim.enabled`` cannot see."""
    return sim.enabled


class Harness:
    """The driver node, a test node publishing cmd_vel and recording outputs, one executor."""

    def __init__(
        self, context: Context, pair: SimulatedPair, activate: bool = True, **overrides: Any
    ) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import Twist, TwistStamped
        from lifecycle_msgs.srv import ChangeState, GetState
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger

        from skidsteer_power.nodes.des_driver import DesDriver

        ns = overrides.pop('namespace', None) or f'/t{uuid.uuid4().hex[:8]}'
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
        self.change_client = self.node.create_client(ChangeState, f'{ns}/des_driver/change_state')
        self.state_client = self.node.create_client(GetState, f'{ns}/des_driver/get_state')
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
            lifecycle: LifecycleNode = self.driver  # rclpy's triggers are unannotated (untyped_calls_exclude)
            assert lifecycle.trigger_configure() == TransitionCallbackReturn.SUCCESS
            assert lifecycle.trigger_activate() == TransitionCallbackReturn.SUCCESS

    def _publish_cmd(self) -> None:
        if self.twist is not None:
            self.publish(*self.twist)

    def publish(self, linear_x: float, angular_z: float) -> None:
        """Publish one cmd_vel (any float, NaN and inf included)."""
        from geometry_msgs.msg import Twist, TwistStamped

        msg = TwistStamped() if self.stamped else Twist()
        twist = msg.twist if self.stamped else msg
        twist.linear.x, twist.angular.z = linear_x, angular_z
        self.cmd_pub.publish(msg)

    def transition(self, transition_id: int) -> bool:
        """Ask for a lifecycle transition through ~/change_state; whether it succeeded."""
        from lifecycle_msgs.srv import ChangeState

        request = ChangeState.Request()
        request.transition.id = transition_id
        return bool(self.call(self.change_client, request).success)

    def state(self) -> str:
        """The driver's lifecycle state label through ~/get_state."""
        from lifecycle_msgs.srv import GetState

        return str(self.call(self.state_client, GetState.Request()).current_state.label)

    def spin_until(self, predicate: Callable[[], object], timeout_s: float = 8.0) -> bool:
        """Spin until ``predicate()`` holds or the deadline passes (a wait, not a timing assertion)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
            if predicate():
                return True
        return bool(predicate())

    def call(self, client: Client, request: object, timeout_s: float = 10.0) -> Any:
        """Call a service through DDS and spin until the answer arrives: the service type's Response
        (Any: rclpy's Future.result is unannotated)."""
        assert client.wait_for_service(timeout_sec=timeout_s)
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout_s)
        return future.result()

    def side_diag(self, side: str) -> tuple[DiagnosticStatus | None, dict[str, str]]:
        """(latest DiagnosticStatus of one amplifier, its values as a dict), or (None, {})."""
        return self.diag(f'des_driver: {side} amplifier')

    def drive_command(self) -> DriveCommand:
        """The driver's DriveCommand (it exists once the driver is configured)."""
        assert self.driver.command is not None, 'the driver is not configured'
        return self.driver.command

    def side_status(self, side: str) -> DiagnosticStatus:
        """The latest DiagnosticStatus of one amplifier (an AssertionError while there is none)."""
        status, _ = self.side_diag(side)
        assert status is not None, f'no diagnostics of the {side} amplifier yet'
        return status

    def diag(self, name: str) -> tuple[DiagnosticStatus | None, dict[str, str]]:
        for array in reversed(self.diags):
            for status in array.status:
                if status.name == name:
                    return status, {kv.key: kv.value for kv in status.values}
        return None, {}

    def close(self) -> None:
        self.driver.destroy_node()
        self.node.destroy_node()
        self.executor.shutdown()
