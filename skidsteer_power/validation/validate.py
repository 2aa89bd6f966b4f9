"""Offline validation: the estimator run over a bag, compared with what the motors measured.

No ROS graph is needed. The bag's ``cmd_vel`` (Twist or TwistStamped: V [m/s], yaw rate [rad/s]) and
``joint_states`` (the vehicle's joints, mapped to the sides by its ``joints:`` section, see
:class:`skidsteer_power.estimator.inputs.JointMap`; the test robot's ``left_motor``/``right_motor``:
shaft speed [rad/s], effort = Kt*I [N m]) are fed in receive-time order to
:class:`skidsteer_power.estimator.EstimatorCore`, as the live ``power_estimator`` node feeds it, so
each joint_states sample is aligned with the prediction in force when it arrived. How long a command
stays in force depends on how it was published (a stream or only on change) and, for on-change
commands, on whether odometry shows the robot still moving (:mod:`skidsteer_power.validation.cmd_timing`).
Compared per side at the motor (motor-equivalent for wheel joints): torque [N m] and terminal
(electrical) power [W]; metrics over samples whose command is in force: MAE, RMSE and the error of
the energy over the run [%]. The share of time and energy whose prediction came from outside the
power map (clamped or limited) is reported too.

Where the bag has odometry or poses, each constant-command segment gets a trace analysis: the
turning radius by the SVD circle fit of eqs. 7.8-7.10 and the mean forward speed
(:mod:`skidsteer_power.analysis.trace`), next to the commanded radius V / yaw rate. A bag without
motor data still gets predictions, predicted energy, battery state and trace analysis.
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from skidsteer_power.bag_io.decode import (
    decode_joint_arrays,
    decode_joint_states,
    decode_pose_twists,
    decode_twists,
)
from skidsteer_power.bag_io.reader import BagReader
from skidsteer_power.drive.prediction_modes import CMD, TWIST, VALIDATE_KINEMATICS
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator.inputs import InputLimits
from skidsteer_power.estimator.measured import apply_to_joint_arrays
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.seams import BatteryModel
from skidsteer_power.validation.cmd_timing import CommandTiming, at_rest, command_timing, hold_ends
from skidsteer_power.validation.online import (
    DERIVED_COLUMNS,
    online_columns,
    online_figures,
    online_summary,
    predicted_battery_J,
)
from skidsteer_power.validation.series import Inputs as Inputs  # re-exported: their old import path
from skidsteer_power.validation.series import RunSeries as RunSeries
from skidsteer_power.validation.series import ValidateOptions as ValidateOptions
from skidsteer_power.validation.summary import (
    BatteryFigures,
    JointsUsed,
    MessageCounts,
    MotionPrediction,
    ValidationSummary,
)
from skidsteer_power.validation.validate_metrics import (  # re-exported: their old import path
    LIVE_TOLERANCE_NM as LIVE_TOLERANCE_NM,
)
from skidsteer_power.validation.validate_metrics import (
    TraceSegment as TraceSegment,
)
from skidsteer_power.validation.validate_metrics import (
    command_segments as command_segments,
)
from skidsteer_power.validation.validate_metrics import (
    error_metrics,
    live_comparison,
    map_coverage,
    trace_segments,
)
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from skidsteer_power.estimator import EstimatorCore
    from skidsteer_power.estimator.core import Comparison
    from skidsteer_power.estimator.inputs import JointMap
    from skidsteer_power.estimator.prediction import Prediction, Predictor
    from skidsteer_power.powertrain.battery import BatteryConfig, BatteryState

LOG = logging.getLogger(__name__)

POSE_TYPES = (
    'nav_msgs/msg/Odometry',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/PoseWithCovarianceStamped',
)
LIVE_PREDICTED_TOPIC = '/power/predicted'


class Row(NamedTuple):
    """One row of :func:`run_estimator`'s series, its fields named as the columns (SI units; NaN where
    the row has no such value): the command and whether it is in force, the predicted and measured
    motor torques [N m] and powers [W] per side, the predicted axle torques [N m], battery-side
    powers [W], traction margin [-], state of charge [-], hold [s], the map flags, motor speeds
    [rad/s] and the online figures (:func:`online_figures`)."""

    t_s: float
    speed_cmd_m_s: float
    yaw_rate_cmd_rad_s: float
    cmd_fresh: float
    predicted_torque_left_Nm: float
    predicted_torque_right_Nm: float
    measured_torque_left_Nm: float
    measured_torque_right_Nm: float
    predicted_power_left_W: float
    predicted_power_right_W: float
    measured_power_left_W: float
    measured_power_right_W: float
    predicted_axle_torque_left_Nm: float
    predicted_axle_torque_right_Nm: float
    predicted_battery_W: float
    measured_battery_W: float
    traction_margin: float
    soc: float
    hold_s: float
    clamped: float
    limited: float
    measured_omega_left_rad_s: float
    measured_omega_right_rad_s: float
    predicted_omega_left_rad_s: float
    predicted_omega_right_rad_s: float
    online_torque_left_Nm: float
    online_torque_right_Nm: float
    terrain_scale: float


ROW_COLUMNS: tuple[str, ...] = Row._fields
SERIES_COLUMNS = (*ROW_COLUMNS, *DERIVED_COLUMNS)
# hold_s: how long the row's values are in force [s] (the weight of the row in energy sums);
# clamped / limited: 1 where the prediction came from outside the power map (see MapQuery);
# *_omega_*: motor speed [rad/s]; online_*, terrain_scale and DERIVED_COLUMNS: bags/online.py


def _topic_of_type(bag: BagReader, wanted: str, types: Sequence[str]) -> str:
    if wanted in bag.topics:
        return wanted if bag.topics[wanted].msgtype in types else ''
    return next((t for t, info in bag.topics.items() if info.msgtype in types), '')


def joint_map_of(options: ValidateOptions) -> JointMap:
    """The joint_states mapping: the vehicle file's ``joints:`` with the options' overrides."""
    from skidsteer_power.estimator import factory

    return factory.joint_map_for(
        load_vehicle(options.vehicle),
        left=options.left_joints,
        right=options.right_joints,
        effort_is=options.effort_is,
        location=options.joints_at,
    )


def read_inputs(bag: BagReader, options: ValidateOptions, joint_map: JointMap | None = None) -> Inputs:
    """Decode commands, joint states, poses and the live node's predictions from ``bag``."""
    t0 = bag.start_ns
    cmd_topic = options.cmd_vel_topic if options.cmd_vel_topic in bag.topics else ''
    if not cmd_topic:
        raise InputError(f'{bag.path}: no {options.cmd_vel_topic} topic: nothing to predict from')
    cmd_t, cmd = decode_twists(bag, cmd_topic, t0)
    joint_map = joint_map or joint_map_of(options)
    names = joint_map.joints
    js_t, position, velocity, effort, ok = decode_joint_arrays(bag, options.joint_states_topic, t0, names)
    (position, velocity, effort), ok, currents_note = apply_to_joint_arrays(
        bag, joint_map, t0, js_t, (position, velocity, effort), ok
    )
    note = ''
    if js_t.size and joint_map.vendor_sources and not ok.any():
        note = currents_note
    elif js_t.size and not joint_map.has_power:
        note = f'the drivetrain mapping gives {options.joint_states_topic} no effort or no speed'
    elif js_t.size and not ok.any():
        note = f'{options.joint_states_topic} never holds all of {", ".join(names)}: no measured power'
    if note:
        js_t, ok = np.zeros(0), np.zeros(0, bool)
        position, velocity, effort = (np.zeros((0, len(names))) for _ in range(3))
    pose_topic = _topic_of_type(bag, options.odom_topic, POSE_TYPES)
    if pose_topic:
        pose_t, pose_xy, pose_yaw, pose_twist = decode_pose_twists(bag, pose_topic, t0)
    else:
        pose_t, pose_xy, pose_yaw, pose_twist = np.zeros(0), np.zeros((0, 2)), np.zeros(0), None
    live_t, _, live_torque, _ = decode_joint_states(
        bag, LIVE_PREDICTED_TOPIC, t0, ('left_motor', 'right_motor')
    )
    return Inputs(
        cmd_t, cmd, js_t, velocity, effort, ok, pose_t, pose_xy, pose_topic, live_t, live_torque,
        js_position=position, js_names=names, pose_yaw=pose_yaw, end_s=bag.duration_s, joint_note=note,
        currents_note='' if note else currents_note, pose_twist=pose_twist,
    )  # fmt: skip


