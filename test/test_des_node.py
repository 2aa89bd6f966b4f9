"""des_driver node end to end: real rclpy and DDS, two simulated amplifiers on ptys."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from des_harness import Harness, enabled
from rclpy.context import Context
from rclpy.lifecycle import LifecycleNode

from skidsteer_power.des.protocol import DesErrorFlags, OpCode
from skidsteer_power.des.simulator import Fault, SimulatedPair
from skidsteer_power.nodes.spin import node_command
from skidsteer_power.stop_signals import STOPPING_SIGNALS, signal_name

pytestmark = pytest.mark.ros

RPM = 2 * math.pi / 60
# Set points for v = 0.2 m/s, yaw rate 0.5 rad/s on the default vehicle file test_robot_track.yaml
# (tread 0.426 m, sprocket r = 0.1 m; its powertrain 12:1):
# v_left = 0.2 - 0.5 * 0.426 / 2 = 0.0935 m/s -> 0.0935 / 0.1 * 12 rad/s = 11.22 rad/s = 107.14 rpm;
# v_right = 0.3065 m/s -> 36.78 rad/s = 351.22 rpm. Right motor mirrored (polarity -1): -351.
LEFT_RPM, RIGHT_RPM = 107, -351


@pytest.fixture
def pair() -> Iterator[SimulatedPair]:
    with SimulatedPair(38400) as sims:
        yield sims


@pytest.fixture
def harness(ros_context: Context, pair: SimulatedPair) -> Iterator[Harness]:
    h = Harness(ros_context, pair)
    yield h
    h.close()


def test_cmd_vel_to_setpoints_to_joint_states(harness: Harness, pair: SimulatedPair) -> None:
    harness.twist = (0.2, 0.5)
    assert harness.spin_until(
        lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (LEFT_RPM, RIGHT_RPM)
    )
    assert enabled(pair.left) and enabled(pair.right)

    def settled() -> bool:
        if not harness.joints:
            return False
        v = harness.joints[-1].velocity
        return bool(abs(v[0] - LEFT_RPM * RPM) < 0.3 and abs(v[1] + RIGHT_RPM * RPM) < 0.3)

    assert harness.spin_until(settled)
    msg = harness.joints[-1]
    assert list(msg.name) == ['left_motor', 'right_motor']
    # Both sides forward-positive; effort = Kt i with the simulator's friction load (> 0 forward).
    assert msg.velocity[1] > msg.velocity[0] > 0
    assert all(0 < e < 0.1 for e in msg.effort)
    assert msg.effort[0] == pytest.approx(0.114 * pair.left.model.mean_current_A, abs=0.005)
    # Position integrates velocity: over ~1 s of joint_states the encoder agrees with the measured
    # speed (trapezoid rule over consecutive messages with fresh data on both sides).
    start = len(harness.joints) - 1
    first = harness.joints[start]
    harness.spin_until(lambda: harness.joints[-1].header.stamp.sec > first.header.stamp.sec + 1, timeout_s=5)
    window = harness.joints[start:]
    stamp = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in window]
    pairs = [
        k
        for k in range(len(window) - 1)
        if all(math.isfinite(v) for v in (*window[k].velocity, *window[k + 1].velocity))
    ]
    assert len(pairs) > 20
    for i in (0, 1):
        moved = sum(window[k + 1].position[i] - window[k].position[i] for k in pairs)
        integral = sum(
            0.5 * (window[k].velocity[i] + window[k + 1].velocity[i]) * (stamp[k + 1] - stamp[k])
            for k in pairs
        )
        assert moved > 0 and moved == pytest.approx(integral, rel=0.1)


def test_published_effort_uses_the_vehicles_motor(
    ros_context: Context, pair: SimulatedPair, strong_motor_vehicle: Path
) -> None:
    """effort = K_t I with the K_t of the vehicle's powertrain (here 0.228 N m/A = 2 x the EC-45's
    0.114, Appendix B line 12), not a built-in EC-45."""
    vehicle = strong_motor_vehicle
    harness = Harness(ros_context, pair, vehicle=str(vehicle))
    try:
        harness.twist = (0.2, 0.0)
        # 0.2 m/s on r = 0.1 m through 12:1: 24 rad/s at each motor
        assert harness.spin_until(
            lambda: bool(harness.joints) and abs(harness.joints[-1].velocity[0] - 24.0) < 0.3
        )
        settled = harness.joints[-1].header.stamp.sec
        harness.spin_until(lambda: harness.joints[-1].header.stamp.sec > settled + 1, timeout_s=5)  # steady
        effort = harness.joints[-1].effort[0]
        assert effort == pytest.approx(0.228 * pair.left.model.mean_current_A, abs=0.01)
        assert effort > 1.5 * 0.114 * pair.left.model.mean_current_A  # not the EC-45's K_t
    finally:
        harness.close()


def test_max_motor_rpm_above_the_vehicles_motor_is_refused(
    ros_context: Context, pair: SimulatedPair, strong_motor_vehicle: Path
) -> None:
    """6000 rpm is within the EC-45's 10 000 rpm but above the fixture motor's 5000 rpm: the node
    refuses to start with one clear error naming that limit (no amplifier is touched)."""
    from skidsteer_power.errors import ConfigError

    with pytest.raises(ConfigError, match=r"above the motor's max\. speed 5000 rpm"):
        Harness(ros_context, pair, activate=False, vehicle=str(strong_motor_vehicle), max_motor_rpm=6000.0)
    assert pair.left.speed_setpoint_rpm == 0 and not pair.left.enabled


def test_twist_stamped_by_parameter(ros_context: Context, pair: SimulatedPair) -> None:
    h = Harness(ros_context, pair, twist_stamped=True)
    try:
        h.twist = (0.2, 0.5)
        assert h.spin_until(
            lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (LEFT_RPM, RIGHT_RPM)
        )
    finally:
        h.close()


def test_watchdog_stops_the_motors(harness: Harness, pair: SimulatedPair) -> None:
    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    harness.twist = None  # cmd_vel stops
    assert harness.spin_until(
        lambda: pair.left.speed_setpoint_rpm == 0 and pair.right.speed_setpoint_rpm == 0
    )
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('watchdog_zero') == 'True')
    assert enabled(pair.left)  # stopped, not disabled: the next cmd_vel drives again
    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)


def test_amplifier_error_stops_both_sides_until_cleared(harness: Harness, pair: SimulatedPair) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_srvs.srv import Trigger

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.right.speed_setpoint_rpm < 0 and pair.left.speed_setpoint_rpm > 0)
    pair.left.raise_error(DesErrorFlags.OVER_CURRENT)
    assert harness.spin_until(
        lambda: pair.right.speed_setpoint_rpm == 0 and pair.left.speed_setpoint_rpm == 0
    )

    def fault_reported() -> bool:
        status, values = harness.side_diag('left')
        return status is not None and 'OVER_CURRENT' in values['errors'] and values['fault_latched'] == 'True'

    assert harness.spin_until(fault_reported)
    assert harness.side_status('left').level == DiagnosticStatus.ERROR
    assert not enabled(pair.left)
    # cmd_vel keeps coming, but the latch holds: still stopped after a while.
    harness.spin_until(lambda: False, timeout_s=0.5)
    assert pair.right.speed_setpoint_rpm == 0
    answer = harness.call(harness.clear_client, Trigger.Request())
    assert answer.success, answer.message
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    assert pair.left.errors == DesErrorFlags(0) and enabled(pair.left)
    assert harness.spin_until(lambda: harness.side_status('left').level == DiagnosticStatus.OK)


def test_lost_port_is_reported_and_reopened(harness: Harness, pair: SimulatedPair) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: bool(harness.joints) and not math.isnan(harness.joints[-1].velocity[0]))
    pair.left.close_port()
    assert harness.spin_until(
        lambda: 'port lost' in (harness.side_status('left').message if harness.diags else '')
    )
    status, values = harness.side_diag('left')
    assert status is not None
    assert status.level == DiagnosticStatus.ERROR and values['connected'] == 'False'
    assert harness.spin_until(lambda: math.isnan(harness.joints[-1].velocity[0]))
    assert not math.isnan(harness.joints[-1].velocity[1])  # the other side keeps reporting
    set_before = len(pair.left.commands_of(OpCode.SET_VELOCITY))
    pair.left.reopen_port()
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('connected') == 'True')
    assert harness.spin_until(lambda: not math.isnan(harness.joints[-1].velocity[0]))
    assert len(pair.left.commands_of(OpCode.SET_VELOCITY)) > set_before
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)


def test_silent_amplifier_is_reported_and_reconnected(harness: Harness, pair: SimulatedPair) -> None:
    from skidsteer_power.des.simulator import Fault

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.right.speed_setpoint_rpm < 0)
    pair.right.inject(Fault.SILENT, count=-1)
    assert harness.spin_until(
        lambda: 'not answering' in (harness.side_status('right').message if harness.diags else '')
    )
    assert harness.side_diag('right')[1]['connected'] == 'False'
    assert harness.spin_until(lambda: math.isnan(harness.joints[-1].velocity[1]))
    pair.right.clear_faults()
    assert harness.spin_until(lambda: harness.side_diag('right')[1].get('connected') == 'True')
    assert harness.spin_until(lambda: not math.isnan(harness.joints[-1].velocity[1]))


def _default_dispositions() -> None:
    """In the probe child before exec: every signal back to its default action (the test process
    may have inherited some as ignored, e.g. SIGINT in a background job), in a process group of its
    own: the test's group may be orphaned (CI started from a shell that has since exited), and
    the kernel discards SIGTSTP, SIGTTIN and SIGTTOU sent to an orphaned group instead of stopping
    it (POSIX); a group whose parent, pytest, is in the same session is not orphaned."""
    os.setpgid(0, 0)
    for signum in range(1, signal.NSIG):
        with contextlib.suppress(OSError, ValueError, RuntimeError):
            signal.signal(signum, signal.SIG_DFL)


def probe_default_actions() -> tuple[set[int], set[int]]:
    """(signals whose default action ends a process, signals whose default action stops it), asked
    of the OS, not of the code under test: one ``sleep`` child per signal with every disposition at
    its default, sent that signal, and watched with waitpid(WUNTRACED) (signal(7): Term and Core end
    it, Stop stops it, Ign and Cont leave it sleeping)."""
    children = {}
    for signum in range(1, signal.NSIG):
        children[signum] = subprocess.Popen(['sleep', '30'], preexec_fn=_default_dispositions)
    time.sleep(0.3)  # every child in its sleep
    for signum, child in children.items():
        os.kill(child.pid, signum)
    ending, stopping = set(), set()
    deadline = time.monotonic() + 1.0
    for signum, child in children.items():
        while True:
            pid, status = os.waitpid(child.pid, os.WNOHANG | os.WUNTRACED)
            if pid and os.WIFSIGNALED(status):
                ending.add(signum)
                child.returncode = -signum
                break
            if pid and os.WIFSTOPPED(status):
                stopping.add(signum)
                break
            if time.monotonic() > deadline:
                break  # ignored (SIGCHLD, SIGURG, SIGWINCH, SIGCONT)
            time.sleep(0.005)
        if child.returncode is None:
            child.kill()
            child.wait()
    return ending, stopping


OS_ENDING, OS_STOPPING = probe_default_actions()
# Not sent to the driver here: SIGKILL (cannot be caught), SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGSYS
# (after a real fault no Python handler can run: the guardian's part, issue 34 item 6), and SIGPIPE,
# SIGXFSZ, which Python sets to ignored at start (Python docs, signal module), so they end no Python
# process. Every other signal whose default action ends a process must leave the motors at zero.
NOT_HANDLED_HERE: set[int] = {
    signal.SIGKILL, signal.SIGSEGV, signal.SIGBUS, signal.SIGILL, signal.SIGFPE, signal.SIGSYS,
    signal.SIGPIPE, signal.SIGXFSZ,
}  # fmt: skip
# signal(7): glibc's threads implementation keeps the first real-time signals (32, 33) for itself and
# moves SIGRTMIN above them; a process cannot take them
NOT_HANDLED_HERE |= set(range(32, signal.SIGRTMIN))
ENDING_SIGNALS = sorted(OS_ENDING - NOT_HANDLED_HERE)
# Sent one by one to a driver process (each ends it, ~4 s each): one of each kind of default action
# and origin (Term from a terminal, a kill, a timer, a real-time one; Core). That every other one
# is caught is read from the kernel in one process (test_the_driver_catches_every_ending_signal).
SENT_SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGALRM, signal.SIGRTMAX]


def _caught_signals(pid: int) -> set[int]:
    """The signals process ``pid`` has a handler for, as the kernel reports (/proc/PID/status SigCgt)."""
    with open(f'/proc/{pid}/status') as status:
        mask = next(int(line.split()[1], 16) for line in status if line.startswith('SigCgt:'))
    return {n for n in range(1, signal.NSIG) if mask >> (n - 1) & 1}


def test_the_driver_catches_every_ending_signal(ros_context: Context, pair: SimulatedPair) -> None:
    """Every signal the OS probe says ends (or stops) a process, less the ones no handler can serve,
    has a handler in a running des_driver (before issue 34: SIGTSTP, SIGTTIN, SIGTTOU had none; the
    old test took its list from stop_signals.py, so removing SIGALRM and SIGPWR went unnoticed)."""
    params = {'left_port': pair.left.port, 'right_port': pair.right.port, 'autostart': 'true'}
    ns = f'/t{uuid.uuid4().hex[:8]}'
    proc = subprocess.Popen(
        node_command('skidsteer_power.nodes.des_driver', ns, params), env=os.environ.copy()
    )
    try:
        deadline = time.monotonic() + 30
        while not (pair.left.enabled and pair.right.enabled):  # spinning: every handler installed
            assert proc.poll() is None and time.monotonic() < deadline, 'the driver never came up'
            time.sleep(0.05)
        time.sleep(0.2)
        missing = (set(ENDING_SIGNALS) | (OS_STOPPING - {signal.SIGSTOP})) - _caught_signals(proc.pid)
        assert not missing, f'not caught: {sorted(signal_name(s) for s in missing)}'
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 0
    finally:
        proc.kill()
        proc.wait()


def test_the_os_probe_finds_what_signal7_lists() -> None:
    """The probe itself: signal(7)'s table, a few rows of each kind (Term, Core, Stop, Ign, Cont)."""
    assert {signal.SIGHUP, signal.SIGALRM, signal.SIGPWR, signal.SIGQUIT, signal.SIGRTMIN} <= OS_ENDING
    assert {signal.SIGSTOP, signal.SIGTSTP, signal.SIGTTIN, signal.SIGTTOU} == OS_STOPPING
    assert not {signal.SIGCHLD, signal.SIGURG, signal.SIGWINCH, signal.SIGCONT} & (OS_ENDING | OS_STOPPING)
    # the stop signals are test_des_failsafe.py's (Ctrl-Z); the ones caught there are these
    assert set(STOPPING_SIGNALS) == OS_STOPPING - {signal.SIGSTOP}


