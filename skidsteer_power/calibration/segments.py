"""Steady segments of a drive recording: constant command, settled motion, averaged measurements.

Calibration compares the model with the robot only where both describe the same thing: a steady
state (chapter 3: the skid-steer models solve for steady turning). A segment is a run of identical
``cmd_vel`` commands (no gap longer than ``gap_s``); its first ``settle_s`` seconds are dropped
(acceleration and sinkage transients), and what is left must be at least ``min_s`` long and settled:
the mean motor speed of each side may differ between the window's two halves by no more than
``settle_tol`` of its value (or ``settle_abs_rad_s`` at the motor, whichever is larger). A window that
is not settled loses its first half until it is, or until it is shorter than ``min_s`` (teleoperated
driving ramps: the settled tail of a hold still counts). Commands within ``cmd_tol`` of each other are
one hold (a joystick's jitter does not cut a hold into pieces).

The measured motion of a segment (see :class:`SegmentOptions` for which topic) is the mean body
twist of ``nav_msgs/Odometry`` (linear.x [m/s], angular.z [rad/s], REP 103) over the window, or, for
pose-only topics (PoseStamped), the path length over time and the slope of the unwrapped heading
from the orientation quaternion. Without any pose topic the command itself is used (and the segment
says so).

A recording without joint_states (cmd_vel and a motion topic only: many robots record no wheel
speeds) gives motion-only segments: a window is settled when its measured motion is (the mean
forward speed and yaw rate of its halves within ``settle_tol``, or :data:`MOTION_SETTLE_ABS`), and
it carries no wheel speed, torque or power, so only the ground's slip can be fitted to it
(``--fit auto`` fits the motion) and no drive controller limit can be identified from it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skidsteer_power.bag_io.decode import decode_joint_arrays, decode_twists
from skidsteer_power.bag_io.reader import BagReader, open_bag
from skidsteer_power.errors import InputError
from skidsteer_power.estimator.inputs import TEST_ROBOT_JOINTS, InputLimits, JointReader
from skidsteer_power.estimator.measured import apply_to_joint_arrays, source_in_bag
from skidsteer_power.powertrain.motor import MotorConstants, terminal_power
from skidsteer_power.powertrain.power_flow import Powertrain

MOTION_SETTLE_ABS = (0.02, 0.02)
"""Without wheel speeds (no joint_states): the drift of a window's mean forward speed [m/s] and yaw
rate [rad/s] between its halves always allowed (ASSUMED: the calibration's noise scales of a steady
window's mean motion, fit.SPEED_SCALE_M_S and YAW_SCALE_RAD_S)."""

POSE_TYPES = (
    'nav_msgs/msg/Odometry',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped',
)
IMU_TYPE = 'sensor_msgs/msg/Imu'
MOTION_TYPES = (*POSE_TYPES, IMU_TYPE)
MAX_HALVINGS = 4  # a window not settled loses its first half at most this often


@dataclass(frozen=True)
class SegmentOptions:
    """How segments are cut (times in s, tolerances relative unless stated).

    settle_s : start of each constant-command run left out [s]; min_s : shortest window kept [s];
    gap_s : a pause in commands longer than this ends a run [s]; cmd_tol : commands closer than this
    (m/s, rad/s) are the same command; settle_tol : allowed relative drift of the mean motor speed
    between the window's halves [-]; settle_abs_rad_s : the same drift always allowed, at the motor
    [rad/s]; odom_topic : the topic with the true body motion (:data:`MOTION_TYPES`; '' = ground
    truth if the bag has a ``*ground_truth*`` topic, else odom, else any pose topic; with or without
    the leading '/'). Wheel odometry dead-reckons from the motor speeds, so it does not see slip
    (module doc).
    """

    settle_s: float = 1.5
    min_s: float = 1.0
    gap_s: float = 1.0
    cmd_tol: float = 0.01
    settle_tol: float = 0.1
    settle_abs_rad_s: float = 2.0
    cmd_vel_topic: str = '/cmd_vel'
    joint_states_topic: str = '/joint_states'
    odom_topic: str = ''
    extra_types: Mapping[str, str] | None = None  # .msg texts by type name (--msg): types the bag lacks


@dataclass
class Recording:
    """Decoded inputs of one bag; times in s from the bag's start."""

    source: str
    cmd_t: np.ndarray
    cmd: np.ndarray  # (n, 2) V [m/s], yaw rate [rad/s]
    js_t: np.ndarray
    omega: np.ndarray  # (n, 2) motor shaft speed [rad/s]
    torque: np.ndarray  # (n, 2) Kt*I [N m]
    pose_t: np.ndarray
    pose_xy: np.ndarray  # (n, 2) [m]
    pose_yaw: np.ndarray  # (n,) heading [rad]
    twist: np.ndarray | None  # (n, 2) odometry body twist V [m/s], yaw rate [rad/s], or None
    gyro: np.ndarray | None = None  # (n,) IMU yaw rate [rad/s] at pose_t (an Imu topic), or None
    battery: np.ndarray | None = None  # (n, 2) measured battery-side power V x I [W] at js_t, or None
    battery_total: bool = False  # the battery power is one whole-robot reading, split half per side


@dataclass(frozen=True)
class SteadyWindow:
    """One steady window of a recording (not a held command: that is
    :class:`skidsteer_power.commands.Segment`), SI units, per side (left, right) where a pair.

    speed_m_s, yaw_rate_rad_s : measured motion (``motion_source`` says from what) [m/s], [rad/s]
    command : the commanded (V, yaw rate); duration_s : window length [s]; samples : joint_states
    count; motor_torque_Nm, motor_omega_rad_s : window means at the motor shaft [N m], [rad/s];
    torque_std_Nm : sample standard deviation of the torque [N m]; terminal_W : mean motor
    terminal power with copper loss [W]; battery_W : measured electrical (battery-side, V x I) power
    per side [W] (NaN: not measured); battery_total : that power is one whole-robot reading split
    half per side (only the sum is measured); source : bag path.
    """

    source: str
    start_s: float
    duration_s: float
    command: tuple[float, float]
    speed_m_s: float
    yaw_rate_rad_s: float
    motion_source: str
    samples: int
    motor_torque_Nm: tuple[float, float]
    motor_omega_rad_s: tuple[float, float]
    torque_std_Nm: tuple[float, float]
    terminal_W: tuple[float, float] = (math.nan, math.nan)
    battery_W: tuple[float, float] = (math.nan, math.nan)
    battery_total: bool = False


def _pose_topic(bag: BagReader, wanted: str) -> str:
    """``wanted`` if given (with or without the leading '/'); else ground truth first (it sees
    slip), then odom, then any pose topic."""
    poses = [t for t, info in bag.topics.items() if info.msgtype in MOTION_TYPES]
    if wanted:
        for name in (wanted, '/' + wanted.lstrip('/')):
            if name in poses:
                return name
        raise InputError(f'{bag.path}: no odometry or pose topic {wanted} ({", ".join(MOTION_TYPES)})')
    poses = [t for t in poses if bag.topics[t].msgtype in POSE_TYPES]
    truth = [t for t in poses if 'ground_truth' in t]
    odom = [t for t in poses if t.lstrip('/') == 'odom']
    return next(iter([*truth, *odom, *poses]), '')


def _quaternion_yaw(q: object) -> float:
    x, y, z, w = (float(getattr(q, k)) for k in ('x', 'y', 'z', 'w'))
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _decode_gyro(bag: BagReader, topic: str, t0: int) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], yaw rate angular_velocity.z [rad/s]) of a sensor_msgs/Imu topic."""
    t, w = [], []
    for message, msg in bag.decoded(topic):
        t.append((message.timestamp_ns - t0) * 1e-9)
        w.append(float(msg.angular_velocity.z))
    return np.array(t, dtype=float), np.array(w, dtype=float)


def _decode_poses(
    bag: BagReader, topic: str, t0: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    msgtype = bag.topics[topic].msgtype
    odometry = msgtype == 'nav_msgs/msg/Odometry'
    nested = odometry or msgtype == 'geometry_msgs/msg/PoseWithCovarianceStamped'
    t, xy, yaw, twist = [], [], [], []
    for message, msg in bag.decoded(topic):
        pose = msg.pose.pose if nested else msg.pose
        t.append((message.timestamp_ns - t0) * 1e-9)
        xy.append((pose.position.x, pose.position.y))
        yaw.append(_quaternion_yaw(pose.orientation))
        if odometry:
            twist.append((msg.twist.twist.linear.x, msg.twist.twist.angular.z))
    twist_arr = np.array(twist, dtype=float).reshape(-1, 2) if odometry else None
    return np.array(t), np.array(xy, dtype=float).reshape(-1, 2), np.array(yaw), twist_arr


def side_readings(
    reader: JointReader,
    names: tuple[str, ...],
    js_t: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    effort: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-side motor-equivalent speed (n, 2) [rad/s] and torque (n, 2) [N m] of decoded joint_states
    rows, through the estimator's own :class:`JointReader` (any joints per side, effort as torque or
    current, at the motor or the wheel); ``ok`` (n,) is False where a row gives no reading. A row
    without any effort (a robot publishing velocities only) gives its speed and a NaN torque."""
    n = js_t.size
    omega, torque, ok = np.full((n, 2), np.nan), np.full((n, 2), np.nan), np.zeros(n, bool)
    no_effort = np.all(np.isnan(effort), axis=1) if effort.size else np.ones(n, bool)
    for i in range(n):
        row_effort = np.zeros(len(names)) if no_effort[i] else effort[i]
        try:
            reading = reader.read(
                names, position[i].tolist(), velocity[i].tolist(), row_effort.tolist(), js_t[i]
            )
        except InputError:
            continue
        if reading is not None:
            omega[i], ok[i] = reading[0], True
            torque[i] = (math.nan, math.nan) if no_effort[i] else reading[1]
    return omega, torque, ok


