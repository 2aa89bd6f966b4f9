"""Look-up map of the set-point prediction: what a command really does, in microseconds (issue 25).

:class:`~skidsteer_power.models.predict.CommandPredictor` solves FESS at a command's wheel speed set
points (milliseconds). This map tabulates that solve over set-point space so the robot can query it
per message. Coordinates: the mean m = (sp_left + sp_right) / 2 and the half difference
d = (sp_right - sp_left) / 2 of the axle speed set points [rad/s], on a rectangular grid over
m in [0, m_max], d in [0, d_max] with m_max = max_speed / r and d_max = max_yaw_rate B / (2 r) (the
vehicle's command envelope, its ``max_speed_m_s`` and ``max_yaw_rate_rad_s``). The other three
quadrants are mirror images, exact for the laterally and fore-aft symmetric vehicles here (module
doc of fess.py): a negative mean is reverse driving (every speed, yaw rate and torque negated), a
negative difference a right turn (sides swapped, yaw rate negated).

Stored per node: V, w_z, both axle torques, both slips, sinkage, traction margin, ``dug_in`` (no
steady state, the dug-in answer) and the contact length. A query interpolates bilinearly in plain
Python floats, then adds the powertrain (motor currents under the current limit, battery power)
exactly as the direct path does (:meth:`CommandPredictor.electrical`'s formulas, via
:meth:`Powertrain.motor_side` on floats). A query in a cell with a dug-in corner is ``limited``, and
so is one whose interpolated motion turns an element past half a revolution in the contact
(:func:`~skidsteer_power.models.setpoint.element_turn_rev`, the direct solve's test); outside the
envelope it is answered at the edge and ``clamped``. Accuracy and speed against the direct solve:
benchmarks/bench_maps.py.

Cells answered exactly (issue 36: the map agrees with the direct solve): where the steady state
changes too abruptly for bilinear interpolation the map does not interpolate but solves the command
directly (:meth:`SetpointMap.query` then costs one set-point solve, milliseconds). Those cells are
the ones with a dug-in corner or whose corners disagree on the pivot test (the limited boundary:
interpolating across it would flag or unflag commands the direct solve does not), and, found at build
time, the cells near the pivot band (a corner's inner / outer set point ratio within
+-:data:`BAND_RATIO`, where the motion turns steeply with the inner set point; on rigid ground every
cell: Coulomb friction has a kink where the wheels begin to skid sideways, near straight driving,
where the Husky's map was 16.7 % off on asphalt) whose centre, solved directly, is off the
interpolated answer by more than :data:`CHECK_POWER` in battery power or :data:`CHECK_SPEED_M_S` in
speed (half the goals of 1 % and 5 mm/s: for a smooth solution bilinear interpolation errs most at
the centre). A spin in place (mean 0) is then solved like the direct path
and symmetric as it is. A command in a cell with a corner the pivot law solved (the direct solve's
fallback) is solved with the pivot law at once, warm-started from the cell's interpolated state
(s0, V, w_z): the law equals eq. 6.6's chord wherever no element turns past half a revolution, so
this is the direct solve's root within its stopping rule, without the chord's failing Newton and
continuation first (husky_a200 x sand_bin: 14.5 s -> 1.75 s for 406 such commands; largest
difference to the direct solve over 1,500 random commands on five vehicle x soil pairs 0.17 % in
battery power and 0.48 mm/s in speed, no flag different).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.cache import atomic_file, default_cache_dir, physics_digest
from skidsteer_power.drive.controller import controller_for_vehicle
from skidsteer_power.drive.current import current_limited
from skidsteer_power.errors import InputError, MapMismatchError
from skidsteer_power.interpolation import Axis, BilinearGrid
from skidsteer_power.maps.identity import check_identity, map_identity
from skidsteer_power.models.predict import REASON_CURRENT, CommandPredictor
from skidsteer_power.models.setpoint import (
    ELEMENT_TURN_LIMIT_REV,
    REASON_PIVOT,
    REASON_TRACTION,
    SetpointSolution,
    element_turn_rev,
)
from skidsteer_power.terramechanics.terrain import terrain_fingerprint
from skidsteer_power.vehicle import vehicle_fingerprint

if TYPE_CHECKING:
    from skidsteer_power.drive.controller import DriveController
    from skidsteer_power.powertrain.power_flow import MotorPoint
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

FIELDS = (
    'speed', 'yaw_rate', 'torque_left', 'torque_right', 'slip_left', 'slip_right', 'sinkage',
    'traction_margin', 'dug_in', 'contact_length', 'shear_path', 's0',
)  # fmt: skip
DEFAULT_NODES = (25, 25)  # (mean, difference) nodes
MAP_MODEL = 'setpoint'  # the model name in a stored map's identity (maps/identity.py)
MAX_NODES = 200_000
BAND_RATIO = 0.4  # cells with a corner's inner / outer set point within +-this are checked (module doc)
CHECK_POWER = 0.005  # a checked cell whose centre is off by more (relative battery power) is exact
CHECK_SPEED_M_S = 0.0025  # ... or by more in speed [m/s]


@dataclass(frozen=True)
class SetpointQuery:
    """One command's answer from the map, SI units (the keys of ``skidsteer-power predict``)."""

    setpoint_left_rad_s: float
    setpoint_right_rad_s: float
    speed_m_s: float
    yaw_rate_rad_s: float
    torque_left_Nm: float
    torque_right_Nm: float
    slip_left: float
    slip_right: float
    sinkage_m: float
    traction_margin: float
    current_left_A: float
    current_right_A: float
    battery_power_W: float
    limited: bool
    clamped: bool
    reason: str
    motors: tuple[MotorPoint[float] | None, MotorPoint[float] | None] = (
        None,
        None,
    )  # the estimator reuses them

    @property
    def turn_radius_m(self) -> float:
        """V / w_z [m]: +-inf straight, 0 spinning in place, NaN at rest."""
        if self.yaw_rate_rad_s == 0:
            return math.nan if self.speed_m_s == 0 else math.inf
        return self.speed_m_s / self.yaw_rate_rad_s


