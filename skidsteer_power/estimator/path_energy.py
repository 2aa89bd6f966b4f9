"""Energy to drive a planned path (a nav_msgs/Path polyline) and the margin left to come home.

Pure (no ROS). A path of poses (x_k, y_k) [m] becomes constant-radius segments (lengths and signed
radii as arrays, :class:`PathGeometry`) and goes through the missions' energy code
(:class:`skidsteer_power.missions.energy.MapLoads`, which ``mission --route FILE.csv`` reaches
through :func:`~skidsteer_power.missions.energy.route_energy_on_map`): one implementation for both and
for the robot's ``energy/path_required_wh``.

Curvature of a polyline: the heading of chord k is theta_k = atan2(dy_k, dx_k); at interior vertex k
the path turns by dtheta_k = wrap(theta_k - theta_{k-1}). Each vertex owns half of each chord next
to it, so the route has one segment per vertex, of length (L_{k-1} + L_k) / 2 and curvature
kappa_k = dtheta_k / ((L_{k-1} + L_k) / 2) [1/m], plus the first and last half chords, straight. This
keeps the total length and the total heading change of the polyline exactly. A circular arc of radius
R sampled every ds has chords 2 R sin(ds / 2R) long turning by ds / R each: the curvature comes out
as 1 / R x (ds / 2R) / sin(ds / 2R), e.g. 0.26 % high for ds = 0.25 m, R = 1 m, and the length
0.26 % short, so the energy of a sampled arc is within a fraction of a per cent of the arc's
(test_path_energy.py measures it against ``mission --route``). Curvature gentler than
:data:`~skidsteer_power.missions.routes.STRAIGHT_CURVATURE` counts as straight, as in the missions.

Duplicate poses (zero-length chords) are dropped. Sign convention REP 103: a left turn has R > 0.

Size (issue 28): a path of more than :data:`MAX_PATH_POSES` poses is decimated first
(:func:`decimate_polyline`, Ramer-Douglas-Peucker with the distance to each kept segment): every
original pose stays within :data:`PATH_TOLERANCE_M` of the decimated polyline. A path that needs more
than :data:`MAX_PATH_POSES` poses even then is an InputError.

Margin (issue 19): remaining battery energy - energy of the path - energy back to the path's start
along the reversed path - a reserve [Wh]. Path energies are the battery (DC bus) energy of the
missions (motor and amplifier losses included), at a constant speed, with the map's axle torques
multiplied by the online terrain scale k (:mod:`skidsteer_power.estimator.adaptation`, "Terrain
scale"; 1 = the map as built).

Drive controller (issue 36): the robot drives the path as its drive controller carries it out. With
a ``path_scale`` (the controller's :meth:`~skidsteer_power.drive.DriveController.path_scale` at the
robot's wheel speed ceiling; the estimator's predictors give theirs), a piece whose twist (V, V / R)
the controller cannot carry out (a velocity limit, the wheel speed ceiling) is driven on the same
path at the highest speed it can, V s with s < 1, for length / (V s): what ``mission`` does with a
route (:func:`~skidsteer_power.missions.energy.driven_route`). Such pieces are counted in
``slowed_segments``.

Cost: the path's geometry (piece lengths and radii, there and back) is computed once per path as
arrays (:class:`PathGeometry`); a new speed only re-queries the map at the path's unique (V, R)
states (:class:`skidsteer_power.missions.energy.MapLoads`), about a millisecond for a 2001-pose path,
so following the commanded speed costs little (benchmarks/bench_scale.py); a new terrain scale only
reruns the powertrain on those loads (:class:`PathTracker`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError
from skidsteer_power.missions.energy import MapLoads, yaw_rate_of
from skidsteer_power.missions.routes import STRAIGHT_CURVATURE, Route
from skidsteer_power.seams import ArrayPowerMapLike, PowertrainLike

JOULES_PER_WH = 3600.0
MIN_CHORD_M = 1e-6  # [m] shorter chords are duplicate poses
MAX_PATH_POSES = 10_000
"""Most poses a planned path keeps; a longer one is decimated to :data:`PATH_TOLERANCE_M`."""
PATH_TOLERANCE_M = 0.05
"""[m] every pose of a decimated path lies within this distance of the decimated polyline."""


def decimate_polyline(xy: np.ndarray, tolerance_m: float, max_points: int) -> np.ndarray:
    """Indices of the points of ``xy`` [m] (n, 2) kept by Ramer-Douglas-Peucker: every dropped point
    lies within ``tolerance_m`` [m] of the segment between the kept points around it (the segment,
    not its line, so a path that doubles back keeps its turning point). InputError when more than
    ``max_points`` points are needed."""
    n = len(xy)
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    kept, stack = 2, [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        start, chord = xy[a], xy[b] - xy[a]
        rel = xy[a + 1 : b] - start
        length2 = float(chord @ chord)
        t = np.clip(rel @ chord / length2, 0.0, 1.0) if length2 > 0 else np.zeros(b - a - 1)
        off = rel - t[:, None] * chord
        dist2 = np.einsum('ij,ij->i', off, off)
        k = int(np.argmax(dist2))
        if dist2[k] > tolerance_m * tolerance_m:
            m = a + 1 + k
            keep[m] = True
            kept += 1
            if kept > max_points:
                raise InputError(
                    f'path of {n:,} poses needs more than {max_points:,} to stay within {tolerance_m:g} m'
                )
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep)


PathScale: TypeAlias = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(V [m/s], w_z [rad/s]) arrays -> (P,) factor in (0, 1] by which the drive controller slows each
twist to carry it out on the same path (module doc, "Drive controller")."""


