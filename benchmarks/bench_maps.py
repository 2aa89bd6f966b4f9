"""Look-up map benchmark (issue 5): build time, one query from Python (goal < 20 us), vectorized
queries per second (goal >= 1e6), the hand-written bilinear kernel against scipy's
RegularGridInterpolator on the same table, and the off-grid accuracy against direct FESS.
"""

from __future__ import annotations

import functools
import time
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from benchmarks.harness import Report, best_time
from skidsteer_power.maps import PowerMap
from skidsteer_power.maps.power_map import DEFAULT_SHAPE
from skidsteer_power.models import fess
from skidsteer_power.terramechanics.terrain import PRESETS
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

N_VECTOR = 1_000_000


class AccuracyRow(TypedDict):
    """One vehicle x terrain row of :func:`accuracy_table` (percentages of the larger side's value)."""

    vehicle: str
    terrain: str
    build_s: float
    flagged_pct: float
    check_pct: float
    torque_pct: float
    speed_pct: float
    power_pct: float
    power_p99_pct: float
    unsolved: int
    worst: tuple[float, float]  # the command (V [m/s], yaw rate [rad/s]) of the largest power error


def _build(report: Report) -> PowerMap:
    dry = PRESETS['dry_sand']
    maps = {}
    for name in ('chapter3_track', 'test_robot_track', 'chapter4_4wheel', 'test_robot_6wheel'):
        vehicle = load_vehicle(name)
        if not vehicle.is_tracked:
            PowerMap.build(vehicle, dry, shape=(2, 3))  # single-wheel table (cached per process)
        start = time.perf_counter()
        maps[name] = PowerMap.build(vehicle, dry)
        elapsed = time.perf_counter() - start
        m = maps[name]
        report.figure(
            f'build default {DEFAULT_SHAPE[0]}x{DEFAULT_SHAPE[1]} map, {name}, dry sand',
            elapsed,
            's',
            note=(
                f'{int(m.converged.sum())}/{m.converged.size} converged, {int(m.limited.sum())} limited, '
                f'{m.meta["inaccurate_cells"]}/{m.meta["checked_cells"]} checked cells flagged'
            ),
        )
    return maps['chapter3_track']


def _queries(report: Report, m: PowerMap) -> None:
    rng = np.random.default_rng(0)
    v = rng.uniform(-1.5, 1.5, N_VECTOR)
    w = rng.uniform(-2.0, 2.0, N_VECTOR)
    one = best_time(lambda: m.query(0.43, -0.71), repeat=7, number=2000)
    report.figure(
        'one query from Python (hand-written kernel)', one * 1e6, 'us', goal='< 20 us', met=one < 20e-6
    )
    vec = best_time(lambda: m.query(v, w), repeat=3)
    report.figure('vectorized queries', N_VECTOR / vec, '1/s', goal='>= 1e6 /s', met=N_VECTOR / vec >= 1e6)
    # kernels alone, same table, same grid coordinates: hand-written bilinear vs scipy
    grid = m._grid
    a = rng.uniform(0.0, float(m.radial[-1]), N_VECTOR)
    u = rng.uniform(-1.0, 1.0, N_VECTOR)
    rgi = RegularGridInterpolator((grid.axis0.values, grid.axis1.values), grid.values)
    t_hand = best_time(lambda: grid(a, u), repeat=3)
    t_rgi = best_time(lambda: rgi(np.column_stack([a, u])), repeat=3)
    s_hand = best_time(lambda: grid.scalar(0.83, -0.31), repeat=7, number=2000)
    s_rgi = best_time(lambda: rgi(np.array([[0.83, -0.31]])), repeat=7, number=200)
    report.figure('kernel, 1e6 points: hand-written bilinear', t_hand * 1e3, 'ms')
    report.figure('kernel, 1e6 points: scipy RegularGridInterpolator', t_rgi * 1e3, 'ms')
    report.figure('kernel, one point: hand-written bilinear', s_hand * 1e6, 'us')
    report.figure('kernel, one point: scipy RegularGridInterpolator', s_rgi * 1e6, 'us')
    report.ratio('hand-written vs scipy, one point', s_rgi, s_hand)
    report.ratio('hand-written vs scipy, 1e6 points', t_rgi, t_hand)
    diff = np.max(np.abs(rgi(np.column_stack([a[:1000], u[:1000]])) - grid(a[:1000], u[:1000])[0]))
    report.figure('max |difference| hand-written vs scipy (all fields)', diff, '')