@pytest.mark.parametrize('signum', SENT_SIGNALS, ids=signal_name)
def test_every_ending_signal_zeroes_speed_then_disables(
    ros_context: Context, pair: SimulatedPair, signum: int
) -> None:
    """Before issue 28 only SIGINT and SIGTERM did: SIGHUP, SIGQUIT, SIGUSR1 ... ended des_driver
    with both amplifiers enabled and turning."""
    from geometry_msgs.msg import Twist
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    ns = f'/t{uuid.uuid4().hex[:8]}'
    params = {
        'left_port': pair.left.port,
        'right_port': pair.right.port,
        'ack_timeout_s': 0.3,
        'cmd_timeout_s': 5.0,
        'autostart': 'true',
    }
    proc = subprocess.Popen(
        node_command('skidsteer_power.nodes.des_driver', ns, params), env=os.environ.copy()
    )
    node = Node('des_sigterm_test', namespace=ns, context=ros_context)
    pub = node.create_publisher(Twist, f'{ns}/cmd_vel', 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        msg = Twist()
        msg.linear.x = 0.2
        deadline = time.monotonic() + 30
        # each side has its own poller thread: wait for both set points, not just the left one
        while not (pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0):
            assert time.monotonic() < deadline, 'the driver never drove both sides'
            pub.publish(msg)
            executor.spin_once(timeout_sec=0.05)
        proc.send_signal(signum)
        assert proc.wait(timeout=15) == 0
        for sim in (pair.left, pair.right):
            assert sim.speed_setpoint_rpm == 0 and not sim.enabled
            log = [c for c in sim.commands if c.opcode in (OpCode.SET_VELOCITY, OpCode.ENABLE)]
            assert [(c.opcode, c.words) for c in log[-2:]] == [
                (OpCode.SET_VELOCITY, (0,)),
                (OpCode.ENABLE, (0,)),
            ]
    finally:
        proc.kill()
        proc.wait()
        node.destroy_node()
        executor.shutdown()


@pytest.mark.parametrize('signum', [signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1], ids=signal_name)
def test_run_on_hardware_ports_zeroes_and_disables_on_a_signal(
    pair: SimulatedPair, tmp_path: Path, signum: signal.Signals
) -> None:
    """``run --left-port --right-port`` (the suite against the amplifiers on the given ports, here the
    simulated pair): before issue 28 a SIGHUP left 344 rpm on the motors."""
    command = [
        sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--left-port', pair.left.port,
        '--right-port', pair.right.port, '--speed', '0.2', '--duration', '120', '--json',
        '--map-cache', str(tmp_path), '--state-file', str(tmp_path / 'e.json'),
    ]  # fmt: skip
    env = {**os.environ, 'ROS_DOMAIN_ID': str(100 + signum)}  # its own graph: no other test's cmd_vel
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0):
            assert proc.poll() is None and time.monotonic() < deadline, 'run never drove both sides'
            time.sleep(0.05)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=30)
        assert proc.returncode == 0, stderr[-2000:]
        for sim in (pair.left, pair.right):
            assert sim.speed_setpoint_rpm == 0 and not sim.enabled
    finally:
        proc.kill()
        proc.wait()