def read_recording(
    path: str | Path,
    options: SegmentOptions | None = None,
    reader: JointReader | None = None,
    *,
    need_joints: bool = False,
) -> Recording:
    """Decode cmd_vel, joint_states and odometry/poses of one bag; InputError if cmd_vel is missing,
    or joint_states where ``need_joints`` (a fit to torque), or both joint_states and a motion topic.

    ``reader`` maps the joints to the sides (the vehicle file's ``joints:``; default: the test
    robot's left_motor/right_motor, effort = Kt I at the motor).
    """
    options = options or SegmentOptions()
    reader = reader or JointReader(TEST_ROBOT_JOINTS, 1.0, 1.0, InputLimits())
    with open_bag(Path(path), extra_types=options.extra_types) as bag:
        t0 = bag.start_ns
        if options.cmd_vel_topic not in bag.topics:
            raise InputError(f'{path}: no {options.cmd_vel_topic} topic: no commands to cut segments from')
        topic = _pose_topic(bag, options.odom_topic)
        has_joints = options.joint_states_topic in bag.topics
        if not has_joints and need_joints:
            raise InputError(
                f'{path}: no {options.joint_states_topic} topic: no motor effort to fit to '
                '(--fit auto fits the ground to the recorded motion instead)'
            )
        if not has_joints and not topic:
            raise InputError(
                f'{path}: no {options.joint_states_topic} topic and no odometry, pose or IMU topic: '
                'neither torque nor motion to fit to'
            )
        cmd_t, cmd = decode_twists(bag, options.cmd_vel_topic, t0)
        if has_joints:
            names = reader.map.joints
            js_t, position, velocity, effort, present = decode_joint_arrays(
                bag, options.joint_states_topic, t0, names
            )
            (position, velocity, effort), _, _ = apply_to_joint_arrays(
                bag, reader.map, t0, js_t, (position, velocity, effort), present
            )
            omega, torque, ok = side_readings(reader, names, js_t, position, velocity, effort)
        else:  # motion only (module doc): no wheel speed, torque or power
            js_t, omega, torque, ok = np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, bool)
        gyro = None
        if topic and bag.topics[topic].msgtype == IMU_TYPE:
            pose_t, gyro = _decode_gyro(bag, topic, t0)
            pose_xy, pose_yaw, twist = np.zeros((pose_t.size, 2)), np.zeros(pose_t.size), None
        elif topic:
            pose_t, pose_xy, pose_yaw, twist = _decode_poses(bag, topic, t0)
        else:
            pose_t, pose_xy, pose_yaw, twist = np.zeros(0), np.zeros((0, 2)), np.zeros(0), None
        total = _measures_total(bag, reader)
    good = ok & np.all(np.isfinite(omega), axis=1)
    battery = None
    if reader.map.measures_battery:  # the vehicle's measured_power: the effort is each side's V x I [W]
        battery, torque = torque[good], np.full_like(torque[good], np.nan)
    else:
        torque = torque[good]
    return Recording(
        str(path),
        cmd_t,
        cmd,
        js_t[good],
        omega[good],
        torque,
        pose_t,
        pose_xy,
        pose_yaw,
        twist,
        gyro,
        battery,
        total,
    )


