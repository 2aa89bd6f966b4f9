"""``skidsteer-power import LOG.csv -o OUT.mcap --vehicle V``: a CSV log as a bag the other commands read.

Many robots log CSV, not bags (issue 35). A column mapping names, per side, the wheel speed (at the
tread [m/s], times ``--speed-scale``), the measured current (times ``--current-scale`` [A]) and
optionally the voltage [V]; the time column (times ``--time-scale`` [s]); optionally the command
(``--cmd-speed``, ``--cmd-yaw-rate``) and the yaw rate (a column of the same CSV, or of a second CSV
merged by time: ``--imu``). The bag (rosbag2 MCAP, :class:`skidsteer_power.bag_io.writer.BagWriter`)
holds:

* ``/joint_states`` (sensor_msgs/JointState): the vehicle's drivetrain joints, velocity = wheel speed /
  wheel radius [rad/s] (each joint of a side alike), position its integral [rad];
* ``/cmd_vel`` (geometry_msgs/Twist): the command columns, or without them the recorded wheel speeds
  taken as the set points (a controller that holds wheel speeds): the twist that the vehicle's own
  drive controller turns into exactly those set points (:meth:`DriveController.twist_of`: its wheel
  separation, with diff_drive_controller's multiplier, and radius multipliers);
* the currents and voltages, one std_msgs/Float64 topic each (``--current-topics``,
  ``--voltage-topics``): what a vehicle file's ``measured_power:`` maps (config/vehicles/husky_a200.yaml
  has the mapping of ``--preset borealtc``);
* ``/imu/data`` (sensor_msgs/Imu: angular_velocity.z = the yaw rate [rad/s]) if a yaw rate is given.

``--preset borealtc`` is the BorealTC dataset's Husky logs (docs/USAGE.md, "import": how its units and
signs were worked out): ``pro_XX.csv`` time, curL, curR (current magnitudes [A]), velL, velR
([m/s] at the tread), merged with ``imu_XX.csv``'s wz (``--imu``). The shipped husky_a200 file maps
those topics as battery-side currents; benchmarks/realdata.py shows from the data that BorealTC's
follow torque (the motors' currents), so validate's measured V x I of such a bag is 24 V x the motor
current, an upper bound of the battery power, not the battery power.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from skidsteer_power.argtypes import range_arg, range_help
from skidsteer_power.cli.common import Subcommands, add_json_flag, emit, finite_float
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import Range

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import MsgType

    from skidsteer_power.bag_io.writer import BagWriter
    from skidsteer_power.drive.controller import DriveController
    from skidsteer_power.estimator.inputs import JointMap

MAX_ROWS = Range('rows', 0, 5_000_000, 'rows', positive=True, integer=True)
"""Largest CSV (rows, each file) an import reads: ~2.3 h of 100 Hz data x 2 (issue 28's rule)."""
START_NS = 1_700_000_000 * 10**9
"""The bag's clock at the CSV's time 0 [ns] (a CSV keeps relative time only)."""
PRESETS: dict[str, dict[str, str]] = {
    'borealtc': {
        'time': 'time',
        'left_speed': 'velL',
        'right_speed': 'velR',
        'left_current': 'curL',
        'right_current': 'curR',
        'imu_time': 'time',
        'imu_yaw_rate': 'wz',
    },
}
"""Column mappings of known logs (``--preset``); explicit options override them."""
CURRENT_TOPICS = 'left_drive/status/battery_current,right_drive/status/battery_current'
VOLTAGE_TOPICS = 'left_drive/status/battery_voltage,right_drive/status/battery_voltage'


@dataclass(frozen=True)
class Columns:
    """The column mapping of one import (names in the CSV header; '' = not recorded)."""

    time: str = 'time'
    left_speed: str = ''
    right_speed: str = ''
    left_current: str = ''
    right_current: str = ''
    left_voltage: str = ''
    right_voltage: str = ''
    cmd_speed: str = ''
    cmd_yaw_rate: str = ''
    yaw_rate: str = ''
    imu_time: str = 'time'
    imu_yaw_rate: str = ''


def read_csv(path: Path, max_rows: int) -> dict[str, np.ndarray]:
    """The numeric columns of a CSV with a header row (name -> float array); InputError if it cannot be
    read, has no rows, or more than ``max_rows``."""
    try:
        with path.open(encoding='utf-8') as handle:
            header = handle.readline().strip().split(',')
            rows = sum(1 for line in handle if line.strip())
    except OSError as err:
        raise InputError(f'{path}: cannot read ({err.strerror or err})') from err
    if rows == 0 or not header or not header[0]:
        raise InputError(f'{path}: no header and data rows')
    if rows > max_rows:
        raise InputError(f'{path}: {rows:,} rows is more than --max-rows {max_rows:,}')
    try:
        table = np.genfromtxt(path, delimiter=',', skip_header=1, dtype=float, invalid_raise=True)
    except ValueError as err:
        raise InputError(f'{path}: not a numeric CSV ({str(err).splitlines()[0]})') from err
    table = table.reshape(rows, -1) if table.ndim < 2 else table
    if table.shape[1] != len(header):
        raise InputError(f'{path}: {table.shape[1]} values per row for {len(header)} header names')
    return {name.strip(): table[:, j] for j, name in enumerate(header)}


def _column(table: dict[str, np.ndarray], name: str, path: Path, option: str) -> np.ndarray:
    if name not in table:
        raise InputError(f'{path}: no column {name!r} ({option}); columns: {", ".join(table)}')
    values = table[name]
    if not np.all(np.isfinite(values)):
        raise InputError(f'{path}: column {name!r} has empty or non-numeric values')
    return values


@dataclass(frozen=True)
class Signals:
    """What one import read, in SI units: per CSV row the time t [s], the wheel speeds at the tread
    (n, 2) [m/s], the command (n, 2) [m/s, rad/s], currents (n, 2) [A] and voltages (n, 2) [V] where
    recorded; the yaw rate [rad/s] at its own times [s] where recorded."""

    t: np.ndarray
    speed: np.ndarray
    cmd: np.ndarray
    cmd_note: str
    currents: np.ndarray | None
    voltages: np.ndarray | None
    yaw_t: np.ndarray | None
    yaw: np.ndarray | None


def _columns2(
    table: dict[str, np.ndarray], path: Path, names: tuple[str, str], options: tuple[str, str]
) -> np.ndarray:
    """Two columns side by side (n, 2)."""
    return np.column_stack([_column(table, names[k], path, options[k]) for k in (0, 1)])


def read_signals(
    path: Path,
    columns: Columns,
    controller: tuple[DriveController, float],
    imu: Path | None,
    scales: tuple[float, float, float],
    max_rows: int,
) -> Signals:
    """The columns of ``path`` (and of ``imu``) the mapping names; ``scales`` = (time, speed, current).
    Without command columns the command is the twist whose set points, through the vehicle's own
    drive controller (``controller`` = (it, the joints' wheel radius [m]): its wheel separation and
    radius multipliers), are the recorded wheel speeds."""
    time_scale, speed_scale, current_scale = scales
    table = read_csv(path, max_rows)
    t = _column(table, columns.time, path, '--time') * time_scale
    if np.any(np.diff(t) < 0):
        raise InputError(f'{path}: the time column {columns.time!r} goes backwards')
    if not (columns.left_speed and columns.right_speed):
        raise InputError('import needs --left-speed and --right-speed (the wheel speed columns)')
    speeds = (columns.left_speed, columns.right_speed)
    speed = _columns2(table, path, speeds, ('--left-speed', '--right-speed')) * speed_scale
    currents = None
    if columns.left_current or columns.right_current:
        if not (columns.left_current and columns.right_current):
            raise InputError('give both --left-current and --right-current')
        names = (columns.left_current, columns.right_current)
        currents = _columns2(table, path, names, ('--left-current', '--right-current')) * current_scale
    voltages = None
    if columns.left_voltage or columns.right_voltage:
        names = (columns.left_voltage or columns.right_voltage, columns.right_voltage or columns.left_voltage)
        voltages = _columns2(table, path, names, ('--left-voltage', '--right-voltage'))
    if columns.cmd_speed or columns.cmd_yaw_rate:
        if not (columns.cmd_speed and columns.cmd_yaw_rate):
            raise InputError(
                'give both --cmd-speed and --cmd-yaw-rate, or neither (set points = wheel speeds)'
            )
        cmd = _columns2(
            table, path, (columns.cmd_speed, columns.cmd_yaw_rate), ('--cmd-speed', '--cmd-yaw-rate')
        )
        cmd_note = f'command from columns {columns.cmd_speed}, {columns.cmd_yaw_rate}'
    else:  # the controller holds wheel speeds: the recorded ones are the set points
        drive, radius_m = controller
        cmd = np.column_stack(drive.twist_of(speed / radius_m))
        cmd_note = (
            'command = the twist whose set points are the recorded wheel speeds (the drive '
            f"controller's kinematics: wheel separation {drive.separation_m:g} m)"
        )
    yaw_t: np.ndarray | None = None
    yaw = None
    if imu is not None:
        imu_table = read_csv(imu, max_rows)
        yaw_t = _column(imu_table, columns.imu_time, imu, '--imu-time') * time_scale
        yaw = _column(imu_table, columns.imu_yaw_rate or 'wz', imu, '--imu-yaw-rate')
    elif columns.yaw_rate:
        yaw_t, yaw = t, _column(table, columns.yaw_rate, path, '--yaw-rate')
    return Signals(t, speed, cmd, cmd_note, currents, voltages, yaw_t, yaw)


class _BagOut:
    """The import's bag: its topics, a typestore, and a count of messages per topic."""

    def __init__(
        self,
        writer: BagWriter,
        signals: Signals,
        current_topics: tuple[str, str],
        voltage_topics: tuple[str, str],
    ) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.writer = writer
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.types = self.store.types
        self.counts: dict[str, int] = {}
        self.cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        self.joint_states = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        float64 = 'std_msgs/msg/Float64'
        self.current = (
            [writer.add_topic('/' + t.lstrip('/'), float64) for t in current_topics]
            if signals.currents is not None
            else []
        )
        self.voltage = (
            [writer.add_topic('/' + t.lstrip('/'), float64) for t in voltage_topics]
            if signals.voltages is not None
            else []
        )
        self.imu = writer.add_topic('/imu/data', 'sensor_msgs/msg/Imu') if signals.yaw is not None else None

    def put(self, connection: Connection, stamp_ns: int, msg: object, msgtype: str) -> None:
        self.writer.write(connection, stamp_ns, self.store.serialize_cdr(msg, msgtype))
        self.counts[connection.topic] = self.counts.get(connection.topic, 0) + 1

    def header(self, t_ns: int) -> MsgType:
        stamp = self.types['builtin_interfaces/msg/Time'](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        return self.types['std_msgs/msg/Header'](stamp=stamp, frame_id='')

    def imu_message(self, t_ns: int, yaw_rate: float) -> None:
        vec, quat, zero9 = (
            self.types['geometry_msgs/msg/Vector3'],
            self.types['geometry_msgs/msg/Quaternion'],
            np.zeros(9),
        )
        msg = self.types['sensor_msgs/msg/Imu'](
            header=self.header(t_ns),
            orientation=quat(0.0, 0.0, 0.0, 1.0),
            orientation_covariance=zero9,
            angular_velocity=vec(0.0, 0.0, yaw_rate),
            angular_velocity_covariance=zero9,
            linear_acceleration=vec(0.0, 0.0, 0.0),
            linear_acceleration_covariance=zero9,
        )
        assert self.imu is not None  # the topic exists whenever a yaw rate was read
        self.put(self.imu, t_ns, msg, 'sensor_msgs/msg/Imu')

    def row(
        self,
        t_ns: int,
        cmd: np.ndarray,
        currents: np.ndarray | None,
        voltages: np.ndarray | None,
        joints: tuple[list[str], np.ndarray, np.ndarray],
    ) -> None:
        """One CSV row: the command, the currents and voltages, then joint_states (after them)."""
        vec = self.types['geometry_msgs/msg/Vector3']
        twist = self.types['geometry_msgs/msg/Twist'](
            vec(float(cmd[0]), 0.0, 0.0), vec(0.0, 0.0, float(cmd[1]))
        )
        self.put(self.cmd, t_ns, twist, 'geometry_msgs/msg/Twist')
        for values, connections in ((currents, self.current), (voltages, self.voltage)):
            for k, connection in enumerate(connections):
                assert values is not None  # a side's topics exist only where its values were recorded
                msg = self.types['std_msgs/msg/Float64'](data=float(values[k]))
                self.put(connection, t_ns, msg, 'std_msgs/msg/Float64')
        names, position, velocity = joints
        js = self.types['sensor_msgs/msg/JointState'](
            header=self.header(t_ns), name=names, position=position, velocity=velocity, effort=np.zeros(0)
        )
        self.put(self.joint_states, t_ns + 1000, js, 'sensor_msgs/msg/JointState')


def write_bag(
    output: Path,
    signals: Signals,
    joints: JointMap,
    radius_m: float,
    topics: tuple[tuple[str, str], tuple[str, str]],
) -> dict[str, int]:
    """The bag of ``signals`` (module doc) for the drivetrain ``joints``; messages per topic."""
    from skidsteer_power.bag_io.writer import BagWriter

    t, n_left, names = signals.t, len(joints.left), list(joints.joints)
    sign = np.array([-1.0 if j in joints.inverted else 1.0 for j in names])
    omega = signals.speed / radius_m  # wheel speed [rad/s]
    position = np.vstack(
        [np.zeros(2), np.cumsum(0.5 * (omega[1:] + omega[:-1]) * np.diff(t)[:, None], axis=0)]
    )
    side = np.r_[np.zeros(n_left, int), np.ones(len(names) - n_left, int)]
    events: list[tuple[int, int, int]] = [(round(x * 1e9), 0, i) for i, x in enumerate(t)]
    if signals.yaw_t is not None:
        events += [(round(x * 1e9), 1, i) for i, x in enumerate(signals.yaw_t)]
    events.sort()
    with BagWriter(output) as writer:
        out = _BagOut(writer, signals, *topics)
        for offset_ns, kind, i in events:
            t_ns = START_NS + offset_ns
            if kind == 1:
                assert signals.yaw is not None
                out.imu_message(t_ns, float(signals.yaw[i]))
                continue
            currents = None if signals.currents is None else signals.currents[i]
            voltages = None if signals.voltages is None else signals.voltages[i]
            state = (names, position[i, side] * sign, omega[i, side] * sign)
            out.row(t_ns, signals.cmd[i], currents, voltages, state)
    return out.counts


class ImportSummary(TypedDict):
    """What :func:`import_csv` wrote (the ``--json`` keys): the bag, its sources, the vehicle, the CSV's
    rows and duration [s], messages per topic, where the command came from and the wheel radius [m]."""

    bag: str
    csv: str
    imu_csv: str | None
    vehicle: str
    rows: int
    duration_s: float
    messages: dict[str, int]
    command: str
    wheel_radius_m: float


def import_csv(
    path: Path,
    output: Path,
    vehicle_name: str,
    columns: Columns,
    *,
    imu: Path | None = None,
    time_scale: float = 1.0,
    speed_scale: float = 1.0,
    current_scale: float = 1.0,
    current_topics: tuple[str, str] = (
        'left_drive/status/battery_current',
        'right_drive/status/battery_current',
    ),
    voltage_topics: tuple[str, str] = (
        'left_drive/status/battery_voltage',
        'right_drive/status/battery_voltage',
    ),
    max_rows: int = int(MAX_ROWS.high),
) -> ImportSummary:
    """Write the bag (module docstring); return what was written (topics, message counts, duration)."""
    from skidsteer_power.drive import controller_for_vehicle
    from skidsteer_power.estimator import factory
    from skidsteer_power.vehicle import load_vehicle

    vehicle = load_vehicle(vehicle_name)
    joints = factory.joint_map_for(vehicle)
    radius = float(vehicle.drive_radius_m)
    controller = controller_for_vehicle(vehicle)
    scales = (time_scale, speed_scale, current_scale)
    signals = read_signals(path, columns, (controller, radius), imu, scales, max_rows)
    counts = write_bag(output, signals, joints, radius, (current_topics, voltage_topics))
    t = signals.t
    return {
        'bag': str(output),
        'csv': str(path),
        'imu_csv': None if imu is None else str(imu),
        'vehicle': vehicle.name,
        'rows': int(t.size),
        'duration_s': float(t[-1] - t[0]) if t.size > 1 else 0.0,
        'messages': counts,
        'command': signals.cmd_note,
        'wheel_radius_m': radius,
    }


def _pair(text: str) -> tuple[str, str]:
    parts = [p.strip() for p in text.split(',')]
    if len(parts) != 2 or not all(parts):
        raise argparse.ArgumentTypeError(f'expected LEFT,RIGHT topic names, not {text!r}')
    return parts[0], parts[1]


def _cmd_import(args: argparse.Namespace) -> int:
    preset = PRESETS.get(args.preset or '', {})
    given = {f: getattr(args, f) for f in Columns.__dataclass_fields__ if getattr(args, f) is not None}
    columns = Columns(**{**preset, **given})
    if args.imu is not None and not columns.imu_yaw_rate:
        columns = Columns(**{**columns.__dict__, 'imu_yaw_rate': 'wz'})
    output = Path(args.output)
    if output.exists():
        raise InputError(f'{output} exists: import writes a new bag')
    summary = import_csv(
        Path(args.csv),
        output,
        args.vehicle,
        columns,
        imu=None if args.imu is None else Path(args.imu),
        time_scale=args.time_scale,
        speed_scale=args.speed_scale,
        current_scale=args.current_scale,
        current_topics=args.current_topics,
        voltage_topics=args.voltage_topics,
        max_rows=args.max_rows,
    )
    emit(summary, args.json)
    return 0


def register(subparsers: Subcommands) -> None:
    parser = subparsers.add_parser(
        'import',
        help='turn a CSV log (wheel speeds, currents, voltages, command, yaw rate) into a bag',
        description='Write a rosbag2 MCAP bag from a CSV log, by a column mapping: /joint_states (the '
        "vehicle's joints, wheel speed / radius), /cmd_vel (the command columns, or the wheel speeds as "
        'set points), one std_msgs/Float64 topic per side for current and voltage (what the vehicle '
        "file's measured_power maps), /imu/data for a yaw rate. validate, calibrate and compare read it.",
    )
    parser.add_argument('csv', metavar='LOG.csv', help='CSV with a header row')
    parser.add_argument('-o', '--output', required=True, metavar='OUT.mcap', help='bag to write (new)')
    parser.add_argument('--vehicle', required=True, help='vehicle name or YAML (joints, wheel radius, tread)')
    parser.add_argument('--preset', choices=sorted(PRESETS), help='a known log layout (borealtc: BorealTC)')
    parser.add_argument('--imu', metavar='IMU.csv', help='a second CSV with the yaw rate, merged by time')
    for name, what in (
        ('time', 'time [s x --time-scale] (default time)'),
        ('left-speed', 'left wheel speed at the tread [m/s x --speed-scale]'),
        ('right-speed', 'right wheel speed at the tread [m/s x --speed-scale]'),
        ('left-current', 'left measured current [A x --current-scale]'),
        ('right-current', 'right measured current [A x --current-scale]'),
        ('left-voltage', 'left voltage [V] (one column for both sides: give it once)'),
        ('right-voltage', 'right voltage [V]'),
        ('cmd-speed', 'commanded forward speed [m/s] (none: the wheel speeds are the set points)'),
        ('cmd-yaw-rate', 'commanded yaw rate [rad/s]'),
        ('yaw-rate', 'measured yaw rate [rad/s] in this CSV'),
        ('imu-time', 'time column of --imu (default time)'),
        ('imu-yaw-rate', 'yaw-rate column of --imu [rad/s] (default wz)'),
    ):
        parser.add_argument(f'--{name}', dest=name.replace('-', '_'), metavar='COL', help=f'column: {what}')
    parser.add_argument(
        '--time-scale', type=finite_float, default=1.0, help='seconds per time unit (default 1)'
    )
    parser.add_argument(
        '--speed-scale', type=finite_float, default=1.0, help='m/s per speed unit (default 1)'
    )
    parser.add_argument(
        '--current-scale', type=finite_float, default=1.0, help='A per current unit (default 1)'
    )
    parser.add_argument(
        '--current-topics',
        type=_pair,
        default=_pair(CURRENT_TOPICS),
        metavar='LEFT,RIGHT',
        help=f'Float64 topics of the currents (default {CURRENT_TOPICS})',
    )
    parser.add_argument(
        '--voltage-topics',
        type=_pair,
        default=_pair(VOLTAGE_TOPICS),
        metavar='LEFT,RIGHT',
        help=f'Float64 topics of the voltages (default {VOLTAGE_TOPICS})',
    )
    parser.add_argument(
        '--max-rows',
        type=range_arg(MAX_ROWS),
        default=int(MAX_ROWS.high),
        metavar='N',
        help=range_help(MAX_ROWS, 'largest CSV read, rows per file'),
    )
    add_json_flag(parser)
    parser.set_defaults(func=_cmd_import)