@dataclass(frozen=True)
class PathGeometry:
    """A polyline as constant-radius pieces (module doc): ``length_m`` [m] and signed
    ``turn_radius_m`` [m] (inf: straight) per piece, and the distinct points ``xy`` [m]."""

    length_m: np.ndarray
    turn_radius_m: np.ndarray
    xy: np.ndarray

    @classmethod
    def from_polyline(cls, x: ArrayLike, y: ArrayLike) -> PathGeometry:
        """InputError when the points are not finite or fewer than two are distinct."""
        xy = np.column_stack([np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()])
        if not np.all(np.isfinite(xy)):
            raise InputError('path points must be finite')
        chords = np.diff(xy, axis=0)
        length = np.hypot(chords[:, 0], chords[:, 1])
        keep = length > MIN_CHORD_M
        chords, length = chords[keep], length[keep]
        if length.size == 0:
            raise InputError('a path needs at least two distinct points')
        heading = np.arctan2(chords[:, 1], chords[:, 0])
        turn = np.angle(np.exp(1j * np.diff(heading)))  # wrapped to (-pi, pi] [rad]
        share = 0.5 * (length[:-1] + length[1:])  # [m] owned by each interior vertex
        curvature = turn / share
        radius = np.where(
            np.abs(curvature) < STRAIGHT_CURVATURE, np.inf, 1.0 / np.where(curvature == 0, 1, curvature)
        )
        pieces = np.r_[0.5 * length[0], share, 0.5 * length[-1]]
        radii = np.r_[np.inf, radius, np.inf]
        return cls(pieces, radii, xy[np.r_[True, keep]])

    @property
    def total_length_m(self) -> float:
        return float(np.sum(self.length_m))

    def loads(
        self, speed_m_s: float, power_map: ArrayPowerMapLike, path_scale: PathScale | None = None
    ) -> tuple[MapLoads, int]:
        """(the map's loads on the pieces driven at ``speed_m_s`` [m/s], pieces slowed): with
        ``path_scale`` each piece as the drive controller carries it out (module doc); the loads
        are :class:`~skidsteer_power.missions.energy.MapLoads`, the missions' energy code."""
        _check_speed(speed_m_s)
        speed = np.full(self.length_m.shape, float(speed_m_s))
        slowed = 0
        if path_scale is not None:
            scale = np.asarray(path_scale(speed, yaw_rate_of(speed, self.turn_radius_m)), dtype=float)
            slowed = int(np.count_nonzero(scale < 1.0))
            speed = speed * scale
        return MapLoads.of(speed, self.turn_radius_m, self.length_m / speed, power_map), slowed