def test_bad_parameters_are_one_clear_error(ros_context: Context, pair: SimulatedPair) -> None:
    from rclpy.parameter import Parameter

    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes.des_driver import DesDriver

    with pytest.raises(ConfigError, match='left_polarity must be'):
        DesDriver(
            context=ros_context,
            parameter_overrides=[
                Parameter('left_port', value=pair.left.port),
                Parameter('right_port', value=pair.right.port),
                Parameter('left_polarity', value=2),
            ],
        )


# -- issue 13 / 17: fail safe and managed ---------------------------------------------------------

CLAMPED_RPM = 1719
# 1e308 m/s is clamped to max_speed_m_s = 1.5 m/s (node default): 1.5 / 0.1 m * 12 = 180 rad/s at the
# motor = 180 / (2 pi / 60) = 1718.9 rpm, below max_motor_rpm 4000, so no further scaling.
FIRST_STEP_MAX_RPM = 115
# The slew limiter advances at most 0.1 s per step at max_accel_m_s2 = 1 m/s^2: 0.1 m/s ->
# 0.1 / 0.1 * 12 = 12 rad/s = 114.6 rpm is the largest first set point after a stop.


def both_zero(pair: SimulatedPair) -> bool:
    return pair.left.speed_setpoint_rpm == 0 and pair.right.speed_setpoint_rpm == 0


