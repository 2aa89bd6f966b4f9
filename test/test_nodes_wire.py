"""nodes/wire.py: a PackedJointState's patched bytes are exactly the message rclpy would serialize
(checked by deserializing them with rclpy), and decoder() reads rclpy's serialization with rosbags."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from skidsteer_power.nodes.wire import PackedJointState, decoder

NAMES = ['left_motor', 'right_motor', 'left_axle', 'right_axle']


def test_packed_joint_state_is_the_message_rclpy_serializes() -> None:
    wire = PackedJointState(NAMES, ('velocity', 'effort'))
    for sec, nanosec, velocity, effort in (
        (1_796_160_000, 123_456_789, [300.0, -299.5, 25.0, -24.96], [0.21, 0.19, 2.4, 2.3]),
        (0, 0, [0.0, 0.0, 0.0, 0.0], [math.nan, math.inf, -0.0, 1e-300]),
    ):
        data = wire.pack(sec, nanosec, velocity, effort)
        expected = JointState(name=NAMES, velocity=velocity, effort=effort)
        expected.header.stamp.sec, expected.header.stamp.nanosec = sec, nanosec
        assert data == serialize_message(expected)
        msg = deserialize_message(data, JointState)
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (sec, nanosec)
        assert list(msg.name) == NAMES and list(msg.position) == []
        np.testing.assert_array_equal(msg.velocity, velocity)
        np.testing.assert_array_equal(msg.effort, effort)


def test_packed_joint_state_rejects_a_field_joint_state_does_not_have() -> None:
    with pytest.raises(ValueError, match='torque'):
        PackedJointState(NAMES, ('velocity', 'torque'))


def test_decoder_reads_rclpys_serialization() -> None:
    twist = TwistStamped()
    twist.header.stamp.sec, twist.header.stamp.nanosec = 12, 345
    twist.header.frame_id = 'base_link'
    twist.twist.linear.x, twist.twist.angular.z = 0.25, -0.5
    got = decoder(TwistStamped)(serialize_message(twist))
    assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (12, 345, 'base_link')
    assert (got.twist.linear.x, got.twist.angular.z) == (0.25, -0.5)
    joint = JointState(name=['a', 'bb'], position=[1.0, 2.0], velocity=[3.0, 4.0], effort=[5.0, 6.0])
    got = decoder(JointState)(serialize_message(joint))
    assert got.name == ['a', 'bb']
    assert got.position.tolist() == [1.0, 2.0] and got.velocity.tolist() == [3.0, 4.0]
    assert got.effort.tolist() == [5.0, 6.0]
