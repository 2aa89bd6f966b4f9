"""Terramechanics benchmark: a 201-point single-wheel slip sweep (goal < 50 ms), plus reference
figures: the same forces by scipy.integrate.quad in a Python loop, and one 2-unknown wheel solve.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad

from benchmarks.harness import Report, best_time
from skidsteer_power.terramechanics import PRESETS, Terrain
from skidsteer_power.terramechanics.soil import shear_stress
from skidsteer_power.terramechanics.track import single_track
from skidsteer_power.terramechanics.wheel import (
    normal_stress,
    shear_displacement,
    solve_wheel,
    wheel_angles,
    wheel_at_slip,
    wheel_forces,
)

R, B, W = 0.1, 0.07, 100.0  # wheel of Figure 2.13


def _quad_forces(terrain: Terrain, z: float, s: float) -> tuple[float, float]:
    tf, tm, tr = (float(a) for a in wheel_angles(terrain, z, s, R))

    def sigma(th: float) -> float:
        return float(normal_stress(terrain, th, tf, tm, tr, R, B))

    def tau(th: float) -> float:
        return float(shear_stress(terrain, sigma(th), shear_displacement(th, tf, s, R)))

    fx = quad(lambda th: -sigma(th) * math.sin(th) + tau(th) * math.cos(th), tr, tf, points=[tm])[0]
    fz = quad(lambda th: sigma(th) * math.cos(th) + tau(th) * math.sin(th), tr, tf, points=[tm])[0]
    return R * B * fx, R * B * fz


def run(report: Report) -> None:
    terrain = PRESETS['dry_sand']
    slips = np.linspace(-1.0, 1.0, 201)
    sweep = best_time(lambda: wheel_at_slip(terrain, W, slips, R, B), repeat=7)
    report.figure(
        'wheel slip sweep, 201 points, with vertical balance (dry sand)',
        sweep * 1e3,
        'ms',
        goal='< 50 ms',
        met=sweep < 0.050,
    )
    state = wheel_at_slip(terrain, W, slips, R, B)
    report.figure(
        '  worst |Fz - W| of that sweep',
        np.abs(state.Fz_N - W).max(),
        'N',
        goal='< 1e-3 N',
        met=bool(np.abs(state.Fz_N - W).max() < 1e-3),
    )

    z = state.sinkage_m
    forces = best_time(lambda: wheel_forces(terrain, z, slips, R, B), repeat=7)
    report.figure('wheel forces only (Gauss-Legendre), 201 points', forces * 1e3, 'ms')
    picks = np.arange(0, 201, 20)
    looped = best_time(lambda: [_quad_forces(terrain, float(z[i]), float(slips[i])) for i in picks], repeat=2)
    per_point_quad = looped / picks.size
    report.figure('wheel forces by scipy quad loop, per point', per_point_quad * 1e3, 'ms')
    report.ratio('quad loop / vectorized quadrature (201 points)', per_point_quad * 201, forces)

    one = best_time(lambda: solve_wheel(terrain, W, 5.0, R, B), repeat=5)
    report.figure('solve_wheel (z, s) for W = 100 N, F_d = 5 N (hybr)', one * 1e3, 'ms')

    loads = np.linspace(10.0, 1000.0, 10_000)
    track = best_time(lambda: single_track(terrain, loads, 0.07, 0.7, 0.2), repeat=7)
    report.figure('single track, 10000 operating points (closed form 2.17)', track * 1e3, 'ms')
