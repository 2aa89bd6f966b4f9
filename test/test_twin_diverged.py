"""A twin run that diverges is one error, never a trace read as a recording (docs/TWIN.md, "Rigid
ground is still a soil to the twin")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.heldout_proxy import commands
from skidsteer_power.commands import Segment
from skidsteer_power.errors import ConvergenceError
from skidsteer_power.terramechanics import load_terrain
from skidsteer_power.twin import Twin, run_commands
from skidsteer_power.vehicle import load_vehicle


def test_a_state_that_is_not_finite_stops_the_run() -> None:
    twin = Twin(load_vehicle('husky_a200'), load_terrain('grass'), seed=1)
    twin.vel = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ConvergenceError, match=r'diverged at t = .* not finite'):
        run_commands(twin, [Segment(0.3, 0.0, 0.5)])


def test_a_diverged_twin_is_an_error_not_a_recording(tmp_path: Path) -> None:
    """The Husky on asphalt, heldout_proxy's first command file of seed 6: a slow reverse turn after
    a spin locks the twin's stiff soil contact into a limit cycle (axle torques of about 2000 N m
    where the robot's weight at the wheel is m g r = 56.58 x 9.81 x 0.1651 = 91.6 N m), which
    overflowed ~4 s later. Measured: stopped at 50.16 s, 970 N m."""
    csv = commands(tmp_path / 'cmd.csv', 150.0, 61)
    bag = tmp_path / 'out.mcap'
    done = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'simulate', '--vehicle', 'husky_a200',
         '--terrain', 'asphalt', '--commands', str(csv), '--seed', '61', '-o', str(bag), '--json'],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2
    lines = [line for line in done.stderr.splitlines() if line.startswith('skidsteer-power: error')]
    assert len(lines) == 1 and 'the twin diverged at t = ' in lines[0], done.stderr
    assert 'Traceback' not in done.stderr
    assert not bag.exists()
