"""Record and replay on a real ROS graph (rclpy + Fast DDS): byte identity, order, signals, real bag."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from rclpy.context import Context

from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io.reader import BagMessage
from skidsteer_power.bag_io.record import Recorder, RecordResult, record
from skidsteer_power.bag_io.replay import Replayer, ReplayOptions, deadlines
from skidsteer_power.bag_io.synthetic import START_NS
from skidsteer_power.bag_io.writer import BagWriter
from skidsteer_power.stop_signals import StopFlag

pytestmark = pytest.mark.ros


def _unique(name: str) -> str:
    return f'/bagtest_{uuid.uuid4().hex[:8]}_{name}'


class BackgroundRecording:
    """``record()`` in a thread with its own context; :meth:`finish` stops it and returns the result."""

    def __init__(self, path: Path, topics: list[str]) -> None:
        self.stop = StopFlag()
        self.ready = threading.Event()
        self.recorder: Recorder | None = None
        self.result: RecordResult | None = None
        self.error: BaseException | None = None

        def on_ready(recorder: Recorder) -> None:
            self.recorder = recorder
            self.ready.set()

        def run() -> None:
            try:
                self.result = record(path, topics, stop=self.stop, on_ready=on_ready)
            except BaseException as err:
                self.error = err
                self.ready.set()

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()
        assert self.ready.wait(20), 'recorder did not start'

    def finish(self) -> RecordResult:
        self.stop.set('test')
        self.thread.join(30)
        assert not self.thread.is_alive(), 'recorder did not stop'
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result


def _wait_for(predicate: Callable[[], bool], timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, 'timed out waiting for the ROS graph'
        time.sleep(0.01)


def _contents(path: Path) -> list[tuple[str, bytes]]:
    with open_bag(path) as bag:
        return [(m.topic, m.data) for m in bag.messages()]


def test_record_replay_record_keeps_every_message_byte_identical_and_in_order(
    ros_context: Context, tmp_path: Path
) -> None:
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    topics = {_unique('cmd'): Twist, _unique('js'): JointState, _unique('text'): String}
    node = __import__('rclpy').create_node('bag_live_publisher', context=ros_context)
    publishers = {t: node.create_publisher(cls, t, 100) for t, cls in topics.items()}
    names = list(topics)
    first = BackgroundRecording(tmp_path / 'first.mcap', names)
    _wait_for(lambda: all(p.get_subscription_count() > 0 for p in publishers.values()))
    sent = []
    for i in range(150):  # 3 topics interleaved, 4 ms apart: order across topics is meaningful
        topic = names[i % 3]
        msg = topics[topic]()
        if isinstance(msg, Twist):
            msg.linear.x, msg.angular.z = 0.001 * i, -0.002 * i
        elif isinstance(msg, JointState):
            msg.name, msg.velocity, msg.effort = (
                ['left_motor', 'right_motor'],
                [1.0 * i, -2.0],
                [0.1, 0.2 * i],
            )
        else:
            msg.data = f'message {i} ' + 'é' * (i % 7)
        publishers[topic].publish(msg)
        sent.append(topic)
        time.sleep(0.004)
    first.finish()
    node.destroy_node()
    recorded = _contents(tmp_path / 'first.mcap')
    assert [t for t, _ in recorded] == sent

    second = BackgroundRecording(tmp_path / 'second.mcap', names)
    with open_bag(tmp_path / 'first.mcap') as bag:
        import rclpy

        replay_node = rclpy.create_node('bag_replayer', context=ros_context)
        result = Replayer(bag, replay_node, ReplayOptions(wait_for_subscribers_s=20)).run()
        replay_node.destroy_node()
    second.finish()
    assert result.message_count == 150
    assert _contents(tmp_path / 'second.mcap') == recorded


def test_replay_deadlines_follow_bag_stamps_scaled_by_rate() -> None:
    stamps = [START_NS, START_NS + 10_000_000, START_NS + 25_000_000, START_NS + 1_000_000_000]
    # Hand calculation: offsets 0, 0.010, 0.025, 1.0 s; at rate 2 they halve; t0 = 5 s is added.
    assert np.allclose(deadlines(stamps, START_NS, rate=2.0, t0=5.0), [5.0, 5.005, 5.0125, 5.5], atol=1e-12)
    assert np.allclose(deadlines(stamps, START_NS + 10_000_000, rate=1.0), [-0.01, 0.0, 0.015, 0.99])


def _string_bag(path: Path, topic: str, n: int, spacing_ns: int) -> list[bytes]:
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    data = [serialize_message(String(data=f'n{i}')) for i in range(n)]
    with BagWriter(path) as writer:
        conn = writer.add_topic(topic, 'std_msgs/msg/String')
        for i, raw in enumerate(data):
            writer.write(conn, START_NS + i * spacing_ns, raw)
    return data


def test_replay_publishes_at_or_after_each_deadline_in_bag_order(
    ros_context: Context, tmp_path: Path
) -> None:
    import rclpy

    topic = _unique('timed')
    _string_bag(tmp_path / 't.mcap', topic, 40, 5_000_000)
    node = rclpy.create_node('bag_timed_replayer', context=ros_context)
    with open_bag(tmp_path / 't.mcap') as bag:
        result = Replayer(bag, node, ReplayOptions(rate=2.0)).run(keep_log=True)
    node.destroy_node()
    due = np.array([d for _, d, _ in result.log])
    published = np.array([p for _, _, p in result.log])
    # Deadlines are the bag's 5 ms spacing at rate 2: 2.5 ms apart; never published early.
    assert np.allclose(np.diff(due), 0.0025, atol=1e-9)
    assert np.all(published >= due)
    assert result.counts == {topic: 40}


def test_start_duration_and_topics_select_the_window(ros_context: Context, tmp_path: Path) -> None:
    import rclpy

    topic = _unique('window')
    _string_bag(tmp_path / 'w.mcap', topic, 100, 10_000_000)  # 0 .. 0.99 s
    node = rclpy.create_node('bag_window_replayer', context=ros_context)
    seen = []
    with open_bag(tmp_path / 'w.mcap') as bag:
        options = ReplayOptions(rate=10.0, start_s=0.2, duration_s=0.3, topics=[topic])
        Replayer(bag, node, options).run(on_message=lambda m: seen.append(m.timestamp_ns))
    node.destroy_node()
    # [0.2 s, 0.5 s) of 10 ms spaced messages: stamps 20 .. 49.
    assert seen == [START_NS + i * 10_000_000 for i in range(20, 50)]


def test_loop_and_clock(ros_context: Context, tmp_path: Path) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock

    topic = _unique('loop')
    _string_bag(tmp_path / 'l.mcap', topic, 20, 10_000_000)  # 0.19 s of bag
    listener = rclpy.create_node('bag_clock_listener', context=ros_context)
    clocks: list[int] = []

    def on_clock(m: Clock) -> None:
        clocks.append(m.clock.sec * 10**9 + m.clock.nanosec)

    listener.create_subscription(Clock, '/clock', on_clock, 100)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(listener)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    node = rclpy.create_node('bag_loop_replayer', context=ros_context)
    stop = StopFlag()
    published: list[int] = []

    def count(message: BagMessage) -> None:
        published.append(message.timestamp_ns)
        if len(published) == 60:
            stop.set('test')

    with open_bag(tmp_path / 'l.mcap') as bag:
        replayer = Replayer(bag, node, ReplayOptions(loop=True, clock=True, clock_hz=100.0))
        clock_pub = replayer._clock_pub
        assert clock_pub is not None
        _wait_for(lambda: clock_pub.get_subscription_count() > 0)
        result = replayer.run(stop, on_message=count)
    time.sleep(0.2)
    executor.shutdown()
    spinner.join(5)
    node.destroy_node()
    listener.destroy_node()
    assert result.passes == 3
    assert published == [START_NS + i * 10_000_000 for i in range(20)] * 3
    # /clock carries bag time: inside the bag's span (one 10 ms tick of slack at a pass's end).
    assert len(clocks) >= 20
    assert min(clocks) >= START_NS and max(clocks) <= START_NS + 200_000_000


def _cli(*args: str) -> list[str]:
    return [sys.executable, '-m', 'skidsteer_power.cli.main', *args]


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_recording_cleanly_without_losing_messages(
    ros_context: Context, tmp_path: Path, signum: signal.Signals
) -> None:
    import rclpy
    from std_msgs.msg import String

    topic = _unique('sig')
    node = rclpy.create_node('bag_signal_publisher', context=ros_context)
    pub = node.create_publisher(String, topic, 1000)
    out = tmp_path / 'sig.mcap'
    proc = subprocess.Popen(
        _cli('record', '-o', str(out), topic, '--json'),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=dict(os.environ),
        text=True,
    )
    try:
        _wait_for(lambda: pub.get_subscription_count() > 0 or proc.poll() is not None, timeout=30)
        assert proc.stderr is not None
        assert proc.poll() is None, proc.stderr.read()
        for i in range(300):  # as fast as possible, then the signal at once
            pub.publish(String(data=f'm{i}'))
        proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout)
    assert summary['stopped_by'] == signal.Signals(signum).name
    assert summary['counts'] == {topic: 300}
    from rclpy.serialization import deserialize_message

    # DDS delivers the CDR padded to 4 bytes, so compare contents, in order.
    assert [deserialize_message(d, String).data for _, d in _contents(out)] == [f'm{i}' for i in range(300)]
    assert not (tmp_path / 'sig.mcap.partial').exists()


def test_real_bag_replays_through_the_cli_byte_for_byte(
    neato_bag: Path, ros_context: Context, tmp_path: Path
) -> None:
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import LaserScan

    listener = rclpy.create_node('bag_real_listener', context=ros_context)
    received: dict[str, list[bytes]] = {'/cmd_vel': [], '/scan': [], '/odom': []}
    for topic, msg_class in (('/cmd_vel', Twist), ('/scan', LaserScan), ('/odom', Odometry)):
        listener.create_subscription(msg_class, topic, received[topic].append, 1000, raw=True)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(listener)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    # 14.8-16.9 s of the bag holds the (0.3 m/s, -1 rad/s) command: teleop traffic on both topics.
    args = ['replay', str(neato_bag), '--topics', *received, '--start', '14.5', '--duration', '2.5']
    run = subprocess.run(
        _cli(*args, '--rate', '2', '--wait-for-subscribers', '20', '--json'),
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ),
    )
    time.sleep(0.3)
    executor.shutdown()
    spinner.join(5)
    listener.destroy_node()
    assert run.returncode == 0, run.stderr
    with open_bag(neato_bag, warn_unknown=False) as bag:
        start = bag.start_ns + 14_500_000_000
        expected = {
            t: [m.data for m in bag.messages([t], start_ns=start, stop_ns=start + 2_500_000_000)]
            for t in received
        }
    assert len(expected['/cmd_vel']) > 20 and len(expected['/scan']) > 5 and len(expected['/odom']) > 5
    assert json.loads(run.stdout)['counts'] == {t: len(v) for t, v in expected.items()}
    assert {t: len(v) for t, v in received.items()} == {t: len(v) for t, v in expected.items()}
    assert received == expected


def test_real_bag_replay_skips_types_without_python_support_with_a_warning(
    neato_bag: Path, ros_context: Context
) -> None:
    import rclpy

    node = rclpy.create_node('bag_real_skipper', context=ros_context)
    with open_bag(neato_bag, warn_unknown=False) as bag:
        replayer = Replayer(bag, node, ReplayOptions())
    node.destroy_node()
    assert {'/accel', '/bump'} <= set(replayer.skipped)
    assert 'neato2_interfaces/msg/Accel is not installed' in replayer.skipped['/accel']
    assert {'/cmd_vel', '/scan', '/stable_scan', '/fsm/state'} <= set(replayer.publishers)
