"""The digital twin's speed against real time (issue 14 goal: >= 20x for the test robot on 2 cores).

Each figure runs a fresh twin (no caches exist) through 20 s of the Table 7.3 experiment sets
(straight and turning holds, with stops) at the default 2 ms step: the best of ``REPEATS`` runs
(the least disturbed by other load on a shared machine) for the wall-clock factor, which carries
the goal, and for the CPU-time factor (process time: what the twin itself needs; goal 25x, the
margin that keeps the wall-clock goal on a machine with a core to spare). The 1-minute load
average is printed beside them. Same-run ratios: the cost of the extended contact laws
(``Twin(contact='classic')`` over the full twin) and of a 1 ms step.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from functools import partial

from benchmarks.harness import Report
from skidsteer_power.commands import Segment
from skidsteer_power.real_robot import table_7_3_segments
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin import Twin, run_commands
from skidsteer_power.vehicle import load_vehicle

GOAL = 20.0
CPU_GOAL = 25.0
REPEATS = 3


def _commands(seconds: float) -> list[Segment]:
    out, total = [], 0.0
    for segment in table_7_3_segments():
        if total >= seconds:
            break
        out.append(segment)
        total += segment.duration_s
    return out


def _times(make: Callable[[], Twin], commands: list[Segment], repeats: int) -> tuple[float, float]:
    """Best wall-clock and best CPU time [s] of ``repeats`` runs of a fresh twin."""
    walls, cpus = [], []
    for _ in range(repeats):
        twin = make()
        wall0, cpu0 = time.perf_counter(), time.process_time()
        run_commands(twin, commands)
        walls.append(time.perf_counter() - wall0)
        cpus.append(time.process_time() - cpu0)
    return min(walls), min(cpus)


def run(report: Report) -> None:
    terrain = load_terrain('sand_bin')
    commands = _commands(20.0)
    simulated = sum(s.duration_s for s in commands)
    report.figure('1-minute load average at the start', os.getloadavg()[0], '', note='2 cores')
    for name in ('test_robot_track', 'test_robot_4wheel', 'test_robot_6wheel'):
        vehicle = load_vehicle(name)
        wall, cpu = _times(partial(Twin, vehicle, terrain), commands, REPEATS)
        label = f'{name}, dt = 2 ms, {simulated:g} s simulated, best of {REPEATS}'
        report.figure(f'{label}: wall-clock speed', simulated / wall, 'x real', goal=f'>= {GOAL:g}x',
                      met=simulated / wall >= GOAL)  # fmt: skip
        report.figure(f'{label}: CPU-time speed', simulated / cpu, 'x real', goal=f'>= {CPU_GOAL:g}x',
                      met=simulated / cpu >= CPU_GOAL)  # fmt: skip
        _, plain = _times(partial(Twin, vehicle, terrain, contact='classic'), commands, REPEATS)
        report.ratio(f'{name}: CPU time, extended / classic contact', cpu, plain)
        _, fine = _times(partial(Twin, vehicle, terrain, dt=1e-3), commands, 1)
        report.ratio(f'{name}: CPU time, dt = 1 ms / dt = 2 ms', fine, cpu)
    report.figure('1-minute load average at the end', os.getloadavg()[0], '', note='2 cores')