def apply_command_timing(inputs: Inputs, hold_s: float | None, floor_s: float) -> CommandTiming:
    """Classify the commands' publishing, set ``inputs.cmd_end`` (when each stops being in force)."""
    timing = command_timing(inputs.cmd_t, inputs.cmd, hold_s, floor_s)
    rest = at_rest(inputs.pose_t, inputs.pose_xy, inputs.pose_yaw) if inputs.pose_t.size > 1 else None
    end = max(inputs.end_s, float(inputs.cmd_t.max()) if inputs.cmd_t.size else 0.0)
    inputs.cmd_end = hold_ends(inputs.cmd_t, timing, end, rest)
    return timing


class WindowedBattery:
    """Steps the wrapped battery with the mean power of each ``window_s`` of steps [s].

    The estimator steps the battery at every input (100s per second of bag); offline that dominates
    the run time. Energy per window is kept exactly (sum of power x dt); only the battery's internal
    loss, which depends on power squared, sees the window mean instead of each sample -- a
    state-of-charge difference far below the battery model's own accuracy (see the test). Every read
    of the battery's state first flushes the open window, so what is read is up to date. It is a
    :class:`~skidsteer_power.seams.BatteryModel`: each member of the protocol is spelled out.
    """

    def __init__(self, battery: BatteryModel, window_s: float = 0.2) -> None:
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

    @property
    def config(self) -> BatteryConfig:
        return self._battery.config

    @property
    def state(self) -> BatteryState:
        self.flush()
        return self._battery.state

    @property
    def soc(self) -> float:
        self.flush()
        return self._battery.soc

    @property
    def remaining_wh(self) -> float:
        self.flush()
        return self._battery.remaining_wh

    def time_to_empty_s(self, power_W: float) -> float:
        self.flush()
        return self._battery.time_to_empty_s(power_W)

    def max_power_W(self) -> float:
        return self._battery.max_power_W()

    def current_for_power(self, power_W: float, soc: float | None = None) -> float:
        self.flush()
        return self._battery.current_for_power(power_W, soc)

    def with_state(self, state: BatteryState) -> WindowedBattery:
        self.flush()
        return WindowedBattery(self._battery.with_state(state), self._window_s)


