"""Drive the twin through a command sequence, sample its sensors, write the bag.

Sensors, as the robot has them (sampled at ``SENSOR_RATE_HZ``, seeded noise):

* joint_states (``left_motor``, ``right_motor``): position from the quadrature encoder (2048 lines x
  4 counts per motor turn, ch. 7.1.2), velocity = change of the quantized position over the sample
  interval [rad/s at the motor, forward positive], effort = K_t I [N m] with I the amplifier's
  current averaged over the interval plus Gaussian noise (``CURRENT_NOISE_A``, ASSUMED) quantized
  to 1 mA (the DES reports mA);
* odom (nav_msgs/Odometry): dead reckoning from those encoder speeds (side speed = omega r / G,
  V = mean, yaw rate = difference / B), so it drifts with slip like real wheel odometry;
* ground_truth/odom: the true pose and hull-frame twist (both odometries at ``ODOM_RATE_HZ``);
* battery/measured (sensor_msgs/BatteryState): bus voltage [V] and current [A], ROS sign
  (negative while discharging), at ``BATTERY_RATE_HZ``.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias

import numpy as np
import numpy.typing as npt
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.bag_io.synthetic import NS, START_NS
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.commands import Segment
from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.terramechanics.ranges import COMMAND_ROWS, SIM_DURATION_S, check_file_size
from skidsteer_power.twin.model import Twin

if TYPE_CHECKING:
    from rosbags.typesys.store import MsgType

SENSOR_RATE_HZ = 50.0
"""Sample rate of the trace and of joint_states in the bag [Hz] (the des_driver's joint_states rate)."""
ODOM_RATE_HZ = 10.0
"""odom and ground_truth/odom rate in the bag [Hz] (a motion-capture rate; keeps bags small)."""
CMD_RATE_HZ = 25.0
"""cmd_vel rate written to the bag [Hz]."""
BATTERY_RATE_HZ = 10.0
"""battery/measured rate [Hz]."""
CURRENT_NOISE_A = 0.02
"""ASSUMED standard deviation of the amplifier's current reading [A]."""
CURRENT_QUANTUM_A = 0.001
"""Current resolution of the DES reading: 1 mA."""
QUADRATURE = 4
"""Counts per encoder line (quadrature decoding)."""
STUCK_WINDOW_S = 2.0
"""Window over which a commanded robot must make progress [s]."""
STUCK_PROGRESS = 0.2
"""Fraction of the commanded motion below which a window counts as stuck [-]."""
COMMAND_TIMEOUT_S = 0.5
"""A bag's command older than this stops the robot (the des_driver's fail-safe timeout) [s]."""


@dataclass
class TwinTrace:
    """Samples of a twin run at ``SENSOR_RATE_HZ`` (arrays over samples; [..., 2] = left, right).

    Truth: t [s], cmd (V [m/s], yaw rate [rad/s]), pose (x, y [m], yaw [rad], world),
    twist (v_x, v_y [m/s] hull frame, yaw rate [rad/s]), current_A (true, mean over the interval),
    axle_torque_Nm (terrain's resisting torque), motor_omega_rad_s (true), bus_voltage_V,
    bus_current_A (mean), energy_J (cumulative bus energy), sinkage_m.
    Sensors: joint_position_rad, joint_velocity_rad_s, joint_effort_Nm, odom_pose, odom_twist.
    """

    vehicle: str
    terrain: str
    t: np.ndarray
    cmd: np.ndarray
    pose: np.ndarray
    twist: np.ndarray
    current_A: np.ndarray
    axle_torque_Nm: np.ndarray
    motor_omega_rad_s: np.ndarray
    bus_voltage_V: np.ndarray
    bus_current_A: np.ndarray
    energy_J: np.ndarray
    sinkage_m: np.ndarray
    joint_position_rad: np.ndarray
    joint_velocity_rad_s: np.ndarray
    joint_effort_Nm: np.ndarray
    odom_pose: np.ndarray
    odom_twist: np.ndarray
    ledger: dict[str, float] = field(default_factory=dict)
    messages: dict[str, int] = field(default_factory=dict)
    contact: str = 'extended'  # the twin's contact laws, 'classic' or 'extended' (Twin)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1]) if self.t.size else 0.0

    @property
    def distance_m(self) -> float:
        """True path length travelled [m]."""
        return float(np.hypot(*np.diff(self.pose[:, :2], axis=0).T).sum()) if self.t.size > 1 else 0.0

    def motion(self, tread_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded and actual motion per sample [m/s]: |V| + |yaw rate| B / 2 of the command, and
        |v| + |yaw rate| B / 2 of the robot (B = ``tread_m`` [m])."""
        wanted = np.abs(self.cmd[:, 0]) + np.abs(self.cmd[:, 1]) * 0.5 * tread_m
        actual = np.hypot(self.twist[:, 0], self.twist[:, 1]) + np.abs(self.twist[:, 2]) * 0.5 * tread_m
        return wanted, actual

    def stuck(self, tread_m: float) -> bool:
        """True if, over some ``STUCK_WINDOW_S`` window with a non-zero command throughout, the robot's
        motion (|v| + |yaw rate| B / 2) stayed below ``STUCK_PROGRESS`` of the commanded motion."""
        n = max(1, round(STUCK_WINDOW_S * SENSOR_RATE_HZ))
        if self.t.size < n:
            return False
        wanted, actual = self.motion(tread_m)
        kernel = np.ones(n)
        commanded = np.convolve(wanted > 1e-6, kernel, 'valid') == n
        ratio = np.convolve(actual, kernel, 'valid') / np.maximum(np.convolve(wanted, kernel, 'valid'), 1e-12)
        return bool(np.any(commanded & (ratio < STUCK_PROGRESS)))

    def summary(self, tread_m: float) -> dict[str, object]:
        """The ``simulate --json`` keys: duration_s, messages, energy_J, distance_m, max_sinkage_m, stuck,
        contact."""
        return {
            'duration_s': self.duration_s,
            'messages': dict(self.messages),
            'energy_J': float(self.energy_J[-1]) if self.energy_J.size else 0.0,
            'distance_m': self.distance_m,
            'max_sinkage_m': float(self.sinkage_m.max()) if self.sinkage_m.size else 0.0,
            'stuck': self.stuck(tread_m),
            'contact': self.contact,
        }


MIN_STEP_S = 1e-9
"""Shortest twin step taken [s] (a bag's time resolution, 1 ns): a command row ends within it."""
TRACTION_BOUND = 10.0
"""A side's axle torque above this many times the robot's whole weight at the drive radius
(m g r) is no physics on any ground (friction coefficients stay below about 1.5): the twin's
integration has diverged [-]."""


_Sample = tuple[
    float, tuple[float, float], np.ndarray, np.ndarray, tuple[float, float],
    np.ndarray, np.ndarray, np.ndarray, float, float, float, float,
]  # fmt: skip
"""One sample of :func:`run_commands`: t, command, pose, twist, mean currents, axle torques, motor
speeds and angles, bus voltage, mean bus current, bus energy, sinkage (the columns of :func:`_trace`)."""


def run_commands(
    twin: Twin,
    commands: Sequence[Segment],
    *,
    rate_hz: float = SENSOR_RATE_HZ,
    progress: Callable[[float], None] | None = None,
) -> TwinTrace:
    """Drive ``twin`` (from its present state) through ``commands`` and sample at ``rate_hz`` [Hz];
    ``progress(seconds)`` is told the twin time [s] of each command done.

    Each command is held for its own duration: the twin steps at its ``dt`` and shortens the step
    that would cross the end of a command or a sample time (a 0.5 ms row is one 0.5 ms step, a 3 ms
    row a 2 ms and a 1 ms step), so the run lasts exactly the commands' total and samples fall on
    the ``rate_hz`` grid; a run ending between samples gets a last sample at its end. Sensor
    averages weight each step by its length.
    """
    full_dt = twin.dt
    period = max(1, round(1.0 / (rate_hz * full_dt))) * full_dt  # a whole number of full steps [s]
    rows: list[_Sample] = []
    current_sum = [0.0, 0.0]
    bus_sum = 0.0
    weight = 0.0  # steps since the last sample, in full steps

    def sample() -> None:
        nonlocal current_sum, bus_sum, weight
        k = weight if weight > 0 else 1.0
        last = twin.last
        rows.append(
            (
                twin.t,
                twin.command,
                twin.pose.copy(),
                twin.vel.copy(),
                (current_sum[0] / k, current_sum[1] / k),
                last.axle_torque_Nm,  # a new array per call of Twin.last
                twin.omega_m.copy(),
                twin.theta_m.copy(),
                twin.bus_voltage_V,
                bus_sum / k,
                twin.energy.bus_J,
                last.sinkage_m,
            )
        )
        current_sum, bus_sum, weight = [0.0, 0.0], 0.0, 0.0

    sample()
    end_s = next_sample_s = twin.t
    next_sample_s += period
    bound_Nm = TRACTION_BOUND * twin.mass * 9.81 * twin.r
    try:
        for segment in commands:
            twin.set_command(segment.speed_m_s, segment.yaw_rate_rad_s)
            end_s += segment.duration_s
            while end_s - twin.t > MIN_STEP_S:
                step = min(full_dt, end_s - twin.t, max(next_sample_s - twin.t, MIN_STEP_S))
                twin.dt = full_dt if step > full_dt - MIN_STEP_S else step
                try:
                    twin._step()
                except ArithmeticError as err:  # an overflow: the state had diverged already
                    raise _diverged(twin, f'{type(err).__name__}: {err}') from err
                w = twin.dt / full_dt  # exactly 1.0 for a full step
                left, right = twin.current_A
                current_sum[0] += w * left
                current_sum[1] += w * right
                bus_sum += w * twin.bus_current_A
                weight += w
                if twin.t >= next_sample_s - MIN_STEP_S:
                    sample()
                    next_sample_s += period
                    _check_physical(twin, rows[-1][5], bound_Nm)
            if progress is not None:
                progress(segment.duration_s)
    finally:
        twin.dt = full_dt
    if weight > 0:
        sample()  # the run ended between two samples
    return _trace(twin, rows)


def _diverged(twin: Twin, what: str) -> ConvergenceError:
    speed, yaw_rate = twin.command
    return ConvergenceError(
        f'the twin diverged at t = {twin.t:.3f} s under the command {speed:g} m/s, {yaw_rate:g} rad/s '
        f'({what}): its trace is no physics from there; a known weakness of its soil contact on rigid '
        'ground (docs/TWIN.md)'
    )


def _check_physical(twin: Twin, axle_torque_Nm: npt.ArrayLike, bound_Nm: float) -> None:
    """ConvergenceError when the twin's state is not finite or a side's axle torque [N m] exceeds
    ``bound_Nm`` (:data:`TRACTION_BOUND`): a trace that silently carries a diverged state would be
    read as a recording."""
    torque = np.abs(np.asarray(axle_torque_Nm, dtype=float))
    state = (twin.vel, twin.omega_m, torque)
    if not all(np.all(np.isfinite(part)) for part in state):
        raise _diverged(twin, 'a state that is not finite')
    if np.any(torque > bound_Nm):
        raise _diverged(
            twin,
            f'axle torque {float(torque.max()):.4g} N m, over {TRACTION_BOUND:g} x the weight at the wheel',
        )


def drive_until_empty(
    twin: Twin, pattern: Sequence[Segment], *, piece_s: float = 0.2, max_pieces: int = 2000
) -> tuple[list[TwinTrace], float | None]:
    """Repeat ``pattern`` until the twin's battery is empty: the traces of each ``piece_s`` [s] piece
    (a whole number of sensor periods, so the empty moment is known to ``piece_s``) and the twin time
    it went empty [s] (None if it had not after ``max_pieces`` pieces). InputError for a segment that
    is not a whole number of pieces."""
    pieces = []
    for seg in pattern:
        count = round(seg.duration_s / piece_s)
        if count < 1 or abs(count * piece_s - seg.duration_s) > 1e-9:
            raise InputError(f'segment of {seg.duration_s} s is not a whole number of {piece_s} s pieces')
        pieces += [Segment(seg.speed_m_s, seg.yaw_rate_rad_s, piece_s)] * count
    traces: list[TwinTrace] = []
    while len(traces) < max_pieces:
        traces.append(run_commands(twin, [pieces[len(traces) % len(pieces)]]))
        if twin.battery.is_empty:
            return traces, twin.t
    return traces, None


def _trace(twin: Twin, rows: list[_Sample]) -> TwinTrace:
    cols = list(zip(*rows, strict=True))
    arr = [np.array(c, dtype=float) for c in cols]
    t, cmd, pose, twist, current, axle, omega, theta, volt, bus, energy, sinkage = arr
    rng = twin.sensor_rng
    motor = twin.powertrain.motor
    counts_per_rad = motor.encoder_counts_per_turn * QUADRATURE / (2.0 * math.pi)
    position = np.floor(theta * counts_per_rad) / counts_per_rad
    dt = np.diff(t, prepend=t[0])
    with np.errstate(invalid='ignore', divide='ignore'):
        velocity = np.where(
            dt[:, None] > 0, np.diff(position, axis=0, prepend=position[:1]) / dt[:, None], 0.0
        )
    measured = np.round((current + rng.normal(0.0, CURRENT_NOISE_A, current.shape)) / CURRENT_QUANTUM_A)
    effort = motor.torque_constant_Nm_A * measured * CURRENT_QUANTUM_A
    side = velocity * twin.r / twin.G
    v = side.mean(axis=1)
    yaw_rate = (side[:, 1] - side[:, 0]) / twin.vehicle.tread_m
    heading = np.concatenate([[0.0], np.cumsum(yaw_rate[1:] * dt[1:])])
    step = v * dt
    odom_xy = np.cumsum(np.column_stack([step * np.cos(heading), step * np.sin(heading)]), axis=0)
    odom_pose = np.column_stack([odom_xy, heading])
    odom_twist = np.column_stack([v, np.zeros_like(v), yaw_rate])
    e = twin.energy
    ledger = {
        'bus_J': e.bus_J,
        'amplifier_J': e.amplifier_J,
        'copper_J': e.copper_J,
        'friction_J': e.friction_J,
        'terrain_J': e.terrain_J,
        'kinetic_J': twin.kinetic_energy(),
    }
    return TwinTrace(
        vehicle=twin.vehicle.name,
        terrain=twin.field.base.name,
        contact=twin.contact_laws,
        t=t,
        cmd=cmd,
        pose=pose,
        twist=twist,
        current_A=current,
        axle_torque_Nm=axle,
        motor_omega_rad_s=omega,
        bus_voltage_V=volt,
        bus_current_A=bus,
        energy_J=energy,
        sinkage_m=sinkage,
        joint_position_rad=position,
        joint_velocity_rad_s=velocity,
        joint_effort_Nm=effort,
        odom_pose=odom_pose,
        odom_twist=odom_twist,
        ledger=ledger,
        messages=_message_counts(t.size),
    )


def _message_counts(n: int) -> dict[str, int]:
    every_cmd, every_odom, every_bat = _every()
    return {
        '/cmd_vel': len(range(0, n, every_cmd)),
        '/joint_states': n,
        '/odom': len(range(0, n, every_odom)),
        '/ground_truth/odom': len(range(0, n, every_odom)),
        '/battery/measured': len(range(0, n, every_bat)),
    }


def _every() -> tuple[int, int, int]:
    """Samples between cmd_vel, odom and battery messages in the bag."""
    cmd, odom, battery = (
        round(SENSOR_RATE_HZ / rate) for rate in (CMD_RATE_HZ, ODOM_RATE_HZ, BATTERY_RATE_HZ)
    )
    return cmd, odom, battery


# ---------------------------------------------------------------------------------------------
# commands
# ---------------------------------------------------------------------------------------------


def commands_from_csv(path: str | os.PathLike[str]) -> list[Segment]:
    """Columns t_s, speed_m_s, yaw_rate_rad_s; each row holds until the next; the last row's t_s
    ends the run (its command is not held). InputError naming the line for bad rows. Read row by row
    and stopped early: a file over ``ROUTE_CSV_BYTES``, more than ``COMMAND_ROWS`` rows or a t_s
    beyond the simulated-time range is refused before the rest is read."""
    import csv

    file = Path(path)
    try:
        check_file_size(file)
        with file.open(newline='', encoding='utf-8') as handle:
            reader = csv.DictReader(handle)
            missing = {'t_s', 'speed_m_s', 'yaw_rate_rad_s'} - set(reader.fieldnames or ())
            if missing:
                raise InputError(f'{file}: missing column(s) {", ".join(sorted(missing))}')
            rows = [_command_row(file, line, row) for line, row in _capped(reader, file)]
    except OSError as err:
        raise InputError(f'cannot read command file {file}: {err.strerror or err}') from err
    except (csv.Error, UnicodeDecodeError) as err:
        raise InputError(f'{file}: not a command CSV ({err})') from err
    if len(rows) < 2:
        raise InputError(f'{file}: need at least two rows (the last one ends the run)')
    times = np.array([r[0] for r in rows])
    if np.any(np.diff(times) < 0) or times[0] < 0:
        raise InputError(f'{file}: t_s must start >= 0 and not decrease')
    segments = [Segment(0.0, 0.0, float(times[0]))] if times[0] > 0 else []
    segments += [Segment(a[1], a[2], b[0] - a[0]) for a, b in itertools.pairwise(rows) if b[0] > a[0]]
    return segments


def _capped(reader: Iterable[dict[str, str]], file: Path) -> Iterator[tuple[int, dict[str, str]]]:
    """(line, row) of ``reader``; InputError past ``COMMAND_ROWS`` rows, before reading further."""
    for line, row in enumerate(reader, start=2):
        if line - 1 > COMMAND_ROWS:
            raise InputError(f'{file}: more than {COMMAND_ROWS:,} rows')
        yield line, row


def _command_row(file: Path, line: int, row: dict[str, str]) -> tuple[float, float, float]:
    try:
        t_s, speed, yaw_rate = (float(row[k]) for k in ('t_s', 'speed_m_s', 'yaw_rate_rad_s'))
    except (TypeError, ValueError):
        raise InputError(f'{file}:{line}: t_s, speed_m_s, yaw_rate_rad_s must be numbers') from None
    values = (t_s, speed, yaw_rate)
    if not all(math.isfinite(v) for v in values):
        raise InputError(f'{file}:{line}: values must be finite')
    try:
        SIM_DURATION_S.check(max(t_s, 1e-9))  # t_s: a run beyond the limit stops here
    except InputError as err:
        raise InputError(f'{file}:{line}: t_s: {err}') from None
    return values


def commands_from_bag(path: str | os.PathLike[str], topic: str = '/cmd_vel') -> list[Segment]:
    """The bag's cmd_vel (Twist or TwistStamped), each held until the next or for at most
    ``COMMAND_TIMEOUT_S`` (then the robot stops, as the des_driver does)."""
    from skidsteer_power.bag_io.decode import decode_twists
    from skidsteer_power.bag_io.reader import open_bag

    with open_bag(path) as bag:
        if topic not in bag.topics:
            raise InputError(f'{path}: no topic {topic} (topics: {", ".join(sorted(bag.topics))})')
        t, values = decode_twists(bag, topic, bag.start_ns)
    if t.size == 0:
        raise InputError(f'{path}: {topic} has no messages')
    segments = [Segment(0.0, 0.0, float(t[0]))] if t[0] > 0 else []
    ends = np.append(t[1:], t[-1] + COMMAND_TIMEOUT_S)
    for start, end, (speed, yaw) in zip(t, ends, values, strict=True):
        held = min(end - start, COMMAND_TIMEOUT_S)
        if held <= 0:  # a later message with the same stamp replaces this one
            continue
        segments.append(Segment(float(speed), float(yaw), float(held)))
        if end - start > held:
            segments.append(Segment(0.0, 0.0, float(end - start - held)))
    return segments


class RouteLike(Protocol):
    """What the twin needs of a mission route (``missions.routes.Route``, a layer above the twin)."""

    @property
    def segments(self) -> Sequence[Segment]: ...


def commands_from_route(route: RouteLike) -> list[Segment]:
    """A mission route (``missions.routes.Route``) as (V, yaw rate = V / R, duration) holds, then 1 s stop."""
    return [*route.segments, Segment(0.0, 0.0, 1.0)]


# ---------------------------------------------------------------------------------------------
# bag
# ---------------------------------------------------------------------------------------------


def write_bag(trace: TwinTrace, path: str | os.PathLike[str], *, start_ns: int = START_NS) -> Path:
    """Write the trace's messages (see the module doc) to a rosbag2 MCAP bag at ``path``."""
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    ser = store.serialize_cdr
    stamps = start_ns + np.round(trace.t * NS).astype(np.int64)
    every_cmd, every_odom, every_bat = _every()
    vec, twist_t = T['geometry_msgs/msg/Vector3'], T['geometry_msgs/msg/Twist']
    with BagWriter(Path(path)) as writer:
        cmd = writer.add_topic('/cmd_vel', 'geometry_msgs/msg/Twist')
        js = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        odom = writer.add_topic('/odom', 'nav_msgs/msg/Odometry')
        truth = writer.add_topic('/ground_truth/odom', 'nav_msgs/msg/Odometry')
        battery = writer.add_topic('/battery/measured', 'sensor_msgs/msg/BatteryState')
        for i, stamp in enumerate(stamps.tolist()):
            if i % every_cmd == 0:
                msg = twist_t(vec(float(trace.cmd[i, 0]), 0.0, 0.0), vec(0.0, 0.0, float(trace.cmd[i, 1])))
                writer.write(cmd, stamp, ser(msg, 'geometry_msgs/msg/Twist'))
            joint = T['sensor_msgs/msg/JointState'](
                _header(T, stamp, ''),
                ['left_motor', 'right_motor'],
                trace.joint_position_rad[i].astype(float),
                trace.joint_velocity_rad_s[i].astype(float),
                trace.joint_effort_Nm[i].astype(float),
            )
            writer.write(js, stamp + 1000, ser(joint, 'sensor_msgs/msg/JointState'))
            if i % every_odom == 0:
                writer.write(
                    odom,
                    stamp + 2000,
                    ser(
                        _odometry(T, stamp, trace.odom_pose[i], trace.odom_twist[i]), 'nav_msgs/msg/Odometry'
                    ),
                )
                writer.write(
                    truth,
                    stamp + 3000,
                    ser(_odometry(T, stamp, trace.pose[i], trace.twist[i]), 'nav_msgs/msg/Odometry'),
                )
            if i % every_bat == 0:
                writer.write(
                    battery, stamp + 4000, ser(_battery(T, stamp, trace, i), 'sensor_msgs/msg/BatteryState')
                )
        trace.messages = dict(writer.counts)
    return Path(path)


MessageClasses: TypeAlias = 'Mapping[str, type[MsgType]]'
"""A typestore's message classes by type name (rosbags ``Typestore.types``): rosbags makes them at
run time from the message definitions, so their constructors have no static signature."""


def _header(types: MessageClasses, stamp_ns: int, frame: str) -> MsgType:
    sec, nsec = divmod(int(stamp_ns), NS)
    return types['std_msgs/msg/Header'](types['builtin_interfaces/msg/Time'](sec, nsec), frame)


def _odometry(types: MessageClasses, stamp_ns: int, pose: np.ndarray, twist: np.ndarray) -> object:
    half = float(pose[2]) / 2
    p = types['geometry_msgs/msg/Pose'](
        types['geometry_msgs/msg/Point'](float(pose[0]), float(pose[1]), 0.0),
        types['geometry_msgs/msg/Quaternion'](0.0, 0.0, math.sin(half), math.cos(half)),
    )
    vec = types['geometry_msgs/msg/Vector3']
    tw = types['geometry_msgs/msg/Twist'](
        vec(float(twist[0]), float(twist[1]), 0.0), vec(0.0, 0.0, float(twist[2]))
    )
    return types['nav_msgs/msg/Odometry'](
        _header(types, stamp_ns, 'odom'),
        'base_link',
        types['geometry_msgs/msg/PoseWithCovariance'](p, np.zeros(36)),
        types['geometry_msgs/msg/TwistWithCovariance'](tw, np.zeros(36)),
    )


def _battery(types: MessageClasses, stamp_ns: int, trace: TwinTrace, i: int) -> object:
    msg: Any = types['sensor_msgs/msg/BatteryState']  # Any: its POWER_SUPPLY_* constants are made at run time
    nan = float('nan')
    return msg(
        header=_header(types, stamp_ns, 'base_link'),
        voltage=float(trace.bus_voltage_V[i]),
        temperature=nan,
        current=-float(trace.bus_current_A[i]),  # ROS: negative while discharging
        charge=nan,
        capacity=nan,
        design_capacity=nan,
        percentage=nan,
        power_supply_status=msg.POWER_SUPPLY_STATUS_DISCHARGING,
        power_supply_health=msg.POWER_SUPPLY_HEALTH_UNKNOWN,
        power_supply_technology=msg.POWER_SUPPLY_TECHNOLOGY_LIPO,
        present=True,
        cell_voltage=np.zeros(0),
        cell_temperature=np.zeros(0),
        location='bus',
        serial_number='',
    )
