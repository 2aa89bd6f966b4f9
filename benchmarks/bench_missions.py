"""Missions: the 729-candidate design study (goal < 10 s on 2 cores), missions, battery stepping."""

from __future__ import annotations

import time

from benchmarks.harness import Report, best_time


def run(report: Report) -> None:
    from skidsteer_power.missions import patrol, run_mission, search_retrieve
    from skidsteer_power.missions.design import design_study
    from skidsteer_power.powertrain import Battery
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    sandy = load_terrain('sandy_soil')
    start = time.perf_counter()
    study = design_study(sandy, workers=2)
    wall = time.perf_counter() - start
    report.figure(
        'design study, 729 candidates, 2 processes (wall)',
        wall,
        's',
        goal='< 10 s',
        met=wall < 10.0,
        note=f'{study["n_converged"]} converged',
    )
    start = time.perf_counter()
    design_study(sandy, workers=1)
    serial = time.perf_counter() - start
    report.ratio('design study speed-up, 2 processes vs 1', serial, wall)

    track = load_vehicle('packbot_track')
    route = patrol()
    t = best_time(lambda: run_mission(track, sandy, route), repeat=3)
    report.figure('patrol mission, packbot_track, map built in memory', t, 's')
    sr = search_retrieve()
    wheel6 = load_vehicle('packbot_6wheel')
    t = best_time(lambda: run_mission(wheel6, sandy, sr), repeat=3)
    report.figure(f'search-retrieve mission ({len(sr.segments)} segments), packbot_6wheel, 2 maps', t, 's')

    battery = Battery.default_test_robot()

    def steps() -> None:
        for _ in range(1000):
            battery.step(40.0, 0.1)

    t = best_time(steps, repeat=3) / 1000
    report.figure(
        'battery step (coulomb counting, RK4)', t * 1e6, 'us', goal='< 1 ms (10 Hz estimator)', met=t < 1e-3
    )