def build_core(
    options: ValidateOptions,
    predictor: Predictor | None = None,
    battery_window_s: float = 0.2,
    kinematics: str | None = None,
) -> EstimatorCore:
    """An :class:`EstimatorCore` for the vehicle and terrain; ``predictor`` None builds the map one:
    the set-point map for ``kinematics`` 'cmd' (default: ``options.kinematics``), else the (V, yaw
    rate) map that takes its input as the motion (``twist`` and the measured-motion kinematics)."""
    from skidsteer_power.estimator import EstimatorCore, EstimatorSettings, factory

    vehicle = load_vehicle(options.vehicle)
    if predictor is None:
        try:
            kind = CMD if (kinematics or options.kinematics) == CMD else TWIST
            predictor, _, _ = factory.map_predictor(vehicle, options.terrain, options.map_cache_dir, kind)
        except ImportError as err:
            raise ConfigError(f'power maps are not available in this installation: {err}') from err
    else:
        factory.check_terrain(options.terrain)
    battery: BatteryModel = factory.battery_for(vehicle)
    if battery_window_s > 0:
        battery = WindowedBattery(battery, battery_window_s)
    powertrain = Powertrain.for_vehicle(vehicle)
    limits = InputLimits.for_powertrain(powertrain)  # the vehicle's own motor and driver (issue 35)
    settings = EstimatorSettings(joint_map=joint_map_of(options), limits=limits)
    return EstimatorCore(predictor, battery, powertrain, settings)


