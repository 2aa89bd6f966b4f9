"""power_estimator node over real rclpy and DDS: energy integration against a closed form, persistence
across a restart, every bad input, staleness. (Map-backed round trips: test_nodes_estimator_map.py.)

Energy tests run on simulated time (``use_sim_time``; the test publishes /clock and waits until the
node has seen each step), so the integral is exact and independent of machine speed.
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64
from test_estimator_core import FixedPowerPredictor

from skidsteer_power.estimator.prediction import Predictor
from skidsteer_power.nodes.power_estimator import PowerEstimator
from skidsteer_power.powertrain import Battery


class Rig:
    """A power_estimator in its own namespace plus a probe node that publishes and records."""

    pub_path: Publisher  # nav_msgs/Path on plan: set by the path-energy tests that publish plans

    def __init__(
        self, context: Context, tmp_path: Path, predictor: Predictor | None = None, **params: object
    ) -> None:
        self.context = context
        self.namespace = f'pe_{uuid.uuid4().hex[:8]}'
        self.tmp_path = tmp_path
        self.executor = SingleThreadedExecutor(context=context)
        self.probe = rclpy.create_node(f'probe_{self.namespace}', namespace=self.namespace, context=context)
        self.received: dict[str, list[Any]] = {}
        for topic, kind in (
            ('power/predicted', JointState),
            ('power/summary', DiagnosticArray),
            ('battery/state', BatteryState),
            ('energy/remaining_wh', Float64),
            ('energy/time_to_empty_s', Float64),
            ('diagnostics', DiagnosticArray),
        ):
            self.received[topic] = []
            self.probe.create_subscription(kind, topic, self.received[topic].append, 100)
        self.stamped = bool(params.get('cmd_vel_stamped', False))
        self.pub_cmd = self.probe.create_publisher(TwistStamped if self.stamped else Twist, 'cmd_vel', 100)
        self.pub_joint = self.probe.create_publisher(JointState, 'joint_states', 100)
        self.pub_clock = self.probe.create_publisher(Clock, '/clock', 10)
        self.executor.add_node(self.probe)
        self._node: PowerEstimator | None = None
        self.start(predictor, **params)

    @property
    def node(self) -> PowerEstimator:
        """The running estimator (between start and stop)."""
        assert self._node is not None, 'the estimator is stopped'
        return self._node

    def start(self, predictor: Predictor | None = None, **params: object) -> PowerEstimator:
        defaults: dict[str, object] = {
            'state_file': str(self.tmp_path / 'energy.json'),
            'publish_period_s': 0.05,
        }
        defaults.update(params)
        overrides = [Parameter(k, value=v) for k, v in defaults.items()]
        self._node = PowerEstimator(
            predictor, namespace=self.namespace, context=self.context, parameter_overrides=overrides
        )
        self.executor.add_node(self.node)
        self.wait_for_connection()
        return self.node

    def wait_for_connection(self) -> None:
        self.spin_until(
            lambda: self.pub_cmd.get_subscription_count() > 0 and self.pub_joint.get_subscription_count() > 0
        )

    def stop(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self._node = None

    def close(self) -> None:
        if self._node is not None:
            self.stop()
        self.executor.shutdown()
        self.probe.destroy_node()

    def spin_until(self, condition: Callable[[], object], timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                raise AssertionError('condition not met within the time limit')
            self.executor.spin_once(timeout_sec=0.01)

    def set_clock(self, t_s: float) -> None:
        sec = math.floor(t_s)
        stamp = Time(sec=sec, nanosec=round((t_s - sec) * 1e9))
        self.pub_clock.publish(Clock(clock=stamp))
        self.spin_until(lambda: abs(self.node.now_s() - t_s) < 1e-6)

    def run_clock(
        self, start_s: float, condition: Callable[[], object], step_s: float = 0.05, limit_s: float = 30.0
    ) -> float:
        """Advance sim time from ``start_s`` in steps (timers fire as it moves) until ``condition``;
        returns the time reached."""
        t = start_s
        while not condition():
            if t > start_s + limit_s:
                raise AssertionError('condition not met within the simulated time limit')
            self.set_clock(t)
            for _ in range(8):  # every output of a timer tick (~6 topics) reaches the probe
                self.executor.spin_once(timeout_sec=0.002)
            t += step_s
        return t

    def joint_state(self, t_s: float, velocity: Iterable[float], effort: Iterable[float]) -> None:
        msg = JointState(name=['left_motor', 'right_motor'], velocity=list(velocity), effort=list(effort))
        self.pub_joint.publish(msg)
        self.spin_until(lambda: self.node.core.joint_fresh.last_s == pytest.approx(t_s, abs=1e-9))

    def command(self, speed: float, yaw_rate: float, stamp: Time | None = None) -> None:
        twist = Twist()
        twist.linear.x, twist.angular.z = speed, yaw_rate
        if not self.stamped:
            self.pub_cmd.publish(twist)
            return
        msg = TwistStamped(twist=twist)
        if stamp is not None:
            msg.header.stamp = stamp
        self.pub_cmd.publish(msg)

    def drive_steady(self, seconds: float = 3.0, rate_hz: float = 20.0) -> None:
        """0.2 m/s straight for ``seconds`` on the node's clock: at each tick a command (waited for
        until the node has taken it) and a joint_states reading of 12 rad/s and 0.13 N m per side."""
        for k in range(round(seconds * rate_hz) + 1):
            t = k / rate_hz
            self.set_clock(t)
            self.command(0.2, 0.0)

            def command_seen(t: float = t) -> bool:
                return bool(self.node.core.cmd_fresh.last_s == pytest.approx(t, abs=1e-9))

            self.spin_until(command_seen)
            self.joint_state(t, (12.0, 12.0), (0.13, 0.13))

    def latest_diagnostics(self) -> dict[str, str]:
        status = self.received['diagnostics'][-1].status[0]
        return {kv.key: kv.value for kv in status.values}


def drive_measured(rig: Rig, seconds: float, rate_hz: float = 10.0) -> None:
    """joint_states on sim time 0..seconds: both motors at 300 rad/s with Kt I = 0.228 N m."""
    for k in range(round(seconds * rate_hz) + 1):
        t = k / rate_hz
        rig.set_clock(t)
        rig.joint_state(t, (300.0, 300.0), (0.228, 0.228))


def test_energy_from_measured_power_matches_the_closed_form(rig_factory: Callable[..., Rig]) -> None:
    """Both motors at 300 rad/s and Kt I = 0.228 N m (I = 2 A): bus power per side
    (0.228 x 300 + 0.710 x 2^2) / 0.92 = 77.43478 W (EC-45 Appendix B, DES 70/10 Appendix A; the hand
    calculation of test_measured_power_by_hand), 154.8696 W in all. Samples at 10 Hz on sim time from
    0 to 10 s, then the clock jumps to 12 s: the measured source holds until 10 s + 0.5 s timeout, so
    E = 154.8696 W x 10.5 s = 1626.130 J, and nothing after (cmd_vel never came: source 'none')."""
    rig = rig_factory(FixedPowerPredictor(999.0), use_sim_time=True, joint_timeout_s=0.5, persist=False)
    rig.set_clock(0.0)
    start_wh = rig.node.core.battery.remaining_wh
    drive_measured(rig, 10.0)
    count = len(rig.received['energy/remaining_wh'])
    rig.run_clock(12.0, lambda: len(rig.received['energy/remaining_wh']) > count + 1)
    power = 2 * (0.228 * 300 + 0.710 * 4) / 0.92
    assert rig.node.core.energy.energy_J['measured'] == pytest.approx(power * 10.5, rel=1e-9)
    assert rig.node.core.energy.energy_J['predicted'] == 0.0
    # the battery's open-circuit energy falls by the terminal energy plus its I^2 R loss (<= 0.4 %)
    drop_wh = start_wh - rig.received['energy/remaining_wh'][-1].data
    assert power * 10.5 / 3600 < drop_wh < 1.004 * power * 10.5 / 3600
    battery = rig.received['battery/state'][-1]
    assert battery.percentage < 1.0 and battery.voltage > 40.0


def test_energy_state_survives_a_restart(rig_factory: Callable[..., Rig], tmp_path: Path) -> None:
    rig = rig_factory(FixedPowerPredictor(999.0), use_sim_time=True, save_period_s=100.0)
    rig.set_clock(0.0)
    drive_measured(rig, 5.0)
    rig.set_clock(6.0)
    rig.node.core.tick(6.0)
    used_wh = rig.node.core.battery.remaining_wh
    energy = dict(rig.node.core.energy.energy_J)
    assert used_wh < Battery.default_test_robot().remaining_wh
    rig.stop()  # saves on shutdown
    assert (tmp_path / 'energy.json').exists()
    rig.received['energy/remaining_wh'].clear()
    rig.start(FixedPowerPredictor(999.0), use_sim_time=True)
    # messages of the old node may still be queued at the probe: judge by the newest of several
    rig.run_clock(6.0, lambda: len(rig.received['energy/remaining_wh']) > 3)
    assert rig.received['energy/remaining_wh'][-1].data == pytest.approx(used_wh, rel=1e-12)
    assert rig.node.core.energy.energy_J == pytest.approx(energy)


def test_periodic_save_writes_the_file(rig_factory: Callable[..., Rig], tmp_path: Path) -> None:
    rig = rig_factory(FixedPowerPredictor(80.0), save_period_s=0.1)
    rig.command(0.2, 0.0)
    rig.spin_until(lambda: (tmp_path / 'energy.json').exists())
    from skidsteer_power.estimator.persistence import load_state

    state = load_state(tmp_path / 'energy.json')
    assert state is not None and state['vehicle'] == 'test_robot_track'


@pytest.mark.parametrize(
    ('speed', 'yaw_rate'), [(math.nan, 0.0), (0.1, math.inf), (-math.inf, 0.0), (40.0, 0.0), (0.1, 1e4)]
)
def test_bad_cmd_vel_is_rejected_and_counted(
    rig_factory: Callable[..., Rig], speed: float, yaw_rate: float
) -> None:
    rig = rig_factory(FixedPowerPredictor(80.0), diagnostics_period_s=0.05)
    rig.command(speed, yaw_rate)
    rig.spin_until(lambda: rig.node.core.rejects.counts['cmd_vel'] == 1)
    rig.command(0.2, 0.0)  # a good one after the bad one is still served
    rig.spin_until(lambda: rig.received['power/predicted'])
    assert len(rig.received['power/predicted']) == 1
    rig.received['diagnostics'].clear()
    rig.spin_until(lambda: rig.received['diagnostics'])
    assert rig.latest_diagnostics()['rejected_cmd_vel'] == '1'


@pytest.mark.parametrize(
    ('names', 'velocity', 'effort'),
    [
        (['left_motor', 'right_motor'], [math.nan, 1.0], [0.1, 0.1]),
        (['left_motor', 'right_motor'], [1.0, 1.0], [math.inf, 0.1]),
        (['left_motor', 'right_motor'], [1.0, 1e5], [0.1, 0.1]),
        (['left_motor', 'right_motor'], [1.0, 1.0], [0.1, -300.0]),
        (['left_motor'], [1.0], [0.1]),
        (['left_motor', 'right_motor'], [], []),
    ],
)
def test_bad_joint_states_are_rejected_and_counted(
    rig_factory: Callable[..., Rig], names: list[str], velocity: list[float], effort: list[float]
) -> None:
    rig = rig_factory(FixedPowerPredictor(80.0), diagnostics_period_s=0.05)
    rig.pub_joint.publish(JointState(name=names, velocity=velocity, effort=effort))
    rig.spin_until(lambda: rig.node.core.rejects.counts['joint_states'] == 1)
    assert rig.node.core.comparison is None and rig.node.core.energy.energy_J['measured'] == 0.0
    rig.received['diagnostics'].clear()
    rig.spin_until(lambda: rig.received['diagnostics'])
    values = rig.latest_diagnostics()
    assert values['rejected_joint_states'] == '1' and values['energy_source'] == 'none'


def stamp_s(msg: DiagnosticArray) -> float:
    return float(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)


def test_stale_inputs_are_flagged(rig_factory: Callable[..., Rig]) -> None:
    rig = rig_factory(FixedPowerPredictor(80.0), use_sim_time=True, diagnostics_period_s=0.1)
    rig.set_clock(1.0)
    rig.command(0.2, 0.0)
    rig.spin_until(lambda: rig.received['power/predicted'])
    diagnostics = rig.received['diagnostics']

    def published_after(t_s: float) -> Callable[[], bool]:
        return lambda: any(stamp_s(m) > t_s for m in diagnostics)

    rig.run_clock(1.05, published_after(1.01), step_s=0.01, limit_s=0.3)
    fresh = next(m for m in diagnostics if stamp_s(m) > 1.01).status[0]
    values = {kv.key: kv.value for kv in fresh.values}
    assert values['cmd_vel_stale'] == 'false' and values['energy_source'] == 'predicted'
    assert 'joint_states stale' in fresh.message
    rig.set_clock(3.0)
    rig.run_clock(3.05, published_after(3.01), step_s=0.01)
    stale = next(m for m in diagnostics if stamp_s(m) > 3.01).status[0]
    values = {kv.key: kv.value for kv in stale.values}
    assert stale.level == bytes([1]) and 'cmd_vel stale' in stale.message
    assert values['energy_source'] == 'none' and values['cmd_vel_stale'] == 'true'


def test_a_foreign_or_torn_state_file_is_reported_and_a_fresh_battery_used(
    rig_factory: Callable[..., Rig], tmp_path: Path
) -> None:
    (tmp_path / 'energy.json').write_text('{"format_version": 1, "vehicle": "packbot_track", "battery": {}}')
    rig = rig_factory(FixedPowerPredictor(80.0), initial_soc=0.5)
    assert rig.node.core.battery.soc == 0.5  # not restored: the file belongs to another vehicle
    rig.stop()
    (tmp_path / 'energy.json').write_text('{"format_version": 1, "batt')
    rig.start(FixedPowerPredictor(80.0))
    assert rig.node.core.battery.soc == 1.0


@pytest.mark.parametrize(
    ('name', 'value', 'match'),
    [('cmd_timeout_s', -1.0, 'cmd_timeout_s must be'),
     ('save_period_s', 0.0, 'save_period_s must be within 0.1 .. 86400'),
     ('vehicle', 'no_such_robot', 'no_such_robot'), ('max_speed_m_s', math.nan, 'max_speed_m_s')],
)  # fmt: skip
def test_bad_start_parameters_are_one_clear_error(
    ros_context: Context, name: str, value: float | str, match: str
) -> None:
    from skidsteer_power.errors import SkidsteerError

    with pytest.raises(SkidsteerError, match=match):
        PowerEstimator(
            FixedPowerPredictor(1.0), context=ros_context, parameter_overrides=[Parameter(name, value=value)]
        )
