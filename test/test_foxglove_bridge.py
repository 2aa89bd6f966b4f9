"""``skidsteer-power bridge`` end to end: a real power_estimator publishes, the bridge runs in its own
process (foxglove-sdk WebSocket server on a loopback port), and a WebSocket client speaking the
Foxglove protocol (v1 frames; subprotocol foxglove.sdk.v1, see SUBPROTOCOLS) subscribes to power
channels, receives messages and decodes them with nothing but the advertised ros2msg schema
(rosbags, empty type store).

Protocol (Foxglove WebSocket protocol v1, server side as foxglove-sdk implements it): JSON text
frames ``serverInfo`` and ``advertise`` (channels: id, topic, encoding, schemaName, schema,
schemaEncoding); the client sends ``subscribe`` with its own subscription ids; each message is a
binary frame: opcode 0x01, uint32 subscription id, uint64 log time [ns], then the payload (CDR).
"""

from __future__ import annotations

import json
import math
import os
import signal
import struct
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from geometry_msgs.msg import Twist
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from test_estimator_core import FixedPowerPredictor
from websockets.sync import client as websockets_sync  # requirements.txt
from websockets.typing import Subprotocol

from skidsteer_power.nodes.power_estimator import PowerEstimator

MESSAGE_DATA = struct.Struct('<BIQ')  # opcode 0x01, subscription id, log time [ns]
# What the Foxglove app offers; the bridge picks the first (foxglove-sdk's name for protocol v1) and
# also serves clients offering only the second (test_foxglove_security.py).
SUBPROTOCOLS = [Subprotocol('foxglove.sdk.v1'), Subprotocol('foxglove.websocket.v1')]


@pytest.fixture
def estimator_graph(ros_context: Context, tmp_path: Path) -> Iterator[str]:
    namespace = f'fox_{uuid.uuid4().hex[:8]}'
    estimator = PowerEstimator(
        FixedPowerPredictor(80.0),
        namespace=namespace,
        context=ros_context,
        parameter_overrides=[Parameter('persist', value=False), Parameter('publish_period_s', value=0.1)],
    )
    teleop = rclpy.create_node('teleop', namespace=namespace, context=ros_context)
    pub = teleop.create_publisher(Twist, 'cmd_vel', 10)
    command = Twist()
    command.linear.x = 0.2
    teleop.create_timer(0.05, lambda: pub.publish(command))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(estimator)
    executor.add_node(teleop)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    yield namespace
    executor.shutdown()
    spinner.join(5)
    teleop.destroy_node()
    estimator.destroy_node()


def start_bridge(topics: list[str]) -> tuple[subprocess.Popen[str], str]:
    argv = [sys.executable, '-m', 'skidsteer_power.cli.main', 'bridge', '--host', '127.0.0.1', '--port', '0']
    proc = subprocess.Popen([*argv, '--topics', *topics, '--json'], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    assert proc.stderr is not None
    seen = []  # 'serving ws://127.0.0.1:PORT' (stderr with --json), after any DDS log lines
    for line in proc.stderr:
        if line.startswith('serving ws://'):
            return proc, line.split()[1]
        seen.append(line)
        if len(seen) > 20:
            break
    proc.kill()
    proc.wait()
    pytest.fail(f'bridge did not start: {"".join(seen)}')


def test_a_foxglove_client_receives_and_decodes_power_messages(estimator_graph: str) -> None:
    ns = estimator_graph
    wanted = {f'/{ns}/power/predicted_left_w': 'std_msgs/msg/Float64',
              f'/{ns}/battery/state': 'sensor_msgs/msg/BatteryState'}  # fmt: skip
    proc, url = start_bridge([*wanted, f'/{ns}/power/summary'])
    try:
        with websockets_sync.connect(url, subprotocols=SUBPROTOCOLS, open_timeout=20) as ws:
            assert ws.subprotocol == 'foxglove.sdk.v1'
            channels: dict[str, dict[str, Any]] = {}  # advertised channels (JSON) by topic
            deadline = time.monotonic() + 30
            while not set(wanted) <= set(channels):
                assert time.monotonic() < deadline, f'advertised only {sorted(channels)}'
                frame = ws.recv(timeout=30)
                if isinstance(frame, str):
                    op = json.loads(frame)
                    if op['op'] == 'advertise':
                        channels.update({c['topic']: c for c in op['channels']})
            subscriptions = {}
            for k, topic in enumerate(wanted, 1):
                channel = channels[topic]
                assert channel['encoding'] == 'cdr' and channel['schemaEncoding'] == 'ros2msg'
                assert channel['schemaName'] == wanted[topic]
                subscriptions[k] = channel
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': k, 'channelId': c['id']} for k, c in subscriptions.items()]}))  # fmt: skip
            decoded: dict[str, list[Any]] = {c['topic']: [] for c in subscriptions.values()}
            while not all(len(v) >= 2 for v in decoded.values()):
                assert time.monotonic() < deadline, {k: len(v) for k, v in decoded.items()}
                frame = ws.recv(timeout=30)
                if isinstance(frame, str):
                    status = json.loads(frame)
                    if status['op'] == 'status' and 'Unknown channel ID' in status['message']:
                        # foxglove-sdk 0.30.3 may refuse a subscription that follows the channel's
                        # advertisement too closely; a client (as the app does) subscribes again
                        time.sleep(0.2)
                        ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                            {'id': k, 'channelId': c['id']} for k, c in subscriptions.items()
                            if not decoded[c['topic']]]}))  # fmt: skip
                    continue
                opcode, sub_id, log_time_ns = MESSAGE_DATA.unpack_from(frame)
                assert opcode == 0x01 and abs(log_time_ns * 1e-9 - time.time()) < 60
                channel = subscriptions[sub_id]
                store = get_typestore(Stores.EMPTY)  # the advertised schema alone must decode it
                store.register(get_types_from_msg(channel['schema'], channel['schemaName']))
                message = store.deserialize_cdr(bytes(frame[MESSAGE_DATA.size :]), channel['schemaName'])
                decoded[channel['topic']].append(message)
        # FixedPowerPredictor(80 W): 40 W per side for every command (test_estimator_core)
        left = decoded[f'/{ns}/power/predicted_left_w'][-1]
        assert left.data == pytest.approx(FixedPowerPredictor(80.0).predict(0.2, 0.0).electrical_W[0])
        battery = decoded[f'/{ns}/battery/state'][-1]
        assert battery.present and math.isnan(battery.temperature) and battery.percentage <= 1.0
        assert battery.current < 0  # 80 W drawn: discharging
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    report = json.loads(out[out.index('{\n') :])  # Fast DDS may log to stdout before it
    assert report['topics'][f'/{ns}/power/predicted_left_w'] > 0
    assert set(report['topics']) == {*wanted, f'/{ns}/power/summary'} and not report['skipped']