def test_lifecycle_transitions_through_the_lifecycle_services(
    ros_context: Context, pair: SimulatedPair
) -> None:
    from lifecycle_msgs.msg import Transition

    h = Harness(ros_context, pair, activate=False)
    try:
        assert h.state() == 'unconfigured'
        assert not h.transition(Transition.TRANSITION_ACTIVATE)  # not from unconfigured; node lives on
        assert h.transition(Transition.TRANSITION_CONFIGURE)
        assert h.state() == 'inactive'
        assert h.driver.pollers['left'].amp.link.is_open and h.driver.pollers['right'].amp.link.is_open
        assert h.spin_until(lambda: bool(h.joints))  # the amplifiers are read while inactive
        h.twist = (0.2, 0.0)
        h.spin_until(lambda: False, timeout_s=0.5)  # cmd_vel flows, but inactive ignores it
        assert both_zero(pair) and not enabled(pair.left) and not enabled(pair.right)
        assert h.transition(Transition.TRANSITION_ACTIVATE)
        assert h.state() == 'active'
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
        assert enabled(pair.left) and enabled(pair.right)
        assert h.transition(Transition.TRANSITION_DEACTIVATE)
        # At the moment the transition answers: zero speed and power stages off on both sides.
        assert both_zero(pair) and not enabled(pair.left) and not enabled(pair.right)
        assert h.state() == 'inactive'
        h.spin_until(lambda: False, timeout_s=0.3)
        assert both_zero(pair)  # cmd_vel still flowing changes nothing
        assert h.transition(Transition.TRANSITION_CLEANUP)
        assert h.state() == 'unconfigured' and h.driver.pollers == {}
        # Configure again (parameters may change while unconfigured) and drive.
        assert h.transition(Transition.TRANSITION_CONFIGURE)
        assert h.transition(Transition.TRANSITION_ACTIVATE)
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)
        assert h.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert h.state() == 'finalized'
        assert both_zero(pair) and not enabled(pair.left) and not enabled(pair.right)
    finally:
        h.close()