def run_estimator(core: EstimatorCore, inputs: Inputs) -> RunSeries:
    """Feed commands and joint states to ``core`` in time order; rows per joint_states sample.

    Without joint states the rows are the command samples (predictions only). No timer ticks: the
    battery integration is exact whenever it is advanced (each input advances it), and the time to
    empty is only wanted at the end.
    """
    times, kinds, index, order = _time_order(inputs)
    fed = _feed_in_time_order(core, inputs, times, kinds, index, order)
    core.tick(max(float(times.max()) if times.size else 0.0, inputs.end_s))
    columns = _series_columns(core, fed.rows, fed.holds, motor_data=inputs.js_t.size > 0)
    return RunSeries(
        columns,
        fed.rejected,
        dict(core.energy.energy_J),
        core.battery.remaining_wh,
        core.battery.soc,
        core.no_data_count,
        dict(fed.reasons),
    )


def _time_order(inputs: Inputs) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Commands and joint states merged: each input's time [s], kind (0 command, 1 joint_states),
    index in its own arrays, and the order to feed them in."""
    times = np.concatenate([inputs.cmd_t, inputs.js_t])
    kinds = np.concatenate([np.zeros(inputs.cmd_t.size, np.int8), np.ones(inputs.js_t.size, np.int8)])
    index = np.concatenate([np.arange(inputs.cmd_t.size), np.arange(inputs.js_t.size)])
    order = np.lexsort((kinds, times))  # stable by time; a command first when stamps tie
    return times, kinds, index, order


class _Fed(NamedTuple):
    """What :func:`_feed_in_time_order` made: the rows, each row's hold [s] (NaN for a joint_states
    row: set from the row times afterwards), the rejected inputs per topic and per reason."""

    rows: list[Row]
    holds: list[float]
    rejected: dict[str, int]
    reasons: Counter[str]


def _feed_in_time_order(
    core: EstimatorCore,
    inputs: Inputs,
    times: np.ndarray,
    kinds: np.ndarray,
    index: np.ndarray,
    order: np.ndarray,
) -> _Fed:
    """Each input to ``core`` in ``order`` (:func:`_time_order`); a row per joint_states reading
    that gave a comparison, or per command when there are no joint states."""
    from skidsteer_power.estimator.core import RejectedInput

    motor_data = inputs.js_t.size > 0
    ends = inputs.cmd_end
    rejected = {'cmd_vel': 0, 'joint_states': 0}
    reasons: Counter[str] = Counter()
    battery_side = bool(core.settings.joint_map.measures_battery)
    rows: list[Row] = []
    names = inputs.js_names
    # Python lists: per-row access to floats is several times faster than to numpy rows
    has_positions = inputs.js_position.shape[0] == inputs.js_t.size
    positions = inputs.js_position.tolist() if has_positions else None
    velocities, efforts, names_ok = inputs.js_velocity.tolist(), inputs.js_effort.tolist(), inputs.js_names_ok
    commands = inputs.cmd.tolist()
    ends_list = None if ends is None else ends.tolist()
    times_list, kinds_list, index_list = times.tolist(), kinds.tolist(), index.tolist()
    row_hold: list[float] = []
    for k in order.tolist():
        now = times_list[k]
        i = index_list[k]
        kind = kinds_list[k]
        try:
            if kind == 0:
                hold = None if ends_list is None else ends_list[i] - now
                core.on_command(commands[i][0], commands[i][1], now, hold)
                if motor_data:
                    continue
                comparison = None
            else:
                if not names_ok[i]:
                    rejected['joint_states'] += 1
                    reasons['joint_states: a mapped joint is missing'] += 1
                    continue
                position = positions[i] if positions is not None else ()
                online = online_figures(core)  # before the reading updates the correction
                comparison = core.on_joint_state(names, velocities[i], efforts[i], now, position)
                if comparison is None:  # speed from positions: waits for a second sample
                    continue
        except RejectedInput as err:
            rejected['cmd_vel' if kind == 0 else 'joint_states'] += 1
            reasons[reason_of(err)] += 1
            continue
        if kind == 0:
            online = online_figures(core)
        fresh = core.prediction is not None and core.cmd_fresh.is_fresh(now)
        if kind == 0:  # until the command's hold ends (holds never overlap), else the staleness
            row_hold.append(core.cmd_fresh.timeout_s if ends_list is None else ends_list[i] - now)
        else:
            row_hold.append(math.nan)
        rows.append(_row(now, core.prediction, fresh, comparison, _soc(core.battery), battery_side, online))
    return _Fed(rows, row_hold, rejected, reasons)


def _series_columns(
    core: EstimatorCore, rows: list[Row], holds: list[float], *, motor_data: bool
) -> dict[str, np.ndarray]:
    """The run's columns: the rows', the online ones derived from them, and ``hold_s``."""
    table = np.array(rows, dtype=float).reshape(-1, len(ROW_COLUMNS))
    columns = {name: table[:, j] for j, name in enumerate(ROW_COLUMNS)}
    battery_side = bool(core.settings.joint_map.measures_battery)
    columns.update(online_columns(columns, core.powertrain, battery_side))
    t = columns['t_s']
    if motor_data:  # a measurement holds until the next one, at most the joint timeout
        columns['hold_s'] = np.minimum(
            np.diff(t, append=t[-1] if t.size else 0.0), core.settings.joint_timeout_s
        )
    else:  # a command row holds as long as the command is in force
        columns['hold_s'] = np.array(holds, dtype=float)
    return columns


def reason_of(err: Exception) -> str:
    """A rejection's reason without its numbers (readings of one kind count together): 'joint_states:
    left side (motor-equivalent) effort = # N m exceeds the plausible limit # N m'."""
    return re.sub(r'-?\d+(\.\d+)?(e[-+]?\d+)?', '#', str(err))


