"""des_driver's cmd_vel QoS: real rclpy and DDS, two simulated amplifiers on ptys.

Many teleop and joystick nodes publish cmd_vel best effort; a reliable reader never matches them (DDS
request/offer rules), so the driver reads best effort, which matches both, and honours the standard
``qos_overrides./cmd_vel.subscription.reliability`` parameter.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from des_harness import Harness
from rclpy.context import Context

from skidsteer_power.des.simulator import SimulatedPair

pytestmark = pytest.mark.ros


@pytest.fixture
def pair() -> Iterator[SimulatedPair]:
    with SimulatedPair(38400) as sims:
        yield sims


def _best_effort_teleop(harness: Harness, ns: str) -> None:
    """A best-effort cmd_vel publisher at 20 Hz on the harness's node (as teleop_twist_joy's)."""
    from geometry_msgs.msg import Twist
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    pub = harness.node.create_publisher(
        Twist, f'{ns}/cmd_vel', QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    )

    def publish() -> None:
        msg = Twist()
        msg.linear.x = 0.2
        pub.publish(msg)

    harness.node.create_timer(0.05, publish)


def test_best_effort_cmd_vel_drives(ros_context: Context, pair: SimulatedPair) -> None:
    ns = f'/t{uuid.uuid4().hex[:8]}'
    h = Harness(ros_context, pair, namespace=ns)
    try:
        _best_effort_teleop(h, ns)
        # 0.2 m/s straight: both set points non-zero (left forward, right mirrored)
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0 and pair.right.speed_setpoint_rpm < 0)
    finally:
        h.close()


def test_reliability_override_is_honoured(ros_context: Context, pair: SimulatedPair) -> None:
    """With ``reliability: reliable`` forced, the best-effort writer no longer matches: the motors stay
    at zero while a reliable writer (the harness's own) still drives."""
    ns = f'/t{uuid.uuid4().hex[:8]}'
    qos: dict[str, Any] = {f'qos_overrides.{ns}/cmd_vel.subscription.reliability': 'reliable'}
    h = Harness(ros_context, pair, namespace=ns, **qos)
    try:
        _best_effort_teleop(h, ns)
        assert not h.spin_until(lambda: pair.left.speed_setpoint_rpm != 0, timeout_s=1.5)
        assert h.driver.counts['received'] == 0
        h.twist = (0.2, 0.0)  # reliable writer
        assert h.spin_until(lambda: pair.left.speed_setpoint_rpm > 0)
    finally:
        h.close()


def test_estimator_counts_the_drivers_no_data_as_no_data(
    ros_context: Context, pair: SimulatedPair, tmp_path: Path
) -> None:
    """The driver's "no fresh data" joint_states (a silent amplifier: NaN in position, velocity and
    effort of that side) reach a real power_estimator over DDS: counted as no data, never rejected;
    the driver's good messages before it are used (measured power)."""
    import math

    from rclpy.parameter import Parameter

    from skidsteer_power.des.simulator import Fault
    from skidsteer_power.nodes.power_estimator import PowerEstimator

    ns = f'/t{uuid.uuid4().hex[:8]}'
    h = Harness(ros_context, pair, namespace=ns)
    estimator = PowerEstimator(
        namespace=ns,
        context=ros_context,
        parameter_overrides=[Parameter('state_file', value=str(tmp_path / 'energy.json'))],
    )
    h.executor.add_node(estimator)
    try:
        h.twist = (0.2, 0.0)
        assert h.spin_until(lambda: estimator.core.comparison is not None)
        pair.right.inject(Fault.SILENT, count=-1)
        assert h.spin_until(lambda: h.joints and math.isnan(h.joints[-1].effort[1]))
        assert h.spin_until(lambda: estimator.core.no_data_count >= 3)
        assert estimator.core.rejects.counts['joint_states'] == 0
    finally:
        h.executor.remove_node(estimator)
        estimator.destroy_node()
        h.close()


def test_parameter_file_matches_the_node_and_is_read(tmp_path: Path, pair: SimulatedPair) -> None:
    """config/des_driver.yaml (installed by setup.py, passed by the launch file) lists every parameter
    with the node's default; a node started with a --params-file takes its values."""
    from pathlib import Path

    import rclpy
    import yaml
    from rclpy.context import Context

    from skidsteer_power.nodes.des_driver import PARAMETERS, DesDriver

    root = Path(__file__).resolve().parents[1]
    shipped = yaml.safe_load((root / 'config' / 'des_driver.yaml').read_text())
    values = shipped['des_driver']['ros__parameters']
    assert values == {spec.name: spec.default for spec in PARAMETERS}
    assert "'des_driver.yaml'" in (root / 'launch' / 'skidsteer_power.launch.py').read_text()
    values.update(left_port=pair.left.port, right_port=pair.right.port, max_speed_m_s=0.7)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'des_driver': {'ros__parameters': values}}))
    context = Context()
    rclpy.init(args=['--ros-args', '--params-file', str(params)], context=context)
    try:
        node = DesDriver(context=context)
        assert node.params.max_speed_m_s == 0.7 and node.params.left_port == pair.left.port
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
