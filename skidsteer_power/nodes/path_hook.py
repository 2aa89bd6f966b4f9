"""The power_estimator's path-energy part: ``plan`` in, ``energy/path_*_wh`` and a diagnostic out.

A thin rclpy helper the node owns (the physics is :mod:`skidsteer_power.estimator.path_energy`):

subscribes ``plan`` nav_msgs/Path (nav2's name; remappable): poses' x, y [m] (frame ignored: only
    lengths and heading changes matter)
publishes (at once on a new path, then with the node's battery topics, every ``publish_period_s``)
    ``energy/path_required_wh`` std_msgs/Float64 [Wh]: battery energy to drive the path at
        ``path_speed_m_s`` (0: the last commanded |V|) with the current map and powertrain, the map's
        axle torques times the online terrain scale (``terrain_scale`` in ``power/correction``)
    ``energy/path_margin_wh`` std_msgs/Float64 [Wh]: remaining - path - back to the path's start along
        the reversed path - ``path_reserve_wh``
    ``diagnostics``: status ``<node>: path energy``, WARN while the margin is negative (every
        ``diagnostics_period_s``, once a path was received)
Nothing is published while no path, no speed (parameter 0 and no command yet) or no map is known;
the diagnostic says which.

Off the executor (issue 28: a 1e5-pose plan blocked the node's only executor thread for 2.65 s, most
of it rclpy deserializing): ``plan`` is subscribed raw, its callback only keeps the newest bytes, and
a worker thread reads the poses (:func:`path_xy`, numpy over the CDR when every pose has the same
frame_id) and builds the geometry, decimating a path of more than ``MAX_PATH_POSES`` poses
(estimator/path_energy.py). The result replaces the plan under the hook's lock, and the next
battery tick evaluates and publishes it; a plan of more than ``MAX_READ_POSES`` poses is refused
unread.
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from nav_msgs.msg import Path
from std_msgs.msg import Float64

from skidsteer_power.errors import InputError, SkidsteerError
from skidsteer_power.estimator.path_energy import (
    MAX_PATH_POSES,
    PATH_TOLERANCE_M,
    PathEnergy,
    PathTracker,
    PlannedPath,
)
from skidsteer_power.nodes.param_spec import ParamSpec
from skidsteer_power.nodes.parameters import PowerEstimatorParameters
from skidsteer_power.nodes.wire import decoder

if TYPE_CHECKING:
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile
    from rclpy.subscription import Subscription

    from skidsteer_power.estimator.prediction import Predictor

MAX_READ_POSES = 2_000_000
"""Most poses of a ``plan`` read (about 140 MB of CDR); a larger one is refused unread."""
_POSE_BYTES = 56  # geometry_msgs/Pose: 7 float64

PARAMETERS = (
    ParamSpec(
        'path_speed_m_s',
        0.0,
        'speed to drive the planned path at [m/s]; 0 = the last commanded speed',
        (0.0, 10.0),
    ),
    ParamSpec('path_reserve_wh', 0.0, 'energy kept in reserve in energy/path_margin_wh [Wh]', (0.0, 1e6)),
)


class PathInputs(NamedTuple):
    """The node's state the path energy reads (one consistent snapshot: the node's ``path_inputs()``).

    predictor : the estimator's predictor (its ``power_map`` and ``powertrain``); command : last
    (V [m/s], yaw rate [rad/s]) or None; remaining_wh : battery energy left [Wh]; terrain_scale : the
    online terrain scale k [-] (estimator/adaptation.py).
    """

    predictor: Predictor
    command: tuple[float, float] | None
    remaining_wh: float
    terrain_scale: float


class PathNode(Protocol):
    """What the hook uses of its node (the power_estimator): a raw subscription, publishers, the
    logger, the name and :meth:`path_inputs`."""

    def create_subscription(
        self,
        msg_type: type,
        topic: str,
        callback: Callable[[bytes], None],
        qos_profile: QoSProfile | int,
        *,
        raw: bool = False,
    ) -> Subscription: ...
    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile | int) -> Publisher: ...
    def get_logger(self) -> RcutilsLogger: ...
    def get_name(self) -> str: ...
    def path_inputs(self) -> PathInputs: ...


class PathEnergyHook:
    """Subscribes ``plan`` on ``node`` and publishes the path energies (module doc)."""

    def __init__(self, node: PathNode, p: PowerEstimatorParameters, qos: QoSProfile | int) -> None:
        """``p``: the node's parameters (:data:`PARAMETERS` among them, within their ranges)."""
        self.node = node
        self.speed_m_s = p.path_speed_m_s
        self.reserve_wh = p.path_reserve_wh
        self.tracker = PathTracker()
        self.status = 'no path received'
        self.received = False
        self.last: tuple[PathEnergy, float] | None = None  # energies and margin [Wh] last published
        self._lock = threading.Lock()  # the tracker and status: worker thread vs executor
        self._wake = threading.Condition()
        self._pending: bytes | None = None
        self._closed = False
        self._worker = threading.Thread(target=self._work, name='path_energy', daemon=True)
        self._worker.start()
        node.create_subscription(Path, 'plan', self._on_path_bytes, qos, raw=True)
        self.pub_required = node.create_publisher(Float64, 'energy/path_required_wh', 10)
        self.pub_margin = node.create_publisher(Float64, 'energy/path_margin_wh', 10)
        # no timers and no diagnostics publisher of its own: the node calls publish() from its battery
        # timer and puts diagnostic_status() into its own diagnostics array (one publisher per topic)

    def _on_path_bytes(self, data: bytes) -> None:
        """Executor thread: keep the newest plan for the worker (an older unread one is dropped)."""
        with self._wake:
            self._pending = data
            self._wake.notify()

    def _work(self) -> None:
        while True:
            with self._wake:
                while self._pending is None and not self._closed:
                    self._wake.wait()
                data, self._pending = self._pending, None
            if data is None:  # closed
                return
            self._take(data)

    def _take(self, data: bytes) -> None:
        """Worker thread: read and build the plan, then swap it in under the lock."""
        try:
            x, y = path_xy(data)
            planned = PlannedPath(x, y) if x.size else None
        except Exception as err:
            if not isinstance(err, SkidsteerError):
                self.node.get_logger().error(f'path energy: cannot read the plan: {err!r}')
            with self._lock:
                self.received = True
                self._reject(err)
            return
        with self._lock:
            self.received = True
            self.tracker.set_planned(planned)
            self.last = None
            self.status = _described(planned)

    def close(self) -> None:
        """Stop the worker thread (the node's destroy_node)."""
        with self._wake:
            self._closed = True
            self._wake.notify()
        self._worker.join(timeout=5.0)

    def _reject(self, err: Exception) -> None:
        """A path that cannot be evaluated: say why and hold no path."""
        self.status = f'path rejected: {err}'
        self.tracker.set_planned(None)
        self.last = None

    def _evaluate(self) -> tuple[PathEnergy | None, float]:
        if self.tracker.path is None:  # before reading the node's state under its lock
            return None, float('nan')
        predictor, command, remaining, terrain_scale = self.node.path_inputs()
        speed = self.speed_m_s or (abs(command[0]) if command else 0.0)
        power_map = getattr(predictor, 'power_map', None)
        if not speed:
            self.status = 'no speed: path_speed_m_s is 0 and no command yet'
            return None, remaining
        if power_map is None:
            self.status = 'the predictor has no power map'
            return None, remaining
        try:
            powertrain = getattr(predictor, 'powertrain', None)
            path_scale = getattr(predictor, 'path_scale', None)  # its drive controller's
            energy = self.tracker.evaluate(speed, power_map, powertrain, terrain_scale, path_scale)
        except SkidsteerError as err:
            self._reject(err)
            return None, remaining
        return energy, remaining

    def publish(self) -> None:
        """Publish required and margin [Wh] for the current path (nothing if unknown)."""
        with self._lock:
            self._publish()

    def _publish(self) -> None:
        energy, remaining = self._evaluate()
        if energy is None:
            self.last = None
            return
        margin = energy.margin_wh(remaining, self.reserve_wh)
        self.last = (energy, margin)
        self.status = (
            f'{energy.length_m:.1f} m at {energy.speed_m_s:.2f} m/s, terrain scale {energy.terrain_scale:.3f}'
        )
        path = self.tracker.path
        if path is not None and path.poses_kept < path.poses_given:
            self.status += f'; {_described(path)}'

        self.pub_required.publish(Float64(data=energy.required_wh))
        self.pub_margin.publish(Float64(data=margin))

    def diagnostic_status(self) -> DiagnosticStatus | None:
        """The ``<node>: path energy`` status, None before the first path."""
        with self._lock:
            return self._diagnostic_status()

    def _diagnostic_status(self) -> DiagnosticStatus | None:
        if not self.received:
            return None
        level, message = DiagnosticStatus.OK, self.status
        values = {'status': self.status}
        if self.last is not None:
            energy, margin = self.last
            values |= {
                'path_required_wh': f'{energy.required_wh:.3f}',
                'path_margin_wh': f'{margin:.3f}',
                'terrain_scale': f'{energy.terrain_scale:.4f}',
                'clamped_segments': str(energy.clamped_segments),
                'limited_segments': str(energy.limited_segments),
                'slowed_segments': str(energy.slowed_segments),
            }
            if margin < 0:
                level = DiagnosticStatus.WARN
                message = f'not enough energy for the path and back: margin {margin:.2f} Wh'
            else:
                message = f'path and back leave {margin:.2f} Wh'
            flagged = energy.clamped_segments + energy.limited_segments
            if flagged:
                message += f" ({flagged} segments outside the map's validity: clamped or limited)"
            if energy.slowed_segments:
                message += f' ({energy.slowed_segments} segments slowed by the drive controller)'

        status = DiagnosticStatus(level=level, name=f'{self.node.get_name()}: path energy', message=message)
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        return status


