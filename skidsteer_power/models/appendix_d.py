"""The real robot's turning circles (dissertation Appendix D) against the set-point prediction.

Appendix D, "Trace of the Test Robot and the Curve Fitted Circle" (dissertation text from line
2090), fits a circle (eqs. 7.8-7.10) to each trace of the chapter 7 test robot driving a constant
command on the sand bin and prints its radius and average forward speed. The 14 turning cells that
survive in the text are :data:`skidsteer_power.real_robot.APPENDIX_D_RADII` (the project's one copy).

One FESS parameter is fitted to these radii: the test robot track's longitudinal shear ratio K_x / K
(``track_longitudinal_shear_ratio`` in ``config/vehicles/test_robot_track.yaml``), to the track's
seven 0.1 m/s cells only (:data:`~skidsteer_power.real_robot.TRACK_FIT_CELLS`,
:func:`fit_track_shear_ratio`); the other seven cells are the check. ``python -m
tools.appendix_d [fit]`` prints the table (and the fit's sweep); the models take no command line.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from skidsteer_power.models.predict import CommandPredictor
from skidsteer_power.real_robot import APPENDIX_D_RADII, TRACK_FIT_CELLS, AppendixDCell
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import Vehicle, load_vehicle

FIT_CANDIDATES = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
"""K_x / K tried by :func:`fit_track_shear_ratio` [-] (1: Wong's inextensible belt); the twin's
sweep (docs/TWIN.md) tried the same values on its own contact."""


@dataclass(frozen=True)
class Row:
    """A cell with the set-point prediction: predicted R [m] and V [m/s], whether it was limited."""

    cell: AppendixDCell
    radius_m: float
    speed_m_s: float
    limited: bool

    @property
    def error(self) -> float:
        """|R_pred / R_real - 1| [-]."""
        return abs(self.radius_m / self.cell.radius_m - 1.0)

    @property
    def commanded_error(self) -> float:
        """|R_cmd / R_real - 1| [-]: the naive prediction (the robot follows the command)."""
        return abs(self.cell.commanded_radius_m / self.cell.radius_m - 1.0)


def check(
    cells: tuple[AppendixDCell, ...] = APPENDIX_D_RADII,
    terrain: str = 'sand_bin',
    vehicles: dict[str, Vehicle] | None = None,
) -> list[Row]:
    """Predict every cell from its set points on ``terrain`` (one batched solve per vehicle);
    ``vehicles`` replaces shipped vehicles by name (the fit's candidates)."""
    ground = load_terrain(terrain)
    given = vehicles or {}
    rows: dict[AppendixDCell, Row] = {}
    for name in sorted({c.vehicle for c in cells}):
        mine = [c for c in cells if c.vehicle == name]
        vehicle = given[name] if name in given else load_vehicle(name)
        pred = CommandPredictor(vehicle, ground).predict(
            np.array([c.speed_cmd for c in mine]), np.array([c.yaw_cmd for c in mine])
        )
        for k, c in enumerate(mine):
            rows[c] = Row(c, float(pred.turn_radius[k]), float(pred.speed[k]), bool(pred.limited[k]))
    return [rows[c] for c in cells]


def summary(rows: list[Row]) -> dict[str, float]:
    """Median and max of |R_pred / R_real - 1| and of the commanded radius's error [-]."""
    err = np.array([r.error for r in rows])
    cmd = np.array([r.commanded_error for r in rows])
    return {
        'median_error': float(np.median(err)),
        'max_error': float(np.max(err)),
        'median_commanded_error': float(np.median(cmd)),
        'max_commanded_error': float(np.max(cmd)),
    }


def fit_track_shear_ratio(candidates: tuple[float, ...] = FIT_CANDIDATES) -> list[tuple[float, float, float]]:
    """(K_x / K, median, max of |R_pred / R_real - 1| over the track's seven 0.1 m/s cells) per
    candidate; the shipped value is the candidate with the smallest median."""
    track = load_vehicle('test_robot_track')
    out = []
    for ratio in candidates:
        trial = dataclasses.replace(
            track, gear=dataclasses.replace(track.tracks(), track_longitudinal_shear_ratio=ratio)
        )
        result = summary(check(TRACK_FIT_CELLS, vehicles={track.name: trial}))
        out.append((ratio, result['median_error'], result['max_error']))
    return out
