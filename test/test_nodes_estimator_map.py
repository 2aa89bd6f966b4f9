"""power_estimator on the real FESS map: cmd_vel -> power/predicted + power/summary round trip (Twist
and TwistStamped), reverse and spin in place, and a run-time terrain change."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from builtin_interfaces.msg import Time
from rclpy.context import Context
from rclpy.parameter import Parameter
from test_nodes_estimator import Rig

from skidsteer_power.estimator.factory import map_predictor
from skidsteer_power.estimator.prediction import Prediction
from skidsteer_power.estimator.summary import SUMMARY_FIELDS, summary_from_key_values
from skidsteer_power.nodes.power_estimator import PowerEstimator
from skidsteer_power.vehicle import load_vehicle


@pytest.fixture(scope='module')
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp('maps'))


@pytest.fixture
def rig(ros_context: Context, tmp_path: Path, cache_dir: str) -> Iterator[Rig]:
    rig = Rig(ros_context, tmp_path, map_cache_dir=cache_dir, terrain='dry_sand')
    yield rig
    rig.close()


def expected(cache_dir: str, terrain: str, speed: float, yaw_rate: float) -> Prediction:
    predictor, _, _ = map_predictor(load_vehicle('test_robot_track'), terrain, cache_dir)
    return predictor.predict(speed, yaw_rate)


@pytest.mark.parametrize(('speed', 'yaw_rate'), [(0.2, 0.1), (-0.2, 0.1), (0.0, 0.5), (0.1, -0.35)])
def test_cmd_vel_round_trip(rig: Rig, cache_dir: str, speed: float, yaw_rate: float) -> None:
    """Forward, reverse, spin in place and a right turn all answer at once with the map's values."""
    rig.command(speed, yaw_rate)
    rig.received['power/summary'].clear()

    def summaries() -> list[dict[str, float]]:
        return [
            summary_from_key_values((kv.key, kv.value) for kv in m.status[0].values)
            for m in rig.received['power/summary']
        ]

    rig.spin_until(
        lambda: rig.received['power/predicted'] and any(s['speed_cmd_m_s'] == speed for s in summaries())
    )
    msg = rig.received['power/predicted'][-1]
    p = expected(cache_dir, 'dry_sand', speed, yaw_rate)
    assert list(msg.name) == ['left_motor', 'right_motor', 'left_axle', 'right_axle']
    assert list(msg.velocity) == pytest.approx([*p.motor_omega_rad_s, *p.axle_omega_rad_s])
    assert list(msg.effort) == pytest.approx([*p.motor_torque_Nm, *p.terrain_torque_Nm])
    summary = next(s for s in summaries() if s['speed_cmd_m_s'] == speed)
    assert tuple(summary) == SUMMARY_FIELDS
    assert summary['speed_cmd_m_s'] == speed and summary['yaw_rate_cmd_rad_s'] == yaw_rate
    assert summary['predicted_battery_W'] == pytest.approx(p.bus_total_W)
    assert summary['terrain_W'] == pytest.approx(p.terrain_total_W)
    assert summary['traction_margin'] == pytest.approx(p.traction_margin)
    assert math.isnan(summary['measured_battery_W'])  # no joint_states yet


