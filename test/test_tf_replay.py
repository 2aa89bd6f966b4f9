"""/tf and /tf_static through record and replay as the genuine tf2_msgs/msg/TFMessage (issue 37 item 7).

tf2_msgs is not on PyPI: ``make tf2-msgs`` (part of ``make setup``) builds interfaces/tf2_msgs,
upstream Jazzy's TFMessage.msg, with the venv's rosidl generators. Four processes over real DDS: a
robot publishing tf with tf2_ros' QoS (tests/tf_peers.py), ``skidsteer-power record`` writing an MCAP,
then ``skidsteer-power replay`` of that MCAP to a late-joining listener in another process. The
transforms the listener decodes with tf2_msgs' own class are compared with what the robot sent (the
formulas in tf_peers.py) and with the bag as rosbags decodes it (an independent CDR decoder).

Without the build (a user's venv made before it), replay skips both topics saying why:
test_bag_habits.py checks that path.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from rosbags.interfaces import QosDurability
from rosbags.typesys import Stores, get_typestore

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / 'test' / 'tf_peers.py'
JAZZY_TFMESSAGE_HASH = 'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087'
"""tf2_msgs/msg/TFMessage's type hash on ROS 2 Jazzy, as ``ros2 topic info -v /tf`` prints it for
the distribution's tf2_msgs (and as rosbag2 stores it in a Jazzy bag's metadata.yaml)."""
COUNT = 40  # /tf messages the robot sends (2 s at 20 Hz)
TIMEOUT_S = 120.0  # bound on each process (not a timing goal) [s]
WAIT_S = 6.0  # replay --wait-for-subscribers [s]: the late /tf_static subscriber makes every wait run out


def _require_tf2_msgs() -> None:
    if importlib.util.find_spec('tf2_msgs') is None:
        if os.environ.get('CI'):
            pytest.fail('tf2_msgs is not built into this venv: `make tf2-msgs` (make setup does it)')
        pytest.skip('tf2_msgs is not built into this venv: run `make tf2-msgs`')


def _env() -> dict[str, str]:
    return {**os.environ, 'PYTHONPATH': str(ROOT)}


def _cli(*args: str) -> list[str]:
    return [sys.executable, '-m', 'skidsteer_power.cli.main', *args]


def test_the_built_type_is_upstream_jazzys() -> None:
    """Same RIHS01 hash as Jazzy's tf2_msgs (rosidl computes it over the type and every type it
    nests), the same as rosbags computes from its own Jazzy definitions, and the DDS type name that
    rmw_fastrtps derives from the package and type names."""
    _require_tf2_msgs()
    from tf2_msgs.msg import TFMessage

    # installed beside the venv's other interface packages (sys.prefix: the ament prefix here)
    description = json.loads((Path(sys.prefix) / 'share' / 'tf2_msgs' / 'msg' / 'TFMessage.json').read_text())
    hashes = {entry['type_name']: entry['hash_string'] for entry in description['type_hashes']}
    assert hashes['tf2_msgs/msg/TFMessage'] == JAZZY_TFMESSAGE_HASH
    assert get_typestore(Stores.ROS2_JAZZY).hash_rihs01('tf2_msgs/msg/TFMessage') == JAZZY_TFMESSAGE_HASH
    assert TFMessage.__module__.startswith('tf2_msgs.msg') and TFMessage.__name__ == 'TFMessage'
    fields = TFMessage.get_fields_and_field_types()
    assert fields == {'transforms': 'sequence<geometry_msgs/TransformStamped>'}


def _record(bag: Path) -> None:
    """The robot's tf, recorded by ``skidsteer-power record /tf /tf_static``."""
    recorder = subprocess.Popen(
        _cli('record', '/tf', '/tf_static', '-o', str(bag), '--json'),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=_env(),
    )  # fmt: skip
    try:
        robot = subprocess.run(
            [sys.executable, str(PEERS), 'publish', str(COUNT)],
            capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=TIMEOUT_S,
        )  # fmt: skip
        assert robot.returncode == 0, robot.stderr
    finally:
        recorder.send_signal(signal.SIGINT)
        out, err = recorder.communicate(timeout=TIMEOUT_S)
    assert recorder.returncode == 0, err
    assert json.loads(out)['counts'] == {'/tf': COUNT, '/tf_static': 1}, out


def _bag_messages(bag: Path) -> tuple[dict[str, list[list[dict[str, Any]]]], dict[str, Any]]:
    """Each topic's messages as rosbags decodes them, and its stored QoS profiles."""
    from rosbags.highlevel import AnyReader
    from tf_peers import as_dicts

    store = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([bag], default_typestore=store) as reader:
        messages: dict[str, list[list[dict[str, Any]]]] = {'/tf': [], '/tf_static': []}
        for connection, _, raw in reader.messages():
            assert connection.msgtype == 'tf2_msgs/msg/TFMessage'
            messages[connection.topic].append(as_dicts(reader.deserialize(raw, connection.msgtype)))
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}  # type: ignore[union-attr]
    return messages, qos