def test_configure_fails_cleanly_without_an_amplifier(ros_context: Context, pair: SimulatedPair) -> None:
    from lifecycle_msgs.msg import Transition

    h = Harness(ros_context, pair, activate=False, configure_timeout_s=1.0)
    try:
        pair.right.inject(Fault.SILENT, -1)
        assert not h.transition(Transition.TRANSITION_CONFIGURE)
        assert h.state() == 'unconfigured'
        assert 'right' in h.driver.configure_error and 'not ready' in h.driver.configure_error
        assert h.driver.pollers == {}
    finally:
        h.close()


def test_clear_faults_service_reports_what_it_could_not_clear(
    ros_context: Context, pair: SimulatedPair, monkeypatch: pytest.MonkeyPatch
) -> None:
    from std_srvs.srv import Trigger

    h = Harness(ros_context, pair, activate=False)
    try:
        answer = h.call(h.clear_client, Trigger.Request())
        assert not answer.success and 'not configured' in answer.message
        lifecycle: LifecycleNode = h.driver  # rclpy's triggers are unannotated (untyped_calls_exclude)
        lifecycle.trigger_configure()
        lifecycle.trigger_activate()
        pair.right.raise_error(DesErrorFlags.OVER_CURRENT)
        assert h.spin_until(lambda: h.side_diag('right')[1].get('fault_latched') == 'True')
        # A fault that persists (the amplifier ignores the clear, as an over-temperature would):
        with monkeypatch.context() as m:
            m.setattr(pair.right, '_op_clear_error', lambda words: ())
            answer = h.call(h.clear_client, Trigger.Request())
        assert not answer.success and 'still latched: right (OVER_CURRENT' in answer.message
        assert not enabled(pair.right) and pair.left.speed_setpoint_rpm == 0
        # An unreachable side is reported, and its request is not left pending for later.
        pair.left.close_port()
        assert h.spin_until(lambda: 'left' in h.drive_command().links_down)
        answer = h.call(h.clear_client, Trigger.Request())
        assert not answer.success
        pair.left.reopen_port()
        assert h.spin_until(lambda: not h.drive_command().links_down)
        answer = h.call(h.clear_client, Trigger.Request())
        assert answer.success, answer.message
        assert pair.right.errors == DesErrorFlags(0) and enabled(pair.right)
    finally:
        h.close()


