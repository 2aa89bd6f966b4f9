"""The floor under power_estimator's CPU figures: a node with its inputs, outputs and executor and
no work between them.

It subscribes to cmd_vel (TwistStamped) and joint_states the way power_estimator does (raw, decoded
by rosbags, batched), spins with the same LeanExecutor and publishes power/predicted and
power/measured with the input's stamp and constant numbers (PackedJointState). What power_estimator
costs above this node is the estimator; this node's own cost is rclpy and Fast DDS, which no change
to the estimator can remove. Started by benchmarks/bench_estimator.py as ``python -m
benchmarks.echo_node --ros-args -r __ns:=/...``; with ``--stock`` it runs :class:`StockEchoNode`, the
same echo in plain rclpy (rclpy messages, rclpy's executor).
"""

from __future__ import annotations

import sys
from typing import Any

from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from skidsteer_power.nodes.spin import Batched, LeanExecutor, QuietNode, spin_node
from skidsteer_power.nodes.wire import PackedJointState, decoder

AXLES = ['left_motor', 'right_motor', 'left_axle', 'right_axle']


class EchoNode(QuietNode):
    def __init__(self) -> None:
        super().__init__('power_estimator')
        best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.predicted = self.create_publisher(JointState, 'power/predicted', 1000)
        self.measured = self.create_publisher(JointState, 'power/measured', 1000)
        self.predicted_wire = PackedJointState(AXLES, ('velocity', 'effort'))
        self.measured_wire = PackedJointState(AXLES[:2], ('velocity', 'effort'))
        zeros = (0.0,) * 4
        for msg_type, topic, wire, publisher in (
            (TwistStamped, 'cmd_vel', self.predicted_wire, self.predicted),
            (JointState, 'joint_states', self.measured_wire, self.measured),
        ):
            decode = decoder(msg_type)

            def echo(data: bytes, decode: Any = decode, wire: Any = wire, publisher: Any = publisher) -> None:
                stamp = decode(data).header.stamp
                n = wire.size
                publisher.publish(wire.pack(stamp.sec, stamp.nanosec, zeros[:n], zeros[:n]))

            batched = Batched(echo)
            batched.subscription = self.create_subscription(msg_type, topic, batched, best_effort, raw=True)


class StockEchoNode(Node):
    """The same echo as plain rclpy code would write it: rclpy messages in and out, spun by rclpy's
    own executor (``--stock``). What a node costs before any of the estimator's node-side work."""

    def __init__(self) -> None:
        super().__init__('power_estimator')
        best_effort = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        predicted = self.create_publisher(JointState, 'power/predicted', 1000)
        measured = self.create_publisher(JointState, 'power/measured', 1000)

        def echo(msg: Any, publisher: Any, names: list[str]) -> None:
            zeros = [0.0] * len(names)
            publisher.publish(JointState(header=msg.header, name=names, velocity=zeros, effort=zeros))

        self.create_subscription(TwistStamped, 'cmd_vel', lambda m: echo(m, predicted, AXLES), best_effort)
        self.create_subscription(
            JointState, 'joint_states', lambda m: echo(m, measured, AXLES[:2]), best_effort
        )


def main(args: list[str] | None = None) -> None:
    argv = list(args if args is not None else sys.argv)
    if '--stock' in argv:
        argv.remove('--stock')
        spin_node(StockEchoNode, 'echo_node', argv)
    else:
        spin_node(EchoNode, 'echo_node', argv, executor=LeanExecutor)


if __name__ == '__main__':
    main()