PREDICTED_COLUMNS = (
    'predicted_torque_left_Nm',
    'predicted_torque_right_Nm',
    'predicted_power_left_W',
    'predicted_power_right_W',
)


def with_other_commands(core: EstimatorCore, inputs: Inputs, series: RunSeries) -> RunSeries:
    """What :func:`error_metrics` reads of ``run_estimator(core, inputs)``, from ``series`` (a run
    with motor data over the same joint_states) and ``inputs``' commands fed to ``core`` alone.

    A joint_states reading's row, measurement and hold do not depend on the prediction (its checks
    are the input limits and the battery's fixed power bound), so they are ``series``'; each row gets
    the prediction of the last command ``core`` took at or before it (a command first when times
    tie) and whether that command is in force (``core.cmd_fresh``: its hold). The online columns,
    which the prediction does change, are left out. A second run over the readings cost validate
    a fifth of its time (60,000 joint_states: 1.4 s of 7.1 s CPU).
    """
    from skidsteer_power.estimator.core import RejectedInput

    ends = None if inputs.cmd_end is None else inputs.cmd_end.tolist()
    battery_side = bool(core.settings.joint_map.measures_battery)
    taken_t: list[float] = []
    holds: list[float] = []
    predicted: list[tuple[float, float, float, float]] = []
    for i, (now, (speed, yaw_rate)) in enumerate(
        zip(inputs.cmd_t.tolist(), inputs.cmd.tolist(), strict=True)
    ):
        try:
            p = core.on_command(speed, yaw_rate, now, None if ends is None else ends[i] - now)
        except RejectedInput:
            continue
        taken_t.append(now)
        holds.append(core.cmd_fresh.timeout_s)
        predicted.append((*p.motor_torque_Nm, *(p.bus_W if battery_side else p.electrical_W)))
    t = series.columns['t_s']
    last = np.searchsorted(np.array(taken_t, dtype=float), t, side='right') - 1
    known = last >= 0
    which = np.maximum(last, 0)
    table = np.array(predicted, dtype=float).reshape(-1, len(PREDICTED_COLUMNS))
    columns = {name: series.columns[name] for name in ('t_s', 'hold_s', *MEASURED_COLUMNS)}
    for j, name in enumerate(PREDICTED_COLUMNS):
        columns[name] = np.where(known, table[which, j] if table.size else math.nan, math.nan)
    if taken_t:  # Freshness.is_fresh: age <= the command's hold
        age = np.maximum(0.0, t - np.array(taken_t)[which])
        fresh = known & (age <= np.array(holds)[which])
    else:
        fresh = np.zeros(t.shape, bool)
    columns['cmd_fresh'] = fresh.astype(float)
    return replace(series, columns=columns)


