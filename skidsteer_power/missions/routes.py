"""Routes: sequences of constant-state segments (length or duration, forward speed, turning radius).

Built-in routes reproduce the two chapter 8 missions from their stated properties:

* ``patrol`` (ch. 8.1, Figure 8.1): a 15 m x 22 m area covered by a lawn-mower path with 1 m turns;
  154.4 m in total, of which 20 % (31.4 m) turning and 123.0 m straight. 31.4 m is ten 180-degree
  turns of radius 1 m (10 pi m), so the path is 11 straight lanes 2 m apart (spanning 20 m of the 22 m
  side) of 123.0 / 11 = 11.18 m each (fitting the 15 m side), joined by U-turns alternately to the
  left and to the right. Figure 8.1 is not published as data; the layout is ours, the totals are the
  dissertation's. Energy depends only on the lengths, radii and speed, not on the layout.
* ``search-retrieve`` (ch. 8.2, Figures 8.6-8.7): out to a target and back along the same path, 271.95 m
  in total at 0.5 m/s, a 10 kg payload on the way back, minimum turning radius 0.5 m. The dissertation's
  path is a smoothed segment of the Curiosity rover's traverse and is not published as data: this
  path is SYNTHETIC, a smooth curvature profile (a fixed sum of sines, so it is deterministic) scaled
  so its sharpest turn has exactly R = 0.5 m, discretized into short constant-radius arcs.

Sign convention (REP 103): R > 0 turns left, R < 0 right, R = inf is straight.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from skidsteer_power.commands import Segment
from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.ranges import (
    FORWARD_SPEED_M_S,
    LEG_DURATION_S,
    LEG_LENGTH_M,
    PAYLOAD_KG,
    TURN_RADIUS_M,
    check_file_size,
)

PATROL_TOTAL_M = 154.4  # ch. 8.1
PATROL_TURN_RADIUS_M = 1.0  # ch. 8.1
PATROL_U_TURNS = 10  # 31.4 m of turning / (pi x 1 m)
PATROL_SPEED_M_S = 0.2  # ch. 8.1
SEARCH_TOTAL_M = 271.95  # ch. 8.2, both trips
SEARCH_MIN_RADIUS_M = 0.5  # ch. 8.2, Figure 8.7
SEARCH_SPEED_M_S = 0.5  # ch. 8.2
SEARCH_PAYLOAD_KG = 10.0  # ch. 8.2, on the way back
STRAIGHT_CURVATURE = 1e-3  # [1/m]: gentler curvature (R > 1 km) counts as straight


@dataclass(frozen=True)
class Route:
    """A named sequence of segments; ``synthetic`` says the geometry is ours, not the source's data."""

    name: str
    segments: tuple[Segment, ...]
    description: str = ''
    synthetic: bool = False
    xy: np.ndarray | None = field(default=None, compare=False)  # optional path points for plots [m]

    def __post_init__(self) -> None:
        if not self.segments:
            raise InputError(f'route {self.name!r} has no segments')

    @property
    def length_m(self) -> float:
        return float(sum(s.length_m for s in self.segments))

    @property
    def duration_s(self) -> float:
        return float(sum(s.duration_s for s in self.segments))

    @property
    def turning_length_m(self) -> float:
        return float(sum(s.length_m for s in self.segments if s.is_turning))

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-segment arrays: speed, turn_radius, payload, length, duration (SI units)."""
        return {
            'speed_m_s': np.array([s.speed_m_s for s in self.segments]),
            'turn_radius_m': np.array([s.turn_radius_m for s in self.segments]),
            'payload_kg': np.array([s.payload_kg for s in self.segments]),
            'length_m': np.array([s.length_m for s in self.segments]),
            'duration_s': np.array([s.duration_s for s in self.segments]),
        }

    def with_speed(self, speed_m_s: float) -> Route:
        """The same path driven at another constant speed [m/s] (lengths kept)."""
        segments = tuple(
            Segment.along(speed_m_s, s.turn_radius_m, length_m=s.length_m, payload_kg=s.payload_kg)
            for s in self.segments
        )
        return replace(self, segments=segments)


def patrol(speed_m_s: float = PATROL_SPEED_M_S) -> Route:
    """The ch. 8.1 patrol: 11 lanes of 11.18 m and 10 U-turns of R = 1 m, 154.4 m (see module doc)."""
    turn_length = math.pi * PATROL_TURN_RADIUS_M
    lane = (PATROL_TOTAL_M - PATROL_U_TURNS * turn_length) / (PATROL_U_TURNS + 1)
    segments: list[Segment] = []
    for k in range(PATROL_U_TURNS + 1):
        segments.append(Segment.along(speed_m_s, math.inf, length_m=lane))
        if k < PATROL_U_TURNS:
            side = 1.0 if k % 2 == 0 else -1.0  # alternate left / right U-turns
            segments.append(Segment.along(speed_m_s, side * PATROL_TURN_RADIUS_M, length_m=turn_length))
    route = Route('patrol', tuple(segments), 'ch. 8.1 patrol of a 15 m x 22 m area (lawn-mower path)')
    return replace(route, xy=_trace(route))


def search_retrieve(
    speed_m_s: float = SEARCH_SPEED_M_S, payload_kg: float = SEARCH_PAYLOAD_KG, step_m: float = 0.2
) -> Route:
    """The ch. 8.2 search-and-retrieve on a SYNTHETIC smooth path (see module doc).

    Out along the path empty, back along it (mirror turns) with ``payload_kg``; each arc ``step_m`` [m].
    """
    one_way = SEARCH_TOTAL_M / 2.0
    n = max(round(one_way / step_m), 8)
    ds = one_way / n
    s_mid = (np.arange(n) + 0.5) * ds
    curvature = _synthetic_curvature(s_mid / one_way)
    radius = np.where(
        np.abs(curvature) < STRAIGHT_CURVATURE, np.inf, 1.0 / np.where(curvature == 0, 1, curvature)
    )
    out = [Segment.along(speed_m_s, float(r), length_m=ds) for r in radius]
    back = [Segment.along(speed_m_s, float(-r), length_m=ds, payload_kg=payload_kg) for r in radius[::-1]]
    route = Route(
        'search-retrieve',
        tuple(out + back),
        'ch. 8.2 search and retrieve, SYNTHETIC smooth path (the Curiosity-derived path is not published)',
        synthetic=True,
    )
    return replace(route, xy=_trace(replace(route, segments=tuple(out))))  # the way back retraces it


# (centre u, half-width u, signed peak curvature / max curvature): smooth cos^2 bends on a straight
# base line. The 1.0 entries are the sharp turns, R = 0.5 m at their apex and about 95 degrees each;
# the gentle bends turn by about 60 degrees; the path keeps a general direction, as a traverse to a
# target does.
_BENDS = (
    (0.07, 0.040, 0.10),
    (0.20, 0.050, -0.08),
    (0.31, 0.006, 1.00),
    (0.44, 0.060, -0.06),
    (0.58, 0.006, -1.00),
    (0.71, 0.045, 0.10),
    (0.84, 0.006, 1.00),
    (0.93, 0.035, -0.12),
)


def _synthetic_curvature(u: np.ndarray) -> np.ndarray:
    """Smooth curvature [1/m] along the normalized path position u in [0, 1]; max |k| = 1 / 0.5 m.

    Straight runs joined by bends whose curvature rises and falls as cos^2 (continuous curvature,
    like a smoothed rover traverse), with fixed positions so the route is deterministic.
    """
    shape = np.zeros_like(u, dtype=float)
    for centre, half_width, peak in _BENDS:
        x = (u - centre) / half_width
        shape += np.where(np.abs(x) < 1.0, peak * np.cos(0.5 * np.pi * x) ** 2, 0.0)
    peak = float(np.max(np.abs(shape)))
    return shape / peak / SEARCH_MIN_RADIUS_M


MAX_TRACE_STEP_RAD = math.pi / 36
"""Largest heading change between two traced points of an arc [rad] (5 degrees; plots stay smooth)."""
MAX_TRACE_STEPS = 200_000
"""Most points a route's trace may have; a route needing more is an InputError (not an OOM kill)."""


