"""Reference skid-steering models of chapters 3 and 4: the text's 8 x 16 map, timed, with a
convergence study of the integration resolution.

The map: 8 speeds in 0.1-1.5 m/s and 16 log-spaced radii in 1-500 m. The text took 244.8 s with
Wong's track model (section 3.3.1) and 2777.2 s with the wheeled model (the issue's figure; section
4.2 reports 1362.2 s for a 5 x 16 map) on a 4.4 GHz i7. Goals here, one core: track < 20 s, wheels
< 120 s, at a resolution whose torques are within 0.5 % of a very fine reference.

Torque error of a point: |T - T_ref| / max(|T_ref_outer|, |T_ref_inner|), i.e. relative to the larger
side torque of that operating point (an inner torque crossing zero would make its own relative error
meaningless); the figure is the worst point of the map.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from benchmarks.harness import Report, best_time
from skidsteer_power.models import SteadyState, solve, wong_track, wong_wheel
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain
from skidsteer_power.vehicle import Vehicle, load_vehicle

Resolution = tuple[int, int]  # integration nodes of a model (see DEFAULT_RESOLUTION of each)

SPEEDS = np.linspace(0.1, 1.5, 8)[:, None]
RADII = np.logspace(0.0, np.log10(500.0), 16)[None, :]
GOAL_ERROR = 0.005

TRACK_STUDY = [(6, 1), (8, 2), (12, 2), (16, 2), (24, 3), (32, 4)]
TRACK_REFERENCE = (128, 12)
WHEEL_STUDY = [(4, 3), (6, 4), (8, 4), (12, 6), (16, 8)]
WHEEL_REFERENCE = (48, 24)
DEFAULT_RESOLUTION = {
    'wong track': wong_track.DEFAULT_RESOLUTION,
    'wong wheel': wong_wheel.DEFAULT_RESOLUTION,
}


def _torque_error(state: SteadyState, ref: SteadyState) -> float:
    scale = np.maximum(np.abs(ref.torque_outer_Nm), np.abs(ref.torque_inner_Nm))
    err_o = np.abs(state.torque_outer_Nm - ref.torque_outer_Nm) / scale
    err_i = np.abs(state.torque_inner_Nm - ref.torque_inner_Nm) / scale
    return float(np.max(np.maximum(err_o, err_i)))


def _study(
    report: Report,
    label: str,
    vehicle: Vehicle,
    terrain: Terrain,
    study: list[Resolution],
    reference: Resolution,
) -> Resolution:
    ref = solve(vehicle, terrain, SPEEDS, RADII, model='wong', resolution=reference)
    converged = f'{int(ref.converged.sum())}/{ref.converged.size}'
    print(f'   {label}: reference resolution {reference}, converged {converged}')
    errors = {}
    for resolution in study:
        state = solve(vehicle, terrain, SPEEDS, RADII, model='wong', resolution=resolution)
        errors[resolution] = _torque_error(state, ref)
        report.figure(f'{label} torque error at resolution {resolution}', 100 * errors[resolution], '%')
    chosen = next((r for r in study if errors[r] < GOAL_ERROR), None)
    report.figure(
        f'{label} coarsest resolution of the study within 0.5 %',
        np.nan if chosen is None else chosen[0],
        'n',
        note='none' if chosen is None else f'resolution {chosen}: {100 * errors[chosen]:.3f} %',
    )
    default = DEFAULT_RESOLUTION[label]
    state = solve(vehicle, terrain, SPEEDS, RADII, model='wong')  # the resolution every caller gets
    err = _torque_error(state, ref)
    report.figure(
        f'{label} default resolution {default}: torque error',
        100 * err,
        '%',
        goal='< 0.5 %',
        met=bool(err < GOAL_ERROR),
        note='the resolution models.solve uses when none is given',
    )
    return chosen or study[-1]


def _time_map(
    report: Report,
    label: str,
    vehicle: Vehicle,
    terrain: Terrain,
    resolution: Resolution,
    goal_s: float,
    text_s: float,
) -> None:
    start = time.perf_counter()
    state = solve(vehicle, terrain, SPEEDS, RADII, model='wong', resolution=resolution)
    first = time.perf_counter() - start
    best = min(
        first,
        best_time(
            lambda: solve(vehicle, terrain, SPEEDS, RADII, model='wong', resolution=resolution), repeat=3
        ),
    )
    report.figure(
        f'{label} 8x16 map at {resolution}',
        best,
        's',
        goal=f'< {goal_s:g} s',
        met=bool(best < goal_s),
        note=f'{int(state.converged.sum())}/{state.converged.size} converged, '
        f'max {int(state.extra["iterations"].max())} Newton steps',
    )
    report.ratio(f'{label} speed-up over the text ({text_s} s on a 4.4 GHz i7)', text_s, best)


def run(report: Report) -> None:
    sand = load_terrain('dry_sand')  # Table 3.3's soil values
    track, wheels = load_vehicle('chapter3_track'), load_vehicle('chapter4_4wheel')

    chosen = _study(report, 'wong track', track, sand, TRACK_STUDY, TRACK_REFERENCE)
    _time_map(report, 'wong track', track, sand, chosen, 20.0, 244.8)
    _time_map(
        report, 'wong track (default resolution)', track, sand, wong_track.DEFAULT_RESOLUTION, 20.0, 244.8
    )

    chosen = _study(report, 'wong wheel', wheels, sand, WHEEL_STUDY, WHEEL_REFERENCE)
    _time_map(report, 'wong wheel', wheels, sand, chosen, 120.0, 2777.2)
    _time_map(
        report, 'wong wheel (default resolution)', wheels, sand, wong_wheel.DEFAULT_RESOLUTION, 120.0, 2777.2
    )
    six = load_vehicle('test_robot_6wheel')
    _time_map(
        report,
        'wong wheel, 6 wheels (default resolution)',
        six,
        sand,
        wong_wheel.DEFAULT_RESOLUTION,
        120.0,
        2777.2,
    )

    for model in ('steeds', 'icr'):
        seconds = best_time(functools.partial(solve, track, sand, SPEEDS, RADII, model=model), repeat=3)
        report.figure(f'{model} track 8x16 map', seconds, 's')

    wong = solve(track, sand, SPEEDS, RADII, model='wong')
    icr = solve(track, sand, SPEEDS, RADII, model='icr')
    gap = np.abs(wong.extra['mu_t'] - icr.extra['mu_t']) / icr.extra['mu_t']
    report.figure(
        'mu_t (eq. 3.27) Wong vs ICR at V = 1.5 m/s, R = 1 m', 100 * gap[-1, 0], '%', note='closest point'
    )
    report.figure('mu_t Wong vs ICR, median over the 8x16 map', 100 * float(np.median(gap)), '%')