def _check_speed(speed_m_s: float) -> None:
    if not (math.isfinite(speed_m_s) and speed_m_s > 0):
        raise InputError(f'path speed must be finite and > 0 m/s, got {speed_m_s}')


def route_from_polyline(x: ArrayLike, y: ArrayLike, speed_m_s: float, name: str = 'path') -> Route:
    """Constant-radius route through the points (x, y) [m], driven at ``speed_m_s`` [m/s] (module doc).

    InputError when the path has fewer than two distinct points or the speed is not > 0.
    """
    _check_speed(speed_m_s)
    g = PathGeometry.from_polyline(x, y)
    segments = tuple(
        Segment.along(speed_m_s, float(r), length_m=float(s))
        for s, r in zip(g.length_m.tolist(), g.turn_radius_m.tolist(), strict=True)
    )
    return Route(name, segments, f'polyline of {len(g.xy)} points', xy=g.xy)


@dataclass(frozen=True)
class PathEnergy:
    """Energies of a path [J] at ``speed_m_s`` [m/s]: there (``required_J``) and back (``return_J``),
    with the map's axle torques multiplied by ``terrain_scale`` [-]."""

    length_m: float
    speed_m_s: float
    required_J: float
    return_J: float
    clamped_segments: int
    terrain_scale: float = 1.0
    limited_segments: int = 0  # segments the map flagged limited (physics limit, cell check)
    slowed_segments: int = 0  # segments the drive controller drives slower (module doc)

    @property
    def required_wh(self) -> float:
        return self.required_J / JOULES_PER_WH

    @property
    def return_wh(self) -> float:
        return self.return_J / JOULES_PER_WH

    def margin_wh(self, remaining_wh: float, reserve_wh: float = 0.0) -> float:
        """Remaining energy [Wh] - there - back - ``reserve_wh`` [Wh] (module doc)."""
        return remaining_wh - self.required_wh - self.return_wh - reserve_wh


@dataclass(frozen=True)
class PathLoads:
    """The map's loads on a path there and back at ``speed_m_s`` [m/s]: all of the path energy that
    neither the powertrain nor the terrain scale changes."""

    speed_m_s: float
    there: MapLoads
    back: MapLoads
    slowed_segments: int = 0  # there and back, by the drive controller (module doc)


class PlannedPath:
    """A planned path's geometry there and back along it (reversed, driven forward), built once.

    The return is built from the reversed points by the same code, not derived from the forward
    pieces (reversed, radii negated): a derived one would differ where a turn is exactly pi."""

    def __init__(self, x: ArrayLike, y: ArrayLike) -> None:
        xs, ys = np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()
        self.poses_given = xs.size
        if xs.size > MAX_PATH_POSES:  # module doc, "Size"
            xy = np.column_stack([xs, ys])
            if not np.all(np.isfinite(xy)):
                raise InputError('path points must be finite')
            kept = decimate_polyline(xy, PATH_TOLERANCE_M, MAX_PATH_POSES)
            xs, ys = xs[kept], ys[kept]
        self.poses_kept = xs.size
        self.there = PathGeometry.from_polyline(xs, ys)
        self.back = PathGeometry.from_polyline(xs[::-1], ys[::-1])

    def loads(
        self, speed_m_s: float, power_map: ArrayPowerMapLike, path_scale: PathScale | None = None
    ) -> PathLoads:
        """The map's loads there and back at ``speed_m_s`` [m/s] (|speed| is driven both ways), with
        ``path_scale`` as the drive controller carries each piece out (module doc)."""
        speed = abs(float(speed_m_s))
        there, slowed_there = self.there.loads(speed, power_map, path_scale)
        back, slowed_back = self.back.loads(speed, power_map, path_scale)
        return PathLoads(speed, there, back, slowed_there + slowed_back)

    def energy(
        self,
        speed_m_s: float,
        power_map: ArrayPowerMapLike,
        powertrain: PowertrainLike,
        terrain_scale: float = 1.0,
        path_scale: PathScale | None = None,
    ) -> PathEnergy:
        """Battery energy there and back at ``speed_m_s`` [m/s] with the loads of ``power_map`` and
        ``powertrain``, axle torques times ``terrain_scale`` [-], driven as ``path_scale`` says."""
        loads = self.loads(speed_m_s, power_map, path_scale)
        return self.energy_from(loads, powertrain, terrain_scale)

    def energy_from(
        self, loads: PathLoads, powertrain: PowertrainLike, terrain_scale: float = 1.0
    ) -> PathEnergy:
        """:meth:`energy` from what :meth:`loads` gave (the map is not queried again)."""
        there = loads.there.energy(powertrain, terrain_scale)
        back = loads.back.energy(powertrain, terrain_scale)
        return PathEnergy(
            length_m=self.there.total_length_m,
            speed_m_s=loads.speed_m_s,
            required_J=there['energy_battery_J'],
            return_J=back['energy_battery_J'],
            clamped_segments=int(there['clamped_segments'] + back['clamped_segments']),
            terrain_scale=float(terrain_scale),
            limited_segments=int(there['limited_segments'] + back['limited_segments']),
            slowed_segments=loads.slowed_segments,
        )