def _measures_total(bag: BagReader, reader: JointReader) -> bool:
    """True when the vehicle's measured power in ``bag`` is one whole-robot reading (``total:``)."""
    if not reader.map.measures_battery:
        return False
    source, _ = source_in_bag(bag, reader.map.measured_power)
    return source is not None and source.total is not None


def command_runs(
    cmd_t: np.ndarray, cmd: np.ndarray, options: SegmentOptions
) -> list[tuple[float, float, int]]:
    """(start [s], end [s], index of a command) of each run of identical commands."""
    if cmd_t.size == 0:
        return []
    change = np.any(np.abs(np.diff(cmd, axis=0)) > options.cmd_tol, axis=1)
    gap = np.diff(cmd_t) > options.gap_s
    breaks = np.flatnonzero(change | gap) + 1
    starts = np.r_[0, breaks]
    ends = np.r_[breaks, cmd_t.size]
    period = float(np.median(np.diff(cmd_t))) if cmd_t.size > 1 else 0.0
    runs = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        # a run lasts until the next (different) command, or one period after its last if it ends
        # in a gap or the bag's end
        end = cmd_t[b] if b < cmd_t.size and not gap[b - 1] else cmd_t[b - 1] + period
        runs.append((float(cmd_t[a]), float(end), a))
    return runs