def _trace(route: Route) -> np.ndarray:
    """x, y path points [m] of the segments (start at the origin heading +x), exact for each arc.

    Sampled by STEPS, not by length: a straight segment is one step whatever its length, an arc one
    step per :data:`MAX_TRACE_STEP_RAD` of heading change. Raises InputError when the route needs more
    than :data:`MAX_TRACE_STEPS` points (e.g. a kilometre-long arc of 1 m radius).
    """
    a = route.arrays()
    length, radius = a['length_m'], a['turn_radius_m']
    curvature = np.where(np.isinf(radius), 0.0, 1.0 / np.where(np.isinf(radius), 1.0, radius))
    turned = np.abs(length * curvature)  # heading change of each segment [rad]
    steps = np.ceil(np.minimum(turned / MAX_TRACE_STEP_RAD, MAX_TRACE_STEPS + 1.0)).clip(min=1)
    total = float(steps.sum())
    if total > MAX_TRACE_STEPS:
        raise InputError(
            f'route {route.name!r} turns through {turned.sum():.3g} rad in all: tracing it needs more '
            f'than {MAX_TRACE_STEPS:,} points; shorten its arcs'
        )
    seg = np.repeat(np.arange(steps.size), steps.astype(int))
    ds = (length / steps)[seg]  # step length [m]
    k = curvature[seg]
    heading_start = np.r_[0.0, np.cumsum(length * curvature)[:-1]][seg]
    first = np.r_[0, np.cumsum(steps)[:-1]].astype(int)[seg]
    within = np.arange(seg.size) - first  # step index inside its segment
    h0 = heading_start + k * ds * within
    h1 = h0 + k * ds
    arc = k != 0.0
    safe_k = np.where(arc, k, 1.0)
    dx = np.where(arc, (np.sin(h1) - np.sin(h0)) / safe_k, ds * np.cos(h0))  # exact on a circle
    dy = np.where(arc, (np.cos(h0) - np.cos(h1)) / safe_k, ds * np.sin(h0))
    return np.column_stack([np.r_[0.0, np.cumsum(dx)], np.r_[0.0, np.cumsum(dy)]])


