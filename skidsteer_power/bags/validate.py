"""Offline validation: the estimator run over a bag, compared with what the motors measured.

No ROS graph is needed. The bag's ``cmd_vel`` (Twist or TwistStamped: V [m/s], yaw rate [rad/s]) and
``joint_states`` (``left_motor``/``right_motor``: shaft speed [rad/s], effort = Kt*I [N m]) are fed in
receive-time order to :class:`skidsteer_power.estimator.EstimatorCore`, exactly as the live
``power_estimator`` node feeds it, so each joint_states sample is aligned with the prediction in force
when it arrived (zero-order hold of the last command). Compared per side at the motor: torque Kt*I
[N m] and terminal (electrical) power [W]; metrics over samples whose command is fresh: MAE, RMSE and
the error of the energy over the run [%].

Where the bag has odometry or poses, each constant-command segment gets a trace analysis: the
turning radius by the SVD circle fit of eqs. 7.8-7.10 and the mean forward speed
(:mod:`skidsteer_power.analysis.trace`), next to the commanded radius V / yaw rate. A bag without
motor data still gets predictions, predicted energy, battery state and trace analysis.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from skidsteer_power.analysis.trace import fit_circle, mean_speed
from skidsteer_power.bags.decode import decode_joint_states, decode_poses, decode_twists
from skidsteer_power.bags.reader import BagReader
from skidsteer_power.errors import ConfigError, InputError

LOG = logging.getLogger(__name__)

POSE_TYPES = (
    'nav_msgs/msg/Odometry',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped',
)
LIVE_PREDICTED_TOPIC = '/power/predicted'


@dataclass(frozen=True)
class ValidateOptions:
    """What to validate and where to write the report.

    vehicle : vehicle name in config/vehicles/ or YAML file; terrain : preset name or YAML file
    report_dir : folder for CSV, PNG, Markdown and JSON (created)
    *_topic : topic names in the bag; odom_topic may be any of :data:`POSE_TYPES`
    map_cache_dir : where the power map is cached (None: the estimator's default)
    battery_window_s : battery stepped with the mean power of windows this long [s] (0: per input)
    settle_s : start of each constant-command segment left out of the trace analysis [s]
    min_segment_s : shortest segment analysed [s]
    segment_gap_s : a pause in commands longer than this ends a segment [s] (teleop keyboards
        repeat a held key only after ~0.5 s, so this is longer than the estimator's staleness)
    plots : write PNG plots
    kinematics : what the estimator predicts from: 'cmd' (the command, as the live node), 'odom'
        (the twist of the Odometry ``odom_topic``) or 'ground_truth' (``/ground_truth/odom``)
    """

    vehicle: str
    terrain: str
    report_dir: str | Path
    cmd_vel_topic: str = '/cmd_vel'
    joint_states_topic: str = '/joint_states'
    odom_topic: str = '/odom'
    map_cache_dir: str | Path | None = None
    battery_window_s: float = 0.2
    settle_s: float = 0.5
    min_segment_s: float = 1.0
    segment_gap_s: float = 1.0
    plots: bool = True
    kinematics: str = 'cmd'


@dataclass
class Inputs:
    """Decoded bag inputs; times in s from the bag's first message."""

    cmd_t: np.ndarray
    cmd: np.ndarray  # (n, 2): V [m/s], yaw rate [rad/s]
    js_t: np.ndarray
    js_omega: np.ndarray  # (n, 2) motor shaft speed left, right [rad/s]
    js_torque: np.ndarray  # (n, 2) Kt*I left, right [N m]
    js_names_ok: np.ndarray  # (n,) bool: both motors present
    pose_t: np.ndarray
    pose_xy: np.ndarray  # (n, 2) [m]
    pose_topic: str = ''
    live_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    live_torque: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


@dataclass
class RunSeries:
    """Aligned time series of one estimator run; one row per joint_states (or cmd_vel) sample."""

    columns: dict[str, np.ndarray]
    rejected: dict[str, int]
    energy_J: dict[str, float]
    remaining_wh: float
    soc: float


SERIES_COLUMNS = (
    't_s',
    'speed_cmd_m_s',
    'yaw_rate_cmd_rad_s',
    'cmd_fresh',
    'predicted_torque_left_Nm',
    'predicted_torque_right_Nm',
    'measured_torque_left_Nm',
    'measured_torque_right_Nm',
    'predicted_power_left_W',
    'predicted_power_right_W',
    'measured_power_left_W',
    'measured_power_right_W',
    'predicted_axle_torque_left_Nm',
    'predicted_axle_torque_right_Nm',
    'predicted_battery_W',
    'measured_battery_W',
    'traction_margin',
    'soc',
)


def _topic_of_type(bag: BagReader, wanted: str, types: Sequence[str]) -> str:
    if wanted in bag.topics:
        return wanted if bag.topics[wanted].msgtype in types else ''
    return next((t for t, info in bag.topics.items() if info.msgtype in types), '')


def read_inputs(bag: BagReader, options: ValidateOptions) -> Inputs:
    """Decode commands, joint states, poses and the live node's predictions from ``bag``."""
    t0 = bag.start_ns
    cmd_topic = options.cmd_vel_topic if options.cmd_vel_topic in bag.topics else ''
    if not cmd_topic:
        raise InputError(f'{bag.path}: no {options.cmd_vel_topic} topic: nothing to predict from')
    cmd_t, cmd = decode_twists(bag, cmd_topic, t0)
    js_t, omega, torque, ok = decode_joint_states(
        bag, options.joint_states_topic, t0, ('left_motor', 'right_motor')
    )
    pose_topic = _topic_of_type(bag, options.odom_topic, POSE_TYPES)
    pose_t, pose_xy = decode_poses(bag, pose_topic, t0) if pose_topic else (np.zeros(0), np.zeros((0, 2)))
    live_t, _, live_torque, _ = decode_joint_states(
        bag, LIVE_PREDICTED_TOPIC, t0, ('left_motor', 'right_motor')
    )
    return Inputs(cmd_t, cmd, js_t, omega, torque, ok, pose_t, pose_xy, pose_topic, live_t, live_torque)


class WindowedBattery:
    """Steps the wrapped battery with the mean power of each ``window_s`` of steps [s].

    The estimator steps the battery at every input (100s per second of bag); offline that dominates
    the run time. Energy per window is kept exactly (sum of power x dt); only the battery's internal
    loss, which depends on power squared, sees the window mean instead of each sample -- a
    state-of-charge difference far below the battery model's own accuracy (see the test). Any read of
    the battery's state first flushes the open window, so what is read is up to date.
    """

    def __init__(self, battery: Any, window_s: float = 0.2) -> None:
        self._battery = battery
        self._window_s = window_s
        self._energy_J = 0.0
        self._dt_s = 0.0

    def step(self, power_W: float, dt_s: float) -> None:
        """Draw ``power_W`` [W] for ``dt_s`` [s] (buffered until the window is full)."""
        self._energy_J += power_W * dt_s
        self._dt_s += dt_s
        if self._dt_s >= self._window_s:
            self.flush()

    def flush(self) -> None:
        if self._dt_s > 0:
            self._battery.step(self._energy_J / self._dt_s, self._dt_s)
        self._energy_J = self._dt_s = 0.0

    @property
    def soc_at_last_flush(self) -> float:
        """State of charge [-] as of the last full window (no flush; for time-series columns)."""
        return self._battery.soc

    def __getattr__(self, name: str) -> Any:
        self.flush()
        return getattr(self._battery, name)


def build_core(options: ValidateOptions, predictor: Any = None, battery_window_s: float = 0.2) -> Any:
    """An :class:`EstimatorCore` for the vehicle and terrain; ``predictor`` None builds the map one."""
    from skidsteer_power.estimator import EstimatorCore, factory

    vehicle = factory.load_vehicle_config(options.vehicle)
    if predictor is None:
        try:
            predictor, _, _ = factory.map_predictor(vehicle, options.terrain, options.map_cache_dir)
        except ImportError as err:
            raise ConfigError(f'power maps are not available in this installation: {err}') from err
    else:
        factory.check_terrain(options.terrain)
    battery: Any = factory.battery_for(vehicle)
    if battery_window_s > 0:
        battery = WindowedBattery(battery, battery_window_s)
    return EstimatorCore(predictor, battery, factory.powertrain_for(vehicle))


def run_estimator(core: Any, inputs: Inputs) -> RunSeries:
    """Feed commands and joint states to ``core`` in time order; rows per joint_states sample.

    Without joint states the rows are the command samples (predictions only). No timer ticks: the
    battery integration is exact whenever it is advanced (each input advances it), and the time to
    empty is only wanted at the end.
    """
    from skidsteer_power.estimator.core import RejectedInput

    motor_data = inputs.js_t.size > 0
    times = np.concatenate([inputs.cmd_t, inputs.js_t])
    kinds = np.concatenate([np.zeros(inputs.cmd_t.size, np.int8), np.ones(inputs.js_t.size, np.int8)])
    index = np.concatenate([np.arange(inputs.cmd_t.size), np.arange(inputs.js_t.size)])
    order = np.lexsort((kinds, times))  # stable by time; a command first when stamps tie
    rejected = {'cmd_vel': 0, 'joint_states': 0}
    rows: list[tuple[float, ...]] = []
    soc_of = (
        (lambda b: b.soc_at_last_flush) if isinstance(core.battery, WindowedBattery) else (lambda b: b.soc)
    )
    names = ('left_motor', 'right_motor')
    cmd_timeout = core.settings.cmd_timeout_s
    for k in order.tolist():
        now = float(times[k])
        i = int(index[k])
        try:
            if kinds[k] == 0:
                core.on_command(float(inputs.cmd[i, 0]), float(inputs.cmd[i, 1]), now)
                if motor_data:
                    continue
                comparison = None
            else:
                if not inputs.js_names_ok[i]:
                    rejected['joint_states'] += 1
                    continue
                comparison = core.on_joint_state(names, inputs.js_omega[i], inputs.js_torque[i], now)
        except RejectedInput:
            rejected['cmd_vel' if kinds[k] == 0 else 'joint_states'] += 1
            continue
        fresh = core.prediction is not None and core.cmd_fresh.age_s(now) <= cmd_timeout
        rows.append(_row(now, core.prediction, fresh, comparison, soc_of(core.battery)))
    core.tick(float(times.max()) if times.size else 0.0)
    table = np.array(rows, dtype=float).reshape(-1, len(SERIES_COLUMNS))
    columns = {name: table[:, j] for j, name in enumerate(SERIES_COLUMNS)}
    return RunSeries(
        columns, rejected, dict(core.energy.energy_J), core.battery.remaining_wh, core.battery.soc
    )


def _row(now: float, p: Any, fresh: bool, comparison: Any, soc: float) -> tuple[float, ...]:
    """One row in :data:`SERIES_COLUMNS` order."""
    nan = math.nan
    if p is None:
        pred = (nan,) * 10
    else:
        pred = (p.speed_m_s, p.yaw_rate_rad_s, *p.motor_torque_Nm, *p.electrical_W, *p.terrain_torque_Nm,
                p.bus_total_W, p.traction_margin)  # fmt: skip
    if comparison is None:
        meas = (nan,) * 5
    else:
        m = comparison.measured
        meas = (*m.torque_Nm, *m.electrical_W, m.bus_total_W)
    return (now, pred[0], pred[1], float(fresh), pred[2], pred[3], meas[0], meas[1], pred[4], pred[5],
            meas[2], meas[3], pred[6], pred[7], pred[8], meas[4], pred[9], soc)  # fmt: skip


def _hold_durations(t: np.ndarray, cap_s: float) -> np.ndarray:
    """Zero-order-hold weight of each sample: time to the next one, at most ``cap_s`` [s]."""
    if t.size == 0:
        return t
    return np.minimum(np.diff(t, append=t[-1]), cap_s)


def error_metrics(series: RunSeries, hold_cap_s: float) -> dict[str, Any]:
    """MAE and RMSE per side of torque [N m] and power [W]; energy over the run and its error [%].

    Only rows with a fresh command and a measurement count. Energy is the zero-order-hold integral
    of both sides' terminal power over those rows (each held at most ``hold_cap_s`` [s]).
    """
    c = series.columns
    valid = (c['cmd_fresh'] > 0) & np.isfinite(c['measured_torque_left_Nm'])
    result: dict[str, Any] = {'samples_compared': int(valid.sum())}
    for quantity, unit in (('torque', 'Nm'), ('power', 'W')):
        for side in ('left', 'right'):
            error = (
                c[f'measured_{quantity}_{side}_{unit}'][valid]
                - c[f'predicted_{quantity}_{side}_{unit}'][valid]
            )
            result[f'{quantity}_{side}'] = {
                f'mae_{unit}': float(np.mean(np.abs(error))) if error.size else math.nan,
                f'rmse_{unit}': float(np.sqrt(np.mean(error**2))) if error.size else math.nan,
            }
    weights = _hold_durations(c['t_s'], hold_cap_s)
    fresh = c['cmd_fresh'] > 0
    predicted = c['predicted_power_left_W'] + c['predicted_power_right_W']
    measured = c['measured_power_left_W'] + c['measured_power_right_W']
    e_pred = (
        float(np.sum((predicted * weights)[valid]))
        if valid.any()
        else float(np.sum((predicted * weights)[fresh]))
    )
    e_meas = float(np.sum((measured * weights)[valid])) if valid.any() else math.nan
    result['energy_predicted_J'] = e_pred
    result['energy_measured_J'] = e_meas
    result['energy_error_pct'] = 100.0 * (e_pred - e_meas) / abs(e_meas) if abs(e_meas) > 1e-9 else math.nan
    return result


@dataclass(frozen=True)
class TraceSegment:
    """What the trace says about one held command (the command: commands.Segment); SI, inf = straight."""

    t_start_s: float
    t_end_s: float
    speed_cmd_m_s: float
    yaw_rate_cmd_rad_s: float
    radius_cmd_m: float
    points: int
    radius_m: float
    center_x_m: float
    center_y_m: float
    rms_residual_m: float
    speed_m_s: float
    note: str = ''


def command_segments(
    cmd_t: np.ndarray, cmd: np.ndarray, timeout_s: float, min_duration_s: float
) -> list[tuple[float, float, float, float]]:
    """(start, end, V, yaw rate) of runs of one repeated command, split where it goes stale [s].

    A run ends at its last command plus the timeout at most (the robot stops when commands stop).
    Runs shorter than ``min_duration_s`` and standstill runs (V = yaw rate = 0) are dropped.
    """
    if cmd_t.size == 0:
        return []
    change = np.any(np.diff(cmd, axis=0) != 0, axis=1) | (np.diff(cmd_t) > timeout_s)
    starts = np.concatenate([[0], np.flatnonzero(change) + 1])
    ends = np.concatenate([starts[1:], [cmd_t.size]])
    segments = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        end = min(cmd_t[b] if b < cmd_t.size else math.inf, cmd_t[b - 1] + timeout_s)
        speed, yaw = float(cmd[a, 0]), float(cmd[a, 1])
        if end - cmd_t[a] >= min_duration_s and (speed != 0 or yaw != 0):
            segments.append((float(cmd_t[a]), float(end), speed, yaw))
    return segments


def trace_segments(inputs: Inputs, options: ValidateOptions) -> list[TraceSegment]:
    """Trace analysis (eqs. 7.8-7.10) of every constant-command segment (a note says why where the
    poses are too few or collinear)."""
    result = []
    runs = command_segments(inputs.cmd_t, inputs.cmd, options.segment_gap_s, options.min_segment_s)
    for start, end, speed, yaw in runs:
        radius_cmd = speed / yaw if yaw != 0 else math.inf
        inside = (inputs.pose_t >= start + options.settle_s) & (inputs.pose_t <= end)
        t, xy = inputs.pose_t[inside], inputs.pose_xy[inside]
        keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
        t, xy = t[keep], xy[keep]
        fit, speed_m, note = None, math.nan, ''
        try:
            speed_m = mean_speed(t, xy[:, 0], xy[:, 1])
            fit = fit_circle(xy[:, 0], xy[:, 1])
        except InputError as err:
            note = str(err)
        result.append(
            TraceSegment(
                t_start_s=start,
                t_end_s=end,
                speed_cmd_m_s=speed,
                yaw_rate_cmd_rad_s=yaw,
                radius_cmd_m=abs(radius_cmd),
                points=int(t.size),
                radius_m=fit.radius_m if fit else (math.inf if 'collinear' in note else math.nan),
                center_x_m=fit.center_x_m if fit else math.nan,
                center_y_m=fit.center_y_m if fit else math.nan,
                rms_residual_m=fit.rms_residual_m if fit else math.nan,
                speed_m_s=speed_m,
                note=note,
            )
        )
    return result


LIVE_TOLERANCE_NM = 1e-6


def live_comparison(inputs: Inputs, predictor: Any) -> dict[str, Any] | None:
    """Offline predictions against the live node's ``power/predicted`` motor torques [N m].

    The node publishes one prediction per command it takes, in order, but may lag behind (a busy
    executor) or miss commands sent before it was matched; so live messages are matched in order
    to the commands' offline predictions (each live message to the next command at or after the
    previous match whose prediction agrees within 1e-6 N m). A live message with no such command
    is a mismatch; its difference is taken against the last command received before it.
    """
    if inputs.live_t.size == 0 or inputs.cmd_t.size == 0:
        return None
    offline = np.array([predictor.predict(float(v), float(r)).motor_torque_Nm for v, r in inputs.cmd])
    # Commands repeat: compare each live message with the distinct predictions only.
    unique, command_kind = np.unique(offline, axis=0, return_inverse=True)
    agrees = np.abs(inputs.live_torque[:, None, :] - unique[None, :, :]).max(axis=2) <= LIVE_TOLERANCE_NM
    positions = [np.flatnonzero(command_kind.ravel() == u) for u in range(len(unique))]
    matched, pointer, mismatched = 0, 0, []
    for k in range(inputs.live_t.size):
        found = _next_position([positions[u] for u in np.flatnonzero(agrees[k])], pointer)
        if found is not None:
            matched += 1
            pointer = found + 1
        else:
            mismatched.append(k)
    worst = 0.0
    if mismatched:
        which = np.searchsorted(inputs.cmd_t, inputs.live_t[mismatched], side='right') - 1
        which = np.maximum(which, 0)
        worst = float(np.abs(offline[which] - inputs.live_torque[mismatched]).max())
    return {
        'messages': int(inputs.live_t.size),
        'matching_within_1e-6': matched,
        'max_abs_torque_diff_Nm': worst,
        'commands_without_live_prediction': int(inputs.cmd_t.size - matched),
    }


def _next_position(sorted_positions: list[np.ndarray], start: int) -> int | None:
    """Smallest entry >= ``start`` over several sorted index arrays, or None."""
    found = None
    for positions in sorted_positions:
        i = int(np.searchsorted(positions, start))
        if i < positions.size and (found is None or positions[i] < found):
            found = int(positions[i])
    return found


KINEMATICS = ('cmd', 'odom', 'ground_truth')
GROUND_TRUTH_TOPIC = '/ground_truth/odom'


def motion_inputs(bag: BagReader, options: ValidateOptions, inputs: Inputs) -> tuple[str, Inputs] | None:
    """``inputs`` with the commands replaced by a measured twist (V [m/s], yaw rate [rad/s]) of an
    Odometry topic: ``/ground_truth/odom`` for 'ground_truth', ``odom_topic`` for 'odom'; for 'cmd'
    the ground truth if the bag has it, else ``odom_topic``. Returns (kinematics, inputs) or None."""
    if options.kinematics not in KINEMATICS:
        raise InputError(f'kinematics must be one of {", ".join(KINEMATICS)}, not {options.kinematics!r}')
    candidates = {'odom': ['odom'], 'ground_truth': ['ground_truth']}.get(
        options.kinematics, ['ground_truth', 'odom']
    )
    for kind in candidates:
        topic = GROUND_TRUTH_TOPIC if kind == 'ground_truth' else options.odom_topic
        if topic in bag.topics and bag.topics[topic].msgtype == 'nav_msgs/msg/Odometry':
            t, twist = [], []
            for message in bag.messages([topic]):
                msg = bag.deserialize(message).twist.twist
                t.append(message.timestamp_ns - bag.start_ns)
                twist.append((msg.linear.x, msg.angular.z))
            if t:
                cmd = np.array(twist, dtype=float).reshape(-1, 2)
                return kind, replace(inputs, cmd_t=np.array(t, dtype=float) / 1e9, cmd=cmd)
    return None


def validate(bag: BagReader, options: ValidateOptions, predictor: Any = None) -> dict[str, Any]:
    """Run the whole validation of ``bag``; write the report; return the JSON summary."""
    from skidsteer_power.bags.report import write_report

    began = time.perf_counter()
    inputs = read_inputs(bag, options)
    core = build_core(options, predictor, options.battery_window_s)
    motion = motion_inputs(bag, options, inputs)
    if options.kinematics != 'cmd' and motion is None:
        raise InputError(f'--kinematics {options.kinematics}: {bag.path} has no such nav_msgs/Odometry twist')
    series = run_estimator(core, inputs if options.kinematics == 'cmd' else motion[1])  # type: ignore[index]
    metrics = error_metrics(series, core.settings.joint_timeout_s)
    motion_summary = None
    if motion is not None and options.kinematics == 'cmd':  # ch. 7.3: also predict from the motion
        other = build_core(options, core.predictor, options.battery_window_s)
        motion_metrics = error_metrics(run_estimator(other, motion[1]), other.settings.joint_timeout_s)
        motion_summary = {'kinematics': motion[0], 'metrics': motion_metrics}
    segments = trace_segments(inputs, options)
    live = live_comparison(inputs, core.predictor)
    elapsed = time.perf_counter() - began
    summary = {
        'bag': str(bag.path),
        'storage': bag.storage,
        'duration_s': bag.duration_s,
        'vehicle': options.vehicle,
        'terrain': options.terrain,
        'predictor': core.predictor.description,
        'has_motor_data': bool(inputs.js_t.size),
        'pose_topic': inputs.pose_topic or None,
        'messages': {
            'cmd_vel': int(inputs.cmd_t.size),
            'joint_states': int(inputs.js_t.size),
            'poses': int(inputs.pose_t.size),
        },
        'rejected': series.rejected,
        'undecodable_topics': bag.undecodable_topics,
        'kinematics': options.kinematics,
        'metrics': metrics,
        'motion_prediction': motion_summary,
        'battery': {
            'energy_measured_J': series.energy_J.get('measured', math.nan),
            'energy_predicted_J': series.energy_J.get('predicted', math.nan),
            'remaining_wh': series.remaining_wh,
            'soc': series.soc,
        },
        'segments': [s.__dict__ for s in segments],
        'live_comparison': live,
        'processing_s': elapsed,
        'real_time_factor': bag.duration_s / elapsed if elapsed > 0 else math.inf,
    }
    summary['report'] = write_report(
        Path(options.report_dir), summary, series, inputs, segments, options.plots
    )
    return summary
