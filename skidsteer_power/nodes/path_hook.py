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
"""

from __future__ import annotations

from typing import Any, NamedTuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Path
from std_msgs.msg import Float64

from skidsteer_power.errors import ConfigError, SkidsteerError
from skidsteer_power.estimator.path_energy import PathEnergy, PathTracker

PARAMETERS: dict[str, tuple[Any, str]] = {
    'path_speed_m_s': (0.0, 'speed to drive the planned path at [m/s]; 0 = the last commanded speed'),
    'path_reserve_wh': (0.0, 'energy kept in reserve in energy/path_margin_wh [Wh]'),
}


class PathInputs(NamedTuple):
    """The node's state the path energy reads (one consistent snapshot: the node's ``path_inputs()``).

    predictor : the estimator's predictor (its ``power_map`` and ``powertrain``); command : last
    (V [m/s], yaw rate [rad/s]) or None; remaining_wh : battery energy left [Wh]; terrain_scale : the
    online terrain scale k [-] (estimator/adaptation.py).
    """

    predictor: Any
    command: tuple[float, float] | None
    remaining_wh: float
    terrain_scale: float


class PathEnergyHook:
    """Subscribes ``plan`` on ``node`` and publishes the path energies (module doc)."""

    def __init__(self, node: Any, p: dict[str, Any], qos: Any) -> None:
        for name in PARAMETERS:
            if not p[name] >= 0:
                raise ConfigError(f'{name} must be >= 0, got {p[name]!r}')
        self.node = node
        self.speed_m_s = float(p['path_speed_m_s'])
        self.reserve_wh = float(p['path_reserve_wh'])
        self.tracker = PathTracker()
        self.status = 'no path received'
        self.received = False
        self.last: tuple[PathEnergy, float] | None = None  # energies and margin [Wh] last published
        node.create_subscription(Path, 'plan', self._on_path, qos)
        self.pub_required = node.create_publisher(Float64, 'energy/path_required_wh', 10)
        self.pub_margin = node.create_publisher(Float64, 'energy/path_margin_wh', 10)
        self.pub_diag = node.create_publisher(DiagnosticArray, 'diagnostics', 10)
        # no timers of its own: the node calls publish() from its battery timer and
        # publish_diagnostics() from its diagnostics timer (one executor entity less each)

    def _on_path(self, msg: Path) -> None:
        x = [pose.pose.position.x for pose in msg.poses]
        y = [pose.pose.position.y for pose in msg.poses]
        self.received = True
        try:
            self.tracker.set_path(x, y)
        except SkidsteerError as err:
            self._reject(err)
            return
        self.status = f'path of {len(x)} poses'
        self.publish()

    def _reject(self, err: SkidsteerError) -> None:
        """A path that cannot be evaluated: say why and hold no path (set_path already cleared it)."""
        self.status = f'path rejected: {err}'
        self.tracker.path = None
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
            energy = self.tracker.evaluate(speed, power_map, powertrain, terrain_scale)
        except SkidsteerError as err:
            self._reject(err)
            return None, remaining
        return energy, remaining

    def publish(self) -> None:
        """Publish required and margin [Wh] for the current path (nothing if unknown)."""
        energy, remaining = self._evaluate()
        if energy is None:
            self.last = None
            return
        margin = energy.margin_wh(remaining, self.reserve_wh)
        self.last = (energy, margin)
        self.status = (
            f'{energy.length_m:.1f} m at {energy.speed_m_s:.2f} m/s, terrain scale {energy.terrain_scale:.3f}'
        )
        self.pub_required.publish(Float64(data=energy.required_wh))
        self.pub_margin.publish(Float64(data=margin))

    def publish_diagnostics(self) -> None:
        if not self.received:
            return
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
            }
            if margin < 0:
                level = DiagnosticStatus.WARN
                message = f'not enough energy for the path and back: margin {margin:.2f} Wh'
            else:
                message = f'path and back leave {margin:.2f} Wh'
            flagged = energy.clamped_segments + energy.limited_segments
            if flagged:
                message += f" ({flagged} segments outside the map's validity: clamped or limited)"
        status = DiagnosticStatus(level=level, name=f'{self.node.get_name()}: path energy', message=message)
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.node.get_clock().now().to_msg()
        self.pub_diag.publish(array)
