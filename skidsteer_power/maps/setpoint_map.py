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
changes too abruptly for bilinear interpolation the map does not interpolate the grid. Those cells are
the ones with a dug-in corner or whose corners disagree on the pivot test (the limited boundary:
interpolating across it would flag or unflag commands the direct solve does not), with a corner the
slip-path fallback solved (the pivot band on soil), and, found at build time, the cells near the
pivot band (a corner's inner / outer set point ratio within +-:data:`BAND_RATIO`, where the motion
turns steeply with the inner set point; on rigid ground every cell: Coulomb friction has a kink where
the wheels begin to skid sideways, near straight driving, where the Husky's map was 16.7 % off on
asphalt) whose centre, solved directly, is off the interpolated answer by more than
:data:`CHECK_POWER` in battery power or :data:`CHECK_SPEED_M_S` in speed (half the goals of 1 % and
5 mm/s: for a smooth solution bilinear interpolation errs most at the centre).

Every exact cell is then refined at build: a :data:`REFINE` x :data:`REFINE` sub-grid over it is
solved (as a query there would be, below) and every sub-cell checked at its centre the same way.
A sub-cell is interpolated in its sub-grid unless it has a dug-in corner (or one the pivot law,
started from the interpolated state, leaves without a steady state), corners that disagree on
the pivot test, or misses the check; inside the pivot band and at its edge it is interpolated without
the pivot test (the pivot law equals eq. 6.6's chord up to half a revolution of an element, so the
answer is continuous across the edge and the direct solve flags nothing there). Only a command in an
exact sub-cell is solved directly at query time (:meth:`SetpointMap.query` then costs one set-point
solve, milliseconds: the estimator at 1 kHz, benchmarks/bench_estimator.py). On test_robot_track x
dry_sand refinement took the share of 5,000 random-walk commands (V 0...0.4 m/s, w_z +-0.6 rad/s)
solved at query time from 34 % to 13 %, the mean query from 1.3 ms to 0.42 ms, the area answered
by the direct solve from 18.6 % to 4.4 % and the build from 0.5 s to 1.5 s (husky_a200, leo_rover,
packbot_4wheel x sand_bin: 2-3 s -> 6.5-8 s; benchmarks/bench_maps.py).

