"""Look-up maps of per-side torque, speed and power over (forward speed V, signed yaw rate w_z).

Inputs are (V, w_z): the estimator gets exactly V and w_z from ``cmd_vel``. The grid, however, is
polar in the (V, L w_z) plane: a "command magnitude" s = hypot(V, L w_z) [m/s] and a "turn angle"
psi = atan2(L w_z, V) [rad], with the length L = max_speed / max_yaw_rate [m]. Why: torque and power
depend mostly on the turning radius R = V / w_z = L cot(psi); on a rectangular (V, w_z) grid the
torque rises so steeply with w_z near straight running at low V (R drops from infinity to a metre
within one yaw-rate step) that bilinear interpolation was measured 36 % off at off-grid points
(16 x 81 grid). The default grid is 31 rings x 101 warped turn angles (psi warped, see
:func:`_angle_coordinate`) plus 40 more angles per side over the turns of radius min_radius ...
3 min_radius, where a wheeled vehicle's outer-side slip rises steeply towards the traction limit.
The map stores torques and slip speeds; each side's axle speed is derived from its exact ground
speed plus the interpolated slip speed, and its power as torque x speed. Accuracy against direct
FESS for every shipped vehicle x terrain: docs/BENCHMARKS.md ("Map accuracy";
``python -m benchmarks.bench_maps``). Straight running is
psi = 0, spinning in place psi = +-pi/2 and rest s = 0: no division by zero anywhere (hypot,
atan2). The grid covers the vehicle's command envelope, V up to ``max_speed`` and |w_z| up to
``max_yaw_rate`` (its vehicle-file fields; the corner included: s_max = sqrt(2) max_speed); a query
outside the envelope is answered at the grid's edge and flagged ``clamped``. At
exactly V = w_z = 0 the query answers rest (all zeros); the s = 0 grid row holds the s -> 0 limit
(the breakaway torques) for interpolation.

Reverse driving (V < 0) is not stored: a vehicle with its CG midway along its contact backing
at (-V, w_z) is the forward solution at (V, w_z) seen from a frame turned 180 degrees about the
vertical, so left and right swap and every side's speed and torque change sign (power, sinkage and
traction margin do not; s0 changes sign). :meth:`PowerMap.query` applies this itself.

Tight turns and spinning in place: the FESS shear-displacement kinematics (eq. 6.6) stop giving a
usable steady state once the turning radius approaches the tread (below about R = 0.5 m for the
chapter 3 track on dry sand the solution jumps to a branch with the inner side reversed and almost no
turning resistance; spinning in place has several roots). The map therefore solves every point with
|R| = |V / w_z| below ``min_radius`` (default twice the tread) at R = min_radius and the *same yaw
rate*, i.e. at V' = min_radius |w_z|, and keeps that point's shear state: its torques, each side's
slip speed r omega - v_side, s0, sinkage and traction margin. Each side's omega then follows its own
ground speed, omega = omega' + (v_side - v_side') / r. The text's argument for this limit: at small
radii "the soil fails and the shear force on the contact surface is saturated" (section 3.4), so the
turning resistance stops growing as R shrinks. Points solved this way are flagged in ``limited``
(the map's and every query's).
A spin in place therefore gets both sides driven in opposite directions with the turning resistance
of the tightest reliable turn at that yaw rate. That turn is not symmetric (its outer side keeps a
driving slip speed and torque, its inner side braking ones), a spin is: each limited point is blended
with its spin mirror image, weight (1 - |R| / min_radius) / 2 (:func:`~skidsteer_power.maps.map_solve.
_spin_symmetric`), so a spin in place has T_left = -T_right and omega_left = -omega_right exactly and
the blend is continuous with the limit answer at R = min_radius (issue 36).
At rest (V = w_z = 0) every torque is 0.

Points that do not converge even after warm starts from converged neighbours keep
``converged=False`` in the map, are filled with the nearest converged point's values and are
reported (never silently dropped). Those, and nodes whose slip ratio reaches :data:`SLIP_LIMIT` (the
traction limit: slip -> 1, where speed and power change too steeply for any interpolation), mark
their cells: a query touching one is flagged ``limited``.

Build-time accuracy check: after the nodes, FESS is solved at the centre of every cell a query could
answer unflagged (left turns; right turns mirrored), and the map's total power there is compared
with it (``cell_error``, relative to the sum of |side powers|). A cell off by more than
:data:`CELL_ERROR_LIMIT` (0.5 %, half the 1 % accuracy goal: for a smooth solution the centre is
where bilinear interpolation errs most, and the margin covers the rest of the cell) is flagged:
every query in it is ``limited``. Those are the fast turns approaching the traction limit, where the
outer side's slip climbs steeply with speed (centrifugal load transfer) and speed and power grow
towards an asymptote; finer uniform grids converged there too slowly to be an answer (16 x 101:
83 %, 31 x 101: 10.8 %). The check costs up to as many solves again as the nodes (fewer: cells
flagged anyway are skipped). Measured per vehicle x terrain: docs/BENCHMARKS.md ("Map accuracy").

Right turns are the mirror image of left turns (every vehicle here is laterally symmetric): only
psi >= 0 is solved, so mirrored commands give mirrored answers exactly.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias, TypedDict, Unpack

import numpy as np
from numpy.typing import NDArray

from skidsteer_power.cache import atomic_file, default_cache_dir, options_digest
from skidsteer_power.errors import ConfigError, InputError, MapMismatchError
from skidsteer_power.interpolation import Axis, BilinearGrid
from skidsteer_power.maps.grid_angles import REFINE_SPAN as REFINE_SPAN
from skidsteer_power.maps.grid_angles import _angle_coordinate as _angle_coordinate
from skidsteer_power.maps.grid_angles import _angle_coordinate_scalar, _refined_angles
from skidsteer_power.maps.identity import check_identity, map_identity
from skidsteer_power.maps.identity import model_version as model_version
from skidsteer_power.maps.map_solve import SLIP_LIMIT as SLIP_LIMIT
from skidsteer_power.maps.map_solve import Ring, _assemble, _check_cells, _mirror, _solve_row
from skidsteer_power.terramechanics.terrain import terrain_fingerprint
from skidsteer_power.vehicle import vehicle_fingerprint

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.models.fess import FessSolver
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

DEFAULT_SHAPE = (31, 101)  # rings (command magnitude) x turn angles (module doc: accuracy)
DEFAULT_REFINE = 40  # extra turn angles per side where 1 < R / min_radius < REFINE_SPAN (module doc)
ENVELOPE_TOLERANCE = 1e-9  # relative: commands this close to the envelope's edge count as inside

FIELDS = (  # stored on the grid and interpolated
    'torque_left_Nm',
    'torque_right_Nm',
    'slip_left_m_s',  # slip speed r omega - v_side [m/s]: speed and power are derived from it
    'slip_right_m_s',
    's0_m',
    'sinkage_m',
    'traction_margin',
    'suspect',  # 1 at nodes past the traction limit (module doc); a query touching one is ``limited``
)
CELL_ERROR_LIMIT = 0.005  # build-time check: a cell whose centre is off by more is flagged (module doc)
QUERY_FIELDS = (  # what a query answers
    'torque_left_Nm',
    'torque_right_Nm',
    'omega_left_rad_s',
    'omega_right_rad_s',
    'power_left_W',
    'power_right_W',
    's0_m',
    'sinkage_m',
    'traction_margin',
)
# quantities that change sign in reverse driving (after the left/right swap)
_ODD_IN_REVERSE = ('torque_left_Nm', 'torque_right_Nm', 'omega_left_rad_s', 'omega_right_rad_s', 's0_m')

_REST = {name: (1.0 if name == 'traction_margin' else 0.0) for name in QUERY_FIELDS}  # V = w_z = 0

ProgressCallback = Callable[[int, int], None]
Values: TypeAlias = float | NDArray[np.float64]
"""A scalar query's float or an array query's values."""
Flags: TypeAlias = bool | NDArray[np.bool_]
"""A scalar query's bool or an array query's flags."""


@dataclass
class MapQuery:
    """Interpolated map values at the queried points (arrays, or floats for a scalar query).

    torque_*_Nm : axle / sprocket torque per side [N m]; omega_*_rad_s : axle speed [rad/s];
    power_*_W : torque x omega [W]; s0_m : turning-centre offset [m]; sinkage_m [m];
    traction_margin [-].

    Flags (bools, arrays for array queries) -- a flagged value is not the map's accuracy:
    clamped : the command lies outside the map's command envelope (|V| > max_speed or |w_z| >
        max_yaw_rate, or not finite); it was answered at the edge of the grid.
    limited : a physics limit: the turn is tighter than the small-radius limit (|V| < min_radius
        |w_z|, spinning in place included; solved at the limit radius, module doc), or the point
        touches a node at the traction limit (no steady state, or slip ratio >= SLIP_LIMIT), or it
        lies in a cell the build-time check found off FESS by more than CELL_ERROR_LIMIT (the
        steep approach to the traction limit; module doc).
    """

    torque_left_Nm: Values
    torque_right_Nm: Values
    omega_left_rad_s: Values
    omega_right_rad_s: Values
    power_left_W: Values
    power_right_W: Values
    s0_m: Values
    sinkage_m: Values
    traction_margin: Values
    clamped: Flags
    limited: Flags

    @property
    def total_power_W(self) -> Values:
        return self.power_left_W + self.power_right_W


class MapOptions(TypedDict):
    """Every option that changes a map, resolved (:func:`build_options`; stored in a map's meta)."""

    max_speed: float  # [m/s]
    max_yaw_rate: float  # [rad/s]
    shape: list[int]  # (rings, angles)
    n: int  # FESS elements per contact
    min_radius: float  # small-radius limit [m]
    refine: int  # angle refinement steps near the small-radius limit


class MapKeywords(TypedDict, total=False):
    """The options :func:`build_options` takes, as keywords (None or missing: the default); the one
    list of them (the map functions take them as ``**options: Unpack[MapKeywords]``)."""

    max_speed: float | None
    max_yaw_rate: float | None
    shape: tuple[int, int] | None
    n: int | None
    min_radius: float | None
    refine: int | None


def build_options(vehicle: Vehicle, **keywords: Unpack[MapKeywords]) -> MapOptions:
    """Every option that changes a map, defaults resolved: the vehicle's command envelope
    (``max_speed_m_s``, ``max_yaw_rate_rad_s``), :data:`DEFAULT_SHAPE`, FESS's default element
    count, the small-radius limit 2 x tread [m]. ``map build`` and the library both use this, so the
    same options give the same cache file and different options never share one."""
    from skidsteer_power.models import fess

    unknown = sorted(set(keywords) - set(MapKeywords.__annotations__))
    if unknown:  # ** takes any name at run time: a typo must not become a default
        raise InputError(
            f'unknown map option(s) {", ".join(unknown)}; known: {", ".join(MapKeywords.__annotations__)}'
        )
    max_speed, max_yaw_rate = keywords.get('max_speed'), keywords.get('max_yaw_rate')
    shape, n, refine = keywords.get('shape'), keywords.get('n'), keywords.get('refine')
    min_radius = keywords.get('min_radius')
    options: MapOptions = {
        'max_speed': float(vehicle.max_speed_m_s if max_speed is None else max_speed),
        'max_yaw_rate': float(vehicle.max_yaw_rate_rad_s if max_yaw_rate is None else max_yaw_rate),
        'shape': [int(k) for k in (DEFAULT_SHAPE if shape is None else shape)],
        'n': int(fess.DEFAULT_ELEMENTS if n is None else n),
        'min_radius': float(2.0 * vehicle.tread_m if min_radius is None else min_radius),
        # the refinement belongs to the default grid; an explicit shape is taken as it is
        'refine': int((DEFAULT_REFINE if shape is None else 0) if refine is None else refine),
    }
    for name, value in (('max_speed', options['max_speed']), ('max_yaw_rate', options['max_yaw_rate'])):
        if not np.isfinite(value) or value <= 0:
            raise InputError(f'{name} must be a finite number > 0, got {value!r}')
    if not np.isfinite(options['min_radius']) or options['min_radius'] <= 0:
        raise InputError(f'min_radius must be a finite number > 0 m, got {min_radius!r}')
    n_s, n_psi = options['shape']
    if n_s < 2 or n_psi < 3:
        raise InputError(f'map shape must be at least (2, 3), got {shape!r}')
    if options['n'] < 2:
        raise InputError(f'FESS elements per contact must be at least 2, got {n!r}')
    return options


@dataclass
class PowerMap:
    """A look-up map for one vehicle on one terrain over the polar (s, psi) grid (module doc)."""

    radial: np.ndarray  # (Ns,) command magnitude s = hypot(V, L w_z) [m/s], starts at 0
    angles: np.ndarray  # (Npsi,) turn angle psi = atan2(L w_z, V) in [-pi/2, pi/2] [rad]
    length_m: float  # L [m]
    values: dict[str, np.ndarray]  # FIELDS -> (Ns, Npsi)
    converged: np.ndarray  # (Ns, Npsi) bool
    limited: np.ndarray  # (Ns, Npsi) bool: solved at the small-radius limit
    meta: JsonObject = field(default_factory=dict)
    path: Path | None = None
    # (Ns - 1, Npsi - 1) build-time check per cell: relative power error at the cell centre [-]; nan
    # where not checked (cells every query flags anyway), inf where FESS found no steady state there
    cell_error: np.ndarray | None = None

    def __post_init__(self) -> None:
        self._axis_s = Axis(self.radial, 'command magnitude')
        self._axis_psi = Axis(_angle_coordinate(self.angles), 'turn angle')
        stacked = np.stack([self.values[name] for name in FIELDS], axis=-1)
        self._grid = BilinearGrid(self._axis_s, self._axis_psi, stacked)
        unchecked = np.full((len(self.radial) - 1, len(self.angles) - 1), np.nan)
        self.set_cell_error(unchecked if self.cell_error is None else self.cell_error)
        self._radius = float(self.meta['drive_radius_m'])
        self._half_tread = 0.5 * float(self.meta['tread_m'])
        self._r_min = float(self.meta['min_radius_m'])
        self._v_max = float(self.meta['max_speed_m_s']) * (1.0 + ENVELOPE_TOLERANCE)
        self._w_max = float(self.meta['max_yaw_rate_rad_s']) * (1.0 + ENVELOPE_TOLERANCE)

    @property
    def speeds(self) -> np.ndarray:
        """Forward speeds [m/s] of the straight-running grid line (all >= 0: reverse by symmetry)."""
        return self.radial

    @property
    def yaw_rates(self) -> np.ndarray:
        """Yaw rates [rad/s] of the spin-in-place grid lines, -max ... +max."""
        return np.concatenate([-self.radial[::-1], self.radial[1:]]) / self.length_m

    # ---------------------------------------------------------------- building
    @classmethod
    def build(
        cls,
        vehicle: Vehicle,
        terrain: Terrain,
        *,
        max_speed: float | None = None,
        max_yaw_rate: float | None = None,
        shape: tuple[int, int] | None = None,
        model: str = 'fess',
        progress: ProgressCallback | None = None,
        n: int | None = None,
        min_radius: float | None = None,
        refine: int | None = None,
        speeds: ArrayLike | None = None,
        yaw_rates: ArrayLike | None = None,
    ) -> PowerMap:
        """Solve the map with FESS: one batched Newton solve per ring s = const from the physical
        first guess (eq. 3.21), failed points re-solved warm-started from converged neighbours.
        (Warm-starting whole rings from the previous ring was tried and dropped: near rest and in
        tight turns the equilibrium has several roots, and a wrong one propagated outwards.)

        Only left turns (psi >= 0) are solved; right turns are their mirror image (left and right
        swap; every vehicle here is laterally symmetric), so mirrored commands give mirrored
        answers exactly and the build takes half the solves.

        Options default per :func:`build_options` (max_speed [m/s] and max_yaw_rate [rad/s]: the
        vehicle's command envelope; shape = (rings, angles); ``n`` FESS elements per contact;
        ``min_radius`` [m] the small-radius limit). ``progress(done, total)`` is called after each
        ring, then after each ring of the cell check (total = 2 rings - 1). ``speeds`` [m/s] and
        ``yaw_rates`` [rad/s] (the interface of docs/INTERFACES.md) are accepted for
        compatibility: they set max_speed = max |speeds|, max_yaw_rate = max |yaw_rates| and
        shape = (their lengths); the grid itself stays polar (module doc).
        """
        max_speed, max_yaw_rate, shape = _envelope_of_axes(speeds, yaw_rates, max_speed, max_yaw_rate, shape)
        if model != 'fess':
            raise InputError(f"maps are built with the FESS model only (model='fess'), not {model!r}")
        from skidsteer_power.models import fess

        options = build_options(
            vehicle,
            max_speed=max_speed,
            max_yaw_rate=max_yaw_rate,
            shape=shape,
            n=n,
            min_radius=min_radius,
            refine=refine,
        )
        n_s, n_psi = options['shape']
        r_min = options['min_radius']
        length = options['max_speed'] / options['max_yaw_rate']
        radial = np.linspace(0.0, np.sqrt(2.0) * options['max_speed'], n_s)
        angles = _refined_angles(n_psi, options['refine'], length, r_min)
        solver = fess.FessSolver(vehicle, terrain, options['n'])
        rows = _solve_rings(solver, radial, angles, length, r_min, progress)
        values, converged, limited = _assemble(rows)
        meta = _build_meta(vehicle, terrain, model, options, solver.n, converged)
        out = cls(radial, angles, float(length), values, converged, limited, meta)
        ring_done = None if progress is None else (lambda k: progress(n_s + k + 1, 2 * n_s - 1))
        cell_error = _check_cells(out, solver, r_min, ring_done)
        out.set_cell_error(cell_error)
        out.meta['inaccurate_cells'] = int(np.sum(out._cell_flag))
        out.meta['checked_cells'] = int(np.sum(~np.isnan(cell_error)))
        return out

    def set_cell_error(self, cell_error: np.ndarray) -> None:
        """The build-time check's power error per cell (see ``cell_error``) and the flags it sets."""
        self.cell_error = cell_error
        self._cell_flag = (cell_error > CELL_ERROR_LIMIT).ravel()  # nan: False
        self._cell_flag_list = self._cell_flag.tolist()

    # ---------------------------------------------------------------- storage
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the map to ``path`` (.npz, with vehicle, terrain and model version inside)."""
        target = Path(path)
        arrays = {f'value_{k}': v for k, v in self.values.items()}
        with atomic_file(target) as tmp:  # a reader never sees half a map
            np.savez_compressed(
                tmp,
                radial=self.radial,
                angles=self.angles,
                length_m=np.array(self.length_m),
                converged=self.converged,
                limited=self.limited,
                cell_error=self.cell_error,  # type: ignore[arg-type]
                meta=np.array(json.dumps(self.meta)),
                **arrays,  # type: ignore[arg-type]
            )
        self.path = target
        return target

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], vehicle: Vehicle | None = None, terrain: Terrain | None = None
    ) -> PowerMap:
        """Read a map; MapMismatchError if it was built for another vehicle, terrain or model
        version than those given (and the current FESS version); ConfigError if unreadable."""
        source = Path(path)
        try:
            with np.load(source, allow_pickle=False) as data:
                meta = json.loads(str(data['meta']))
                values = {name: np.array(data[f'value_{name}']) for name in FIELDS}
                arrays: dict[str, np.ndarray] = {
                    k: np.array(data[k])
                    for k in ('radial', 'angles', 'length_m', 'converged', 'limited', 'cell_error')
                }
        except FileNotFoundError:
            raise ConfigError(f'map file not found: {source}') from None
        except (OSError, KeyError, ValueError, TypeError, json.JSONDecodeError) as err:
            # TypeError: a plain .npy array (not a zip archive) cannot be opened as an archive
            raise ConfigError(f'{source}: not a skidsteer_power map ({err})') from err
        check_identity(source, meta, vehicle, terrain)
        out = cls(
            arrays['radial'],
            arrays['angles'],
            float(arrays['length_m']),
            values,
            arrays['converged'].astype(bool),
            arrays['limited'].astype(bool),
            meta,
            cell_error=arrays['cell_error'],
        )
        out.path = source
        return out

    # ---------------------------------------------------------------- queries
    def query(self, speed: float | ArrayLike, yaw_rate: float | ArrayLike) -> MapQuery:
        """Interpolated values at (V [m/s], w_z [rad/s]); broadcast arrays or scalars.

        Torques, slip speeds, s0, sinkage and margin are interpolated; each side's axle speed is
        (its exact ground speed V -/+ w_z B/2 + its slip speed) / r and its power torque x speed.
        V < 0 is answered by the 180-degree symmetry (module doc). Flags: see :class:`MapQuery`.
        """
        if isinstance(speed, float) and isinstance(yaw_rate, float):  # per message: no numpy at all
            return self._query_scalar(speed, yaw_rate)
        if np.ndim(speed) == 0 and np.ndim(yaw_rate) == 0:
            return self._query_scalar(float(np.asarray(speed)), float(np.asarray(yaw_rate)))
        v, w = np.broadcast_arrays(np.asarray(speed, dtype=float), np.asarray(yaw_rate, dtype=float))
        shape = v.shape
        v, w = v.ravel(), w.ravel()
        reverse = v < 0
        va = np.abs(v)
        lw = self.length_m * w
        out, off_grid, cell = self._grid(np.hypot(v, lw), _angle_coordinate(np.arctan2(lw, va)))
        bad = ~np.isfinite(v) | ~np.isfinite(w)
        rest = (v == 0) & (w == 0)
        grid = {name: out[:, k] for k, name in enumerate(FIELDS)}
        omega_l = (va - w * self._half_tread + grid['slip_left_m_s']) / self._radius
        omega_r = (va + w * self._half_tread + grid['slip_right_m_s']) / self._radius
        columns = {
            'torque_left_Nm': grid['torque_left_Nm'],
            'torque_right_Nm': grid['torque_right_Nm'],
            'omega_left_rad_s': omega_l,
            'omega_right_rad_s': omega_r,
            'power_left_W': grid['torque_left_Nm'] * omega_l,
            'power_right_W': grid['torque_right_Nm'] * omega_r,
            's0_m': grid['s0_m'],
            'sinkage_m': grid['sinkage_m'],
            'traction_margin': grid['traction_margin'],
        }
        if np.any(reverse):
            columns = _reverse(columns, reverse)
        fields = {
            name: np.where(bad, np.nan, np.where(rest, _REST[name], col)).reshape(shape)
            for name, col in columns.items()
        }
        clamped = off_grid | bad | (va > self._v_max) | (np.abs(w) > self._w_max)
        limited = (grid['suspect'] > 0) | self._cell_flag[cell] | (va < self._r_min * np.abs(w))
        return MapQuery(**fields, clamped=clamped.reshape(shape), limited=(limited & ~bad).reshape(shape))

    def _query_scalar(self, v: float, w: float) -> MapQuery:
        if v != v or w != w or math.isinf(v) or math.isinf(w):  # never a silent number
            return MapQuery(**dict.fromkeys(QUERY_FIELDS, float('nan')), clamped=True, limited=False)
        va = abs(v)
        lw = self.length_m * w
        vals, off_grid, cell = self._grid.scalar(
            math.hypot(v, lw), _angle_coordinate_scalar(math.atan2(lw, va))
        )
        tl, tr, sl, sr, s0, sinkage, margin, suspect = vals
        clamped = off_grid or va > self._v_max or abs(w) > self._w_max
        limited = suspect > 0 or self._cell_flag_list[cell] or va < self._r_min * abs(w)
        if v == 0 and w == 0:
            return MapQuery(**_REST, clamped=False, limited=False)
        ol = (va - w * self._half_tread + sl) / self._radius
        orr = (va + w * self._half_tread + sr) / self._radius
        if v < 0:  # 180-degree symmetry (module doc)
            tl, tr, ol, orr, s0 = -tr, -tl, -orr, -ol, -s0
        return MapQuery(tl, tr, ol, orr, tl * ol, tr * orr, s0, sinkage, margin, clamped, limited)

    # ---------------------------------------------------------------- description
    def summary(self) -> JsonObject:
        """Metadata and grid extent, for ``map show``."""
        return {
            **self.meta,
            'path': str(self.path) if self.path else None,
            'grid': {
                'rings': len(self.radial),
                'angles': len(self.angles),
                'length_m': self.length_m,
                'max_command_m_s': float(self.radial[-1]),
            },
            'converged_points': int(np.sum(self.converged)),
            'total_points': int(self.converged.size),
            'limited_points': int(np.sum(self.limited)),
            'inaccurate_cells': int(np.sum(self._cell_flag)),
            'total_cells': int(self._cell_flag.size),
            'max_power_W': float(np.nanmax(self._node_power())),
            'min_traction_margin': float(np.min(self.values['traction_margin'])),
        }

    def _node_power(self) -> np.ndarray:
        """Total terrain power [W] at the grid nodes (rings x angles)."""
        s, psi = np.meshgrid(self.radial, self.angles, indexing='ij')
        q = self.query(s * np.cos(psi), s * np.sin(psi) / self.length_m)
        return np.asarray(q.power_left_W + q.power_right_W)


def _envelope_of_axes(
    speeds: ArrayLike | None,
    yaw_rates: ArrayLike | None,
    max_speed: float | None,
    max_yaw_rate: float | None,
    shape: tuple[int, int] | None,
) -> tuple[float | None, float | None, tuple[int, int] | None]:
    """(max_speed [m/s], max_yaw_rate [rad/s], shape) of :meth:`PowerMap.build`, set from the
    ``speeds`` and ``yaw_rates`` axes of docs/INTERFACES.md where given (the grid stays polar)."""
    if speeds is not None:
        max_speed = float(np.max(np.abs(_axis(speeds, 'speeds'))))
    if yaw_rates is not None:
        max_yaw_rate = float(np.max(np.abs(_axis(yaw_rates, 'yaw_rates'))))
    if shape is None and speeds is not None and yaw_rates is not None:
        shape = (len(np.ravel(speeds)), max(len(np.ravel(yaw_rates)), 3))
    return max_speed, max_yaw_rate, shape


def _solve_rings(
    solver: FessSolver,
    radial: np.ndarray,
    angles: np.ndarray,
    length: float,
    r_min: float,
    progress: ProgressCallback | None,
) -> list[Ring]:
    """One batched FESS solve per ring s = const [m/s], left turns only (psi >= 0), each row then
    mirrored to the right turns; ``progress(ring, 2 rings - 1)`` after each (the cell check follows)."""
    n_s, n_psi = len(radial), len(angles)
    left = angles >= 0  # solved; the rest mirrored
    rows: list[Ring] = []
    for k, s in enumerate(radial):
        ring = max(float(s), 1e-3 * radial[1])  # s = 0: the limit s -> 0 along each angle
        v = ring * np.cos(angles[left])
        w = ring * np.sin(angles[left]) / length
        rows.append(_mirror(_solve_row(solver, v, w, r_min), n_psi))
        if progress is not None:
            progress(k + 1, 2 * n_s - 1)
    return rows


def _build_meta(
    vehicle: Vehicle,
    terrain: Terrain,
    model: str,
    options: MapOptions,
    elements: int,
    converged: np.ndarray,
) -> JsonObject:
    """A new map's ``meta``: its identity, build options and what the solves found."""
    return {
        **map_identity(vehicle, terrain, model),
        'options': options,
        'options_digest': options_digest(options),
        'elements': elements,
        'min_radius_m': options['min_radius'],
        'max_speed_m_s': options['max_speed'],
        'max_yaw_rate_rad_s': options['max_yaw_rate'],
        'drive_radius_m': float(vehicle.drive_radius_m),
        'tread_m': float(vehicle.tread_m),
        'failed_points': int(np.sum(~converged)),
    }


def _axis(values: ArrayLike, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).ravel()
    if len(arr) < 2 or not np.all(np.isfinite(arr)) or not np.all(np.diff(arr) > 0):
        raise InputError(f'{name} must hold at least 2 finite, strictly increasing values')
    return arr


def _reverse(columns: dict[str, np.ndarray], reverse: np.ndarray) -> dict[str, np.ndarray]:
    """Turn forward-driving columns into reverse driving where ``reverse`` (180-degree symmetry)."""
    out = dict(columns)
    for a, b in (
        ('torque_left_Nm', 'torque_right_Nm'),
        ('omega_left_rad_s', 'omega_right_rad_s'),
        ('power_left_W', 'power_right_W'),
    ):
        out[a] = np.where(reverse, columns[b], columns[a])
        out[b] = np.where(reverse, columns[a], columns[b])
    for name in _ODD_IN_REVERSE:
        out[name] = np.where(reverse, -out[name], out[name])
    return out


# -------------------------------------------------------------------- cache


def cache_path(
    vehicle: Vehicle,
    terrain: Terrain,
    cache_dir: str | os.PathLike[str] | None = None,
    model: str = 'fess',
    **options: Unpack[MapKeywords],
) -> Path:
    """Where :func:`load_or_build` (and ``map build``) keep the map of this vehicle and terrain built
    with ``options`` (:func:`build_options`; defaults resolved first, so explicit defaults and
    omitted ones name the same file). The name holds every input that changes the map: vehicle and
    terrain fingerprints, the physics-code digest and the options' digest."""
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    digest = options_digest(build_options(vehicle, **options))
    vehicle_part = f'{vehicle.name}-{vehicle_fingerprint(vehicle)}'
    terrain_part = f'{terrain.name}-{terrain_fingerprint(terrain)}'
    return folder / f'{vehicle_part}_{terrain_part}_{model_version(model)}_{digest}.npz'


def load_or_build(
    vehicle: Vehicle,
    terrain: Terrain,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    progress: ProgressCallback | None = None,
    rebuild: bool = False,
    **options: Unpack[MapKeywords],
) -> tuple[PowerMap, bool]:
    """The cached map of ``vehicle`` on ``terrain`` (default options: :func:`build_options`),
    building (and saving) it if it is missing, unreadable or was built for another vehicle, terrain,
    physics code or options.

    Returns (map, built). cache_dir defaults to $SKIDSTEER_POWER_CACHE or ~/.cache/skidsteer_power.
    """
    path = cache_path(vehicle, terrain, cache_dir, **options)
    if path.exists() and not rebuild:
        try:
            return PowerMap.load(path, vehicle, terrain), False
        except (MapMismatchError, ConfigError):
            pass  # stale or damaged: rebuild below, never use it
    built = PowerMap.build(vehicle, terrain, progress=progress, **options)
    built.save(path)
    return built, True
