"""The vectorized decode of one-layout topics (bag_io/cdr_fixed.py) against the rosbags type store's
own deserializer (an independent CDR implementation), and its refusals (None: decode one by one)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io.cdr_fixed import header_doubles, joint_state_doubles
from skidsteer_power.bag_io.decode import decode_joint_arrays, decode_planar_poses
from skidsteer_power.bag_io.writer import BagWriter

STORE = get_typestore(Stores.ROS2_JAZZY)
RNG = np.random.default_rng(7)


def _header(k: int, frame: str = 'base_link') -> Any:  # rosbags' message classes are made at run time
    Time = STORE.types['builtin_interfaces/msg/Time']
    Header = STORE.types['std_msgs/msg/Header']
    return Header(stamp=Time(sec=k, nanosec=1000 * k), frame_id=frame)


def _joint_state(k: int, names: list[str], counts: tuple[int, int, int] | None = None) -> bytes:
    JointState = STORE.types['sensor_msgs/msg/JointState']
    n = len(names)
    p, v, e = counts or (n, n, n)
    msg = JointState(
        header=_header(k),
        name=names,
        position=RNG.normal(size=p),
        velocity=RNG.normal(size=v),
        effort=RNG.normal(size=e),
    )
    return bytes(STORE.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def _odometry(k: int, frame: str = 'odom', child: str = 'base_link') -> bytes:
    t = STORE.types
    Point, Quat, Vec = (
        t['geometry_msgs/msg/Point'],
        t['geometry_msgs/msg/Quaternion'],
        t['geometry_msgs/msg/Vector3'],
    )
    q = RNG.normal(size=4)
    q /= np.linalg.norm(q)
    pose = t['geometry_msgs/msg/Pose'](position=Point(*RNG.normal(size=3)), orientation=Quat(*q))
    twist = t['geometry_msgs/msg/Twist'](linear=Vec(*RNG.normal(size=3)), angular=Vec(*RNG.normal(size=3)))
    msg = t['nav_msgs/msg/Odometry'](
        header=_header(k, frame),
        child_frame_id=child,
        pose=t['geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=RNG.normal(size=36)),
        twist=t['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=RNG.normal(size=36)),
    )
    return bytes(STORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry'))


@pytest.mark.parametrize('names', [['left_motor', 'right_motor'], ['fl', 'rear_left_wheel', 'fr', 'rr', 'x']])
def test_joint_states_match_the_type_store(names: list[str]) -> None:
    raw = [_joint_state(k, names) for k in range(50)]
    wanted = [names[-1], names[0]]  # another order than the message's
    got = joint_state_doubles(raw, wanted)
    assert got is not None
    rows = [names.index(n) for n in wanted]
    for field, values in zip(('position', 'velocity', 'effort'), got, strict=True):
        expected = np.array(
            [getattr(STORE.deserialize_cdr(d, 'sensor_msgs/msg/JointState'), field)[rows] for d in raw]
        )
        np.testing.assert_array_equal(values, expected)  # the same bytes read as float64: exactly equal


def test_joint_states_of_another_layout_are_refused() -> None:
    names = ['left_motor', 'right_motor']
    same = [_joint_state(k, names) for k in range(5)]
    assert joint_state_doubles([*same, _joint_state(9, ['right_motor', 'left_motor'])], names) is None
    assert joint_state_doubles([_joint_state(0, names, (2, 2, 0))] * 3, names) is None  # no effort
    assert joint_state_doubles([_joint_state(0, names, (0, 2, 2))] * 3, names) is None  # no position
    assert joint_state_doubles(same, ['left_motor', 'missing']) is None
    big_endian = [b'\x00\x00' + d[2:] for d in same]
    assert joint_state_doubles(big_endian, names) is None
    assert joint_state_doubles([], names) is None


def test_odometry_matches_the_type_store_and_other_frames_are_refused() -> None:
    raw = [_odometry(k) for k in range(40)]
    got = header_doubles(raw, 2, 85)
    assert got is not None
    for row, data in zip(got, raw, strict=True):
        msg: Any = STORE.deserialize_cdr(data, 'nav_msgs/msg/Odometry')  # a run-time message class
        pose, twist = msg.pose.pose, msg.twist.twist
        o = pose.orientation
        assert row[:7].tolist() == [pose.position.x, pose.position.y, pose.position.z, o.x, o.y, o.z, o.w]
        assert row[7:43].tolist() == msg.pose.covariance.tolist()
        assert (row[43], row[48]) == (twist.linear.x, twist.angular.z)
    assert header_doubles([*raw, _odometry(50, frame='map')], 2, 85) is None  # length changes
    assert header_doubles([*raw, _odometry(50, frame='odox')], 2, 85) is None  # same length, other bytes
    assert header_doubles(raw, 1, 85) is None  # not this layout


def test_decode_gives_the_same_arrays_one_by_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """decode_joint_arrays / decode_planar_poses with and without the vectorized path, same bag."""
    from skidsteer_power.bag_io import decode, open_bag

    path = tmp_path / 'b.mcap'
    names = ['left_motor', 'right_motor']
    with BagWriter(path) as writer:
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        odom = writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        for k in range(30):
            writer.write(js, 10**9 + k * 10**7, _joint_state(k, names))
            writer.write(odom, 10**9 + k * 10**7 + 1, _odometry(k))
    with open_bag(path) as bag:
        fast_js = decode_joint_arrays(bag, '/joint_states', bag.start_ns, names)
        fast_poses = decode_planar_poses(bag, '/odom', bag.start_ns)
        monkeypatch.setattr(decode, 'joint_state_doubles', lambda raw, names: None)
        monkeypatch.setattr(decode, 'header_doubles', lambda raw, strings, count: None)
        slow_js = decode_joint_arrays(bag, '/joint_states', bag.start_ns, names)
        slow_poses = decode_planar_poses(bag, '/odom', bag.start_ns)
    for a, b in zip((*fast_js, *fast_poses), (*slow_js, *slow_poses), strict=True):
        np.testing.assert_array_equal(a, b)
    assert fast_js[4].all() and fast_poses[0].size == 30
    assert all(math.isfinite(v) for v in fast_poses[2])