def _accuracy(report: Report, m: PowerMap) -> None:
    vehicle, dry = load_vehicle('chapter3_track'), PRESETS['dry_sand']
    rng = np.random.default_rng(1)
    v, w = rng.uniform(0.0, 1.5, 3000), rng.uniform(-2.0, 2.0, 3000)
    keep = np.abs(v) >= m.meta['min_radius_m'] * np.abs(w)
    v, w = v[keep][:1000], w[keep][:1000]
    q = m.query(v, w)
    direct = fess.FessSolver(vehicle, dry).solve_twist(v, w)
    power_err = np.abs(q.power_left_W + q.power_right_W - direct.power.sum(axis=1)) / np.abs(
        direct.power
    ).sum(axis=1)
    report.figure(
        'off-grid total power vs direct FESS, max (1000 pts)',
        power_err.max() * 100,
        '%',
        goal='< 1 %',
        met=power_err.max() < 0.01,
    )
    scale = np.abs(direct.torque).max(axis=1)
    t_err = np.maximum(
        np.abs(q.torque_left_Nm - direct.torque[:, 0]), np.abs(q.torque_right_Nm - direct.torque[:, 1])
    )
    rel = t_err / scale
    k = int(rel.argmax())
    report.figure(
        'off-grid side torque vs direct FESS, max',
        rel.max() * 100,
        '%',
        goal='< 1 %',
        met=rel.max() < 0.01,
        note=f'worst at V={v[k]:.3f} m/s, w={w[k]:.4f} rad/s; abs {t_err[k]:.3g} N m',
    )
    report.figure('off-grid side torque vs direct FESS, 95th percentile', np.percentile(rel, 95) * 100, '%')
    turning = np.abs(v) < 20 * np.abs(w)  # |R| < 20 m
    report.figure('off-grid side torque vs direct FESS, max for |R| < 20 m', rel[turning].max() * 100, '%')