class SetpointMap:
    """The set-point prediction of one vehicle x terrain over (mean, half difference) of set points."""

    def __init__(
        self,
        predictor: CommandPredictor,
        mean: np.ndarray,
        diff: np.ndarray,
        values: np.ndarray,
        checked: np.ndarray | None = None,
    ) -> None:
        """``checked`` (n_mean - 1, n_diff - 1) bool: cells the build-time check found off (module
        doc); with those with a dug-in corner or a mixed pivot test they are answered exactly."""
        self.predictor = predictor
        self.grid = BilinearGrid(
            Axis(mean, 'set point mean'), Axis(diff, 'set point half difference'), values
        )
        self._radius = float(predictor.vehicle.drive_radius_m)
        # element_turn_rev's test in floats: |w_z| xi / v_rim > limit [rev] times 2 pi [rad]
        self._turn_limit = ELEMENT_TURN_LIMIT_REV * 2.0 * math.pi
        shape = (len(mean) - 1, len(diff) - 1)
        self.checked = np.zeros(shape, dtype=bool) if checked is None else np.asarray(checked, dtype=bool)
        if self.checked.shape != shape:
            raise InputError(f'set-point map: checked cells {self.checked.shape} do not match {shape}')
        # the element-turn (pivot) test belongs to eq. 6.6's chord: not on rigid ground, and a cell
        # with a corner the slip-path fallback solved (the pivot band on soil) is answered exactly
        self._pivot_test = not predictor.solver.fess.path_law
        path = self.grid.values[..., FIELDS.index('shear_path')] > 0
        fallback = _corner_any(path) if self._pivot_test else np.zeros(shape, dtype=bool)
        self.exact = _corner_any(self._dug_in()) | _mixed(self._pivot_nodes()) | fallback | self.checked
        self._cell_exact = self.exact.ravel().tolist()
        self._cell_path = fallback.ravel().tolist()
        self._limit = predictor.current_limit_A

    def _dug_in(self) -> np.ndarray:
        return np.asarray(self.grid.values[..., FIELDS.index('dug_in')] > 0)

    def _pivot_nodes(self) -> np.ndarray:
        """(n_mean, n_diff) the direct solve's pivot test at every node (:func:`element_turn_rev`)."""
        m, d = np.meshgrid(self.grid.axis0.values, self.grid.axis1.values, indexing='ij')
        inner_rim = np.abs(m - d) * self._radius
        yaw = self.grid.values[..., FIELDS.index('yaw_rate')]
        contact = self.grid.values[..., FIELDS.index('contact_length')]
        turn = element_turn_rev(yaw, contact, inner_rim)
        path = self.grid.values[..., FIELDS.index('shear_path')] > 0
        pivot: np.ndarray = (turn > ELEMENT_TURN_LIMIT_REV) & ~self._dug_in() & ~path & self._pivot_test
        return pivot

    @property
    def exact_fraction(self) -> float:
        """Share of the map's cells answered by the direct solve [-] (module doc)."""
        return float(np.mean(self.exact))

    @classmethod
    def build(
        cls,
        vehicle: Vehicle,
        terrain: Terrain,
        nodes: tuple[int, int] = DEFAULT_NODES,
        predictor: CommandPredictor | None = None,
    ) -> SetpointMap:
        """Solve every node in one batched set-point solve (nodes = (mean, difference) counts, each
        >= 2, at most MAX_NODES in all)."""
        n_mean, n_diff = (int(n) for n in nodes)
        if min(n_mean, n_diff) < 2 or n_mean * n_diff > MAX_NODES:
            raise InputError(
                f'set-point map nodes must be >= 2 each and at most {MAX_NODES:,} in all: {nodes}'
            )
        predictor = predictor or CommandPredictor(vehicle, terrain)
        mean_top, diff_top = envelope(predictor)
        mean = np.linspace(0.0, mean_top, n_mean)
        diff = np.linspace(0.0, diff_top, n_diff)
        m, d = np.meshgrid(mean, diff, indexing='ij')
        sol = predictor.solver.solve(np.column_stack([(m - d).ravel(), (m + d).ravel()]))
        columns = (
            sol.speed,
            sol.yaw_rate,
            sol.torque[:, 0],
            sol.torque[:, 1],
            sol.slip[:, 0],
            sol.slip[:, 1],
            sol.sinkage,
            sol.traction_margin,
            sol.dug_in.astype(float),
            sol.contact_length,
            np.asarray(sol.shear_path, dtype=float),
            sol.s0,
        )
        values = np.stack(columns, axis=-1).reshape(n_mean, n_diff, len(FIELDS))
        unchecked = cls(predictor, mean, diff, values)
        return cls(predictor, mean, diff, values, unchecked.check_cells())

    def check_cells(self) -> np.ndarray:
        """The build-time check (module doc): (n_mean - 1, n_diff - 1) True where a cell near the
        pivot band, not already exact, misses CHECK_POWER or CHECK_SPEED_M_S at its centre."""
        mean, diff = self.grid.axis0.values, self.grid.axis1.values
        m, d = np.meshgrid(mean, diff, indexing='ij')
        with np.errstate(invalid='ignore', divide='ignore'):
            ratio = np.abs((m - d) / (m + d))
        band = _corner_any(np.nan_to_num(ratio, nan=0.0) <= BAND_RATIO) & ~self.exact
        if self.predictor.solver.fess.terrain.is_rigid:  # Coulomb contact kinks where wheels skid
            band = ~self.exact
        cells = np.argwhere(band)
        out = np.zeros(band.shape, dtype=bool)
        if cells.size == 0:
            return out
        mc = 0.5 * (mean[cells[:, 0]] + mean[cells[:, 0] + 1])
        dc = 0.5 * (diff[cells[:, 1]] + diff[cells[:, 1] + 1])
        sp = np.column_stack([mc - dc, mc + dc])
        sol = self.predictor.solver.solve(sp)
        _, _, p_direct, _ = self.predictor.electrical(sol.torque, sp)
        vals = self.grid.values
        i, j = cells[:, 0], cells[:, 1]
        centre = 0.25 * (vals[i, j] + vals[i + 1, j] + vals[i, j + 1] + vals[i + 1, j + 1])  # bilinear
        torque = centre[:, [FIELDS.index('torque_left'), FIELDS.index('torque_right')]]
        _, _, p_map, _ = self.predictor.electrical(torque, sp)
        p_err = np.abs(p_map - p_direct) / np.maximum(np.abs(p_direct), 1.0)
        v_err = np.abs(centre[:, FIELDS.index('speed')] - sol.speed)
        off = sol.limited | (p_err > CHECK_POWER) | (v_err > CHECK_SPEED_M_S)
        out[i[off], j[off]] = True
        return out

    @property
    def limited_fraction(self) -> float:
        """Share of the map's nodes with no steady state [-] (dug in; the pivot flag is per query)."""
        return float(np.mean(self._dug_in()))

    def query(self, speed_cmd: float, yaw_cmd: float) -> SetpointQuery:
        """The prediction for one command (V [m/s], w_z [rad/s]) in plain Python floats."""
        located = self._locate(speed_cmd, yaw_cmd)
        if isinstance(located, _Deferred):
            return self._direct_many([located])[0]
        return located

    def query_many(self, speeds: Sequence[float], yaw_rates: Sequence[float]) -> list[SetpointQuery]:
        """:meth:`query` of every command (V [m/s], w_z [rad/s]); the commands in exact cells are
        solved together in one batched set-point solve (a set-point solve costs milliseconds, a
        batch of them hardly more than one), the others interpolated."""
        answers: list[SetpointQuery | None] = []
        where: list[int] = []
        deferred: list[_Deferred] = []
        for v, w in zip(speeds, yaw_rates, strict=True):
            located = self._locate(v, w)
            if isinstance(located, _Deferred):
                where.append(len(answers))
                deferred.append(located)
                answers.append(None)
            else:
                answers.append(located)
        for k, answer in zip(where, self._direct_many(deferred), strict=True):
            answers[k] = answer
        return [a for a in answers if a is not None]

    def _locate(self, speed_cmd: float, yaw_cmd: float) -> SetpointQuery | _Deferred:
        """The interpolated answer for one command, or for a command in an exact cell what
        :meth:`_direct_many` solves."""
        v, w = float(speed_cmd), float(yaw_cmd)
        if not (math.isfinite(v) and math.isfinite(w)):
            raise InputError('commanded speed and yaw rate must be finite numbers (m/s, rad/s)')
        (sp_l, sp_r), clamped_sp = self._setpoints(v, w)
        flip = -1.0 if sp_l + sp_r < 0 else 1.0  # reverse: (l, r) -> (-l, -r), the fore-aft mirror
        mean, diff = 0.5 * flip * (sp_l + sp_r), 0.5 * flip * (sp_r - sp_l)
        reverse, right_turn = flip < 0, diff < 0
        vals, off_grid, cell = self.grid.scalar(mean, abs(diff))
        speed, yaw, t_l, t_r, s_l, s_r, sinkage, margin, _, contact, _, s0 = vals
        if self._cell_exact[cell]:
            warm = None
            if self._cell_path[cell]:  # the mirrored interpolated state: (s0, V, w_z) of the command
                warm = (flip * s0, flip * speed, flip * (-yaw if right_turn else yaw))
            return _Deferred((sp_l, sp_r), clamped_sp or off_grid, warm)
        inner_rim = min(abs(sp_l), abs(sp_r)) * self._radius
        pivot = (
            self._pivot_test
            and yaw != 0
            and (inner_rim == 0 or abs(yaw) * contact / inner_rim > self._turn_limit)
        )
        if right_turn:  # a right turn: the left turn's mirror image
            yaw, t_l, t_r, s_l, s_r = -yaw, t_r, t_l, s_r, s_l
        if reverse:  # every speed, yaw rate and torque negated (module doc of fess.py)
            speed, yaw, t_l, t_r = -speed, -yaw, -t_l, -t_r
        traction = False  # a cell with a dug-in corner is exact (above)
        t_l, i_l, left, over_l = self._side('left', t_l, sp_l)
        t_r, i_r, right, over_r = self._side('right', t_r, sp_r)
        current = over_l or over_r
        reason = REASON_TRACTION if traction else REASON_PIVOT if pivot else REASON_CURRENT if current else ''
        return SetpointQuery(
            sp_l, sp_r, speed, yaw, t_l, t_r, s_l, s_r, sinkage, margin, i_l, i_r,
            float(left.electrical_power_W) + float(right.electrical_power_W),
            traction or pivot or current, clamped_sp or off_grid, reason, (left, right),
        )  # fmt: skip

    def _direct_many(self, deferred: Sequence[_Deferred]) -> list[SetpointQuery]:
        """The set-point solve of the commands in exact cells (module doc) in one batch, with the
        powertrain of :meth:`query` (the direct path's formulas)."""
        if not deferred:
            return []
        sol = self._solve_deferred(deferred)
        out = []
        for k, item in enumerate(deferred):
            (sp_l, sp_r), clamp = item.setpoints, item.clamped
            t_l, i_l, left, over_l = self._side('left', float(sol.torque[k, 0]), sp_l)
            t_r, i_r, right, over_r = self._side('right', float(sol.torque[k, 1]), sp_r)
            current = over_l or over_r
            reason = sol.reason[k] or (REASON_CURRENT if current else '')
            query = SetpointQuery(
                sp_l, sp_r, float(sol.speed[k]), float(sol.yaw_rate[k]), t_l, t_r,
                float(sol.slip[k, 0]), float(sol.slip[k, 1]), float(sol.sinkage[k]),
                float(sol.traction_margin[k]), i_l, i_r,
                float(left.electrical_power_W) + float(right.electrical_power_W),
                bool(sol.limited[k]) or current, clamp, reason, (left, right),
            )  # fmt: skip
            out.append(query)
        return out

    def _solve_deferred(self, deferred: Sequence[_Deferred]) -> SetpointSolution:
        """The direct solve of every deferred command. In a cell with a corner the pivot law
        solved, the pivot law at once, warm-started from the interpolated state: where the direct
        solve falls back to it that is its answer, elsewhere it equals eq. 6.6's chord
        (:meth:`SetpointSolver.path_solver`), and it skips the chord's failing Newton and
        continuation (5x faster cold, about 50x warm on husky_a200 x sand_bin). A command it
        leaves limited gets the direct solve's own answer."""
        solver = self.predictor.solver
        setpoints = np.array([item.setpoints for item in deferred], dtype=float)
        sol = solver.solve(setpoints) if not any(item.warm for item in deferred) else None
        if sol is not None:
            return sol
        path = np.array([item.warm is not None for item in deferred])
        warm = np.array([item.warm or (math.nan,) * 3 for item in deferred], dtype=float)
        sol = solver.path_solver().solve(setpoints, x0=warm)
        redo = ~path | sol.limited
        if np.any(redo):
            sol.replace_rows(np.flatnonzero(redo), solver.solve(setpoints[redo]))
        return sol

    def _setpoints(self, v: float, w: float) -> tuple[tuple[float, float], bool]:
        """The drive controller's set points (in floats, :meth:`DriveController.apply_one`)."""
        pred = self.predictor
        left, right, clamped = pred.controller.apply_one(v, w, ceiling_rad_s=pred.max_axle_rad_s)
        return (left, right), clamped

    def _side(self, side: str, torque: float, omega: float) -> tuple[float, float, MotorPoint[float], bool]:
        """(torque [N m], current [A], motor point (:class:`MotorPoint`), over the limit) of one side
        under the current limit (:func:`~skidsteer_power.drive.current.current_limited`, the direct
        path's formula, in floats)."""
        held, current, point, over = current_limited(
            self.predictor.powertrain, side, torque, omega, self._limit
        )
        return float(held), float(current), point, bool(over)


