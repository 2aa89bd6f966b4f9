"""A stale command is a zero command (issue 37 item 4): the prediction falls back to standing still,
and standing still is OK, not WARN. Core and node (real rclpy publisher, real DDS)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from rclpy.context import Context
from std_msgs.msg import Float64
from test_cmd_vel_input import Graph
from test_estimator_core import FixedPowerPredictor

from skidsteer_power.estimator.core import EstimatorCore, EstimatorSettings
from skidsteer_power.estimator.prediction import Prediction
from skidsteer_power.estimator.summary import summary_dict
from skidsteer_power.powertrain import Battery, Powertrain

WATTS_PER_M_S = 400.0  # the test predictor: battery power = 400 W s/m * |V| (0.3 m/s -> 120 W)


class SpeedPowerPredictor(FixedPowerPredictor):
    """Battery power proportional to |V|: standing still predicts 0 W."""

    def __init__(self) -> None:
        super().__init__(0.0)

    def predict(self, speed_m_s: float, yaw_rate_rad_s: float) -> Prediction:
        self.battery_W = WATTS_PER_M_S * abs(speed_m_s)
        base = super().predict(speed_m_s, yaw_rate_rad_s)
        k = abs(speed_m_s) / 0.3  # speeds and torques too: standing predicts zero everywhere
        scaled: dict[str, Any] = {
            f.name: tuple(k * v for v in getattr(base, f.name))
            for f in dataclasses.fields(base)
            if isinstance(getattr(base, f.name), tuple)
        }
        return dataclasses.replace(base, **scaled)


def test_core_predicts_standing_once_the_command_is_stale() -> None:
    core = EstimatorCore(
        SpeedPowerPredictor(),
        Battery.default_test_robot(),
        Powertrain.default_test_robot(),
        EstimatorSettings(cmd_timeout_s=0.5),
    )
    core.on_command(0.3, 0.0, 0.0)
    core.tick(0.4)
    assert summary_dict(core, 0.4)['predicted_left_W'] == 60.0  # 120 W / 2, still in force
    # in time order (a reading stamped before an earlier tick is a clock step back, issue 34 item 10)
    core.on_joint_state(['left_motor', 'right_motor'], [0.0, 0.0], [0.0, 0.0], 0.9)
    core.tick(1.0)  # 1 s after the command: the watchdog holds zero
    values = summary_dict(core, 1.0)
    assert values['predicted_left_W'] == 0.0 and values['predicted_speed_left_rad_s'] == 0.0
    assert values['cmd_vel_stale'] == 1.0
    level, message, diag = core.diagnostics(1.0)
    assert level == 0 and 'standing' in message  # joint_states fresh, robot standing: OK
    assert diag['expired_commands'] == '1'
    core.tick(2.0)
    assert core.expired_commands == 1  # once per stale command, not per tick


def test_node_publishes_the_standing_prediction(ros_context: Context, tmp_path: Path) -> None:
    g = Graph(ros_context, tmp_path, cmd_timeout_s=0.3)
    g.node.core.predictor = SpeedPowerPredictor()
    try:
        summaries: list[DiagnosticArray] = []
        g.client.create_subscription(DiagnosticArray, 'power/summary', summaries.append, 100)
        publisher = g.client.create_publisher(Twist, 'cmd_vel', 10)
        msg = Twist()
        msg.linear.x = 0.3
        before = len(g.predicted)
        deadline = time.monotonic() + 5.0
        while len(g.predicted) == before and time.monotonic() < deadline:
            publisher.publish(msg)
            g.spin_until(lambda: len(g.predicted) > before, 0.1)
        moving = g.predicted[-1]
        assert list(moving.effort[:2]) != [0.0, 0.0] or moving.velocity[0] != 0.0

        figures: list[Float64] = []
        g.client.create_subscription(Float64, 'power/predicted_left_w', figures.append, 100)
        assert g.spin_until(lambda: bool(figures) and figures[-1].data == 0.0)  # standing still: 0 W
        assert len(g.predicted) >= 1  # power/predicted: one message per cmd_vel, none for the expiry

        def summary_standing() -> bool:
            if not summaries:
                return False
            values = {kv.key: float(kv.value) for kv in summaries[-1].status[0].values}
            return values['cmd_vel_stale'] == 1.0 and values['predicted_left_W'] == 0.0

        assert g.spin_until(summary_standing)
    finally:
        g.close()