A directly solved command starts from the cell's interpolated state (s0, V, w_z). A spin in place
(mean 0) is solved like the direct path and symmetric as it is. A command in a cell with a corner
the pivot law solved (the direct solve's fallback) is solved with the pivot law at once
(:meth:`SetpointMap.solve_at`): the law equals eq. 6.6's chord wherever no element turns past half a
revolution, so this is the direct solve's root within its stopping rule, without the chord's failing
Newton and continuation first (husky_a200 x sand_bin: 14.5 s -> 1.75 s for 406 such commands; largest
difference to the direct solve over 1,500 random commands on five vehicle x soil pairs 0.17 % in
battery power and 0.48 mm/s in speed, no flag different).
"""

from __future__ import annotations

import itertools
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
MAX_REFINE = 8  # sub-cells per side of an exact cell, at most
BAND_RATIO = 0.4  # cells with a corner's inner / outer set point within +-this are checked (module doc)
CHECK_POWER = 0.005  # a checked cell whose centre is off by more (relative battery power) is exact
CHECK_SPEED_M_S = 0.0025  # ... or by more in speed [m/s]
REFINE = 4  # an exact cell is subdivided into REFINE x REFINE sub-cells at build (module doc)


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
        refined: Refinements | None = None,
    ) -> None:
        """``checked`` (n_mean - 1, n_diff - 1) bool: cells the build-time check found off (module
        doc); with those with a dug-in corner, a mixed pivot test or a corner the pivot law solved
        they are exact. ``refined``: the sub-grids of exact cells (:class:`Refinements`); an exact
        cell without one is answered by the direct solve everywhere."""
        self.predictor = predictor
        self.grid = BilinearGrid(
            Axis(mean, 'set point mean'), Axis(diff, 'set point half difference'), values
        )
        self._radius = float(predictor.vehicle.drive_radius_m)
        # element_turn_rev's test in floats: |w_z| xi / v_rim > limit [rev] times 2 pi [rad]
        self._turn_limit = ELEMENT_TURN_LIMIT_REV * 2.0 * math.pi
        # the element-turn (pivot) test belongs to eq. 6.6's chord: not on rigid ground
        self._pivot_test = not predictor.solver.fess.path_law
        self._limit = predictor.current_limit_A
        self.cells = _CellFlags.top(self, self.grid, checked)
        self.checked = self.cells.checked
        self.exact = self.cells.exact
        self.refined = refined if refined is not None else Refinements.empty(len(FIELDS))
        self._sub = self.refined.grids(self)

    def node_flags(self, grid: BilinearGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dug in, pivot test fails, pivot law solved) at every node of ``grid`` (this map's or a
        sub-grid's): the direct solve's flags (:func:`element_turn_rev`'s test on the chord)."""
        m, d = np.meshgrid(grid.axis0.values, grid.axis1.values, indexing='ij')
        inner_rim = np.abs(m - d) * self._radius
        dug = np.asarray(grid.values[..., FIELDS.index('dug_in')] > 0)
        path = np.asarray(grid.values[..., FIELDS.index('shear_path')] > 0)
        yaw = grid.values[..., FIELDS.index('yaw_rate')]
        contact = grid.values[..., FIELDS.index('contact_length')]
        turn = element_turn_rev(yaw, contact, inner_rim)
        pivot = (turn > ELEMENT_TURN_LIMIT_REV) & ~dug & ~path & self._pivot_test
        return dug, np.asarray(pivot), path

    def _dug_in(self) -> np.ndarray:
        return self.node_flags(self.grid)[0]

    @property
    def exact_fraction(self) -> float:
        """Share of the map's area answered by the direct solve [-] (module doc): the exact cells,
        of a refined one its exact sub-cells."""
        share = self.exact.astype(float).ravel()
        for cell, sub in self._sub.items():
            share[cell] = float(np.mean(sub.flags.exact))
        return float(np.mean(share))

    @classmethod
    def build(
        cls,
        vehicle: Vehicle,
        terrain: Terrain,
        nodes: tuple[int, int] = DEFAULT_NODES,
        predictor: CommandPredictor | None = None,
        refine: int = REFINE,
    ) -> SetpointMap:
        """Solve every node in one batched set-point solve (nodes = (mean, difference) counts, each
        >= 2, at most MAX_NODES in all), check the cells near the pivot band, then subdivide every
        exact cell ``refine`` x ``refine`` (1: none; at most MAX_REFINE) and check its sub-cells
        (module doc)."""
        n_mean, n_diff = (int(n) for n in nodes)
        if min(n_mean, n_diff) < 2 or n_mean * n_diff > MAX_NODES:
            raise InputError(
                f'set-point map nodes must be >= 2 each and at most {MAX_NODES:,} in all: {nodes}'
            )
        if not 1 <= int(refine) <= MAX_REFINE:
            raise InputError(f'set-point map refine must be 1...{MAX_REFINE}, not {refine}')
        predictor = predictor or CommandPredictor(vehicle, terrain)
        mean_top, diff_top = envelope(predictor)
        mean = np.linspace(0.0, mean_top, n_mean)
        diff = np.linspace(0.0, diff_top, n_diff)
        unchecked = cls(predictor, mean, diff, solve_nodes(predictor, mean, diff))
        top = cls(predictor, mean, diff, unchecked.grid.values, unchecked.check_cells())
        return cls(predictor, mean, diff, top.grid.values, top.checked, top.refine(int(refine)))

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
        return self.off_at_centres([self.grid], [band])[0]

    def off_at_centres(
        self,
        grids: Sequence[BilinearGrid],
        candidates: Sequence[np.ndarray],
        paths: Sequence[np.ndarray] | None = None,
    ) -> list[np.ndarray]:
        """(cells of each grid) True where a ``candidates`` cell's centre, solved directly, is
        limited or off its bilinear answer by more than CHECK_POWER or CHECK_SPEED_M_S; every
        grid's centres in one batched solve. Solved cold (the direct solve), or with ``paths``
        (cells of sub-grids) as a query in that cell would be, were it exact (:meth:`solve_at`)."""
        picks = [np.argwhere(c) for c in candidates]
        out = [np.zeros(c.shape, dtype=bool) for c in candidates]
        if not any(len(cells) for cells in picks):
            return out
        centres = [_centres(grid, cells) for grid, cells in zip(grids, picks, strict=True)]
        mc = np.concatenate([c[0] for c in centres])
        dc = np.concatenate([c[1] for c in centres])
        interpolated = np.concatenate([c[2] for c in centres])
        sp = np.column_stack([mc - dc, mc + dc])
        if paths is None:
            sol = self.predictor.solver.solve(sp)
        else:
            warm = np.concatenate([self._warm(g, c[0], c[1]) for g, c in zip(grids, centres, strict=True)])
            path = np.concatenate([p[c[:, 0], c[:, 1]] for p, c in zip(paths, picks, strict=True)])
            sol = self.solve_at(sp, warm, path)
        _, _, p_direct, _ = self.predictor.electrical(sol.torque, sp)
        torque = interpolated[:, [FIELDS.index('torque_left'), FIELDS.index('torque_right')]]
        _, _, p_map, _ = self.predictor.electrical(torque, sp)
        p_err = np.abs(p_map - p_direct) / np.maximum(np.abs(p_direct), 1.0)
        v_err = np.abs(interpolated[:, FIELDS.index('speed')] - sol.speed)
        off = sol.limited | (p_err > CHECK_POWER) | (v_err > CHECK_SPEED_M_S)
        split = np.cumsum([len(cells) for cells in picks])[:-1]
        for mask, cells, cell_off in zip(out, picks, np.split(off, split), strict=True):
            mask[cells[cell_off, 0], cells[cell_off, 1]] = True
        return out

    def refine(self, factor: int) -> Refinements:
        """The sub-grids of every exact cell, ``factor`` x ``factor`` sub-cells each, solved in one
        batch and checked at every sub-cell centre (module doc)."""
        cells = np.flatnonzero(self.exact.ravel()) if factor > 1 else np.zeros(0, dtype=int)
        if cells.size == 0:
            return Refinements.empty(len(FIELDS), factor)
        axes = [self._sub_axes(int(c), factor) for c in cells]
        shape = (cells.size, factor + 1, factor + 1, len(FIELDS))
        values = self._sub_node_values(cells, factor).reshape(shape)
        grids = [_sub_grid(sub_mean, sub_diff, values[k]) for k, (sub_mean, sub_diff) in enumerate(axes)]
        flags = [_CellFlags.sub(self, grid, None) for grid in grids]
        checked = self.off_at_centres(grids, [~f.exact for f in flags], [f.path_any for f in flags])
        return Refinements(cells, values, np.array(checked, dtype=bool))

    def _sub_node_values(self, cells: np.ndarray, factor: int) -> np.ndarray:
        """(R (factor + 1)^2, F) the :data:`FIELDS` at every sub-grid node of ``cells`` (R,), in
        sub-grid order. A node is solved once however many refined cells share it, and a node of the
        map's own grid is its value there; a node is solved with the pivot law at once only where
        every cell around it has a corner the pivot law solved (:meth:`solve_at`), else directly."""
        k, n1 = factor, len(self.grid.axis1.values) - 1
        ci, cj = np.divmod(cells, n1)
        a, b = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing='ij')
        gi, gj = (ci[:, None, None] * k + a).ravel(), (cj[:, None, None] * k + b).ravel()  # fine lattice
        stride = n1 * k + 1
        unique, inverse = np.unique(gi * stride + gj, return_inverse=True)
        ui, uj = np.divmod(unique, stride)
        owner_band = np.repeat(self.cells.path_any.ravel()[cells], (k + 1) ** 2)
        band = np.ones(unique.size, dtype=bool)
        np.logical_and.at(band, inverse, owner_band)
        fine_mean = _fine_axis(self.grid.axis0.values, k)
        fine_diff = _fine_axis(self.grid.axis1.values, k)
        m, d = fine_mean[ui], fine_diff[uj]
        out = np.empty((unique.size, len(FIELDS)))
        on_map = (ui % k == 0) & (uj % k == 0)
        out[on_map] = self.grid.values[ui[on_map] // k, uj[on_map] // k]
        rest = ~on_map
        sp = np.column_stack([m[rest] - d[rest], m[rest] + d[rest]])
        warm = self._warm(self.grid, m[rest], d[rest])
        out[rest] = _solution_values(self.solve_at(sp, warm, band[rest], redo=False))
        return out[inverse]

    def _warm(self, grid: BilinearGrid, m: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(P, 3) the interpolated (s0 [m], V [m/s], w_z [rad/s]) of ``grid`` at set point mean and
        half difference (m, d) >= 0 [rad/s] (:meth:`solve_at`'s warm start)."""
        vals: np.ndarray = grid(m, d)[0]
        return vals[:, [FIELDS.index('s0'), FIELDS.index('speed'), FIELDS.index('yaw_rate')]]

    def _sub_axes(self, cell: int, factor: int) -> tuple[np.ndarray, np.ndarray]:
        """The (mean, difference) node values [rad/s] of one top cell's sub-grid."""
        i, j = divmod(cell, len(self.grid.axis1.values) - 1)
        mean, diff = self.grid.axis0.values, self.grid.axis1.values
        return np.linspace(mean[i], mean[i + 1], factor + 1), np.linspace(diff[j], diff[j + 1], factor + 1)

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
        flags = self.cells
        if flags.exact_list[cell] and cell in self._sub:  # a refined exact cell: its sub-grid
            sub = self._sub[cell]
            vals, _, cell = sub.grid.scalar(mean, abs(diff))
            flags = sub.flags
        speed, yaw, t_l, t_r, s_l, s_r, sinkage, margin, _, contact, _, s0 = vals
        if flags.exact_list[cell]:
            warm = (flip * s0, flip * speed, flip * (-yaw if right_turn else yaw))  # mirrored back
            return _Deferred((sp_l, sp_r), clamped_sp or off_grid, warm, flags.path_any_list[cell])
        inner_rim = min(abs(sp_l), abs(sp_r)) * self._radius
        pivot = (
            self._pivot_test
            and not flags.no_pivot_list[cell]  # the pivot law's region: it has no such limit
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
        """The direct solve of every deferred command (:meth:`solve_at`)."""
        setpoints = np.array([item.setpoints for item in deferred], dtype=float)
        warm = np.array([item.warm for item in deferred], dtype=float)
        return self.solve_at(setpoints, warm, np.array([item.path for item in deferred]))

    def solve_at(
        self, setpoints: np.ndarray, warm: np.ndarray, path: np.ndarray, *, redo: bool = True
    ) -> SetpointSolution:
        """The direct solve of set points (P, 2) [rad/s], warm-started from the interpolated state
        ``warm`` (P, 3) (s0 [m], V [m/s], w_z [rad/s]). A ``path`` row (in a cell with a corner the
        pivot law solved) is solved with the pivot law at once: where the direct solve falls back
        to it that is its answer, elsewhere it equals eq. 6.6's chord (:meth:`SetpointSolver.
        path_solver`), and it skips the chord's failing Newton and continuation (5x faster cold,
        about 50x warm on husky_a200 x sand_bin). A row it leaves limited gets the direct solve's
        own answer, from the no-slip first guess; with ``redo=False`` (a sub-grid's nodes, module
        doc) it stays limited and is marked dug in, so the sub-cells around it are solved at query
        time instead (the direct solve's chord, continuation and fallback there cost seconds)."""
        solver = self.predictor.solver
        rows, chord = np.flatnonzero(path), np.flatnonzero(~path)
        if rows.size == 0:
            return solver.solve(setpoints, x0=warm)
        sol = solver.path_solver().solve(setpoints[rows], x0=warm[rows])
        failed = np.flatnonzero(sol.limited)  # these get the direct solve's own answer, cold
        if failed.size and redo:
            sol.replace_rows(failed, solver.solve(setpoints[rows[failed]]))
        elif failed.size:
            sol.dug_in[failed] = True
        if chord.size == 0:
            return sol
        out = sol.take(np.zeros(len(setpoints), dtype=int))  # (P,) rows, every one overwritten
        out.replace_rows(rows, sol)
        out.replace_rows(chord, solver.solve(setpoints[chord], x0=warm[chord]))
        return out

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
    warm: tuple[float, float, float]
    path: bool


@dataclass(frozen=True)
class _CellFlags:
    """Per cell of a grid (the map's or a sub-grid's, row-major): answered by the direct solve,
    found off by the build-time check, a corner the pivot law solved (an exact one is then solved
    with the pivot law at once), and interpolated without the pivot test (a sub-cell with such a
    corner, module doc). The lists are the arrays' values in plain Python for the query."""

    exact: np.ndarray
    checked: np.ndarray
    path_any: np.ndarray
    no_pivot: np.ndarray
    exact_list: list[bool]
    path_any_list: list[bool]
    no_pivot_list: list[bool]

    @classmethod
    def top(cls, smap: SetpointMap, grid: BilinearGrid, checked: np.ndarray | None) -> _CellFlags:
        """The map's own cells: a corner the pivot law solved makes a cell exact (module doc)."""
        dug, pivot, path = smap.node_flags(grid)
        checked = _checked(grid, checked)
        path_any = _corner_any(path) & smap._pivot_test
        exact = _corner_any(dug) | _mixed(pivot) | path_any | checked
        return cls._of(exact, checked, path_any, np.zeros_like(exact))

    @classmethod
    def sub(cls, smap: SetpointMap, grid: BilinearGrid, checked: np.ndarray | None) -> _CellFlags:
        """A sub-grid's cells: interpolated in and at the edge of the pivot law's region too (the
        law equals eq. 6.6's chord up to half a revolution of an element, so the answer is
        continuous across the edge, and the direct solve flags no pivot there), unless the check
        finds them off (module doc)."""
        dug, pivot, path = smap.node_flags(grid)
        checked = _checked(grid, checked)
        path_any = _corner_any(path) & smap._pivot_test
        exact = _corner_any(dug) | _mixed(pivot) | checked
        return cls._of(exact, checked, path_any, path_any)

    @classmethod
    def _of(
        cls, exact: np.ndarray, checked: np.ndarray, path_any: np.ndarray, no_pivot: np.ndarray
    ) -> _CellFlags:
        return cls(
            exact, checked, path_any, no_pivot,
            exact.ravel().tolist(), path_any.ravel().tolist(), no_pivot.ravel().tolist(),
        )  # fmt: skip


def _checked(grid: BilinearGrid, checked: np.ndarray | None) -> np.ndarray:
    """The check's cells of ``grid`` as bool (none given: none), or InputError on a shape mismatch."""
    shape = (len(grid.axis0.values) - 1, len(grid.axis1.values) - 1)
    out = np.zeros(shape, dtype=bool) if checked is None else np.asarray(checked, dtype=bool)
    if out.shape != shape:
        raise InputError(f'set-point map: checked cells {out.shape} do not match {shape}')
    return out


@dataclass(frozen=True)
class _SubGrid:
    """One refined exact cell: its bilinear grid over the cell and its sub-cells' flags."""

    grid: BilinearGrid
    flags: _CellFlags


@dataclass(frozen=True)
class Refinements:
    """The sub-grids of a map's exact cells (module doc), as stored: ``cells`` (R,) the map's cell
    numbers (row-major over (n_mean - 1, n_diff - 1)), ``values`` (R, k + 1, k + 1, F) the
    :data:`FIELDS` at each sub-grid's nodes, ``checked`` (R, k, k) the sub-cells the check found off."""

    cells: np.ndarray
    values: np.ndarray
    checked: np.ndarray

    @classmethod
    def empty(cls, n_fields: int, factor: int = REFINE) -> Refinements:
        """No refined cell."""
        k = max(int(factor), 1)
        values = np.zeros((0, k + 1, k + 1, n_fields))
        return cls(np.zeros(0, dtype=int), values, np.zeros((0, k, k), dtype=bool))

    def grids(self, smap: SetpointMap) -> dict[int, _SubGrid]:
        """{cell: sub-grid} of ``smap``, or InputError where these do not fit its grid."""
        r, n0, n1 = len(self.cells), self.values.shape[1], self.values.shape[2]
        if self.values.shape != (r, n0, n0, len(FIELDS)) or self.checked.shape != (r, n0 - 1, n0 - 1):
            raise InputError(f'set-point map: refinements {self.values.shape} do not fit the map')
        out = {}
        for k, cell in enumerate(int(c) for c in self.cells):
            if not 0 <= cell < smap.exact.size or not smap.exact.flat[cell]:
                raise InputError(f'set-point map: refined cell {cell} is not an exact cell')
            sub_mean, sub_diff = smap._sub_axes(cell, n1 - 1)
            grid = _sub_grid(sub_mean, sub_diff, self.values[k])
            out[cell] = _SubGrid(grid, _CellFlags.sub(smap, grid, self.checked[k]))
        return out


def _centres(grid: BilinearGrid, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean [rad/s], half difference [rad/s], bilinear fields) at the centres of ``cells`` (C, 2)
    (cell indices) of ``grid``: the average of each cell's four corners."""
    mean, diff, vals = grid.axis0.values, grid.axis1.values, grid.values
    i, j = cells[:, 0], cells[:, 1]
    centre = 0.25 * (vals[i, j] + vals[i + 1, j] + vals[i, j + 1] + vals[i + 1, j + 1])
    return 0.5 * (mean[i] + mean[i + 1]), 0.5 * (diff[j] + diff[j + 1]), centre


def _fine_axis(values: np.ndarray, factor: int) -> np.ndarray:
    """An axis's nodes [rad/s] with ``factor`` - 1 more evenly between each pair (the sub-grids'
    nodes, :meth:`SetpointMap._sub_axes`: the same linspace per cell)."""
    pieces = [np.linspace(lo, hi, factor + 1)[:-1] for lo, hi in itertools.pairwise(values)]
    return np.concatenate([*pieces, values[-1:]])


def _sub_grid(mean: np.ndarray, diff: np.ndarray, values: np.ndarray) -> BilinearGrid:
    """The bilinear grid over one exact cell (sub-grid node values [rad/s], fields)."""
    return BilinearGrid(Axis(mean, 'sub-cell mean'), Axis(diff, 'sub-cell half difference'), values)


def solve_nodes(predictor: CommandPredictor, mean: np.ndarray, diff: np.ndarray) -> np.ndarray:
    """(len(mean), len(diff), F) the :data:`FIELDS` at every node of a (mean, difference) grid
    [rad/s], in one batched set-point solve."""
    m, d = np.meshgrid(mean, diff, indexing='ij')
    return _node_values(predictor, m.ravel(), d.ravel()).reshape(len(mean), len(diff), len(FIELDS))


def _node_values(predictor: CommandPredictor, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, F) the :data:`FIELDS` at set points (mean ``m``, half difference ``d``) [rad/s]."""
    return _solution_values(predictor.solver.solve(np.column_stack([m - d, m + d])))


def _solution_values(sol: SetpointSolution) -> np.ndarray:
    """(N, F) the :data:`FIELDS` of a set-point solution."""
    columns = (
        sol.speed, sol.yaw_rate, sol.torque[:, 0], sol.torque[:, 1], sol.slip[:, 0], sol.slip[:, 1],
        sol.sinkage, sol.traction_margin, sol.dug_in.astype(float), sol.contact_length,
        np.asarray(sol.shear_path, dtype=float), sol.s0,
    )  # fmt: skip
    return np.stack(columns, axis=-1)


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
                refined = Refinements(data['refine_cells'], data['refine_values'], data['refine_checked'])
            top = envelope(predictor)
            if values.shape == (len(mean), len(diff), len(FIELDS)) and (mean[-1], diff[-1]) == top:
                return SetpointMap(predictor, mean, diff, values, checked, refined), False
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
            refine_cells=built.refined.cells,
            refine_values=built.refined.values,
            refine_checked=built.refined.checked,
            meta=np.array(json.dumps(map_identity(vehicle, terrain, MAP_MODEL))),
        )
    return built, True