@dataclass(frozen=True)
class _Deferred:
    """A command in an exact cell: its set points [rad/s], whether they were clamped, and in a
    cell the pivot law solved the interpolated state (s0 [m], V [m/s], w_z [rad/s]) to start from."""

    setpoints: tuple[float, float]
    clamped: bool
    warm: tuple[float, float, float] | None


def envelope(predictor: CommandPredictor) -> tuple[float, float]:
    """The largest set point mean and half difference [rad/s] the map covers: those of the vehicle
    file's drive controller at its velocity limits (V_max / r, w_max B / 2 / r), at most its ceiling
    (a predictor given another controller queries the same map)."""
    ctrl = controller_for_vehicle(predictor.vehicle, predictor.powertrain)
    r = min(ctrl.radii_m)
    top = ctrl.ceiling_for(predictor.max_axle_rad_s)
    half_separation = 0.5 * ctrl.separation_m
    return min(ctrl.max_speed_m_s / r, top), min(ctrl.max_yaw_rate_rad_s * half_separation / r, top)


def _corner_any(nodes: np.ndarray) -> np.ndarray:
    """(n - 1, m - 1) cells with any of their four corner nodes True."""
    cells: np.ndarray = nodes[:-1, :-1] | nodes[1:, :-1] | nodes[:-1, 1:] | nodes[1:, 1:]
    return cells