def test_huge_and_non_finite_commands(harness: Harness, pair: SimulatedPair) -> None:
    harness.twist = (1e308, 0.0)
    assert harness.spin_until(
        lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (CLAMPED_RPM, -CLAMPED_RPM),
        timeout_s=10,
    )
    moving = [c.words[0] for c in pair.left.commands_of(OpCode.SET_VELOCITY) if c.words[0] != 0]
    assert 0 < moving[0] <= FIRST_STEP_MAX_RPM  # a ramp, not a step to 1719 rpm
    assert all(w <= CLAMPED_RPM for w in moving)

    def command_diag() -> dict[str, str]:
        return harness.diag('des_driver: command')[1]

    assert harness.spin_until(lambda: int(command_diag().get('cmd_vel_clamped', 0)) > 0)
    # A NaN or inf command is rejected: it neither moves the motors nor keeps the last command alive.
    for bad in ((math.nan, 0.0), (0.2, math.inf), (-math.inf, math.nan)):
        harness.twist = bad
        assert harness.spin_until(lambda: both_zero(pair))  # cmd_timeout_s after the last valid one
    assert harness.spin_until(lambda: int(command_diag()['cmd_vel_rejected_non_finite']) >= 3)
    assert command_diag()['setpoints_non_finite'] == '0'
    # Then a valid command drives again, and the node never stopped publishing.
    harness.twist = (0.2, 0.5)
    assert harness.spin_until(
        lambda: (pair.left.speed_setpoint_rpm, pair.right.speed_setpoint_rpm) == (LEFT_RPM, RIGHT_RPM)
    )