MEASURED_COLUMNS = (
    'measured_torque_left_Nm',
    'measured_torque_right_Nm',
    'measured_power_left_W',
    'measured_power_right_W',
)


def _soc(battery: BatteryModel) -> float:
    """State of charge [-] for a row: a windowed battery's as of its last full window (no flush)."""
    return battery.soc_at_last_flush if isinstance(battery, WindowedBattery) else battery.soc


def _row(
    now: float,
    p: Prediction | None,
    fresh: bool,
    comparison: Comparison | None,
    soc: float,
    battery_side: bool,
    online: tuple[float, float, float],
) -> Row:
    """One :class:`Row` (``hold_s`` NaN: set after the run). The power columns are the motor terminal
    power, or the battery-side power when the measurement is battery-side (``battery_side``: V x I
    from ``measured_power``); ``online``: :func:`online_figures`."""
    nan = math.nan
    if p is None:
        speed = yaw = battery = margin = clamped = limited = nan
        torque = power = axle = omega = (nan, nan)
    else:
        speed, yaw, torque, axle, omega = (
            p.speed_m_s, p.yaw_rate_rad_s, p.motor_torque_Nm, p.terrain_torque_Nm, p.motor_omega_rad_s
        )  # fmt: skip
        power = p.bus_W if battery_side else p.electrical_W
        battery, margin, clamped, limited = (
            p.bus_total_W,
            p.traction_margin,
            float(p.clamped),
            float(p.limited),
        )
    if comparison is None:
        m_torque = m_power = m_omega = (nan, nan)
        m_battery = nan
    else:
        m = comparison.measured
        m_torque, m_omega, m_battery = m.torque_Nm, m.omega_rad_s, m.bus_total_W
        m_power = m.bus_W if battery_side else m.electrical_W
    return Row(
        t_s=now,
        speed_cmd_m_s=speed,
        yaw_rate_cmd_rad_s=yaw,
        cmd_fresh=float(fresh),
        predicted_torque_left_Nm=torque[0],
        predicted_torque_right_Nm=torque[1],
        measured_torque_left_Nm=m_torque[0],
        measured_torque_right_Nm=m_torque[1],
        predicted_power_left_W=power[0],
        predicted_power_right_W=power[1],
        measured_power_left_W=m_power[0],
        measured_power_right_W=m_power[1],
        predicted_axle_torque_left_Nm=axle[0],
        predicted_axle_torque_right_Nm=axle[1],
        predicted_battery_W=battery,
        measured_battery_W=m_battery,
        traction_margin=margin,
        soc=soc,
        hold_s=nan,
        clamped=clamped,
        limited=limited,
        measured_omega_left_rad_s=m_omega[0],
        measured_omega_right_rad_s=m_omega[1],
        predicted_omega_left_rad_s=omega[0],
        predicted_omega_right_rad_s=omega[1],
        online_torque_left_Nm=online[0],
        online_torque_right_Nm=online[1],
        terrain_scale=online[2],
    )


def stream_hold_ends(t: np.ndarray, cap_s: float) -> np.ndarray:
    """When each row of a stream sampled at times ``t`` [s] stops being in force: at the next row,
    at most ``cap_s`` [s] after it (a 5 Hz odometry held for a 0.5 s command hold would overlap the
    next four rows and count their energy 2.5 times)."""
    ends: np.ndarray = np.minimum(np.append(t[1:], math.inf), t + cap_s)  # numpy types it Any
    return ends


KINEMATICS = VALIDATE_KINEMATICS
FROM_COMMAND = (CMD, TWIST)  # predicted from the command: at its set points, or as the motion
GROUND_TRUTH_TOPIC = '/ground_truth/odom'


