"""The floor under power_estimator's CPU figures: a node with its inputs, outputs and executor and
no work between them.

It subscribes to cmd_vel (TwistStamped) and joint_states the way power_estimator does (raw, decoded
by rosbags, batched), spins with the same LeanExecutor and publishes power/predicted and
power/measured with the input's stamp and constant numbers (PackedJointState). What power_estimator
costs above this node is the estimator; this node's own cost is rclpy and Fast DDS, which no change
to the estimator can remove. Started by benchmarks/bench_estimator.py as ``python -m
benchmarks.echo_node --ros-args -r __ns:=/...``.
"""

from __future__ import annotations

import sys
from typing import Any

from geometry_msgs.msg import TwistStamped
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


def main(args: list[str] | None = None) -> None:
    spin_node(EchoNode, 'echo_node', args if args is not None else sys.argv, executor=LeanExecutor)


if __name__ == '__main__':
    main()
