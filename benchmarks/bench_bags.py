"""Bags: offline validate throughput; replay rate and timing against the bag, measured by a recorder.

    python -m benchmarks.run bags

Replay figures use two processes: this one replays, ``skidsteer-power record`` (a subprocess, with its
own interpreter) records, and the recorded receive times are compared with the bag's times.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.harness import Report

os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(101, 200)))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

VEHICLE, TERRAIN = 'test_robot_track', 'sand_bin'


def _validate_throughput(report: Report, folder: Path) -> None:
    from skidsteer_power.bags import open_bag
    from skidsteer_power.bags.synthetic import Segment, write_drive_bag
    from skidsteer_power.bags.validate import ValidateOptions, validate
    from skidsteer_power.estimator import factory

    # Ten minutes of the Table 7.3 commands (V 0.1/0.2 m/s, yaw rates 0-0.35 rad/s), 100 Hz.
    yaw_rates = [0.0, 0.01, 0.02, 0.04, 0.08, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35]
    runs = [Segment(v, r, 600 / 22) for v in (0.1, 0.2) for r in yaw_rates]
    bag_path = folder / 'ten_minutes.mcap'
    write_drive_bag(bag_path, runs, rate_hz=100, odom_hz=10)
    vehicle = factory.load_vehicle_config(VEHICLE)
    predictor, _, _ = factory.map_predictor(vehicle, TERRAIN, folder / 'maps')  # built once, not timed
    options = ValidateOptions(VEHICLE, TERRAIN, folder / 'report', map_cache_dir=folder / 'maps')
    with open_bag(bag_path) as bag:
        messages = bag.message_count
        duration = bag.duration_s
        start = time.perf_counter()
        summary = validate(bag, options)
        wall = time.perf_counter() - start
    report.figure('validate, 10 min 100 Hz bag: messages', messages, 'msgs')
    report.figure('validate throughput (with report and plots)', messages / wall, 'msg/s')
    report.figure(
        'validate speed (with report and plots)',
        duration / wall,
        'x real',
        goal='>= 100x real time',
        met=duration / wall >= 100,
    )
    report.figure('validate speed (estimator run only, no files)', summary['real_time_factor'], 'x real')
    del predictor


def _record_subprocess(out: Path, topics: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'record', '-o', str(out), *topics, '--json'],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _replay_against_recorder(bag_path: Path, out: Path, topics: list[str], context) -> tuple:
    import rclpy

    from skidsteer_power.bags import open_bag
    from skidsteer_power.bags.replay import Replayer, ReplayOptions

    recorder = _record_subprocess(out, topics)
    node = rclpy.create_node('bench_replayer', context=context)
    try:
        with open_bag(bag_path) as bag:
            replayer = Replayer(bag, node, ReplayOptions(wait_for_subscribers_s=30))
            result = replayer.run(keep_log=True)
            expected = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
        time.sleep(0.5)
        recorder.send_signal(2)
        recorder.communicate(timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.destroy_node()
    with open_bag(out) as bag:
        received = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
    return result, expected, received


def _string_bag(path: Path, topics: list[str], rate_hz: float, seconds: float) -> None:
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from skidsteer_power.bags.synthetic import START_NS
    from skidsteer_power.bags.writer import BagWriter

    step = round(1e9 / rate_hz)
    n = round(seconds * rate_hz)
    with BagWriter(path) as writer:
        conns = [writer.add_topic(t, 'std_msgs/msg/String') for t in topics]
        for i in range(n):
            for k, conn in enumerate(conns):  # topics offset within the period: evenly spread
                stamp = START_NS + i * step + k * step // len(conns)
                writer.write(conn, stamp, serialize_message(String(data=f'{k}:{i}:' + 'x' * 64)))


def _timing_errors(expected: list, received: list, topics: list[str]) -> np.ndarray | None:
    """|recorded - bag| message times after removing the median offset [s], matched per topic by
    position; None if a topic lost, gained or changed a message (DDS pads the CDR to 4 bytes, so the
    stored bytes must be a prefix of the received ones)."""
    bag_t, rec_t = [], []
    for topic in topics:
        sent = [m for m in expected if m[0] == topic]
        got = [m for m in received if m[0] == topic]
        if len(sent) != len(got) or not all(b[2].startswith(a[2]) for a, b in zip(sent, got, strict=True)):
            return None
        bag_t += [m[1] for m in sent]
        rec_t += [m[1] for m in got]
    delta = (np.array(rec_t, dtype=float) - np.array(bag_t, dtype=float)) / 1e9
    return np.abs(delta - np.median(delta))


def _replay_figures(report: Report, folder: Path) -> None:
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        topics = [f'/bench_rate_{k}' for k in range(4)]
        _string_bag(folder / 'rate.mcap', topics, 500, 5.0)  # 4 x 500 Hz = 2 kHz aggregate
        result, expected, received = _replay_against_recorder(
            folder / 'rate.mcap', folder / 'rate_rec.mcap', topics, context
        )
        published = np.array([p for _, _, p in result.log])
        achieved = (len(published) - 1) / (published[-1] - published[0])
        late = result.late_s
        report.figure(
            'replay: aggregate rate achieved (bag: 2000 msg/s)',
            achieved,
            'msg/s',
            goal='>= 2000',
            met=achieved >= 1990,
        )
        report.figure(
            'replay at 2 kHz: publish lateness p99',
            float(np.percentile(late, 99)) * 1e3,
            'ms',
            goal='<= 5',
            met=float(np.percentile(late, 99)) <= 0.005,
        )
        report.figure('replay at 2 kHz: publish lateness max', float(late.max()) * 1e3, 'ms')
        report.figure(
            'replay at 2 kHz: messages recorded / published',
            len(received) / len(expected),
            'ratio',
            goal='1',
            met=len(received) == len(expected),
        )

        topics = ['/bench_timing_cmd', '/bench_timing_js']
        _string_bag(folder / 'timing.mcap', topics, 100, 10.0)
        _, expected, received = _replay_against_recorder(
            folder / 'timing.mcap', folder / 'timing_rec.mcap', topics, context
        )
        errors = _timing_errors(expected, received, topics)
        if errors is None:
            report.figure(
                'replay timing vs bag: messages recorded / published',
                len(received) / len(expected),
                'ratio',
                goal='1',
                met=False,
            )
        else:
            worst = float(errors.max())
            report.figure(
                'replay timing vs bag (recorded in another process): max |error|',
                worst * 1e3,
                'ms',
                goal='<= 5',
                met=worst <= 0.005,
            )
            report.figure('replay timing vs bag: p99 |error|', float(np.percentile(errors, 99)) * 1e3, 'ms')
    finally:
        rclpy.try_shutdown(context=context)


def run(report: Report) -> None:
    with tempfile.TemporaryDirectory(prefix='bench_bags_') as tmp:
        folder = Path(tmp)
        _validate_throughput(report, folder)
        _replay_figures(report, folder)