@pytest.mark.parametrize('stop_both', [True, False])
def test_one_side_link_lost_stops_both_sides(
    ros_context: Context, pair: SimulatedPair, stop_both: bool
) -> None:
    h = Harness(ros_context, pair, stop_both_on_link_loss=stop_both)
    try:
        h.twist = (0.2, 0.0)
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
        pair.left.close_port()
        assert h.spin_until(lambda: h.side_diag('left')[1].get('connected') == 'False')
        if stop_both:
            assert h.spin_until(lambda: pair.right.speed_setpoint_rpm == 0)
            assert h.spin_until(lambda: 'link down: left' in h.side_status('right').message)
            h.spin_until(lambda: False, timeout_s=0.3)
            assert pair.right.speed_setpoint_rpm == 0  # stays stopped although cmd_vel keeps coming
        else:
            h.spin_until(lambda: False, timeout_s=0.5)
            assert pair.right.speed_setpoint_rpm < 0  # opted out: the other side keeps following
        pair.left.reopen_port()
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    finally:
        h.close()


def test_poller_exception_zeroes_disables_reports_and_restarts(
    harness: Harness, pair: SimulatedPair, monkeypatch: pytest.MonkeyPatch
) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus

    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    amp = harness.driver.pollers['left'].amp
    real_read_current = amp.read_current
    raised: list[float] = []

    def read_current_with_a_bug(*args: Any, **kwargs: Any) -> Any:
        if not raised:
            raised.append(time.monotonic())
            raise ZeroDivisionError('injected bug')
        return real_read_current(*args, **kwargs)

    monkeypatch.setattr(amp, 'read_current', read_current_with_a_bug)
    marks = {side: len(sim.commands) for side, sim in (('left', pair.left), ('right', pair.right))}
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('poller_faults') == '1')
    status, values = harness.side_diag('left')
    assert status is not None
    assert (
        status.level == DiagnosticStatus.ERROR
        and 'ZeroDivisionError: injected bug' in values['last_poller_fault']
    )
    # Left: zero, then disable, right after the fault; right: zero (one side down stops both).
    left_log = [(c.opcode, c.words) for c in list(pair.left.commands)[marks['left'] :]]
    assert left_log.index((OpCode.SET_VELOCITY, (0,))) < left_log.index((OpCode.ENABLE, (0,)))

    def right_zeroed() -> bool:
        new = list(pair.right.commands)[marks['right'] :]
        return (OpCode.SET_VELOCITY, (0,)) in [(c.opcode, c.words) for c in new]

    assert harness.spin_until(right_zeroed)
    # Restarted: driving again on the fresh command, with the fault still counted and shown as ERROR.
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    assert enabled(pair.left) and harness.driver.pollers['left'].alive
    assert harness.spin_until(lambda: harness.side_diag('left')[1].get('connected') == 'True')
    status, values = harness.side_diag('left')
    assert status is not None
    assert status.level == DiagnosticStatus.ERROR and 'restarted after a poller fault' in status.message


