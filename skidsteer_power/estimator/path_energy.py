"""Energy to drive a planned path (a nav_msgs/Path polyline) and the margin left to come home.

Pure (no ROS). A path of poses (x_k, y_k) [m] becomes a route of constant-radius segments
(:class:`~skidsteer_power.missions.routes.Route`) and goes through the missions' route-energy code
(:func:`skidsteer_power.missions.energy.route_energy_on_map`): one implementation for
``mission --route FILE.csv`` and the robot's ``energy/path_required_wh``.

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

Margin (issue 19): remaining battery energy - energy of the path - energy back to the path's start
along the reversed path - a reserve [Wh]. Path energies are the battery (DC bus) energy of the
missions (motor and amplifier losses included), at a constant speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from skidsteer_power.errors import InputError
from skidsteer_power.missions.energy import route_energy_on_map
from skidsteer_power.missions.routes import STRAIGHT_CURVATURE, Route, Segment

JOULES_PER_WH = 3600.0
MIN_CHORD_M = 1e-6  # [m] shorter chords are duplicate poses


def route_from_polyline(x: Any, y: Any, speed_m_s: float, name: str = 'path') -> Route:
    """Constant-radius route through the points (x, y) [m], driven at ``speed_m_s`` [m/s] (module doc).

    InputError when the path has fewer than two distinct points or the speed is not > 0.
    """
    if not (math.isfinite(speed_m_s) and speed_m_s > 0):
        raise InputError(f'path speed must be finite and > 0 m/s, got {speed_m_s}')
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
    pieces = [(0.5 * length[0], math.inf), *zip(share.tolist(), radius.tolist(), strict=True)]
    pieces.append((0.5 * length[-1], math.inf))
    segments = tuple(Segment.along(speed_m_s, float(r), length_m=float(s)) for s, r in pieces)
    return Route(name, segments, f'polyline of {len(length) + 1} points', xy=xy[np.r_[True, keep]])


@dataclass(frozen=True)
class PathEnergy:
    """Energies of a path [J] at ``speed_m_s`` [m/s]: there (``required_J``) and back (``return_J``)."""

    length_m: float
    speed_m_s: float
    required_J: float
    return_J: float
    clamped_segments: int

    @property
    def required_wh(self) -> float:
        return self.required_J / JOULES_PER_WH

    @property
    def return_wh(self) -> float:
        return self.return_J / JOULES_PER_WH

    def margin_wh(self, remaining_wh: float, reserve_wh: float = 0.0) -> float:
        """Remaining energy [Wh] - there - back - ``reserve_wh`` [Wh] (module doc)."""
        return remaining_wh - self.required_wh - self.return_wh - reserve_wh


def path_energy(x: Any, y: Any, speed_m_s: float, power_map: Any, powertrain: Any) -> PathEnergy:
    """Battery energy to drive the polyline (x, y) [m] at ``speed_m_s`` [m/s] and back along it
    (reversed path, driven forward), with the loads of ``power_map`` and ``powertrain``."""
    xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    there = route_from_polyline(xs, ys, abs(speed_m_s))
    back = route_from_polyline(xs[::-1], ys[::-1], abs(speed_m_s), name='return')
    e_there = route_energy_on_map(there, power_map, powertrain)
    e_back = route_energy_on_map(back, power_map, powertrain)
    return PathEnergy(
        length_m=there.length_m,
        speed_m_s=abs(speed_m_s),
        required_J=e_there['energy_battery_J'],
        return_J=e_back['energy_battery_J'],
        clamped_segments=int(e_there['clamped_segments'] + e_back['clamped_segments']),
    )


class PathTracker:
    """The last planned path and its energies, recomputed only when the path, the speed or the
    predictor (terrain) changes; the node asks it for (required, margin) [Wh] whenever it publishes."""

    def __init__(self) -> None:
        self.xy: tuple[np.ndarray, np.ndarray] | None = None
        self._key: tuple[Any, ...] | None = None
        self.energy: PathEnergy | None = None

    def set_path(self, x: Any, y: Any) -> None:
        """A new plan [m]; an empty path clears it."""
        xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        self.xy = (xs, ys) if xs.size else None
        self._key = None
        self.energy = None

    def evaluate(self, speed_m_s: float, power_map: Any, powertrain: Any) -> PathEnergy | None:
        """Energies of the current path at ``speed_m_s`` [m/s] (None: no path, or speed 0)."""
        if self.xy is None or power_map is None or not speed_m_s:
            return None
        key = (abs(float(speed_m_s)), id(power_map), id(powertrain))
        if key != self._key:
            self.energy = path_energy(self.xy[0], self.xy[1], abs(speed_m_s), power_map, powertrain)
            self._key = key
        return self.energy