def motion_inputs(bag: BagReader, options: ValidateOptions, inputs: Inputs) -> tuple[str, Inputs] | None:
    """``inputs`` with the commands replaced by a measured twist (V [m/s], yaw rate [rad/s]) of an
    Odometry topic: ``/ground_truth/odom`` for 'ground_truth', ``odom_topic`` for 'odom'; for 'cmd'
    the ground truth if the bag has it, else ``odom_topic``. Returns (kinematics, inputs) or None."""
    if options.kinematics not in KINEMATICS:
        raise InputError(f'kinematics must be one of {", ".join(KINEMATICS)}, not {options.kinematics!r}')
    candidates = {'odom': ['odom'], 'ground_truth': ['ground_truth']}.get(  # cmd, twist: either
        options.kinematics, ['ground_truth', 'odom']
    )
    for kind in candidates:
        topic = GROUND_TRUTH_TOPIC if kind == 'ground_truth' else options.odom_topic
        if topic in bag.topics and bag.topics[topic].msgtype == 'nav_msgs/msg/Odometry':
            twist: np.ndarray | None
            if topic == inputs.pose_topic and inputs.pose_twist is not None:  # decoded with the poses
                t, twist = inputs.pose_t, inputs.pose_twist
            else:
                t, _, _, twist = decode_pose_twists(bag, topic, bag.start_ns)
            if t.size and twist is not None:
                return kind, replace(inputs, cmd_t=t, cmd=twist)
    return None


@dataclass
class BagPrediction:
    """The estimator run over a bag (:func:`predict_bag`): decoded inputs, the core after the run,
    command timing, (kinematics, inputs with the measured twist as commands) or None, the series."""

    inputs: Inputs
    core: EstimatorCore
    timing: CommandTiming
    motion: tuple[str, Inputs] | None
    series: RunSeries


def predict_bag(
    bag: BagReader, options: ValidateOptions, predictor: Predictor | None = None
) -> BagPrediction:
    """Run the estimator over ``bag`` from what ``options.kinematics`` says (the command, as the
    live node, by default): the prediction every other offline comparison starts from (validate,
    compare)."""
    inputs = read_inputs(bag, options)
    core = build_core(options, predictor, options.battery_window_s)
    timing = apply_command_timing(inputs, options.cmd_hold_s, core.settings.cmd_timeout_s)
    motion = motion_inputs(bag, options, inputs)
    if motion is not None:  # a measured twist is a stream: each row holds until the next one
        ends = stream_hold_ends(motion[1].cmd_t, core.settings.cmd_timeout_s)
        motion = (motion[0], replace(motion[1], cmd_end=ends))
    from_command = options.kinematics in FROM_COMMAND
    if from_command:
        driven = inputs
    elif motion is not None:
        driven = motion[1]
    else:
        raise InputError(f'--kinematics {options.kinematics}: {bag.path} has no such nav_msgs/Odometry twist')
    series = run_estimator(core, driven)
    return BagPrediction(inputs, core, timing, motion, series)


DROPPED_LOUD = 1.0 / 3.0
"""A run that drops this share of its readings or more gets a loud warning (issue 35) [-]."""


def console_warnings(summary: ValidationSummary) -> list[str]:
    """What the console must say beside a validation's numbers (:func:`reading_warnings`)."""
    return reading_warnings(
        summary.joint_states_read,
        summary.rejected.get('joint_states', 0),
        summary.rejected_reasons,
        summary.motor_data_note,
        summary.metrics.energy_measured_J,
    )


def reading_warnings(
    read: int, dropped: int, reasons: dict[str, int], note: str | None, measured_J: float
) -> list[str]:
    """What the console must say beside a validation's numbers (issue 35): readings dropped
    (``dropped`` of ``read``), how many and why (``reasons``: count per reason; loud from
    :data:`DROPPED_LOUD` of them); measured power the bag lacks (``note``, once); a measured energy
    ``measured_J`` [J] with the wrong sign."""
    lines = []
    if dropped:
        ordered = sorted(reasons.items(), key=lambda item: -item[1])
        why = '; '.join(f'{n} x {reason}' for reason, n in ordered if reason.startswith('joint_states'))
        share = dropped / read if read else 1.0
        loud = (
            'WARNING: A THIRD OR MORE OF THE READINGS DROPPED: the measured energy leaves them out. '
            if share >= DROPPED_LOUD
            else ''
        )
        lines.append(f'{loud}{dropped} of {read} measured readings dropped ({100 * share:.1f} %): {why}')
    if note:
        lines.append(note)
    if measured_J < 0:
        lines.append(
            f'the measured energy is negative ({measured_J:.4g} J): a battery-side current read as a motor '
            "current? (the vehicle file's measured_power: current_is: battery, signed: false)"
        )
    return lines