def _mixed(nodes: np.ndarray) -> np.ndarray:
    """(n - 1, m - 1) cells whose four corner nodes are not all alike."""
    every = nodes[:-1, :-1] & nodes[1:, :-1] & nodes[:-1, 1:] & nodes[1:, 1:]
    cells: np.ndarray = _corner_any(nodes) & ~every
    return cells


def cache_path(
    vehicle: Vehicle,
    terrain: Terrain,
    nodes: tuple[int, int] = DEFAULT_NODES,
    cache_dir: str | os.PathLike[str] | None = None,
) -> Path:
    """Where :func:`load_or_build` keeps the set-point map: the name holds the vehicle and terrain
    fingerprints, the physics-code digest and the node counts (everything that changes the nodes)."""
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    parts = (
        f'{vehicle.name}-{vehicle_fingerprint(vehicle)}',
        f'{terrain.name}-{terrain_fingerprint(terrain)}',
        physics_digest(),
        f'{nodes[0]}x{nodes[1]}',
    )
    return folder / ('setpoint_' + '_'.join(parts) + '.npz')


def load_or_build(
    vehicle: Vehicle,
    terrain: Terrain,
    nodes: tuple[int, int] = DEFAULT_NODES,
    cache_dir: str | os.PathLike[str] | None = None,
    controller: DriveController | None = None,
) -> tuple[SetpointMap, bool]:
    """The cached set-point map of ``vehicle`` on ``terrain``, built and saved if missing,
    unreadable or stored for another vehicle, terrain or physics code (its identity, as a power
    map's: :mod:`skidsteer_power.maps.identity`). Returns (map, built). ``controller``: the drive
    controller its queries make set points with (default: the vehicle file's; e.g. the des_driver's
    own limits); the nodes and the cache are the vehicle's either way."""
    path = cache_path(vehicle, terrain, nodes, cache_dir)
    predictor = CommandPredictor(vehicle, terrain, controller=controller)
    if path.exists():
        try:
            with np.load(path, allow_pickle=False) as data:
                check_identity(path, json.loads(str(data['meta'])), vehicle, terrain)
                mean, diff, values, checked = data['mean'], data['diff'], data['values'], data['checked']
            top = envelope(predictor)
            if values.shape == (len(mean), len(diff), len(FIELDS)) and (mean[-1], diff[-1]) == top:
                return SetpointMap(predictor, mean, diff, values, checked), False
        except (OSError, ValueError, KeyError, TypeError, InputError, MapMismatchError):
            pass  # damaged, stale or another map: rebuild below, never use it
    built = SetpointMap.build(vehicle, terrain, nodes, predictor)  # missing, damaged or another envelope
    with atomic_file(path) as handle:
        np.savez(
            handle,
            mean=built.grid.axis0.values,
            diff=built.grid.axis1.values,
            values=built.grid.values,
            checked=built.checked,
            meta=np.array(json.dumps(map_identity(vehicle, terrain, MAP_MODEL))),
        )
    return built, True
