"""The data of a validation run (:mod:`skidsteer_power.validation.validate`), in a module of their own so
that the modules working on them (validate_metrics, online, report) import them without importing
validate, which imports those modules: what to validate, the decoded bag inputs, the aligned series."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class ValidateOptions:
    """What to validate and where to write the report.

    vehicle : vehicle name in config/vehicles/ or YAML file; terrain : preset name or YAML file
    report_dir : folder for CSV, PNG, Markdown and JSON (created)
    *_topic : topic names in the bag; odom_topic may be any of :data:`POSE_TYPES`
    map_cache_dir : where the power map is cached (None: the estimator's default)
    battery_window_s : battery stepped with the mean power of windows this long [s] (0: per input)
    settle_s : start of each constant-command segment left out of the trace analysis [s]
    min_segment_s : shortest segment analysed [s] (just over settle_s: a short leg of a square counts)
    segment_gap_s : unused (kept for callers); segments end where a command's hold ends
    plots : write PNG plots
    cmd_hold_s : how long a command stays in force [s] (None: inferred, see bags/cmd_timing.py; inf:
        until the next command)
    left_joints, right_joints, effort_is, joints_at : override the vehicle file's joint_states
        mapping ('' = the file's; joint lists comma-separated)
    kinematics : what the estimator predicts from: 'cmd' (the command at its wheel speed set points,
        as the live node), 'twist' (the command taken as the motion, the old reading), 'odom' (the
        twist of the Odometry ``odom_topic``) or 'ground_truth' (``/ground_truth/odom``)
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
    min_segment_s: float = 0.6
    segment_gap_s: float = 1.0
    plots: bool = True
    cmd_hold_s: float | None = None
    left_joints: str = ''
    right_joints: str = ''
    effort_is: str = ''
    joints_at: str = ''
    kinematics: str = 'cmd'


@dataclass
class Inputs:
    """Decoded bag inputs; times in s from the bag's first message."""

    cmd_t: np.ndarray
    cmd: np.ndarray  # (n, 2): V [m/s], yaw rate [rad/s]
    js_t: np.ndarray
    js_velocity: np.ndarray  # (n, k) velocity of the mapped joints [rad/s]
    js_effort: np.ndarray  # (n, k) effort of the mapped joints [N m or A]
    js_names_ok: np.ndarray  # (n,) bool: every mapped joint present
    pose_t: np.ndarray
    pose_xy: np.ndarray  # (n, 2) [m]
    pose_topic: str = ''
    live_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    live_torque: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    js_position: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (n, k) [rad]
    js_names: tuple[str, ...] = ('left_motor', 'right_motor')
    pose_yaw: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) heading [rad]
    cmd_end: np.ndarray | None = None  # (n,) time each command stops being in force [s]
    end_s: float = 0.0  # last message of the bag [s]
    joint_note: str = ''  # why joint_states give no measured power, if they do not
    currents_note: str = ''  # where the motor currents come from, if a vendor topic (side_currents)
    pose_twist: np.ndarray | None = None  # (n, 2) V [m/s], yaw rate [rad/s] of an Odometry pose topic


@dataclass
class RunSeries:
    """Aligned time series of one estimator run; one row per joint_states (or cmd_vel) sample."""

    columns: dict[str, np.ndarray]
    rejected: dict[str, int]
    energy_J: dict[str, float]
    remaining_wh: float
    soc: float
    no_data: int = 0  # joint_states saying "no fresh data" (NaN in every field): skipped, not rejected
    reasons: dict[str, int] = field(default_factory=dict)  # why readings were rejected: count per reason


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
    predicted_speed_m_s: float = math.nan
    predicted_radius_m: float = math.nan