def test_bad_port_is_one_clear_error() -> None:
    run = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'bridge', '--port', '70000'],
        capture_output=True, text=True, timeout=60, env={**os.environ},
    )  # fmt: skip
    assert run.returncode == 2 and 'port must be 0..65535' in run.stderr and 'Traceback' not in run.stderr


def test_the_shipped_layout_is_the_generated_one_and_reads_published_topics() -> None:
    """config/foxglove/operator_layout.json is foxglove-sdk layout output (python -m
    skidsteer_power.ui.foxglove_layout), and every topic a panel reads is one the suite publishes
    (odometry comes from the robot's own odometry source)."""
    from skidsteer_power import resources
    from skidsteer_power.estimator.summary import COMMAND_FIGURES, MEASUREMENT_FIGURES
    from skidsteer_power.ui.foxglove_layout import layout_json, topics_used

    shipped = resources.find('foxglove', 'operator_layout', ('.json',)).read_text(encoding='utf-8')
    assert shipped == layout_json()
    published = {f'/{topic}' for topic, _ in (*COMMAND_FIGURES, *MEASUREMENT_FIGURES)}
    published |= {'/battery/state', '/energy/time_to_empty_s', '/energy/remaining_wh', '/odom'}
    published |= {'/energy/path_required_wh', '/energy/path_margin_wh'}  # nodes/path_hook.py
    used = topics_used(shipped)
    assert used <= published and {'/power/predicted_left_w', '/power/measured_right_w'} <= used


def test_latched_topics_reach_the_bridge_and_others_match_any_publisher(ros_context: Context) -> None:
    """A transient-local message published before the bridge starts still reaches its channel; a
    best-effort (sensor-data) publisher matches too. In-process bridge (real rclpy + foxglove-sdk)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    ns = f'/latch_{uuid.uuid4().hex[:6]}'
    node = rclpy.create_node('latch_probe', context=ros_context)
    latched = node.create_publisher(
        String, f'{ns}/robot_description', QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    latched.publish(String(data='<robot/>'))
    sensor = node.create_publisher(JointState, f'{ns}/joint_states', qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    bridge = FoxgloveBridge(
        node, host='127.0.0.1', port=0, topics=[f'{ns}/robot_description', f'{ns}/joint_states']
    )
    try:
        deadline = time.monotonic() + 20
        while not (len(bridge.forwarded) == 2 and all(f.messages for f in bridge.forwarded.values())):
            assert time.monotonic() < deadline, {t: f.messages for t, f in bridge.forwarded.items()}
            sensor.publish(JointState(name=['left_motor'], velocity=[1.0]))
            executor.spin_once(timeout_sec=0.05)
        assert bridge.forwarded[f'{ns}/robot_description'].messages == 1  # the latched one, published once
    finally:
        bridge.close()
        executor.shutdown()
        node.destroy_node()