def validate(
    bag: BagReader, options: ValidateOptions, predictor: Predictor | None = None
) -> ValidationSummary:
    """Run the whole validation of ``bag``; write the report; return the summary (``as_json``: the
    JSON of ``validate --json``)."""
    from skidsteer_power.validation.report import write_report

    began = time.perf_counter()
    run = predict_bag(bag, options, predictor)
    inputs, core, timing, motion, series = run.inputs, run.core, run.timing, run.motion, run.series
    from_command = options.kinematics in FROM_COMMAND
    metrics = error_metrics(series)
    motion_summary = None
    if motion is not None and from_command:  # ch. 7.3: also predict from the motion
        measured_motion = None if options.kinematics == 'cmd' and predictor is None else core.predictor
        other = build_core(options, measured_motion, options.battery_window_s, kinematics='twist')
        if inputs.js_t.size:  # the readings are the first run's: only the commands differ
            motion_series = with_other_commands(other, motion[1], series)
        else:
            motion_series = run_estimator(other, motion[1])
        motion_summary = MotionPrediction(motion[0], error_metrics(motion_series))
    segments = trace_segments(inputs, options, core.predictor)
    fitted = [s for s in segments if s.points >= 2]  # fewer: no speed, no circle: left out
    live = live_comparison(inputs, core.predictor)
    elapsed = time.perf_counter() - began
    joint_map = core.settings.joint_map
    summary = ValidationSummary(
        bag=str(bag.path),
        storage=bag.storage,
        duration_s=bag.duration_s,
        vehicle=options.vehicle,
        terrain=options.terrain,
        predictor=core.predictor.description,
        has_motor_data=bool(inputs.js_t.size),
        motor_data_note=inputs.joint_note or None,
        motor_currents_from=inputs.currents_note or None,
        joints=JointsUsed(
            tuple(joint_map.left), tuple(joint_map.right), joint_map.effort_is, joint_map.location
        ),
        pose_topic=inputs.pose_topic or None,
        cmd_vel_mode=timing.mode,
        cmd_hold_s=timing.hold_s,
        cmd_hold_inferred=timing.inferred,
        cmd_period_s=timing.period_s,
        cmd_timing=timing.describe(),
        coverage=map_coverage(series),
        messages=MessageCounts(int(inputs.cmd_t.size), int(inputs.js_t.size), int(inputs.pose_t.size)),
        rejected=series.rejected,
        rejected_reasons=series.reasons,
        power_compared='battery' if joint_map.measures_battery else 'terminal',
        joint_states_read=int(inputs.js_t.size),
        joint_states_no_data=series.no_data,
        undecodable_topics=bag.undecodable_topics,
        kinematics=options.kinematics,
        metrics=metrics,
        motion_prediction=motion_summary,
        online_prediction=online_summary(series, core),
        battery=BatteryFigures(
            energy_measured_J=series.energy_J.get('measured', math.nan),
            # the open-loop prediction over the same time as the measurement (issue 27: the tracker's
            # 'predicted' tally below counts only time without a fresh measurement, 0 J on a bag
            # whose joint_states never stop)
            energy_predicted_J=predicted_battery_J(series),
            energy_drawn_from_prediction_J=series.energy_J.get('predicted', math.nan),
            remaining_wh=series.remaining_wh,
            soc=series.soc,
        ),
        segments=fitted,
        segments_with_too_few_poses=len(segments) - len(fitted),
        live_comparison=live,
        processing_s=elapsed,
        real_time_factor=bag.duration_s / elapsed if elapsed > 0 else math.inf,
    )
    files = write_report(Path(options.report_dir), summary, series, inputs, fitted, options.plots)
    return replace(summary, report=files)
