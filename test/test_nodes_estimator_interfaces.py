"""power_estimator's ROS interface over real rclpy and DDS: ~/reset_energy, QoS (best-effort and
reliable joint_states publishers, qos_overrides), the named figures (and their timer) and BatteryState
conventions."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64
from std_srvs.srv import Trigger
from test_estimator_core import FixedPowerPredictor
from test_nodes_estimator import Rig, drive_measured

from skidsteer_power.estimator.prediction import Predictor
from skidsteer_power.estimator.summary import (
    COMMAND_FIGURES,
    MEASUREMENT_FIGURES,
    SUMMARY_FIELDS,
    SUMMARY_STATUS_NAME,
    summary_from_key_values,
)

# Both motors at 300 rad/s, Kt I = 0.228 N m (I = 2 A): motor terminal power per side
# 0.228 x 300 + 0.710 x 2^2 = 71.24 W (EC-45 Appendix B: R = 0.710 ohm; see test_nodes_estimator).
MEASURED_SIDE_W = 0.228 * 300 + 0.710 * 4


@pytest.fixture
def rigs(ros_context: Context, tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    made: list[Rig] = []

    def make(predictor: Predictor | None = None, **params: object) -> Rig:
        made.append(Rig(ros_context, tmp_path, predictor, **params))
        return made[-1]

    yield make
    for rig in made:
        rig.close()


def call_trigger(rig: Rig, name: str) -> Trigger.Response:
    client = rig.probe.create_client(Trigger, name)
    rig.spin_until(client.service_is_ready)
    future = client.call_async(Trigger.Request())
    rig.spin_until(future.done)
    return future.result()


def test_reset_energy_fills_the_battery_zeroes_the_tallies_and_rewrites_the_state(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    rig = rigs(FixedPowerPredictor(999.0), use_sim_time=True, save_period_s=100.0)
    rig.set_clock(0.0)
    drive_measured(rig, 5.0)
    rig.set_clock(6.0)
    rig.node.save()
    before = json.loads((tmp_path / 'energy.json').read_text())
    assert before['energy_J']['measured'] > 0 and before['battery']['state']['soc'] < 1.0
    response = call_trigger(rig, f'/{rig.namespace}/power_estimator/reset_energy')
    assert response.success and 'full' in response.message
    core = rig.node.core
    assert core.battery.soc == 1.0 and core.energy.energy_J == {'measured': 0.0, 'predicted': 0.0}
    after = json.loads((tmp_path / 'energy.json').read_text())
    assert after['battery']['state']['soc'] == 1.0
    assert after['energy_J'] == {'measured': 0.0, 'predicted': 0.0}


def _joint_states(velocity: float) -> JointState:
    return JointState(name=['left_motor', 'right_motor'], velocity=[velocity] * 2, effort=[0.228] * 2)


def _publish_until_used(rig: Rig, publisher: Publisher, velocity: float) -> None:
    def used() -> bool:
        comparison = rig.node.core.comparison
        return comparison is not None and comparison.measured.omega_rad_s[0] == velocity

    for _ in range(200):  # best effort: a message may be dropped, so publish until one is used
        publisher.publish(_joint_states(velocity))
        rig.executor.spin_once(timeout_sec=0.02)
        if used():
            return
    raise AssertionError(f'joint_states at {velocity} rad/s never used')


def test_best_effort_and_reliable_joint_states_publishers_are_both_used(rigs: Callable[..., Rig]) -> None:
    rig = rigs(FixedPowerPredictor(80.0), persist=False)
    best_effort = rig.probe.create_publisher(JointState, 'joint_states', qos_profile_sensor_data)
    reliable = rig.probe.create_publisher(JointState, 'joint_states', QoSProfile(depth=10))
    rig.spin_until(lambda: best_effort.get_subscription_count() > 0 and reliable.get_subscription_count() > 0)
    _publish_until_used(rig, best_effort, 111.0)
    _publish_until_used(rig, reliable, 222.0)
    _publish_until_used(rig, best_effort, 333.0)


def _subscription_reliability(rig: Rig, topic: str) -> ReliabilityPolicy:
    infos = rig.probe.get_subscriptions_info_by_topic(f'/{rig.namespace}/{topic}')
    (info,) = [i for i in infos if i.node_name == 'power_estimator']
    reliability: ReliabilityPolicy = info.qos_profile.reliability
    return reliability


def test_subscriptions_are_best_effort_unless_overridden(rigs: Callable[..., Rig]) -> None:
    rig = rigs(FixedPowerPredictor(80.0), persist=False)
    rig.spin_until(lambda: rig.probe.get_subscriptions_info_by_topic(f'/{rig.namespace}/joint_states'))
    assert _subscription_reliability(rig, 'joint_states') == ReliabilityPolicy.BEST_EFFORT
    rig.stop()
    # qos_overrides are enabled: the standard parameter switches the subscription to reliable
    key = f'qos_overrides./{rig.namespace}/joint_states.subscription.reliability'
    rig.start(FixedPowerPredictor(80.0), persist=False, **{key: 'reliable'})

    def reliable() -> bool:
        infos = rig.probe.get_subscriptions_info_by_topic(f'/{rig.namespace}/joint_states')
        return any(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)

    rig.spin_until(reliable)
    assert _subscription_reliability(rig, 'joint_states') == ReliabilityPolicy.RELIABLE


def test_named_figures_per_message_and_summary_by_key(rigs: Callable[..., Rig]) -> None:
    rig = rigs(FixedPowerPredictor(80.0), persist=False, publish_period_s=0.05)
    figures: dict[str, list[float]] = {}
    for topic, _ in (*COMMAND_FIGURES, *MEASUREMENT_FIGURES):
        figures[topic] = []

        def on_figure(m: Float64, t: str = topic) -> None:
            figures[t].append(m.data)

        rig.probe.create_subscription(Float64, topic, on_figure, 10)
    rig.command(0.2, 0.0)
    rig.spin_until(lambda: all(figures[t] for t, _ in COMMAND_FIGURES))
    rig.pub_joint.publish(_joint_states(300.0))
    rig.spin_until(lambda: all(figures[t] for t, _ in MEASUREMENT_FIGURES))
    assert figures['power/measured_left_w'][-1] == pytest.approx(MEASURED_SIDE_W, rel=1e-12)
    assert figures['power/measured_right_w'][-1] == pytest.approx(MEASURED_SIDE_W, rel=1e-12)
    # FixedPowerPredictor: 80 W at the battery for any command
    assert figures['power/predicted_battery_w'][-1] == pytest.approx(80.0, rel=1e-12)
    rig.received['power/summary'].clear()
    rig.spin_until(lambda: rig.received['power/summary'])
    (status,) = rig.received['power/summary'][-1].status
    assert status.name == SUMMARY_STATUS_NAME
    summary = summary_from_key_values((kv.key, kv.value) for kv in status.values)
    assert tuple(summary) == SUMMARY_FIELDS
    assert summary['speed_cmd_m_s'] == 0.2
    assert summary['measured_left_W'] == figures['power/measured_left_w'][-1]  # repr: exact


def test_figures_are_the_latest_value_per_timer_tick_not_per_message(rigs: Callable[..., Rig]) -> None:
    # sim time: the figure timer (figure_period_s = 1 s) fires only when the test moves the clock
    rig = rigs(FixedPowerPredictor(80.0), persist=False, use_sim_time=True, figure_period_s=1.0)
    figures: list[float] = []

    def on_figure(m: Float64) -> None:
        figures.append(m.data)

    rig.probe.create_subscription(Float64, 'power/predicted_battery_w', on_figure, 100)
    rig.set_clock(0.0)
    for i in range(20):
        rig.command(0.01 * (i + 1), 0.0)
    rig.spin_until(lambda: len(rig.received['power/predicted']) == 20)  # per message, as before
    assert figures == []  # no tick yet: nothing, however many commands
    rig.set_clock(1.0)
    rig.spin_until(lambda: figures)
    for _ in range(20):
        rig.executor.spin_once(timeout_sec=0.005)
    assert figures == [80.0]  # one tick: the latest value once (FixedPowerPredictor: 80 W)
    rig.set_clock(2.0)
    for _ in range(20):
        rig.executor.spin_once(timeout_sec=0.005)
    assert figures == [80.0]  # no new command since: nothing new
    rig.command(0.3, 0.0)
    rig.spin_until(lambda: len(rig.received['power/predicted']) == 21)
    rig.set_clock(3.0)
    rig.spin_until(lambda: len(figures) == 2)


def test_battery_state_follows_the_message_conventions(rigs: Callable[..., Rig]) -> None:
    rig = rigs(FixedPowerPredictor(80.0), persist=False, publish_period_s=0.05)
    rig.spin_until(lambda: rig.received['battery/state'])
    idle = rig.received['battery/state'][-1]
    assert idle.power_supply_status == BatteryState.POWER_SUPPLY_STATUS_NOT_CHARGING and idle.current == 0.0
    assert idle.present and idle.power_supply_technology == BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO
    assert math.isnan(idle.temperature)
    assert len(idle.cell_voltage) == 12 and all(math.isnan(v) for v in idle.cell_voltage)  # 2 x 6S
    assert idle.capacity == pytest.approx(5.0) and idle.percentage == 1.0
    rig.command(0.2, 0.0)  # 80 W predicted: discharging, current negative by the message's convention
    rig.received['battery/state'].clear()
    rig.spin_until(lambda: any(m.current < 0 for m in rig.received['battery/state']))
    driving = next(m for m in rig.received['battery/state'] if m.current < 0)
    assert driving.power_supply_status == BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
    # 80 W from about 50.4 V (12 cells at 4.20 V, full): I ~ 1.6 A
    assert -1.7 < driving.current < -1.5


def test_sensor_data_outputs_by_parameter(rigs: Callable[..., Rig]) -> None:
    rig = rigs(FixedPowerPredictor(80.0), persist=False, output_qos='sensor_data')
    topic = f'/{rig.namespace}/power/predicted'
    rig.spin_until(lambda: rig.probe.get_publishers_info_by_topic(topic))
    (info,) = rig.probe.get_publishers_info_by_topic(topic)
    assert info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT


def test_bad_qos_parameters_are_one_clear_error(ros_context: Context) -> None:
    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes.power_estimator import PowerEstimator

    for name, value in (('input_reliability', 'sometimes'), ('output_qos', 'fast')):
        with pytest.raises(ConfigError, match=name):
            PowerEstimator(
                FixedPowerPredictor(1.0),
                context=ros_context,
                parameter_overrides=[Parameter(name, value=value), Parameter('persist', value=False)],
            )
    assert rclpy.ok(context=ros_context)


def test_battery_fields_status_follows_the_current_sign() -> None:
    """Pure: drawing power discharges (current < 0 by the message's convention), regenerating
    charges (current > 0), nothing drawn is neither; unknown quantities are NaN, never 0."""
    from skidsteer_power.estimator.factory import battery_message_fields
    from skidsteer_power.powertrain import Battery

    battery = Battery.default_test_robot(soc=0.5)
    drawing = battery_message_fields(battery, 100.0)
    regen = battery_message_fields(battery, -30.0)
    idle = battery_message_fields(battery, 0.0)
    assert drawing['status'] == 'discharging' and drawing['current'] < 0
    assert regen['status'] == 'charging' and regen['current'] > 0
    assert idle['status'] == 'not_charging' and idle['current'] == 0.0
    assert math.isnan(idle['temperature']) and idle['present'] and idle['chemistry'] == 'LiPo'
    # terminal voltage: above open circuit while charging, below while discharging (R > 0)
    assert regen['voltage'] > idle['voltage'] > drawing['voltage']