def accuracy_table(points: int = 1000, seed: int = 7) -> list[AccuracyRow]:
    """Map vs direct FESS at ``points`` random off-grid commands in each shipped vehicle's envelope
    (0 <= V <= max speed, |yaw rate| <= max yaw rate), for every vehicle x terrain preset.

    Per combination: build time [s] (CPU time of this process: the machine is shared); the fraction
    of points the map flags (clamped or limited), and of all points the fraction flagged only by
    the build-time cell check (``PowerMap`` module doc); among the unflagged points: max
    side-torque error (relative to the larger side torque), max side-speed error (relative to the
    larger side speed), max and 99th-percentile power error (|difference of total terrain power|
    relative to the sum of |side powers|), and how many unflagged points FESS itself could not
    solve (each counts as a miss).
    """
    from skidsteer_power.terramechanics.terrain import PRESETS
    from skidsteer_power.vehicle import available_vehicles

    rows: list[AccuracyRow] = []
    rng = np.random.default_rng(seed)
    for name in available_vehicles():
        vehicle = load_vehicle(name)
        v = rng.uniform(0.0, vehicle.max_speed_m_s, points)
        w = rng.uniform(-vehicle.max_yaw_rate_rad_s, vehicle.max_yaw_rate_rad_s, points)
        for terrain_name, terrain in PRESETS.items():
            start = time.process_time()
            m = PowerMap.build(vehicle, terrain)
            build_s = time.process_time() - start
            q = m.query(v, w)
            direct = fess.FessSolver(vehicle, terrain).solve_twist(v, w)
            flagged = np.asarray(q.clamped | q.limited)  # array queries give arrays
            unchecked = PowerMap(m.radial, m.angles, m.length_m, m.values, m.converged, m.limited, m.meta)
            q0 = unchecked.query(v, w)  # the same map without the cell check's flags
            by_check = flagged & ~np.asarray(q0.clamped | q0.limited)
            ok = ~flagged & direct.converged
            t_map = np.column_stack([q.torque_left_Nm, q.torque_right_Nm])
            o_map = np.column_stack([q.omega_left_rad_s, q.omega_right_rad_s])
            t_err = np.abs(t_map - direct.torque).max(axis=1) / np.abs(direct.torque).max(axis=1)
            o_err = np.abs(o_map - direct.omega).max(axis=1) / np.abs(direct.omega).max(axis=1)
            p_err = np.abs(q.total_power_W - direct.power.sum(axis=1)) / np.abs(direct.power).sum(axis=1)
            worst = int(np.argmax(np.where(ok, p_err, -1.0))) if ok.any() else 0
            rows.append(
                {
                    'vehicle': name,
                    'terrain': terrain_name,
                    'build_s': build_s,
                    'flagged_pct': 100.0 * float(flagged.mean()),
                    'check_pct': 100.0 * float(by_check.mean()),
                    'torque_pct': 100.0 * float(t_err[ok].max()) if ok.any() else np.nan,
                    'speed_pct': 100.0 * float(o_err[ok].max()) if ok.any() else np.nan,
                    'power_pct': 100.0 * float(p_err[ok].max()) if ok.any() else np.nan,
                    'power_p99_pct': 100.0 * float(np.percentile(p_err[ok], 99)) if ok.any() else np.nan,
                    'unsolved': int(np.sum(~flagged & ~direct.converged)),
                    'worst': (float(v[worst]), float(w[worst])),
                }
            )
    return rows


def markdown_table(rows: list[AccuracyRow]) -> str:
    """The docs/BENCHMARKS.md table of :func:`accuracy_table`."""
    lines = [
        '| vehicle | terrain | build [CPU s] | flagged [%] | of which by the cell check [%] '
        '| side torque max [%] | side speed max [%] | power max [%] | power p99 [%] '
        '| unflagged, FESS unsolved |',
        '| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |',
    ]
    for r in rows:
        lines.append(
            f'| {r["vehicle"]} | {r["terrain"]} | {r["build_s"]:.1f} | {r["flagged_pct"]:.1f} '
            f'| {r["check_pct"]:.1f} '
            f'| {r["torque_pct"]:.2f} | {r["speed_pct"]:.2f} | {r["power_pct"]:.2f} '
            f'| {r["power_p99_pct"]:.2f} | {r["unsolved"]} |'
        )
    return '\n'.join(lines)


def _table(report: Report) -> None:
    rows = accuracy_table()
    report.tables['map-accuracy'] = markdown_table(rows)
    print(report.tables['map-accuracy'], flush=True)
    worst = max(rows, key=lambda r: r['power_pct'])
    report.figure(
        'off-grid power vs direct FESS, unflagged points, worst vehicle x terrain',
        worst['power_pct'],
        '%',
        goal='<= 1 %',
        met=worst['power_pct'] <= 1.0,
        note=f'{worst["vehicle"]} on {worst["terrain"]} at V, w = {worst["worst"]}',
    )
    missed = sum(r['power_pct'] > 1.0 for r in rows)
    report.figure('vehicle x terrain combinations above 1 % on power', missed, '', note=f'of {len(rows)}')
    unsolved = sum(r['unsolved'] for r in rows)
    report.figure(
        'unflagged points FESS could not solve (all combinations)',
        unsolved,
        'pts',
        goal='0',
        met=unsolved == 0,
    )
    report.figure('slowest map build (CPU time)', max(r['build_s'] for r in rows), 's')
    report.figure('largest share of points flagged by the cell check', max(r['check_pct'] for r in rows), '%')


