"""Decode a bag topic into numpy arrays: commands, joint states, planar poses.

Times are receive times [s] from ``t0_ns`` (commands on the real robot are often unstamped).
Decoding goes through the rosbags type store, so any definition the reader knows works.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from skidsteer_power.bags.reader import BagReader
from skidsteer_power.errors import InputError

NS = 1e9
TWIST_TYPES = ('geometry_msgs/msg/Twist', 'geometry_msgs/msg/TwistStamped')


def _check_type(bag: BagReader, topic: str, types: Sequence[str]) -> str:
    msgtype = bag.topics[topic].msgtype
    if msgtype not in types:
        raise InputError(f'{topic} is {msgtype}, expected {" or ".join(types)}')
    return msgtype


# CDR of a geometry_msgs/Twist: 4-byte encapsulation header, then six float64 (no padding needed).
_CDR_LITTLE_ENDIAN = b'\x00\x01'
_TWIST_SIZE = 4 + 6 * 8


def twists_vectorized(raw: list[bytes]) -> np.ndarray | None:
    """(n, 2) linear.x [m/s], angular.z [rad/s] of little-endian CDR Twists in one numpy view.

    None when any message is not a plain little-endian Twist (then decode one by one). Measured on a
    60,000-message topic: ~0.05 s against ~0.3 s through the generic deserializer.
    """
    if not raw or any(len(d) != _TWIST_SIZE or d[:2] != _CDR_LITTLE_ENDIAN for d in raw):
        return None
    table = np.frombuffer(b''.join(raw), dtype=np.uint8).reshape(len(raw), _TWIST_SIZE)
    values = np.ascontiguousarray(table[:, 4:]).view('<f8')
    return values[:, [0, 5]].astype(float)


def decode_twists(bag: BagReader, topic: str, t0_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], (n, 2) array of linear.x [m/s], angular.z [rad/s]) of a Twist/TwistStamped topic."""
    stamped = _check_type(bag, topic, TWIST_TYPES).endswith('Stamped')
    if not stamped:
        messages = list(bag.messages([topic]))
        fast = twists_vectorized([m.data for m in messages])
        if fast is not None:
            t = np.array([m.timestamp_ns - t0_ns for m in messages], dtype=float) / NS
            return t, fast
    t, values = [], []
    for message in bag.messages([topic]):
        msg = bag.deserialize(message)
        twist = msg.twist if stamped else msg
        t.append(message.timestamp_ns - t0_ns)
        values.append((twist.linear.x, twist.angular.z))
    return np.array(t, dtype=float) / NS, np.array(values, dtype=float).reshape(-1, 2)


def decode_joint_states(
    bag: BagReader, topic: str, t0_ns: int, names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], velocity (n, k), effort (n, k), ok (n,)) for joints ``names`` of a JointState topic.

    ``ok`` is False where a joint or its velocity/effort is missing (those entries are NaN).
    An absent topic gives empty arrays.
    """
    k = len(names)
    if topic not in bag.topics:
        return np.zeros(0), np.zeros((0, k)), np.zeros((0, k)), np.zeros(0, bool)
    _check_type(bag, topic, ('sensor_msgs/msg/JointState',))
    t, velocity, effort, ok = [], [], [], []
    nan_row = (np.nan,) * k
    for message in bag.messages([topic]):
        msg = bag.deserialize(message)
        t.append(message.timestamp_ns - t0_ns)
        index = {name: i for i, name in enumerate(msg.name)}
        try:
            rows = [index[name] for name in names]
            velocity.append(tuple(msg.velocity[rows]))
            effort.append(tuple(msg.effort[rows]))
            ok.append(True)
        except (KeyError, IndexError):
            velocity.append(nan_row)
            effort.append(nan_row)
            ok.append(False)
    return (
        np.array(t, dtype=float) / NS,
        np.array(velocity, dtype=float).reshape(-1, k),
        np.array(effort, dtype=float).reshape(-1, k),
        np.array(ok, dtype=bool),
    )


def decode_poses(bag: BagReader, topic: str, t0_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], (n, 2) positions x, y [m]) of an Odometry, PoseStamped or PoseWithCovarianceStamped topic."""
    msgtype = bag.topics[topic].msgtype
    nested = msgtype in ('nav_msgs/msg/Odometry', 'geometry_msgs/msg/PoseWithCovarianceStamped')
    t, xy = [], []
    for message in bag.messages([topic]):
        msg = bag.deserialize(message)
        position = (msg.pose.pose if nested else msg.pose).position
        t.append(message.timestamp_ns - t0_ns)
        xy.append((position.x, position.y))
    return np.array(t, dtype=float) / NS, np.array(xy, dtype=float).reshape(-1, 2)
