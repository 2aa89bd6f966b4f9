"""power_estimator under load: a fresh command on every message, plus joint_states at the same rate.

The node runs in its own process (as on the robot: ``python -m skidsteer_power.nodes.power_estimator``
with the real FESS map of the test robot on dry sand, spun by its own ``main``); this process
publishes the inputs from its main thread and receives the outputs on the same node, spun in a second
thread. Every input's header stamp is its send time and both outputs copy it (power/predicted the
TwistStamped's, power/measured the joint_states'), so each output is matched to its input and its
latency is receive time - stamp. The receiver takes the outputs raw and reads only the stamp out of
the CDR bytes, with the lean executor, so its own Python cost stays small next to the node's.

Commands are a random-walk joystick (V in 0...0.4 m/s, yaw rate in -0.6...0.6 rad/s, a new value on
every message), so the predictor's cache never answers: the realistic worst case while commands
change. The cache-hit case (two alternating commands) is reported separately and labelled so, and
so is the held case at 1 kHz: two Table 7.3-like commands held 2.5 s each, joint_states at their
predicted motor speeds and 1.2 x their predicted torques, so the online adaptation settles and runs
on every joint_states (the correction scale it learned is reported, to show that it did).

"Lost" counts inputs with no output within 3 s after the last send (loss anywhere on the way counts).
Latency includes DDS both ways and the receiver's Python path, so it is an upper bound for the node
alone. CPU: the node process's user + system time from the first send until its last output arrived,
over that wall time (so idle time after the work is not averaged in), and per input message; the
node's idle CPU (timers only) is reported before the runs. On this shared 2-core machine the figures
depend on what else runs: the 1-minute load average is noted with each run.

The floor: the same runs are first made against benchmarks/echo_node.py, a node with the estimator's
inputs, outputs and executor and no work between them, and the ratio power_estimator / floor of the
node CPU is reported per rate. What the floor costs is rclpy and Fast DDS on this machine: a goal
below it cannot be met by any estimator code. For reference, the same echo written as plain rclpy
code (rclpy messages, rclpy's executor: ``echo_node --stock``) is measured too, with the ratio
power_estimator / stock echo.

Same-run before/after: with ``ESTIMATOR_BASELINE_SRC=/path/to/other/checkout`` the same runs are made
against that checkout's node first (``python -m`` from that directory), and the ratios current /
baseline of CPU per message and p99 latency are reported.
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from benchmarks.harness import Report

RATES_HZ = (50.0, 100.0, 200.0, 1000.0)
SECONDS = 5.0
DRAIN_S = 3.0  # after the last send, how long outputs may still arrive [s]
GOALS = {  # rate [Hz] -> (p99 latency [ms], CPU [cores], lost messages allowed or None)
    100.0: (2.0, 0.05, None),
    1000.0: (5.0, 0.5, 0),
}
OUTPUTS = ('power/predicted', 'power/measured')
FLOOR = 'FLOOR (echo node: same inputs, outputs, executor; no estimator)'
STOCK = 'STOCK rclpy echo node (rclpy messages and executor; no estimator)'
BASELINE = 'baseline'
INPUT_OF = {'power/predicted': 'cmd_vel', 'power/measured': 'joint_states'}
FRESH, CACHE, HELD = 'fresh', 'cache', 'held'
LABEL = {FRESH: '', CACHE: ', CACHE HIT (2 alternating commands)', HELD: ', HELD (2 commands, 2.5 s each)'}
HELD_COMMANDS = ((0.2, 0.0), (0.15, 0.1))  # [m/s], [rad/s]: Table 7.3-like, no flag on the test robot
Held = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
"""A held command (V [m/s], yaw rate [rad/s]), its predicted motor speeds [rad/s] and torques [N m]."""


def _start_echo(namespace: str, env: dict[str, str], stock: bool = False) -> subprocess.Popen[str]:
    """benchmarks/echo_node.py: the same inputs, outputs and executor with no estimator (the floor);
    ``stock``: the same echo in plain rclpy (rclpy messages and executor)."""
    from skidsteer_power.nodes.spin import node_command

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return subprocess.Popen(
        node_command('benchmarks.echo_node', namespace) + (['--stock'] if stock else []),
        env=env,
        cwd=root,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def _start_node(
    namespace: str, cache_dir: str, env: dict[str, str], cwd: str | None = None
) -> subprocess.Popen[str]:
    from skidsteer_power.nodes.spin import node_command

    params = {'map_cache_dir': cache_dir, 'persist': 'false', 'cmd_vel_stamped': 'true', 'qos_depth': 1000}
    argv = node_command('skidsteer_power.nodes.power_estimator', namespace, params)
    return subprocess.Popen(
        argv, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )


def _cpu_seconds(pid: int) -> float:
    with open(f'/proc/{pid}/stat', encoding='ascii') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def cdr_stamp_s(data: bytes) -> float:
    """The header stamp [s] of a serialized message that starts with std_msgs/Header (JointState,
    TwistStamped): after the 4-byte CDR encapsulation header, int32 sec and uint32 nanosec."""
    little = data[1] & 1  # encapsulation kind: CDR_BE 0, CDR_LE 1
    sec: int
    nanosec: int
    sec, nanosec = struct.unpack_from('<iI' if little else '>iI', data, 4)  # two ints
    return sec + 1e-9 * nanosec


def _stamp_now(header: Any) -> float:
    now = time.time()
    header.stamp.sec, header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


class Load:
    """Input publisher (``receive=False``) or output receiver (``receive=True``) in one process."""

    def __init__(self, namespace: str, receive: bool = False) -> None:
        import rclpy
        from geometry_msgs.msg import TwistStamped
        from rclpy.context import Context
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState

        from skidsteer_power.nodes.spin import LeanExecutor

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('bench_load', namespace=namespace, context=self.context)
        qos = QoSProfile(depth=1000)
        self.pub_cmd = self.node.create_publisher(TwistStamped, 'cmd_vel', qos)
        self.pub_joint = self.node.create_publisher(JointState, 'joint_states', qos)
        # output topic -> [(input stamp [s], receive time [s])]
        self.received: dict[str, list[tuple[float, float]]] = {topic: [] for topic in OUTPUTS}
        self.sent: dict[str, set[float]] = {'cmd_vel': set(), 'joint_states': set()}  # input stamps [s]
        self.executor = LeanExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.subs = []
        self.correction: dict[str, float] = {}  # the last power/correction (names: values)
        if receive:
            self.correction_sub = self.node.create_subscription(  # not in subs: the echo node has none
                JointState, 'power/correction', self._on_correction, QoSProfile(depth=10)
            )
            for topic in OUTPUTS:
                self.subs.append(
                    self.node.create_subscription(
                        JointState, topic, self._receiver(self.received[topic]), qos, raw=True
                    )
                )
        self._msg_types = (TwistStamped, JointState)

    def _on_correction(self, msg: Any) -> None:
        self.correction = dict(zip(msg.name, msg.position, strict=True))

    @staticmethod
    def _receiver(into: list[tuple[float, float]]) -> Callable[[bytes], None]:
        def on_output(data: bytes) -> None:
            into.append((cdr_stamp_s(data), time.time()))

        return on_output

    def wait_connected(self, subscribers: int, timeout_s: float = 30.0) -> bool:
        """Wait until the node (and the receiver) subscribe to the inputs."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if (
                min(self.pub_cmd.get_subscription_count(), self.pub_joint.get_subscription_count())
                >= subscribers
            ):
                return True
            time.sleep(0.05)
        return False

    def receive_until(self, done: threading.Event, expected: int, drain_s: float) -> None:
        """Spin until ``done`` is set (the sender finished) and then every output topic has
        ``expected`` messages, or ``drain_s`` [s] passed since ``done``."""
        deadline = None
        while True:
            self.executor.spin_once(timeout_sec=0.05)
            if done.is_set():
                deadline = deadline or time.monotonic() + drain_s
                complete = min(len(v) for v in self.received.values()) >= expected
                if complete or time.monotonic() > deadline:
                    return

    def drive(
        self, rate_hz: float, seconds: float, *, mode: str = FRESH, held: Sequence[Held] = (), seed: int = 0
    ) -> int:
        """Publish both inputs at ``rate_hz`` for ``seconds``; returns the number sent of each.

        ``mode`` FRESH: a random-walk joystick, a new command on every message; CACHE: two alternating
        commands (every prediction after the first two is a cache hit); HELD: the ``held`` commands,
        each for an equal share of ``seconds``, with joint_states at their predicted motor speeds and
        1.2 x their predicted torques (the adaptation settles and learns). Each input's stamp is its
        send time (unique: the outputs are matched by it)."""
        twist_type, joint_type = self._msg_types
        period = 1.0 / rate_hz
        n = round(rate_hz * seconds)
        rng = np.random.default_rng(seed)
        steps = rng.normal(0.0, 1.0, (n, 2)) * (0.004, 0.006)
        speed, yaw = 0.2, 0.0
        cmd = twist_type()
        joint = joint_type(name=['left_motor', 'right_motor'], velocity=[300.0, 300.0], effort=[0.2, 0.2])
        for stamps in self.sent.values():
            stamps.clear()
        t0 = time.monotonic()
        for i in range(n):
            target = t0 + i * period
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            if mode == FRESH:  # reflect at the joystick's limits
                speed = 0.4 - abs(0.4 - abs(speed + steps[i, 0]))
                yaw = 0.6 - abs(0.6 - abs(yaw + steps[i, 1] + 0.6)) - 0.6
                cmd.twist.linear.x, cmd.twist.angular.z = float(speed), float(yaw)
            elif mode == CACHE:
                cmd.twist.linear.x, cmd.twist.angular.z = 0.2, 0.1 if i % 2 else 0.05
            else:
                (cmd.twist.linear.x, cmd.twist.angular.z), omega, torque = held[i * len(held) // n]
                joint.velocity, joint.effort = list(omega), [1.2 * t for t in torque]
            self.sent['cmd_vel'].add(_stamp_now(cmd.header))
            self.pub_cmd.publish(cmd)
            self.sent['joint_states'].add(_stamp_now(joint.header))
            self.pub_joint.publish(joint)
        return n

    def close(self) -> None:
        import rclpy.utilities

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.utilities.try_shutdown(context=self.context)


def _stop(process: subprocess.Popen[str]) -> None:
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def run(report: Report) -> None:
    from skidsteer_power.estimator.factory import map_predictor
    from skidsteer_power.vehicle import load_vehicle

    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    baseline = os.environ.get('ESTIMATOR_BASELINE_SRC')
    variants = [(FLOOR, None), (STOCK, None)] + ([(BASELINE, baseline)] if baseline else []) + [('', None)]
    results: dict[str, dict[str, dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as cache_dir:
        predictor = map_predictor(load_vehicle('test_robot_track'), 'dry_sand', cache_dir)[0]  # not timed
        held = [
            (c, p.motor_omega_rad_s, p.motor_torque_Nm)
            for c in HELD_COMMANDS
            for p in [predictor.predict(*c)]
        ]
        for name, src in variants:
            namespace = f'bench_{uuid.uuid4().hex[:8]}'
            node = (
                _start_echo(namespace, env, stock=name == STOCK)
                if name in (FLOOR, STOCK)
                else _start_node(namespace, cache_dir, env, src)
            )
            load = Load(namespace, receive=True)
            try:
                if not load.wait_connected(subscribers=1):
                    error = node.stderr.read() if node.poll() is not None and node.stderr else ''
                    raise RuntimeError(f'{name or "power_estimator"} did not come up: {error}')
                _wait_outputs(load)
                time.sleep(1.0)
                prefix = {FLOOR: f'{FLOOR}: ', STOCK: f'{STOCK}: ', BASELINE: f'BASELINE {baseline}: '}.get(
                    name, ''
                )
                cpu0, wall0 = _cpu_seconds(node.pid), time.monotonic()
                time.sleep(3.0)
                idle = (_cpu_seconds(node.pid) - cpu0) / (time.monotonic() - wall0)
                report.figure(f'{prefix}node CPU idle (timers only)', idle, 'cores')
                results[name] = {}
                for rate in RATES_HZ:
                    results[name][f'{rate:g}'] = _sustained(report, load, node, rate, FRESH, prefix=prefix)
                if name not in (FLOOR, STOCK):
                    results[name][CACHE] = _sustained(report, load, node, 1000.0, CACHE, prefix=prefix)
                    results[name][HELD] = _sustained(
                        report, load, node, 1000.0, HELD, prefix=prefix, held=held
                    )
            finally:
                load.close()
                _stop(node)
    for rate in RATES_HZ:
        key = f'{rate:g}'
        report.ratio(
            f'{key} Hz: node CPU, power_estimator / floor (same run)',
            results[''][key]['cores'],
            results[FLOOR][key]['cores'],
        )
        report.ratio(
            f'{key} Hz: node CPU, power_estimator / stock rclpy echo node (same run)',
            results[''][key]['cores'],
            results[STOCK][key]['cores'],
        )
    if baseline:
        for key, now in results[''].items():
            before = results[BASELINE][key]
            label = {CACHE: '1000 Hz, CACHE HIT', HELD: '1000 Hz, HELD'}.get(key, f'{key} Hz')
            for figure in ('CPU per message', 'p99 cmd_vel', 'p99 joint_states'):
                if before.get(figure) and now.get(figure):
                    report.ratio(
                        f'{label}: {figure}, this / baseline (same run)', now[figure], before[figure]
                    )


def _wait_outputs(load: Load) -> None:
    deadline = time.monotonic() + 30.0
    while min(sub.get_publisher_count() for sub in load.subs) < 1 and time.monotonic() < deadline:
        time.sleep(0.05)  # discovery of the node's outputs


def _sustained(
    report: Report,
    load: Load,
    node: subprocess.Popen[str],
    rate: float,
    mode: str,
    prefix: str = '',
    held: Sequence[Held] = (),
) -> dict[str, float]:
    """One run at ``rate`` [Hz] of both inputs (``mode``, :meth:`Load.drive`); figures: loss, p50/p99
    latency, CPU. Returns them."""
    busy = os.getloadavg()[0]
    for values in load.received.values():
        values.clear()
    load.correction = {}
    done = threading.Event()
    n_expected = round(rate * SECONDS)
    thread = threading.Thread(target=load.receive_until, args=(done, n_expected, DRAIN_S), daemon=True)
    thread.start()
    time.sleep(0.5)
    cpu0, wall0, start = _cpu_seconds(node.pid), time.monotonic(), time.time()
    n = load.drive(rate, SECONDS, mode=mode, held=held, seed=int(rate))
    sending_s = time.monotonic() - wall0
    done.set()
    thread.join()
    cpu1 = _cpu_seconds(node.pid)
    last = max((t for values in load.received.values() for _, t in values), default=time.time())
    busy_wall = max(last - start, sending_s)  # the node's work: first send to last output [s]
    cores = (cpu1 - cpu0) / busy_wall
    per_msg_us = (cpu1 - cpu0) / (2 * n) * 1e6
    label = prefix + f'{rate:g} Hz' + LABEL[mode]
    p99_goal, cpu_goal, lost_goal = (
        GOALS.get(rate, (None, None, None)) if mode == FRESH and not prefix else (None,) * 3
    )
    latencies = {
        topic: [t - stamp for stamp, t in values if stamp in load.sent[INPUT_OF[topic]]]
        for topic, values in load.received.items()
    }
    lost = {topic: n - len(values) for topic, values in latencies.items()}
    total_lost = sum(lost.values())
    report.under(
        f'{label}: inputs lost (cmd_vel + joint_states)',
        total_lost,
        'msgs',
        lost_goal,
        inclusive=True,
        note=f'{lost["power/predicted"]} cmd_vel + {lost["power/measured"]} joint_states of {n} each',
    )
    figures = {'CPU per message': per_msg_us, 'cores': cores}
    for topic, delays in latencies.items():
        name = f'{INPUT_OF[topic]} -> {topic}'
        if not delays:
            continue
        p50, p99 = (float(np.percentile(delays, q)) * 1e3 for q in (50, 99))
        figures[f'p99 {INPUT_OF[topic]}'] = p99
        report.figure(f'{label}: {name} p50 latency', p50, 'ms')
        report.under(
            f'{label}: {name} p99 latency',
            p99,
            'ms',
            p99_goal,
            note=f'1-min load average before the run {busy:.2f} on {os.cpu_count()} cores',
        )
    report.under(
        f'{label}: node CPU',
        cores,
        'cores',
        cpu_goal,
        note=f'over {busy_wall:.2f} s from the first send to the last output',
    )
    report.figure(f'{label}: node CPU per input message', per_msg_us, 'us')
    if mode == HELD:  # (the echo nodes never run it) the last power/correction of this run
        scales = [load.correction.get(f'scale_{side}', math.nan) for side in ('left', 'right')]
        report.figure(
            f'{label}: correction scale learned (left, right mean; 1.2 = measured / predicted torque)',
            float(np.mean(scales)),
            '-',
            note=f'left {scales[0]:.3f}, right {scales[1]:.3f}: the adaptation settled and ran',
        )
    return figures