def _measured_motion(
    rec: Recording, lo: float, hi: float, command: tuple[float, float]
) -> tuple[float, float, str]:
    sel = (rec.pose_t >= lo) & (rec.pose_t <= hi)
    if np.count_nonzero(sel) < 3:
        return command[0], command[1], 'command'
    if rec.gyro is not None:
        return math.nan, float(rec.gyro[sel].mean()), 'imu yaw rate'
    if rec.twist is not None:
        v, w = rec.twist[sel].mean(axis=0)
        return float(v), float(w), 'odometry twist'
    t, xy = rec.pose_t[sel], rec.pose_xy[sel]
    heading = np.unwrap(rec.pose_yaw[sel])
    yaw_rate = float(np.polyfit(t - t[0], heading, 1)[0])
    path = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
    speed = math.copysign(path / max(t[-1] - t[0], 1e-9), command[0] if command[0] != 0 else 1.0)
    return speed, yaw_rate, 'pose'


def find_segments(
    rec: Recording, options: SegmentOptions | None = None, motor: MotorConstants | None = None
) -> tuple[list[SteadyWindow], dict[str, int]]:
    """Steady segments of ``rec`` and the count of runs dropped per reason (``motor``: for power; the
    vehicle's powertrain motor, default the test robot's, :meth:`Powertrain.default_test_robot`)."""
    options = options or SegmentOptions()
    motor = motor or Powertrain.default_test_robot().motor
    dropped = {'standing': 0, 'too_short': 0, 'not_settled': 0}
    segments = []
    for start, end, k in command_runs(rec.cmd_t, rec.cmd, options):
        held = rec.cmd[(rec.cmd_t >= start) & (rec.cmd_t < end)]
        mid = np.median(held, axis=0) if held.size else rec.cmd[k]  # the hold's command (cmd_tol)
        command = (float(mid[0]), float(mid[1]))
        if abs(command[0]) <= options.cmd_tol and abs(command[1]) <= options.cmd_tol:
            dropped['standing'] += 1
            continue
        window = settled_window(rec, start + options.settle_s, end, options)
        if isinstance(window, str):
            dropped[window] += 1
            continue
        lo, hi, sel = window
        n = int(np.count_nonzero(sel))
        torque = rec.torque[sel]
        speed, yaw_rate, motion = _measured_motion(rec, lo, hi, command)
        segments.append(
            SteadyWindow(
                source=rec.source,
                start_s=lo,
                duration_s=hi - lo,
                command=command,
                speed_m_s=speed,
                yaw_rate_rad_s=yaw_rate,
                motion_source=motion,
                samples=n,
                motor_torque_Nm=_mean_pair(torque),
                motor_omega_rad_s=_mean_pair(rec.omega[sel]),
                torque_std_Nm=_std_pair(torque),
                terminal_W=_mean_terminal_power(rec, sel, motor),
                battery_W=_mean_pair(rec.battery[sel]) if rec.battery is not None else (math.nan, math.nan),
                battery_total=rec.battery_total,
            )
        )
    return segments, dropped


