"""Synthetic drive bags: constant-command segments of an ideal (no-slip) unicycle, for tests and benchmarks.

Nothing here is a measurement. The trace integrates the commanded forward speed V [m/s] and yaw rate
[rad/s] exactly (a circle of radius V / yaw rate per segment), so trace analysis has a known answer.
Joint states carry kinematic motor speeds (side speed V -/+ yaw rate * B / 2 over the drive radius,
times the gear ratio) and a caller-supplied effort; serialization uses the rosbags Jazzy type store,
so no ROS installation is needed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.commands import Segment

if TYPE_CHECKING:
    from rosbags.typesys.store import MsgType

    MessageTypes: TypeAlias = dict[str, type[MsgType]]  # a typestore's classes by message type name

NS = 1_000_000_000
MotorArrays = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
START_NS = 1_700_000_000 * NS  # an arbitrary epoch time for synthetic bags [ns]


@dataclass(frozen=True)
class DriveSamples:
    """Sampled drive: time [s from start], commands, pose (x, y [m], heading [rad]) per sample."""

    t: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray


def sample_drive(segments: Sequence[Segment], rate_hz: float) -> DriveSamples:
    """Sample the ideal unicycle driving ``segments`` at ``rate_hz`` [Hz]; exact per-step integration."""
    durations = np.array([s.duration_s for s in segments], dtype=float)
    n = max(1, round(durations.sum() * rate_hz))
    t = np.arange(n) / rate_hz
    index = np.minimum(np.searchsorted(np.cumsum(durations), t, side='right'), len(segments) - 1)
    speed = np.array([s.speed_m_s for s in segments])[index]
    yaw = np.array([s.yaw_rate_rad_s for s in segments])[index]
    dt = 1.0 / rate_hz
    heading = np.concatenate([[0.0], np.cumsum(yaw * dt)[:-1]])
    # Exact displacement of a constant (V, r) step: chord of the arc (sinc form covers r = 0).
    half = yaw * dt / 2
    step = speed * dt * np.sinc(half / np.pi)
    dx = step * np.cos(heading + half)
    dy = step * np.sin(heading + half)
    x = np.concatenate([[0.0], np.cumsum(dx)[:-1]])
    y = np.concatenate([[0.0], np.cumsum(dy)[:-1]])
    return DriveSamples(t, speed, yaw, x, y, heading)


def motor_speeds(
    samples: DriveSamples, tread_m: float, drive_radius_m: float, gear_ratio: float
) -> tuple[np.ndarray, np.ndarray]:
    """Kinematic (no-slip) motor shaft speeds [rad/s] of the left and right side."""
    left = (samples.speed - samples.yaw_rate * tread_m / 2) / drive_radius_m * gear_ratio
    right = (samples.speed + samples.yaw_rate * tread_m / 2) / drive_radius_m * gear_ratio
    return left, right


def write_drive_bag(
    path: str | Path,
    segments: Sequence[Segment],
    *,
    rate_hz: float = 100.0,
    odom_hz: float | None = 10.0,
    joint_states: bool = True,
    tread_m: float = 0.4,
    drive_radius_m: float = 0.1,
    gear_ratio: float = 12.0,
    motors: Callable[[DriveSamples], MotorArrays] | None = None,
    start_ns: int = START_NS,
) -> DriveSamples:
    """Write /cmd_vel (Twist), /joint_states (JointState) at ``rate_hz`` and /odom at ``odom_hz`` [Hz].

    ``motors(samples) -> (omega_left, omega_right, torque_left, torque_right)`` gives the joint
    states (motor shaft speed [rad/s], Kt*I [N m]); default: kinematic speeds and 0.1 N m.
    Returns the samples written.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    samples = sample_drive(segments, rate_hz)
    if motors is None:
        left_w, right_w = motor_speeds(samples, tread_m, drive_radius_m, gear_ratio)
        left_e = right_e = np.full(samples.t.size, 0.1)
    else:
        left_w, right_w, left_e, right_e = (np.asarray(a, dtype=float) for a in motors(samples))
    stamps = start_ns + np.round(samples.t * NS).astype(np.int64)
    odom_every = 0 if odom_hz is None else max(1, round(rate_hz / odom_hz))
    Twist, Vector3 = types['geometry_msgs/msg/Twist'], types['geometry_msgs/msg/Vector3']
    with BagWriter(path) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState') if joint_states else None
        odom = writer.add_topic('/odom', 'nav_msgs/msg/Odometry') if odom_every else None
        for i, stamp in enumerate(stamps.tolist()):
            linear, angular = float(samples.speed[i]), float(samples.yaw_rate[i])
            twist = Twist(Vector3(linear, 0.0, 0.0), Vector3(0.0, 0.0, angular))
            writer.write(cmd, stamp, store.serialize_cdr(twist, 'geometry_msgs/msg/Twist'))
            if js is not None:
                msg = _joint_state(types, stamp, (left_w[i], right_w[i]), (left_e[i], right_e[i]))
                writer.write(js, stamp + 1000, store.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))
            if odom is not None and i % odom_every == 0:
                msg = _odometry(types, stamp, samples, i)
                writer.write(odom, stamp + 2000, store.serialize_cdr(msg, 'nav_msgs/msg/Odometry'))
    return samples


def _header(types: MessageTypes, stamp_ns: int, frame: str) -> MsgType:
    sec, nsec = divmod(int(stamp_ns), NS)
    return types['std_msgs/msg/Header'](types['builtin_interfaces/msg/Time'](sec, nsec), frame)


def _joint_state(
    types: MessageTypes, stamp_ns: int, omega: tuple[float, float], torque: tuple[float, float]
) -> MsgType:
    return types['sensor_msgs/msg/JointState'](
        _header(types, stamp_ns, ''),
        ['left_motor', 'right_motor'],
        np.zeros(2),
        np.array(omega, dtype=float),
        np.array(torque, dtype=float),
    )


def _odometry(types: MessageTypes, stamp_ns: int, s: DriveSamples, i: int) -> MsgType:
    half = s.heading[i] / 2
    pose = types['geometry_msgs/msg/Pose'](
        types['geometry_msgs/msg/Point'](float(s.x[i]), float(s.y[i]), 0.0),
        types['geometry_msgs/msg/Quaternion'](0.0, 0.0, float(np.sin(half)), float(np.cos(half))),
    )
    vec = types['geometry_msgs/msg/Vector3']
    linear, angular = vec(float(s.speed[i]), 0.0, 0.0), vec(0.0, 0.0, float(s.yaw_rate[i]))
    twist = types['geometry_msgs/msg/Twist'](linear, angular)
    return types['nav_msgs/msg/Odometry'](
        _header(types, stamp_ns, 'odom'),
        'base_link',
        types['geometry_msgs/msg/PoseWithCovariance'](pose, np.zeros(36)),
        types['geometry_msgs/msg/TwistWithCovariance'](twist, np.zeros(36)),
    )


def write_command_csv(path: str | Path, segments: Sequence[Segment]) -> Path:
    """Write ``segments`` as a command CSV (t_s, speed_m_s, yaw_rate_rad_s; each row held until the
    next, the last row ends the run), the input of ``skidsteer-power simulate --commands``."""
    lines = ['t_s,speed_m_s,yaw_rate_rad_s']
    t = 0.0
    for s in segments:
        lines.append(f'{t:.6g},{s.speed_m_s:.6g},{s.yaw_rate_rad_s:.6g}')
        t += s.duration_s
    lines.append(f'{t:.6g},0,0')
    Path(path).write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return Path(path)