def test_exception_in_a_callback_zeroes_and_disables(
    harness: Harness, pair: SimulatedPair, monkeypatch: pytest.MonkeyPatch
) -> None:
    harness.twist = (0.2, 0.0)
    assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)

    def broken_set_twist(*args: object) -> None:
        raise RuntimeError('injected bug in the cmd_vel callback')

    monkeypatch.setattr(harness.driver.command, 'set_twist', broken_set_twist)
    with pytest.raises(RuntimeError, match='injected bug'):
        harness.spin_until(lambda: False, timeout_s=5.0)
    assert both_zero(pair) and not enabled(pair.left) and not enabled(pair.right)


def test_geometry_comes_from_the_vehicle_file(
    ros_context: Context, pair: SimulatedPair, tmp_path: Path
) -> None:
    from rclpy.parameter import Parameter

    from skidsteer_power.nodes.des_driver import DesDriver

    vehicle = tmp_path / 'narrow.yaml'
    vehicle.write_text(
        'name: narrow\nrunning_gear: track\nmass_kg: 30.0\ncg_height_m: 0.15\ntread_m: 0.3\n'
        'track_length_m: 0.45\ntrack_width_m: 0.074\nsprocket_radius_m: 0.08\n'
        'powertrain: {preset: test_robot, gear_ratio: 10.0}\n'
    )
    driver = DesDriver(
        context=ros_context,
        parameter_overrides=[
            Parameter('left_port', value=pair.left.port),
            Parameter('right_port', value=pair.right.port),
            Parameter('vehicle', value=str(vehicle)),
        ],
    )
    try:
        geometry = driver.setup.geometry
        assert (geometry.tread_m, geometry.drive_radius_m, geometry.gear_ratio) == (0.3, 0.08, 10.0)
        # V 0.2 m/s, yaw rate 0.5 rad/s: v_left = 0.2 - 0.5 * 0.3 / 2 = 0.125 m/s -> 0.125 / 0.08 * 10
        # = 15.625 rad/s = 149.2 rpm; v_right = 0.275 m/s -> 34.375 rad/s = 328.3 rpm (mirrored: -).
        rpm = geometry.motor_rpm(0.2, 0.5)
        assert rpm['left'] == pytest.approx(149.21, abs=0.01)
        assert rpm['right'] == pytest.approx(-328.25, abs=0.01)
    finally:
        driver.destroy_node()
