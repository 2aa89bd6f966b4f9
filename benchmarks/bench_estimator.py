"""power_estimator under load: sustained 1 kHz cmd_vel plus 1 kHz joint_states.

The node runs in its own process (as on the robot: ``python -m skidsteer_power.nodes.power_estimator``
with the real FESS map of the test robot on dry sand); this process publishes the inputs from its
main thread and receives the outputs on the same node, spun in a second thread. Each input carries
its identity, so every output is matched to its input:

* cmd_vel is TwistStamped (``cmd_vel_stamped``) whose stamp is the send time; power/predicted copies
  the stamp, so latency = receive time - stamp;
* joint_states carry a sequence number in the left motor speed (k x 0.1 rad/s); power/measured
  echoes it as its ``left_motor`` velocity.

"Lost" counts inputs with no matching output (loss anywhere on the way counts). Latency includes
DDS both ways and the receiver's Python path, so it is an upper bound for the node alone. On this
shared 2-core machine the figures depend on what else runs; the load average is noted.
CPU: the node process's user + system time per second of wall time at 100 Hz of each input.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
import uuid

import numpy as np

from benchmarks.harness import Report

RATE_HZ = 1000.0
SECONDS = 5.0
CPU_RATE_HZ = 100.0
CPU_SECONDS = 10.0


def _start_node(namespace: str, cache_dir: str, env: dict[str, str]) -> subprocess.Popen:
    params = {
        'map_cache_dir': cache_dir,
        'persist': 'false',
        'cmd_vel_stamped': 'true',
        'qos_depth': '1000',
    }
    argv = [
        sys.executable,
        '-m',
        'skidsteer_power.nodes.power_estimator',
        '--ros-args',
        '-r',
        f'__ns:=/{namespace}',
    ]
    for key, value in params.items():
        argv += ['-p', f'{key}:={value}']
    return subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _cpu_seconds(pid: int) -> float:
    with open(f'/proc/{pid}/stat', encoding='ascii') as handle:
        fields = handle.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class Load:
    """Input publisher (``receive=False``) or output receiver (``receive=True``) in one process."""

    def __init__(self, namespace: str, receive: bool = False) -> None:
        import rclpy
        from geometry_msgs.msg import TwistStamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('bench_load', namespace=namespace, context=self.context)
        qos = QoSProfile(depth=1000)
        self.pub_cmd = self.node.create_publisher(TwistStamped, 'cmd_vel', qos)
        self.pub_joint = self.node.create_publisher(JointState, 'joint_states', qos)
        self.predicted_latency: list[float] = []
        self.joint_received: dict[int, float] = {}
        self.joint_sent: dict[int, float] = {}
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        if receive:
            self.subs = [
                self.node.create_subscription(JointState, 'power/predicted', self._on_predicted, qos),
                self.node.create_subscription(JointState, 'power/measured', self._on_measured, qos),
            ]
        self._msg_types = (TwistStamped, JointState)

    def _on_predicted(self, msg) -> None:
        sent = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        self.predicted_latency.append(time.time() - sent)

    def _on_measured(self, msg) -> None:
        self.joint_received.setdefault(round(msg.velocity[0] / 0.1), time.time())

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

    def receive_for(self, seconds: float) -> dict:
        """Spin for ``seconds``; what arrived, as JSON-able data."""
        from rclpy.task import Future

        self.executor.spin_until_future_complete(Future(), timeout_sec=seconds)
        return {'predicted_latency': self.predicted_latency, 'joint_received': self.joint_received}

    def drive(self, rate_hz: float, seconds: float, start_k: int) -> tuple[int, int]:
        """Publish both inputs at ``rate_hz`` for ``seconds``; returns (number sent of each, next k)."""
        twist_type, joint_type = self._msg_types
        period = 1.0 / rate_hz
        n = round(rate_hz * seconds)
        t0 = time.monotonic()
        for i in range(n):
            target = t0 + i * period
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            cmd = twist_type()
            cmd.twist.linear.x, cmd.twist.angular.z = 0.2, 0.1 if i % 2 else 0.05
            now = time.time()
            cmd.header.stamp.sec, cmd.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
            self.pub_cmd.publish(cmd)
            k = start_k + i
            joint = joint_type(name=['left_motor', 'right_motor'], velocity=[k % 10000 * 0.1, 300.0])
            joint.effort = [0.2, 0.2]
            self.joint_sent[k] = time.time()
            self.pub_joint.publish(joint)
        return n, start_k + n

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _stop(process: subprocess.Popen) -> None:
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def run(report: Report) -> None:
    from skidsteer_power.estimator.factory import map_predictor
    from skidsteer_power.vehicle import load_vehicle

    namespace = f'bench_{uuid.uuid4().hex[:8]}'
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    with tempfile.TemporaryDirectory() as cache_dir:
        map_predictor(load_vehicle('test_robot_track'), 'dry_sand', cache_dir)  # build once, outside timing
        node = _start_node(namespace, cache_dir, env)
        load = Load(namespace, receive=True)
        try:
            if not load.wait_connected(subscribers=1):
                raise RuntimeError('power_estimator did not come up')
            time.sleep(1.0)
            _sustained(report, load)
            _cpu(report, load, node)
        finally:
            load.close()
            _stop(node)


def _sustained(report: Report, load: Load) -> None:
    busy = os.getloadavg()[0]
    deadline = time.monotonic() + 30.0
    while min(sub.get_publisher_count() for sub in load.subs) < 1 and time.monotonic() < deadline:
        time.sleep(0.05)  # discovery of the node's outputs
    received: dict = {}
    thread = threading.Thread(target=lambda: received.update(load.receive_for(SECONDS + 5.0)), daemon=True)
    thread.start()
    time.sleep(0.5)
    n, _ = load.drive(RATE_HZ, SECONDS, start_k=1)
    thread.join()
    predicted = received['predicted_latency']
    joint = [t - load.joint_sent[k] for k, t in received['joint_received'].items() if k in load.joint_sent]
    lost_cmd, lost_joint = n - len(predicted), n - len(joint)
    report.figure('cmd_vel lost at 1 kHz (+1 kHz joint_states)', lost_cmd, 'msgs', goal='0',
                  met=lost_cmd == 0, note=f'of {n}')  # fmt: skip
    report.figure('joint_states lost at 1 kHz (+1 kHz cmd_vel)', lost_joint, 'msgs', goal='0',
                  met=lost_joint == 0, note=f'of {n}')  # fmt: skip
    pairs = (('cmd_vel -> power/predicted', predicted), ('joint_states -> power/measured', joint))
    for name, values in pairs:
        if values:
            p99 = float(np.percentile(values, 99)) * 1e3
            report.figure(f'{name} p99 latency', p99, 'ms', goal='< 2 ms', met=p99 < 2.0,
                          note=f'median {np.median(values) * 1e3:.3f} ms; 1-min load average before '
                               f'the run {busy:.2f} on {os.cpu_count()} cores')  # fmt: skip


def _cpu(report: Report, load: Load, node: subprocess.Popen) -> None:
    time.sleep(1.0)
    cpu0, wall0 = _cpu_seconds(node.pid), time.monotonic()
    time.sleep(CPU_SECONDS / 2)
    cpu1, wall1 = _cpu_seconds(node.pid), time.monotonic()
    load.drive(CPU_RATE_HZ, CPU_SECONDS, start_k=100_000)
    cpu2, wall2 = _cpu_seconds(node.pid), time.monotonic()
    report.figure('node CPU time per second, idle (timers, DDS)', (cpu1 - cpu0) / (wall1 - wall0), 's/s')
    report.figure('node CPU time per second at 100 Hz cmd_vel + 100 Hz joint_states',
                  (cpu2 - cpu1) / (wall2 - wall1), 's/s')  # fmt: skip