def settled_window(
    rec: Recording, lo: float, hi: float, options: SegmentOptions
) -> tuple[float, float, np.ndarray] | str:
    """(start [s], end [s], joint_states mask) of the settled part of the hold [lo, hi), or why
    there is none ('too_short' | 'not_settled'): a window not settled loses its first half, at most
    :data:`MAX_HALVINGS` times, while it stays at least ``min_s`` long (module doc). Without
    joint_states the measured motion must settle (:func:`motion_samples`); the mask is then empty."""
    motion_only = rec.js_t.size == 0
    t, values = motion_samples(rec) if motion_only else (rec.js_t, rec.omega)
    floor = np.array(MOTION_SETTLE_ABS) if motion_only else np.full(2, options.settle_abs_rad_s)
    measured = np.all(np.isfinite(values), axis=0)  # a gyro gives no forward speed: its yaw rate only
    values, floor = values[:, measured], floor[measured]
    for attempt in range(MAX_HALVINGS + 1):
        sel = (t >= lo) & (t < hi)
        n = int(np.count_nonzero(sel))
        if hi - lo < options.min_s or n < 6:
            return 'too_short' if attempt == 0 else 'not_settled'
        held = values[sel]
        half = n // 2
        first, second = held[:half].mean(axis=0), held[half:].mean(axis=0)
        allowed = np.maximum(options.settle_tol * np.abs(held.mean(axis=0)), floor)
        if not np.any(np.abs(first - second) > allowed):
            return lo, hi, (rec.js_t >= lo) & (rec.js_t < hi)
        lo = 0.5 * (lo + hi)
    return 'not_settled'


def motion_samples(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(t (n,) [s], measured (V [m/s], yaw rate [rad/s]) (n, 2)) of the recording's motion topic: an
    odometry twist, a gyro's yaw rate (V NaN), or the pose's differences (path speed, heading rate)."""
    t = rec.pose_t
    if rec.twist is not None:
        return t, rec.twist
    if rec.gyro is not None:
        return t, np.column_stack([np.full(t.size, np.nan), rec.gyro])
    if t.size < 2:
        return t, np.zeros((t.size, 2))
    dt = np.maximum(np.diff(t), 1e-9)
    speed = np.hypot(*np.diff(rec.pose_xy, axis=0).T) / dt
    yaw_rate = np.diff(np.unwrap(rec.pose_yaw)) / dt
    return t[1:], np.column_stack([speed, yaw_rate])


def _mean_pair(values: np.ndarray) -> tuple[float, float]:
    """Per-column mean of the finite entries of (n, 2) ``values`` (NaN for a column without one)."""
    out = []
    for k in range(2):
        col = values[:, k][np.isfinite(values[:, k])]
        out.append(float(col.mean()) if col.size else math.nan)
    return out[0], out[1]


def _std_pair(values: np.ndarray) -> tuple[float, float]:
    """Per-column sample standard deviation of the finite entries (NaN with fewer than two)."""
    out = []
    for k in range(2):
        col = values[:, k][np.isfinite(values[:, k])]
        out.append(float(col.std(ddof=1)) if col.size > 1 else math.nan)
    return out[0], out[1]


def _mean_terminal_power(rec: Recording, sel: np.ndarray, motor: MotorConstants) -> tuple[float, float]:
    """Mean motor terminal power per side over the window [W] (with copper loss, as measured.py)."""
    return _mean_pair(np.asarray(terminal_power(motor, rec.torque[sel], rec.omega[sel])))