def _replay_to_listener(
    bag: Path, tf_count: int, static_count: int, *replay_args: str
) -> tuple[dict[str, Any], dict[str, Any]]:
    """``replay BAG --json`` to a tf_peers.py listener in another process: both outputs, parsed."""
    listener = subprocess.Popen(
        [sys.executable, str(PEERS), 'listen', str(tf_count), str(static_count)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=_env(),
    )  # fmt: skip
    try:
        assert listener.stdout is not None and listener.stdout.readline().strip() == 'ready'
        # waits (WAIT_S) for /tf's listener; /tf_static has none until the listener's 5th /tf
        # message, so the wait always runs out: WAIT_S is the listener's time to match on a loaded CI
        replay = subprocess.run(
            _cli('replay', str(bag), '--json', '--wait-for-subscribers', str(WAIT_S), *replay_args),
            capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=TIMEOUT_S,
        )  # fmt: skip
        out, err = listener.communicate(timeout=TIMEOUT_S)
    finally:
        if listener.poll() is None:
            listener.kill()
            listener.communicate()
    assert replay.returncode == 0, replay.stderr
    assert listener.returncode == 0, err
    heard: dict[str, Any] = json.loads(out)
    result: dict[str, Any] = json.loads(replay.stdout)
    return result, heard


def _assert_genuine_on_graph(heard: dict[str, Any]) -> None:
    """The listener saw the replay's publishers as tf2_msgs/msg/TFMessage with Jazzy's hash, /tf
    volatile and /tf_static transient-local."""
    for topic, durability in (('/tf', 'VOLATILE'), ('/tf_static', 'TRANSIENT_LOCAL')):
        publishers = heard['graph'][topic]
        assert [p['node'] for p in publishers] == ['skidsteer_replay'], publishers
        assert publishers[0]['type'] == 'tf2_msgs/msg/TFMessage'
        assert publishers[0]['type_hash'] == JAZZY_TFMESSAGE_HASH
        assert publishers[0]['durability'] == durability


def test_recorded_tf_replays_as_tfmessage_to_a_late_listener(tmp_path: Path) -> None:
    """record -> MCAP -> replay -> a listener with tf2_msgs' class: every transform as sent, the
    static ones reaching a listener that subscribed after they were published (transient-local,
    as the robot offered them and the bag stored), and the genuine type and hash on the graph."""
    _require_tf2_msgs()
    from tf_peers import LATE_AFTER, as_dicts, static_message, tf_message

    bag = tmp_path / 'tf.mcap'
    _record(bag)
    in_bag, stored_qos = _bag_messages(bag)
    sent_tf = [as_dicts(tf_message(k)) for k in range(COUNT)]
    sent_static = [as_dicts(static_message())]
    assert in_bag == {'/tf': sent_tf, '/tf_static': sent_static}
    assert [p.durability for p in stored_qos['/tf_static']] == [QosDurability.TRANSIENT_LOCAL]
    assert [p.durability for p in stored_qos['/tf']] == [QosDurability.VOLATILE]

    result, heard = _replay_to_listener(bag, COUNT, 1)
    assert result['skipped'] == {} and result['counts'] == {'/tf': COUNT, '/tf_static': 1}
    assert heard['received'] == {'/tf': sent_tf, '/tf_static': sent_static}
    # late: subscribed after 5 /tf messages, all of which the bag has after the static one
    assert heard['static_subscribed_after'] >= LATE_AFTER
    _assert_genuine_on_graph(heard)


def test_a_real_robots_tf_replays_to_a_late_listener(neato_bag: Path) -> None:
    """The Neato's bag (../shared/realbags/neato-teleop: real rosbag2, real tf2_ros; its /tf_static
    from two static broadcasters, both stored transient-local): its first 3 s of /tf and both
    /tf_static messages reach a listener subscribed late to /tf_static, as rosbags decodes them."""
    _require_tf2_msgs()
    from rosbags.highlevel import AnyReader
    from tf_peers import LATE_AFTER, as_dicts

    store = get_typestore(Stores.ROS2_JAZZY)
    expected: dict[str, list[list[dict[str, Any]]]] = {'/tf': [], '/tf_static': []}
    with AnyReader([neato_bag], default_typestore=store) as reader:
        connections = [c for c in reader.connections if c.topic in expected]
        stop = reader.start_time + 3_000_000_000
        for connection, _, raw in reader.messages(connections=connections, stop=stop):
            expected[connection.topic].append(as_dicts(reader.deserialize(raw, connection.msgtype)))
    assert len(expected['/tf']) > 3 * LATE_AFTER and len(expected['/tf_static']) == 2
    result, heard = _replay_to_listener(
        neato_bag, len(expected['/tf']), 2, '--topics', '/tf', '/tf_static', '--duration', '3'
    )
    assert result['counts'] == {t: len(v) for t, v in expected.items()}
    assert heard['received'] == expected and heard['static_subscribed_after'] >= LATE_AFTER
    _assert_genuine_on_graph(heard)


def test_tf_static_without_stored_qos_is_replayed_transient_local(tmp_path: Path) -> None:
    """A bag written without QoS metadata (rosbags' writer, as other tools write bags): /tf_static
    is replayed transient-local anyway (tf2_ros' static broadcaster always offers it), /tf volatile."""
    from rclpy.qos import DurabilityPolicy

    from skidsteer_power.bag_io.replay import replay_qos

    assert replay_qos('/tf_static', []).durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert replay_qos('/tf', []).durability == DurabilityPolicy.VOLATILE
