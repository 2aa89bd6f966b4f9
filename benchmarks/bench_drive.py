"""The drive layer and the command line's start-up (issue 36).

- ``skidsteer-power --help`` start-up: median wall time of repeated runs (goal < 0.3 s), beside a bare
  ``python -c pass`` measured in the same run (the interpreter's own floor on this machine);
- ``predict --commands``: rows per second from the set-point map, in-process (goal >= 2,000 rows/s,
  "thousands of commands a second"), and the whole command for 10,000 rows;
- the controller: vectorized set points per second; :func:`identify` on a 10-minute 50 Hz recording.
"""

from __future__ import annotations

import functools
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.harness import Report, best_time
from skidsteer_power.cli.predict import predict_records, read_commands
from skidsteer_power.drive import DriveController, Ramp, identify
from skidsteer_power.maps.setpoint_map import load_or_build
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

HELP_RUNS = 15
HELP_GOAL_S = 0.3
BATCH_ROWS = 10_000
BATCH_GOAL_ROWS_S = 2_000.0
APPLY_COMMANDS = 1_000_000


def _wall(argv: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def _startup(report: Report) -> None:
    floor = statistics.median(_wall([sys.executable, '-c', 'pass']) for _ in range(HELP_RUNS))
    runs = [_wall([sys.executable, '-m', 'skidsteer_power.cli.main', '--help']) for _ in range(HELP_RUNS)]
    report.under(
        f'skidsteer-power --help start-up, median of {HELP_RUNS}',
        statistics.median(runs),
        's',
        HELP_GOAL_S,
        note=f'min {min(runs):.3f} s; bare python -c pass median {floor:.3f} s in the same run',
    )


def _commands_csv(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    v, w = rng.uniform(-1.5, 1.5, BATCH_ROWS), rng.uniform(-2.0, 2.0, BATCH_ROWS)
    path = folder / 'commands.csv'
    path.write_text(
        'speed_m_s,yaw_rate_rad_s\n' + ''.join(f'{a:.4f},{b:.4f}\n' for a, b in zip(v, w, strict=True))
    )
    return path


def _batch(report: Report, folder: Path) -> None:
    path = _commands_csv(folder)
    commands = read_commands(path, BATCH_ROWS)
    for name, ground in (
        ('test_robot_track', 'sand_bin'),
        ('husky_a200', 'sand_bin'),
        ('husky_a200', 'grass'),
    ):
        vehicle, terrain = load_vehicle(name), load_terrain(ground)
        smap, _ = load_or_build(vehicle, terrain)  # built once and cached, as a robot's first query would
        elapsed = best_time(functools.partial(predict_records, vehicle, terrain, commands, False), repeat=3)
        report.figure(
            f'predict --commands, {BATCH_ROWS:,} rows from the set-point map (in-process), {name} x {ground}',
            BATCH_ROWS / elapsed,
            'rows/s',
            goal=f'>= {BATCH_GOAL_ROWS_S:,.0f} rows/s',
            met=BATCH_ROWS / elapsed >= BATCH_GOAL_ROWS_S,
            note=f'the cached map loaded in each call; {smap.exact_fraction:.0%} of its area answered by '
            'the direct solve (one batch for the whole file)',
        )
    argv = [sys.executable, '-m', 'skidsteer_power.cli.main', 'predict', '--vehicle', 'test_robot_track']
    argv += ['--terrain', 'sand_bin', '--commands', str(path), '--json']
    report.figure(f'skidsteer-power predict --commands, {BATCH_ROWS:,} rows, whole command', _wall(argv), 's')


def _controller(report: Report) -> None:
    ctrl = DriveController(0.5708, 0.1651, max_speed_m_s=1.0, max_yaw_rate_rad_s=2.0, max_wheel_rad_s=6.1)
    rng = np.random.default_rng(1)
    v, w = rng.uniform(-1.5, 1.5, APPLY_COMMANDS), rng.uniform(-3.0, 3.0, APPLY_COMMANDS)
    elapsed = best_time(lambda: ctrl.apply(v, w), repeat=3)
    report.figure('DriveController.apply, vectorized', APPLY_COMMANDS / elapsed, 'commands/s')
    ramp = Ramp(ctrl.with_values(max_accel_m_s2=1.0, max_yaw_accel_rad_s2=2.0))
    steps = 100_000
    start = time.perf_counter()
    for k in range(steps):
        ramp.step(0.8 if k % 1000 < 500 else -0.3, 1.0, 0.002)
    report.figure('Ramp.step (one command, floats)', (time.perf_counter() - start) / steps * 1e6, 'us')
    t = np.arange(30_000) * 0.02  # 10 minutes at 50 Hz
    cmd = np.column_stack(
        [np.repeat(rng.uniform(-1.5, 1.5, 150), 200), np.repeat(rng.uniform(-3, 3, 150), 200)]
    )
    sp = ctrl.apply(cmd[:, 0], cmd[:, 1]).setpoint + rng.normal(0.0, 0.02, (30_000, 2))
    start = time.perf_counter()
    found = identify(t, cmd, sp, prior=ctrl.with_values(max_wheel_rad_s=np.inf))
    report.figure(
        'identify, 10 min at 50 Hz (150 held commands)',
        time.perf_counter() - start,
        's',
        note=f'ceiling back as {found.values["max_wheel_rad_s"].value:.4f} rad/s (true 6.1)',
    )


def run(report: Report) -> None:
    _startup(report)
    with tempfile.TemporaryDirectory() as folder:
        _batch(report, Path(folder))
    _controller(report)