def path_energy(
    x: ArrayLike,
    y: ArrayLike,
    speed_m_s: float,
    power_map: ArrayPowerMapLike,
    powertrain: PowertrainLike,
    terrain_scale: float = 1.0,
    path_scale: PathScale | None = None,
) -> PathEnergy:
    """Battery energy to drive the polyline (x, y) [m] at ``speed_m_s`` [m/s] and back along it
    (reversed path, driven forward), with the loads of ``power_map`` and ``powertrain`` and the axle
    torques times ``terrain_scale`` [-], each piece as ``path_scale``'s drive controller carries it
    out (module doc; None: as asked)."""
    return PlannedPath(x, y).energy(speed_m_s, power_map, powertrain, terrain_scale, path_scale)


class PathTracker:
    """The last planned path (geometry built once) and its energies. The map is queried again only
    when the path, the speed or the predictor (terrain) changes; a new terrain scale, which moves on
    every estimator tick while the adaptation learns, only reruns the powertrain on the kept loads."""

    def __init__(self) -> None:
        self.path: PlannedPath | None = None
        self._loads_key: tuple[object, ...] | None = None
        self._loads: PathLoads | None = None
        self._key: tuple[object, ...] | None = None
        self.energy: PathEnergy | None = None

    def set_path(self, x: ArrayLike, y: ArrayLike) -> None:
        """A new plan [m]; an empty path clears it; InputError (and no path) for a bad one."""
        self.set_planned(None)
        if np.asarray(x).size:
            self.path = PlannedPath(x, y)

    def set_planned(self, path: PlannedPath | None) -> None:
        """A plan whose geometry was built elsewhere (e.g. on a worker thread); None clears it."""
        self.path, self._loads_key, self._loads, self._key, self.energy = path, None, None, None, None

    def evaluate(
        self,
        speed_m_s: float,
        power_map: ArrayPowerMapLike | None,
        powertrain: PowertrainLike | None,
        terrain_scale: float = 1.0,
        path_scale: PathScale | None = None,
    ) -> PathEnergy | None:
        """Energies of the current path at ``speed_m_s`` [m/s] as ``path_scale``'s drive controller
        drives it (None: no path, map or powertrain, or speed 0)."""
        if self.path is None or power_map is None or powertrain is None or not speed_m_s:
            return None
        # the objects, not their id(): no reuse mix-up
        loads_key = (abs(float(speed_m_s)), power_map, path_scale)
        if self._loads is None or not _same(loads_key, self._loads_key):
            self._loads = self.path.loads(speed_m_s, power_map, path_scale)
            self._loads_key = loads_key
        key = (*loads_key, powertrain, float(terrain_scale))
        if not _same(key, self._key):
            self.energy = self.path.energy_from(self._loads, powertrain, terrain_scale)
            self._key = key
        return self.energy


def _same(key: tuple[object, ...], kept: tuple[object, ...] | None) -> bool:
    """Cache keys of numbers and objects: numbers equal, objects the same ones."""
    return kept is not None and all(
        a == b if isinstance(a, float) else a is b for a, b in zip(key, kept, strict=True)
    )
