"""The twin's motion against the real robot's (ch. 7.3.4): the turning radii of Appendix D and the
completed / stuck grid of Table 7.3 (``skidsteer_power.real_robot``), on the twin's sand_bin.

* radius: a hold of ``RADIUS_HOLD_S`` from rest; radius = mean speed / mean yaw rate of the true
  motion (what ``/ground_truth/odom`` records) after the start-up ``START_UP_S``;
* completed: a hold of ``GRID_HOLD_S`` from rest in which the twin never got stuck
  (:meth:`TwinTrace.stuck`: over a 2 s window, less than 20 % of the commanded motion).

``python -m skidsteer_power.twin.motion [radii|grid|fit] [--contact classic|extended]`` prints them;
``fit`` repeats the fit of ``track_contact.TRACK_LONGITUDINAL_MODULUS`` to :data:`FIT_CELLS`.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np

from skidsteer_power.commands import Segment
from skidsteer_power.real_robot import APPENDIX_D_RADII, TRACK_FIT_CELLS, AppendixDCell, table_7_3_cells
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin.model import Twin
from skidsteer_power.twin.sensors import run_commands
from skidsteer_power.vehicle import load_vehicle

TERRAIN = 'sand_bin'
"""The twin's floor for the chapter 7.3 comparisons (the sand bin the test robot drove on)."""
RADIUS_HOLD_S = 8.0
"""Hold of each radius cell [s]."""
START_UP_S = 3.0
"""Start-up left out of the radius [s]: set-point ramp, sinkage and shear settling."""
GRID_HOLD_S = 6.0
"""Hold of each Table 7.3 cell [s]."""
FIT_CELLS = TRACK_FIT_CELLS
"""The subset the track's longitudinal shear modulus is fitted to: the track's seven 0.1 m/s cells (the
other seven Appendix D cells and Table 7.3 are the check)."""
FIT_CANDIDATES = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
"""K_x / K tried by the fit [-] (1: Wong's isotropic shear, the belt inextensible)."""


@dataclass(frozen=True)
class RadiusCell:
    """One Appendix D cell with the twin's figures: radii [m], mean speed [m/s]."""

    vehicle: str
    speed_cmd: float
    yaw_rate_cmd: float
    radius_real: float
    radius_twin: float
    speed_twin: float

    @property
    def radius_cmd(self) -> float:
        return self.speed_cmd / self.yaw_rate_cmd

    @property
    def ratio_error(self) -> float:
        """R_twin / R_real - 1 [-]."""
        return self.radius_twin / self.radius_real - 1.0


def twin_turn(vehicle: str, speed: float, yaw_rate: float, contact: str = 'extended') -> tuple[float, float]:
    """(radius [m], mean speed [m/s]) of the twin holding (V [m/s], yaw rate [rad/s]) on sand_bin;
    the radius is inf if the mean yaw rate is not positive."""
    twin = Twin(load_vehicle(vehicle), load_terrain(TERRAIN), contact=contact)
    trace = run_commands(twin, [Segment(speed, yaw_rate, RADIUS_HOLD_S)])
    settled = trace.t >= START_UP_S
    mean_speed = float(np.hypot(trace.twist[settled, 0], trace.twist[settled, 1]).mean())
    mean_yaw = float(trace.twist[settled, 2].mean())
    return (mean_speed / mean_yaw if mean_yaw > 0 else math.inf), mean_speed


def twin_completes(vehicle: str, speed: float, yaw_rate: float, contact: str = 'extended') -> bool:
    """True if the twin holding (V [m/s], yaw rate [rad/s]) from rest on sand_bin never got stuck."""
    v = load_vehicle(vehicle)
    trace = run_commands(
        Twin(v, load_terrain(TERRAIN), contact=contact), [Segment(speed, yaw_rate, GRID_HOLD_S)]
    )
    return not trace.stuck(v.tread_m)


def radius_cells(
    contact: str = 'extended', cells: tuple[AppendixDCell, ...] = APPENDIX_D_RADII
) -> list[RadiusCell]:
    """The twin at the Appendix D cells (all 14 by default)."""
    out = []
    for c in cells:
        radius, mean_speed = twin_turn(c.vehicle, c.speed_cmd, c.yaw_cmd, contact)
        out.append(RadiusCell(c.vehicle, c.speed_cmd, c.yaw_cmd, c.radius_m, radius, mean_speed))
    return out


def radius_summary(cells: list[RadiusCell]) -> tuple[float, float]:
    """(median, max) of |R_twin / R_real - 1| [-]."""
    errors = np.abs([c.ratio_error for c in cells])
    return float(np.median(errors)), float(errors.max())


def grid_mismatches(
    contact: str = 'extended', cells: list[tuple[str, float, float, bool]] | None = None
) -> tuple[int, list[tuple[str, float, float, bool]]]:
    """(cells checked, cells where the twin disagrees with Table 7.3 as (vehicle, V, yaw rate, real
    completed)); all 66 cells by default."""
    cells = table_7_3_cells() if cells is None else cells
    wrong = [c for c in cells if twin_completes(c[0], c[1], c[2], contact) != c[3]]
    return len(cells), wrong


def fit_track_longitudinal_modulus(
    candidates: tuple[float, ...] = FIT_CANDIDATES,
) -> list[tuple[float, float, float]]:
    """(K_x / K, median, max of |R_twin / R_real - 1| over :data:`FIT_CELLS`) for each candidate
    (extended contact); the fit keeps the smallest median."""
    from unittest import mock

    from skidsteer_power.twin import track_contact

    out = []
    for value in candidates:
        with mock.patch.object(track_contact, 'TRACK_LONGITUDINAL_MODULUS', value):
            out.append((value, *radius_summary(radius_cells('extended', FIT_CELLS))))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m skidsteer_power.twin.motion')
    parser.add_argument('what', nargs='*', choices=('radii', 'grid', 'fit'), default=['radii', 'grid'])
    parser.add_argument('--contact', choices=('classic', 'extended'), default='extended')
    args = parser.parse_args(argv)
    if 'radii' in args.what:
        cells = radius_cells(args.contact)
        print('vehicle | V cmd | yaw cmd | R cmd | R real | R twin | V twin | R twin / R real - 1')
        for c in cells:
            radii = f'{c.radius_cmd:.2f} | {c.radius_real:.2f} | {c.radius_twin:.2f}'
            print(f'{c.vehicle} | {c.speed_cmd:g} | {c.yaw_rate_cmd:g} | {radii} | {c.speed_twin:.3f} | '
                  f'{100 * c.ratio_error:+.0f} %', flush=True)  # fmt: skip
        median, worst = radius_summary(cells)
        print(f'median |R_twin / R_real - 1| {100 * median:.1f} %, max {100 * worst:.1f} %')
    if 'fit' in args.what:
        for value, median, worst in fit_track_longitudinal_modulus():
            print(f'K_x / K = {value:g}: median {100 * median:.1f} %, max {100 * worst:.1f} %', flush=True)
    if 'grid' in args.what:
        n, wrong = grid_mismatches(args.contact)
        print(f'Table 7.3: {n - len(wrong)} of {n} cells agree; disagree: {wrong}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