def test_twist_stamped_keeps_the_stamp(ros_context: Context, tmp_path: Path, cache_dir: str) -> None:
    rig = Rig(ros_context, tmp_path, map_cache_dir=cache_dir, cmd_vel_stamped=True)
    try:
        # a fresh stamp (the node's clock, plus 5678 ns to tell it apart): one far from the node's
        # clock is refused (issue 34 item 5, cmd_vel_stamp_tolerance_s)
        now = rig.node.get_clock().now().to_msg()
        stamp = Time(sec=now.sec, nanosec=(now.nanosec // 10_000) * 10_000 + 5678)
        rig.command(0.2, 0.0, stamp=stamp)
        rig.spin_until(lambda: rig.received['power/predicted'])
        out = rig.received['power/predicted'][-1]
        assert (out.header.stamp.sec, out.header.stamp.nanosec) == (stamp.sec, stamp.nanosec)
        assert list(out.effort[:2]) == pytest.approx(
            list(expected(cache_dir, 'dry_sand', 0.2, 0.0).motor_torque_Nm)
        )
    finally:
        rig.close()


def test_terrain_changes_at_run_time(rig: Rig, cache_dir: str) -> None:
    rig.command(0.2, 0.1)
    rig.spin_until(lambda: rig.received['power/predicted'])
    on_sand = list(rig.received['power/predicted'][-1].effort)
    result = rig.node.set_parameters([Parameter('terrain', value='clay')])[0]
    assert result.successful
    assert rig.node.wait_for_terrain_change(timeout_s=60.0)
    assert rig.node.terrain_name == 'clay'
    rig.received['power/predicted'].clear()
    rig.command(0.2, 0.1)
    rig.spin_until(lambda: rig.received['power/predicted'])
    on_clay = list(rig.received['power/predicted'][-1].effort)
    clay = expected(cache_dir, 'clay', 0.2, 0.1)
    assert on_clay == pytest.approx([*clay.motor_torque_Nm, *clay.terrain_torque_Nm])
    assert on_clay != pytest.approx(on_sand)


def test_unknown_terrain_is_refused_and_the_map_kept(rig: Rig) -> None:
    result = rig.node.set_parameters([Parameter('terrain', value='lava_field')])[0]
    assert not result.successful and 'lava_field' in result.reason
    assert rig.node.get_parameter('terrain').value == 'dry_sand' and rig.node.terrain_name == 'dry_sand'


def test_start_only_parameters_are_read_only_at_run_time(rig: Rig) -> None:
    result = rig.node.set_parameters([Parameter('vehicle', value='packbot_track')])[0]
    assert not result.successful and 'read-only' in result.reason  # its descriptor says read_only
    assert rig.node.get_parameter('vehicle').value != 'packbot_track'


def test_parameter_file_matches_the_node_and_is_read(tmp_path: Path, cache_dir: str) -> None:
    """config/estimator.yaml lists every parameter with the node's default; a node started with a
    --params-file (here with terrain changed to clay) takes its values."""
    import yaml
    from rclpy.context import Context

    from skidsteer_power.nodes.power_estimator import PARAMETERS

    path = Path(__file__).resolve().parents[1] / 'config' / 'estimator.yaml'
    values = yaml.safe_load(path.read_text())['power_estimator']['ros__parameters']
    assert values == {spec.name: spec.default for spec in PARAMETERS}
    values.update(terrain='clay', map_cache_dir=cache_dir, persist=False)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'power_estimator': {'ros__parameters': values}}))
    context = Context()
    rclpy.init(args=['--ros-args', '--params-file', str(params)], context=context)
    try:
        node = PowerEstimator(context=context)
        assert node.terrain_name == 'clay' and node.get_parameter('persist').value is False
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_predicted_twist_and_odometry(rig: Rig, cache_dir: str) -> None:
    """Issue 25: power/predicted_twist carries the motion the set-point prediction expects (reference:
    the same map's SetpointPredictor), odom/predicted dead-reckons it, ~/reset_odometry restarts it."""
    from geometry_msgs.msg import TwistStamped
    from nav_msgs.msg import Odometry
    from std_srvs.srv import Trigger

    twists: list[Any] = []  # TwistStamped messages
    odoms: list[Any] = []  # Odometry messages
    rig.probe.create_subscription(TwistStamped, 'power/predicted_twist', twists.append, 10)
    rig.probe.create_subscription(Odometry, 'odom/predicted', odoms.append, 100)
    rig.spin_until(lambda: rig.node.pub_predicted_twist.get_subscription_count() > 0)
    rig.command(0.2, 0.1)
    rig.spin_until(lambda: twists)
    p = expected(cache_dir, 'dry_sand', 0.2, 0.1)
    assert twists[-1].twist.linear.x == pytest.approx(p.achieved_speed_m_s)
    assert twists[-1].twist.angular.z == pytest.approx(p.achieved_yaw_rate_rad_s)
    assert 0 < twists[-1].twist.angular.z < 0.1  # the track skids: less yaw than commanded

    def motion_in_summary() -> bool:
        for m in rig.received['power/summary']:
            s = summary_from_key_values((kv.key, kv.value) for kv in m.status[0].values)
            if s.get('predicted_motion_speed_m_s') == pytest.approx(p.achieved_speed_m_s):
                return s['predicted_motion_yaw_rate_rad_s'] == pytest.approx(p.achieved_yaw_rate_rad_s)
        return False

    rig.spin_until(motion_in_summary)  # the monitor shows it from power/summary
    rig.spin_until(lambda: odoms and odoms[-1].pose.pose.position.x > 0.01)
    client = rig.probe.create_client(Trigger, f'/{rig.namespace}/power_estimator/reset_odometry')
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    rig.spin_until(future.done)
    assert future.result().success
    odoms.clear()
    rig.spin_until(lambda: odoms)
    assert odoms[0].pose.pose.position.x < 0.01  # back at the origin (one publish period travelled)