def run(report: Report) -> None:
    m = _build(report)
    _queries(report, m)
    _accuracy(report, m)
    _table(report)
    setpoint_maps(report)


if __name__ == '__main__':  # python -m benchmarks.bench_maps: docs/BENCHMARKS.md's accuracy table only
    print(markdown_table(accuracy_table()))


SETPOINT_VEHICLES = ('test_robot_track', 'test_robot_6wheel', 'packbot_4wheel', 'leo_rover', 'husky_a200')


def setpoint_maps(report: Report) -> None:
    """Issue 25: the set-point map of each vehicle on sand_bin: build time (goal <= 10 s on this
    2-core machine), query time (goal <= 20 us); issue 36: its answers against the direct set-point
    solve at 200 random commands over the envelope (points neither flags limited), on sand_bin and on
    rigid ground (asphalt): battery power within 1 % and speed within 5 mm/s at every such point."""
    from skidsteer_power.maps.setpoint_map import SetpointMap
    from skidsteer_power.terramechanics.terrain import load_terrain

    for ground in ('sand_bin', 'asphalt'):
        for name in SETPOINT_VEHICLES:
            setpoint_map_case(report, load_vehicle(name), load_terrain(ground), SetpointMap)


def setpoint_map_case(report: Report, vehicle: Vehicle, terrain: Terrain, setpoint_map: Any) -> None:
    """One vehicle x terrain of :func:`setpoint_maps` (figures named by the vehicle on sand_bin, as
    before, and by vehicle x terrain elsewhere)."""
    name = vehicle.name if terrain.name == 'sand_bin' else f'{vehicle.name} x {terrain.name}'
    start = time.perf_counter()
    smap = setpoint_map.build(vehicle, terrain)
    built = time.perf_counter() - start
    report.under(f'set-point map build, {vehicle.name} x {terrain.name}', built, 's', 10.0, inclusive=True)
    query = best_time(functools.partial(smap.query, 0.3, 0.4), repeat=5, number=2000)
    report.under(f'set-point map query, {name}', query * 1e6, 'us', 20.0, inclusive=True)
    rng = np.random.default_rng(11)
    v = rng.uniform(-1.0, 1.0, 200) * vehicle.max_speed_m_s
    w = rng.uniform(-1.0, 1.0, 200) * vehicle.max_yaw_rate_rad_s
    direct = smap.predictor.predict(v, w)
    answers = [smap.query(float(a), float(b)) for a, b in zip(v, w, strict=True)]
    flagged = np.array([q.limited for q in answers])
    ok = ~direct.limited & ~flagged
    power = np.array([q.battery_power_W for q in answers])
    err = np.abs(power - direct.battery_power) / np.maximum(np.abs(direct.battery_power), 1.0)
    speed_err = np.abs(np.array([q.speed_m_s for q in answers]) - direct.speed)
    report.figure(
        f'set-point map vs direct, {name}: median battery power error', np.median(err[ok]) * 100, '%'
    )
    report.under(
        f'set-point map vs direct, {name}: max battery power error',
        np.max(err[ok]) * 100,
        '%',
        1.0,
        inclusive=True,
    )
    report.under(
        f'set-point map vs direct, {name}: max speed error',
        np.max(speed_err[ok]) * 1e3,
        'mm/s',
        5.0,
        inclusive=True,
    )
    report.under(
        f'set-point map vs direct, {name}: commands flagged by one only',
        float(np.count_nonzero(flagged != direct.limited)),
        '',
        0.0,
        inclusive=True,
    )
    report.figure(f'set-point map, {name}: limited nodes', smap.limited_fraction * 100, '%')
    report.figure(f'direct set-point solve, {name}: limited commands', np.mean(direct.limited) * 100, '%')
