"""The digital twin's speed against real time (issue 14 goal: >= 20x for the test robot on 2 cores).

Each figure runs a fresh twin (no caches exist) through 20 s of the Table 7.3 experiment sets
(straight and turning holds, with stops) at the default 2 ms step, and once at 1 ms. Wall-clock
factors suffer from other load on a shared machine; the CPU-time factor (process time) is what
the twin itself needs and is reported beside it.
"""

from __future__ import annotations

import time

from benchmarks.harness import Report
from skidsteer_power.bags.synthetic import table_7_3_segments
from skidsteer_power.commands import Segment
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin import Twin, run_commands
from skidsteer_power.vehicle import load_vehicle

GOAL = 20.0


def _commands(seconds: float) -> list[Segment]:
    out, total = [], 0.0
    for segment in table_7_3_segments():
        if total >= seconds:
            break
        out.append(segment)
        total += segment.duration_s
    return out


def run(report: Report) -> None:
    terrain = load_terrain('sand_bin')
    commands = _commands(20.0)
    simulated = sum(s.duration_s for s in commands)
    for name in ('test_robot_track', 'test_robot_4wheel', 'test_robot_6wheel'):
        for dt in (2e-3, 1e-3):
            twin = Twin(load_vehicle(name), terrain, dt=dt)
            wall0, cpu0 = time.perf_counter(), time.process_time()
            run_commands(twin, commands)
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            label = f'{name}, dt = {dt * 1e3:g} ms, {simulated:g} s simulated'
            goal = dict(goal=f'>= {GOAL:g}x', met=simulated / wall >= GOAL) if dt == 2e-3 else {}
            report.figure(f'{label}: wall-clock speed', simulated / wall, 'x real', **goal)  # type: ignore[arg-type]
            report.figure(f'{label}: CPU-time speed', simulated / cpu, 'x real')