BUILTIN: dict[str, Callable[..., Route]] = {'patrol': patrol, 'search-retrieve': search_retrieve}


def builtin_route(name: str, speed_m_s: float | None = None) -> Route:
    """A built-in route by name ('patrol' | 'search-retrieve'), at its chapter 8 speed unless given."""
    try:
        factory = BUILTIN[name]
    except KeyError:
        raise InputError(f'unknown route {name!r}; built-ins: {", ".join(BUILTIN)} (or a CSV file)') from None
    return factory() if speed_m_s is None else factory(speed_m_s)


CSV_COLUMNS = ('length_m', 'duration_s', 'speed_m_s', 'turn_radius_m', 'payload_kg')


def read_route_csv(path: str | os.PathLike[str], default_speed_m_s: float | None = None) -> Route:
    """Read a route CSV: one segment per row (header row; SI units).

    Columns: ``length_m`` or ``duration_s`` (one per row), ``speed_m_s`` (optional when a default is
    given), ``turn_radius_m`` (signed; empty or ``inf`` = straight), ``payload_kg`` (optional, 0).
    Read row by row: a file over ``ROUTE_CSV_BYTES`` is refused unread, and reading stops at the row
    past :data:`MAX_TRACE_STEPS` (each row is at least one traced point), so memory stays bounded.
    """
    check_file_size(path)
    segments: list[Segment] = []
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            fields = [f.strip().lower() for f in (reader.fieldnames or [])]
            reader.fieldnames = fields
            if 'length_m' not in fields and 'duration_s' not in fields:
                raise InputError(f'{path}: route CSV needs a length_m or duration_s column')
            for k, row in enumerate(reader, start=2):
                if len(segments) >= MAX_TRACE_STEPS:
                    raise InputError(f'{path}: more than {MAX_TRACE_STEPS:,} rows (one point each at least)')
                segments.append(_segment(row, path, k, default_speed_m_s))
    except UnicodeDecodeError as err:
        raise InputError(f'{path}: not a text CSV file ({err.reason})') from err
    except csv.Error as err:
        raise InputError(f'{path}: not a route CSV ({err})') from err
    if not segments:
        raise InputError(f'{path}: route has no segments')
    route = Route(os.path.basename(os.fspath(path)), tuple(segments), f'route from {os.fspath(path)}')
    return replace(route, xy=_trace(route))


def _segment(row: dict[str, str], path: object, line: int, default_speed: float | None) -> Segment:
    def number(key: str, default: float | None = None) -> float | None:
        text = (row.get(key) or '').strip()
        if not text:
            return default
        try:
            return float(text)
        except ValueError:
            raise InputError(f'{path}:{line}: {key} is not a number: {text!r}') from None

    def number_or(key: str, default: float) -> float:
        value = number(key)
        return default if value is None else value

    speed = number('speed_m_s', default_speed)
    if speed is None:
        raise InputError(f'{path}:{line}: no speed_m_s and no --speed given')
    radius, payload = number_or('turn_radius_m', math.inf), number_or('payload_kg', 0.0)
    try:
        FORWARD_SPEED_M_S.check(speed)  # the ranges of the command line (terramechanics.ranges)
        if not math.isinf(radius) and radius != 0:
            TURN_RADIUS_M.check(radius)
        PAYLOAD_KG.check(payload)
        length, duration = number('length_m'), number('duration_s')
        if length is not None:
            LEG_LENGTH_M.check(length)  # a 1e300 m leg would give 1.9e302 J (issue 28)
        if duration is not None:
            LEG_DURATION_S.check(duration)
        return Segment.along(
            speed_m_s=speed,
            turn_radius_m=radius,
            length_m=length,
            duration_s=duration,
            payload_kg=payload,
        )
    except InputError as err:
        raise InputError(f'{path}:{line}: {err}') from None


def resolve_route(spec: str, speed_m_s: float | None = None) -> Route:
    """A built-in route name or a CSV path; ``speed_m_s`` overrides the built-in speed."""
    if spec in BUILTIN:
        return builtin_route(spec, speed_m_s)
    if not os.path.isfile(spec):
        raise InputError(f'route {spec!r}: not a built-in ({", ".join(BUILTIN)}) and no such CSV file')
    return read_route_csv(spec, speed_m_s)
