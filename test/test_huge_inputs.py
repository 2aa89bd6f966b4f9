"""One joint_states with a finite but huge effort (issue 28: ``[9e307, 9e307]``) is a counted bad input
everywhere the estimator's :class:`JointReader` reads it: validate, calibrate (real MCAP bags written
by the project's writer, real CLI processes). It once ended them with ``AssertionError('unreachable')``
(the finiteness test summed the values and the sum overflowed)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from skidsteer_power.bag_io.synthetic import DriveSamples, MotorArrays, motor_speeds, write_drive_bag
from skidsteer_power.calibration.segments import SegmentOptions, find_segments, read_recording
from skidsteer_power.commands import Segment

HUGE = 9e307  # finite; two of them sum to inf (float max 1.797e308)
PLAN = [Segment(0.2, 0.0, 4.0), Segment(0.0, 0.0, 1.0), Segment(0.1, 0.2, 4.0)]
RATE_HZ = 20


def _huge_in_the_middle(samples: DriveSamples) -> MotorArrays:
    """Kinematic speeds (tread 0.4 m, radius 0.1 m, G 12: write_drive_bag's defaults), 0.1 N m
    everywhere but one message of [9e307, 9e307] N m in the first segment."""
    left_w, right_w = motor_speeds(samples, 0.4, 0.1, 12.0)
    effort = np.full(samples.t.size, 0.1)
    effort[2 * RATE_HZ] = HUGE  # t = 2 s, inside the first segment's settled window
    return left_w, right_w, effort, effort.copy()


@pytest.fixture(scope='module')
def huge_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('huge') / 'huge.mcap'
    write_drive_bag(path, PLAN, rate_hz=RATE_HZ, motors=_huge_in_the_middle)
    return path


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', *args], capture_output=True, text=True, timeout=300
    )


def test_validate_counts_the_huge_message_as_rejected(huge_bag: Path, tmp_path: Path) -> None:
    run = _cli(
        'validate', str(huge_bag), '--vehicle', 'test_robot_track', '--terrain', 'dry_sand', '--report',
        str(tmp_path / 'rep'), '--map-cache', str(tmp_path / 'maps'), '--no-plots', '--json',
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert 'Traceback' not in run.stderr
    summary = json.loads(run.stdout)
    assert summary['rejected'] == {'cmd_vel': 0, 'joint_states': 1}
    assert summary['messages']['joint_states'] == 9 * RATE_HZ  # 9 s of PLAN at 20 Hz: every one read


def test_calibration_drops_the_huge_message_and_keeps_the_segment(huge_bag: Path) -> None:
    recording = read_recording(huge_bag)
    assert recording.js_t.size == 9 * RATE_HZ - 1  # all but the huge one
    segments, _ = find_segments(recording, SegmentOptions(settle_s=1.5))
    assert [s.command for s in segments] == [(0.2, 0.0), (0.1, 0.2)]
    for seg in segments:  # the synthetic bag's constant 0.1 N m, not a mean pulled up by 9e307
        assert seg.motor_torque_Nm == pytest.approx((0.1, 0.1))


def test_calibrate_cli_gives_a_result_or_one_line(huge_bag: Path, tmp_path: Path) -> None:
    run = _cli(
        'calibrate', str(huge_bag), '--vehicle', 'test_robot_track', '--terrain', 'dry_sand',
        '--out-terrain', str(tmp_path / 't.yaml'), '--json',
    )  # fmt: skip
    assert 'Traceback' not in run.stderr
    # two steady segments are too few to fit: the one clear line of calibrate, exit 2
    assert run.returncode == 2 and run.stderr.count('\n') == 1
    assert 'only 2 steady segment(s)' in run.stderr