def _described(planned: PlannedPath | None) -> str:
    if planned is None:
        return 'empty path: none held'
    if planned.poses_kept < planned.poses_given:
        return (
            f'path of {planned.poses_given} poses, decimated to {planned.poses_kept} '
            f'(within {PATH_TOLERANCE_M:g} m; more than {MAX_PATH_POSES} poses)'
        )
    return f'path of {planned.poses_given} poses'


def path_xy(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """x, y [m] of the poses of a serialized nav_msgs/Path (CDR). When every pose's frame_id has the
    same length (the usual case: one frame), the poses sit at a fixed stride and one numpy view reads
    them all (measured: 1e6 poses in about 0.1 s, against about 24 s through rclpy); otherwise the
    rosbags decoder reads them. InputError beyond ``MAX_READ_POSES`` poses or for bad bytes."""
    try:
        fast = _path_xy_strided(data)
        if fast is not None:
            return fast
        msg = decoder(Path)(data)
    except (struct.error, ValueError, IndexError, KeyError, AssertionError) as err:
        raise InputError(f'plan: not a nav_msgs/Path ({err})') from err
    x = np.array([p.pose.position.x for p in msg.poses], dtype=float)
    y = np.array([p.pose.position.y for p in msg.poses], dtype=float)
    return x, y


def _path_xy_strided(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The fixed-stride read of :func:`path_xy` (little-endian CDR); None when it does not apply."""
    if data[:2] != b'\x00\x01':  # CDR little endian (what rmw writes on x86 and ARM)
        return None

    def align(offset: int, n: int) -> int:  # CDR aligns relative to the payload after the 4-byte header
        return 4 + (offset - 4 + n - 1) // n * n

    offset = 4 + 8  # header.stamp
    (length,) = struct.unpack_from('<I', data, offset)
    offset = align(offset + 4 + length, 4)
    (count,) = struct.unpack_from('<I', data, offset)
    if count > MAX_READ_POSES:
        raise InputError(f'plan of {count:,} poses: at most {MAX_READ_POSES:,} are read')
    first = offset + 4  # pose 0 (its stamp is 4-aligned, so its padding may differ from the rest)
    if count == 0:
        return np.zeros(0), np.zeros(0)
    (frame,) = struct.unpack_from('<I', data, first + 8)
    position = align(first + 12 + frame, 8)
    head = struct.unpack_from('<2d', data, position)
    rest = position + _POSE_BYTES  # pose 1 starts 8-aligned, and so does every later one
    inner = align(rest + 12 + frame, 8) - rest  # pose.position.x within a PoseStamped
    stride = inner + _POSE_BYTES
    if rest + (count - 1) * stride > len(data):
        return None
    table = np.frombuffer(data, dtype=np.uint8, count=(count - 1) * stride, offset=rest).reshape(-1, stride)
    if np.any(table[:, 8:12].copy().view('<u4').ravel() != frame):
        return None  # frame_ids of different lengths: no fixed stride
    xy = np.vstack([head, table[:, inner : inner + 16].copy().view('<f8')])
    return xy[:, 0].copy(), xy[:, 1].copy()
