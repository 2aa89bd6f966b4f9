"""Decode a bag topic into numpy arrays: commands, joint states, planar poses.

Times are receive times [s] from ``t0_ns`` (commands on the real robot are often unstamped).
Decoding goes through the rosbags type store, so any definition the reader knows works.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from skidsteer_power.bag_io.cdr_fixed import header_doubles, joint_state_doubles
from skidsteer_power.bag_io.reader import BagReader
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
    stamps_ns: list[int] = []
    values: list[tuple[float, float]] = []
    for message, msg in bag.decoded(topic):
        twist = msg.twist if stamped else msg
        stamps_ns.append(message.timestamp_ns - t0_ns)
        values.append((twist.linear.x, twist.angular.z))
    return np.array(stamps_ns, dtype=float) / NS, np.array(values, dtype=float).reshape(-1, 2)


def decode_joint_states(
    bag: BagReader, topic: str, t0_ns: int, names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], velocity (n, k), effort (n, k), ok (n,)) for joints ``names`` of a JointState topic.

    ``ok`` is False where a joint or its velocity/effort is missing (those entries are NaN).
    An absent topic gives empty arrays.
    """
    t, _, velocity, effort, present = decode_joint_arrays(bag, topic, t0_ns, names)
    ok = present & np.all(np.isfinite(velocity), axis=1) & np.all(np.isfinite(effort), axis=1)
    return t, np.where(ok[:, None], velocity, np.nan), np.where(ok[:, None], effort, np.nan), ok


def decode_joint_arrays(
    bag: BagReader, topic: str, t0_ns: int, names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], position (n, k), velocity (n, k), effort (n, k), present (n,)) for joints ``names``.

    Values are in the message's units (rad, rad/s, N m or A). ``present`` is False where a joint is
    missing from a message (its row is NaN); a missing or short position/velocity/effort array
    (ros2_control publishes only the state interfaces a joint has) gives NaN in that column.
    An absent topic gives empty arrays.
    """
    k = len(names)
    if topic not in bag.topics:
        empty = np.zeros((0, k))
        return np.zeros(0), empty, empty.copy(), empty.copy(), np.zeros(0, bool)
    _check_type(bag, topic, ('sensor_msgs/msg/JointState',))
    messages = list(bag.messages([topic]))
    fast = joint_state_doubles([m.data for m in messages], names)
    if fast is not None:
        t_fast = np.array([m.timestamp_ns - t0_ns for m in messages], dtype=float) / NS
        return t_fast, *fast, np.ones(len(messages), bool)
    t, present = [], []
    columns: dict[str, list[np.ndarray]] = {'position': [], 'velocity': [], 'effort': []}
    nan_row = np.full(k, np.nan)
    last_names: list[str] | None = None
    rows: list[int] = []
    for message, msg in bag.decoded(topic):
        t.append(message.timestamp_ns - t0_ns)
        if msg.name != last_names:  # joint order rarely changes: look the rows up once
            index = {name: i for i, name in enumerate(msg.name)}
            rows = [index.get(name, -1) for name in names]
            last_names = msg.name
        ok = min(rows) >= 0
        present.append(ok)
        top = max(rows)
        for field_name, column in columns.items():
            values = getattr(msg, field_name)
            column.append(values[rows] if ok and len(values) > top else nan_row)
    position, velocity, effort = (np.array(columns[f], dtype=float).reshape(-1, k) for f in columns)
    return np.array(t, dtype=float) / NS, position, velocity, effort, np.array(present, dtype=bool)


def decode_poses(bag: BagReader, topic: str, t0_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], (n, 2) positions x, y [m]) of an Odometry, PoseStamped or PoseWithCovarianceStamped topic."""
    t, xy, _ = decode_planar_poses(bag, topic, t0_ns)
    return t, xy


def decode_planar_poses(bag: BagReader, topic: str, t0_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], (n, 2) positions x, y [m], (n,) heading [rad]) of a pose topic (see :func:`decode_poses`).

    The heading is the yaw of the orientation quaternion (REP 103: about z, + = left).
    """
    t, xy, yaw, _ = decode_pose_twists(bag, topic, t0_ns)
    return t, xy, yaw


# doubles after the header of each pose type: strings in the header (Odometry: child_frame_id too),
# float64 count (pose 7, covariance 36, twist 6 + 36)
_POSE_LAYOUT = {
    'nav_msgs/msg/Odometry': (2, 85),
    'geometry_msgs/msg/PoseWithCovarianceStamped': (1, 43),
    'geometry_msgs/msg/PoseStamped': (1, 7),
}
_ODOM_TWIST = (43, 48)  # linear.x, angular.z among an Odometry's doubles


def _yaw(x: float, y: float, z: float, w: float) -> float:
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def decode_pose_twists(
    bag: BagReader, topic: str, t0_ns: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`decode_planar_poses` and, for an Odometry, its twist: (n, 2) linear.x [m/s], angular.z
    [rad/s] (None for the other pose types), read in one pass."""
    msgtype = bag.topics[topic].msgtype
    odometry = msgtype == 'nav_msgs/msg/Odometry'
    messages = list(bag.messages([topic]))
    fast = header_doubles([m.data for m in messages], *_POSE_LAYOUT[msgtype])
    if fast is not None:
        t = np.array([m.timestamp_ns - t0_ns for m in messages], dtype=float) / NS
        yaw = np.array([_yaw(*q) for q in fast[:, 3:7].tolist()], dtype=float)
        return t, fast[:, :2].copy(), yaw, fast[:, list(_ODOM_TWIST)] if odometry else None
    nested = msgtype in ('nav_msgs/msg/Odometry', 'geometry_msgs/msg/PoseWithCovarianceStamped')
    stamps, rows, twists = [], [], []
    for message, msg in bag.decoded(topic):
        pose = msg.pose.pose if nested else msg.pose
        q = pose.orientation
        stamps.append(message.timestamp_ns - t0_ns)
        rows.append((pose.position.x, pose.position.y, _yaw(q.x, q.y, q.z, q.w)))
        if odometry:
            twists.append((msg.twist.twist.linear.x, msg.twist.twist.angular.z))
    table = np.array(rows, dtype=float).reshape(-1, 3)
    twist = np.array(twists, dtype=float).reshape(-1, 2) if odometry else None
    return np.array(stamps, dtype=float) / NS, table[:, :2], table[:, 2], twist
