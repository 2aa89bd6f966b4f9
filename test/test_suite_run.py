"""The node suite under ``run --simulate``: power_estimator + des_driver against simulated DES 70/10
amplifiers on ptys, loaded in real time by the digital twin of the test robot on dry sand (real rclpy,
DDS, pyserial)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import pytest
import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import BatteryState, JointState

from skidsteer_power.nodes.suite import Suite, SuiteOptions


def test_simulated_suite_produces_joint_states_predictions_and_a_falling_battery(
    ros_context: Context, tmp_path: Path
) -> None:
    namespace = f'suite_{uuid.uuid4().hex[:8]}'
    options = SuiteOptions(
        simulate=True, map_cache_dir=str(tmp_path / 'maps'), state_file=str(tmp_path / 'energy.json'),
        namespace=namespace, estimator_params={'publish_period_s': 0.1},
    )  # fmt: skip
    suite = Suite(options, context=ros_context).start()
    probe = rclpy.create_node('suite_probe', namespace=namespace, context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    joints: list[JointState] = []
    predicted: list[JointState] = []
    battery: list[BatteryState] = []
    probe.create_subscription(JointState, 'joint_states', joints.append, 100)
    probe.create_subscription(JointState, 'power/predicted', predicted.append, 100)
    probe.create_subscription(BatteryState, 'battery/state', battery.append, 100)
    truth: list[Odometry] = []
    odom: list[Odometry] = []
    probe.create_subscription(Odometry, 'ground_truth/odom', truth.append, 100)
    probe.create_subscription(Odometry, 'odom', odom.append, 100)
    publisher = probe.create_publisher(Twist, 'cmd_vel', 10)
    command = Twist()
    command.linear.x, command.angular.z = 0.2, 0.1  # Table 7.3: V = 0.2 m/s, yaw rate 0.1 rad/s
    try:
        deadline = time.monotonic() + 60.0
        next_command = 0.0
        moving: list[Any] = []  # JointState messages
        while time.monotonic() < deadline and (len(moving) < 20 or len(battery) < 10 or len(truth) < 20):
            if time.monotonic() >= next_command:
                publisher.publish(command)
                next_command = time.monotonic() + 0.1
            executor.spin_once(timeout_sec=0.02)
            moving = [j for j in joints if all(math.isfinite(v) and v > 1.0 for v in j.velocity)]
        energy = dict(suite.estimator.core.energy.energy_J)
    finally:
        executor.shutdown()
        probe.destroy_node()
        suite.shutdown()
    assert len(moving) >= 20, 'the simulated motors never turned'
    assert moving[-1].name == ['left_motor', 'right_motor']
    assert moving[-1].velocity[1] > moving[-1].velocity[0]  # left turn: right side faster
    assert predicted and predicted[-1].name[:2] == ['left_motor', 'right_motor']
    assert battery[-1].percentage < battery[0].percentage < 1.0 + 1e-12
    assert energy['measured'] > 0.0
    assert (tmp_path / 'energy.json').exists()  # saved on shutdown
    # the twin moved: its true pose advanced; the encoder odometry, blind to the tracks' slip,
    # believes the robot turned more than it did
    assert truth[-1].pose.pose.position.x > 0.01
    assert odom and odom[-1].pose.pose.orientation.z > truth[-1].pose.pose.orientation.z > 0.0


def run_cli(*args: str, env_extra: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, **(env_extra or {})}
    return subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'run', *args],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip


@pytest.mark.slow
def test_run_simulate_cli_reports_a_falling_battery(tmp_path: Path) -> None:
    result = run_cli(
        '--simulate', '--duration', '4', '--speed', '0.2', '--json',
        '--map-cache', str(tmp_path), '--state-file', str(tmp_path / 'e.json'),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout)
    assert report['joint_states_received'] > 0 and report['predicted_received'] > 0
    assert report['soc_end'] < report['soc_start'] and report['energy_used_J'] > 0


@pytest.mark.parametrize(
    ('args', 'match'),
    [
        (('--vehicle', 'no_such_robot', '--simulate', '--duration', '1'), 'no_such_robot'),
        (('--terrain', 'lava', '--simulate', '--duration', '1'), 'lava'),
        (('--duration', '-1'), 'duration = -1 s is outside its range'),
    ],
)
def test_run_bad_arguments_give_one_line(
    tmp_path: Path, args: tuple[str, str, str, str, str] | tuple[str, str], match: str
) -> None:
    result = run_cli(*args, '--map-cache', str(tmp_path), '--state-file', str(tmp_path / 'e.json'))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and match in lines[0] and 'Traceback' not in result.stderr


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_run_stops_cleanly_on_a_signal_and_keeps_the_energy_state(
    tmp_path: Path, signum: signal.Signals
) -> None:
    """SIGTERM, or SIGINT even when inherited as ignored (a background job of a script), ends the
    suite cleanly: the JSON summary is printed and the energy state is saved (nothing accumulated is
    lost)."""
    state = tmp_path / 'e.json'
    command = [
        sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--simulate', '--duration', '120',
        '--speed', '0.2', '--json', '--map-cache', str(tmp_path), '--state-file', str(state),
    ]  # fmt: skip
    ignore_sigint = (
        (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if signum == signal.SIGINT else None
    )
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ignore_sigint if signum == signal.SIGINT else None,
    )
    try:
        deadline = time.monotonic() + 60.0  # a wait for the start-up and some driving, not a timing goal
        while _drawn_J(state) <= 0.0 and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _drawn_J(state) > 0.0, 'the suite saved no energy drawn (did it drive?)'
        process.send_signal(signum)
        stdout, stderr = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, stderr[-2000:]
    report = json.loads(stdout)
    assert report['duration_s'] < 60
    saved = json.loads(state.read_text())
    assert saved  # the estimator wrote its state on shutdown


def _drawn_J(state_file: Path) -> float:
    """The energy drawn [J] in a saved energy state (the estimator saves every 0.5 s); 0 before the
    first save (or mid-replace)."""
    try:
        return float(json.loads(state_file.read_text())['battery']['state']['drawn_J'])
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


# a planted fault in a real `run --simulate` process: every joint_states callback of power_estimator
# raises (issue 28 found one that did: a finite but huge effort), which ends its spin thread
_DYING_ESTIMATOR = """
import sys
from skidsteer_power.estimator import inputs
def planted(self, what, values, rows):
    raise AssertionError('planted fault')
inputs.JointReader._pick = planted
from skidsteer_power.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def test_run_stops_non_zero_when_a_thread_of_the_suite_dies(tmp_path: Path) -> None:
    """Before: the estimator thread died, the suite went on printing 'drive 0.0 W' and exited 0
    after --duration. Now the suite stops, one error line names the thread, exit 1, no summary."""
    result = subprocess.run(
        [sys.executable, '-c', _DYING_ESTIMATOR, 'run', '--simulate', '--duration', '60', '--json',
         '--speed', '0.2', '--map-cache', str(tmp_path), '--state-file', str(tmp_path / 'e.json')],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode == 1, result.stderr[-2000:]
    assert result.stdout == ''  # no summary of a run that failed
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith('skidsteer-power run: error: spin-power_estimator died: AssertionError')
    assert json.loads((tmp_path / 'e.json').read_text())  # the energy state was saved on the way out
