"""``run --simulate`` with a ros2_control vehicle measures (issue 37 items 3 and 8): real processes
(the CLI), simulated DES 70/10 amplifiers, real DDS; and bags/replay_and_validate.sh notices a suite
that died."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_suite(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--simulate', '--json', *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=300, env=env, cwd=ROOT)


def test_leo_rover_suite_measures_with_twist_stamped(tmp_path: Path) -> None:
    """leo_rover's own joints are wheel_*_joint (ros2_control); the suite's joint_states are
    des_driver's left_motor/right_motor: the estimator is told so, and measures."""
    env = {**os.environ, 'XDG_STATE_HOME': str(tmp_path)}
    done = run_suite(
        '--vehicle', 'leo_rover', '--terrain', 'sand_bin', '--duration', '4', '--speed', '0.3',
        '--cmd-vel-type', 'twist_stamped', env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary['energy_source'] == 'measured' and summary['energy_used_J'] > 0
    assert summary['predicted_received'] > 0  # TwistStamped commands reached the estimator
    assert 'lacks' not in done.stderr  # no "joint_states lacks wheel_FL_joint"
    assert not list(tmp_path.rglob('energy_*.json'))  # --simulate starts fresh and leaves no state


def test_replay_and_validate_fails_when_the_suite_dies(tmp_path: Path) -> None:
    env = {**os.environ, 'BIN': str(Path(sys.executable).parent), 'ROS_DOMAIN_ID': '97'}
    done = subprocess.run(
        ['bash', 'bags/replay_and_validate.sh', 'bags/test_robot_track_sand_bin.mcap', 'no_such_vehicle',
         str(tmp_path / 'out')],
        capture_output=True, text=True, timeout=120, env=env, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 1
    assert 'the node suite died (at start-up)' in done.stderr


def test_replay_and_validate_domain_ids_are_documented_ones() -> None:
    """ROS 2 documents domain IDs 0-101 as safe everywhere (docs.ros.org, 'The ROS_DOMAIN_ID')."""
    text = (ROOT / 'bags' / 'replay_and_validate.sh').read_text(encoding='utf-8')
    assert 'ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))' in text  # 1..100
    assert '--terrain "$TERRAIN"' in text and 'sand_bin --' not in text
