"""The real robot's turning circles (dissertation Appendix D) against the set-point prediction.

Appendix D, "Trace of the Test Robot and the Curve Fitted Circle" (dissertation text from line
2090), fits a circle (eqs. 7.8-7.10) to each trace of the chapter 7 test robot driving a constant
command on the sand bin and prints its radius and average forward speed. Fourteen turning cells
survive in the text (the straight runs drifted on 59.06 m and 43.46 m circles and are left out):
the track at 0.1 m/s (seven yaw rates) and 0.2 m/s (two), and the six-wheel robot at 0.2 m/s, whose
five printed circles are the last five of its section and so belong to its five highest yaw rates
(issue 25). The commanded yaw rates are those of Figure 7.38's runs.

This is truth the predictor does not contain: nothing here is fitted to these radii.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skidsteer_power.models.predict import CommandPredictor
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle


@dataclass(frozen=True)
class Cell:
    """One Appendix D run: vehicle, command (V [m/s], yaw rate [rad/s]), measured R [m] and V [m/s]."""

    vehicle: str
    speed_cmd: float
    yaw_cmd: float
    radius_m: float
    speed_m_s: float

    @property
    def commanded_radius_m(self) -> float:
        return self.speed_cmd / self.yaw_cmd


CELLS = (
    # track, 0.1 m/s (Appendix D, text lines 2174-2216)
    Cell('test_robot_track', 0.1, 0.01, 19.44, 0.10),
    Cell('test_robot_track', 0.1, 0.02, 7.40, 0.10),
    Cell('test_robot_track', 0.1, 0.04, 3.64, 0.10),
    Cell('test_robot_track', 0.1, 0.08, 1.83, 0.10),
    Cell('test_robot_track', 0.1, 0.10, 1.44, 0.10),
    Cell('test_robot_track', 0.1, 0.15, 1.00, 0.09),
    Cell('test_robot_track', 0.1, 0.20, 0.84, 0.08),
    # track, 0.2 m/s (lines 2239-2246)
    Cell('test_robot_track', 0.2, 0.01, 33.49, 0.20),
    Cell('test_robot_track', 0.2, 0.02, 17.48, 0.20),
    # six wheels, 0.2 m/s (lines 2131-2158)
    Cell('test_robot_6wheel', 0.2, 0.15, 2.45, 0.20),
    Cell('test_robot_6wheel', 0.2, 0.20, 1.92, 0.19),
    Cell('test_robot_6wheel', 0.2, 0.25, 1.62, 0.18),
    Cell('test_robot_6wheel', 0.2, 0.30, 1.44, 0.17),
    Cell('test_robot_6wheel', 0.2, 0.35, 1.26, 0.17),
)


@dataclass(frozen=True)
class Row:
    """A cell with the set-point prediction: predicted R [m] and V [m/s], whether it was limited."""

    cell: Cell
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


def check(cells: tuple[Cell, ...] = CELLS, terrain: str = 'sand_bin') -> list[Row]:
    """Predict every cell from its set points on ``terrain`` (one batched solve per vehicle)."""
    ground = load_terrain(terrain)
    rows: dict[Cell, Row] = {}
    for name in sorted({c.vehicle for c in cells}):
        mine = [c for c in cells if c.vehicle == name]
        pred = CommandPredictor(load_vehicle(name), ground).predict(
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
