"""rosbag2 habits (issue 37 item 7): ``info`` as ``ros2 bag info`` on real bags, ``record -a`` and
``record`` without ``-o`` (rosbag2's default name) over real DDS, and a bag with /tf replayed where
tf2_msgs is not installed (it is not on PyPI; ``make tf2-msgs`` builds it: test_tf_replay.py):
skipped, saying why and how to get it."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from skidsteer_power.cli.bag_info import bag_info, info_text

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'test_robot_track_sand_bin.mcap'


def cli(*args: str, cwd: Path = ROOT, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, 'PYTHONPATH': str(ROOT)}
    return subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', *args],
        capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout,
    )  # fmt: skip


def test_info_matches_the_bags_own_summary() -> None:
    """Counts and types against the MCAP summary read by the mcap library (not by the code under test)."""
    with BAG.open('rb') as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    by_channel = summary.statistics.channel_message_counts
    expected = {
        channel.topic: (summary.schemas[channel.schema_id].name, by_channel[cid])
        for cid, channel in summary.channels.items()
    }
    info = bag_info(str(BAG))
    assert {t['topic']: (t['type'], t['count']) for t in info['topics']} == expected
    assert info['messages'] == summary.statistics.message_count == 10295
    assert info['storage'] == 'mcap' and info['size_bytes'] == BAG.stat().st_size
    duration_ns = summary.statistics.message_end_time - summary.statistics.message_start_time
    assert info['duration_s'] == pytest.approx(duration_ns * 1e-9)
    text = info_text(info)
    assert re.search(
        r'^Topic information: Topic: /battery/measured +\| Type: sensor_msgs/msg/BatteryState', text, re.M
    )
    assert re.search(
        r'^ {19}Topic: /cmd_vel +\| Type: geometry_msgs/msg/Twist +\| Count: 2451 \|', text, re.M
    )
    assert 'Storage id:        mcap' in text and 'Messages:          10295' in text


def test_info_cli_json_and_a_missing_bag() -> None:
    done = cli('info', str(BAG), '--json')
    assert done.returncode == 0 and json.loads(done.stdout)['messages'] == 10295
    missing = cli('info', '/nonexistent.mcap')
    assert missing.returncode == 2 and len(missing.stderr.strip().splitlines()) == 1


def test_record_all_and_the_default_name(tmp_path: Path) -> None:
    done = cli('record', '-a', '--duration', '1', '--json', cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    made = [p.name for p in tmp_path.iterdir()]
    assert len(made) == 1 and re.fullmatch(r'rosbag2_\d{4}_\d{2}_\d{2}-\d{2}_\d{2}_\d{2}', made[0]), made
    assert json.loads(done.stdout)['bag'].endswith(made[0]) or made[0] in json.loads(done.stdout)['bag']
    both = cli('record', '-a', '/cmd_vel', '--duration', '1', cwd=tmp_path)
    assert both.returncode == 2 and 'not both' in both.stderr


def test_replay_names_why_tf_is_not_replayed(tmp_path: Path) -> None:
    """A bag with /tf (tf2_msgs/msg/TFMessage) and /cmd_vel, replayed by a process in which tf2_msgs
    cannot be imported (as in a venv without ``make tf2-msgs``): /cmd_vel is replayed, /tf is skipped
    with the reason (rclpy has no type support for it) and the way to build it."""
    store = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / 'tf_bag'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        tf = writer.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=store)
        cmd = writer.add_connection('/cmd_vel', 'geometry_msgs/msg/Twist', typestore=store)
        Twist = store.types['geometry_msgs/msg/Twist']
        Vector3 = store.types['geometry_msgs/msg/Vector3']
        TFMessage = store.types['tf2_msgs/msg/TFMessage']
        for k in range(5):
            t = 1_700_000_000_000_000_000 + k * 50_000_000
            writer.write(tf, t, store.serialize_cdr(TFMessage(transforms=[]), 'tf2_msgs/msg/TFMessage'))
            twist = Twist(linear=Vector3(x=0.1, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
            writer.write(cmd, t, store.serialize_cdr(twist, 'geometry_msgs/msg/Twist'))
    # None in sys.modules makes every import of tf2_msgs raise ImportError, as when it is absent
    without_tf2_msgs = (
        "import sys; sys.modules['tf2_msgs'] = None; "
        'from skidsteer_power.cli.main import main; sys.exit(main(sys.argv[1:]))'
    )
    env = {**os.environ, 'PYTHONPATH': str(ROOT)}
    done = subprocess.run(
        [sys.executable, '-c', without_tf2_msgs, 'replay', str(bag), '--json'],
        capture_output=True, text=True, cwd=ROOT, env=env, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert list(result['skipped']) == ['/tf']
    reason = result['skipped']['/tf']
    assert 'tf2_msgs/msg/TFMessage is not installed' in reason and 'type support' in reason
    assert 'make tf2-msgs' in reason
    assert result['counts'] == {'/cmd_vel': 5}


def test_call_reset_energy_on_a_running_suite(tmp_path: Path) -> None:
    """``skidsteer-power call reset_energy`` against ``run --simulate --namespace`` (two processes)."""
    env = {**os.environ, 'PYTHONPATH': str(ROOT), 'XDG_STATE_HOME': str(tmp_path)}
    suite = subprocess.Popen(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--simulate', '--namespace', 'robot7',
         '--duration', '60', '--quiet'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env,
    )  # fmt: skip
    try:
        done = cli('call', 'reset_energy', '--namespace', 'robot7', '--timeout', '40', '--json', timeout=90)
        assert done.returncode == 0, done.stderr
        answer = json.loads(done.stdout)
        assert answer['service'] == '/robot7/power_estimator/reset_energy' and answer['success'] is True
        assert answer['message'].startswith('battery reset to full')
    finally:
        suite.terminate()
        suite.communicate(timeout=30)
    absent = cli('call', 'reset_energy', '--namespace', 'nobody_here', '--timeout', '1')
    assert absent.returncode == 2 and 'no service /nobody_here/power_estimator/reset_energy' in absent.stderr
    unknown = cli('call', 'reboot')
    assert unknown.returncode == 2 and len(unknown.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ('args', 'says'),
    [
        (('call', '/bad name!', '--timeout', '1'), "invalid service name '/bad name!'"),
        (('call', 'reset_energy', '--namespace', 'bad ns!'), "invalid namespace 'bad ns!'"),
        (('call', 'reset_energy', '--timeout', '61'), 'outside its range (0, 60] s'),
        (('run', '--simulate', '--namespace', 'bad ns!', '--duration', '1'), "invalid namespace 'bad ns!'"),
    ],
)
def test_bad_ros_names_are_one_line(args: tuple[str, ...], says: str) -> None:
    """A name rclpy would refuse with a traceback is refused before any node: one line, exit 2."""
    done = cli(*args, timeout=60)
    assert done.returncode == 2 and done.stderr.count('\n') == 1 and says in done.stderr, done.stderr
