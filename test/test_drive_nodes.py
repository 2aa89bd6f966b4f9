"""The drive controller's limits on the nodes' paths from a command (issue 36): power_estimator
predicts through the driver's own limits (the live-suite case: des_driver max_speed_m_s 0.5 and a
1.0 m/s command predicted 120 rad/s at the motors where the driver commanded 60)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pytest

from skidsteer_power.nodes.suite import Suite, SuiteOptions
from skidsteer_power.vehicle import load_vehicle

if TYPE_CHECKING:
    from test_nodes_estimator import Rig

# test_robot_track: sprocket radius 0.1 m, 12:1 (config/vehicles/test_robot_track.yaml, section 7.1.1)
RADIUS_M, GEAR = 0.1, 12.0


@pytest.mark.parametrize(
    ('limit', 'motor_rad_s'), [(0.0, 1.0 / RADIUS_M * GEAR), (0.5, 0.5 / RADIUS_M * GEAR)]
)
def test_the_estimator_predicts_at_the_drivers_limits(
    rig_factory: Callable[..., Rig], limit: float, motor_rad_s: float
) -> None:
    # 0: the vehicle file's 1.5 m/s, the command passes: 1.0 / 0.1 x 12 = 120 rad/s; 0.5: 60 rad/s
    rig = rig_factory(drive_max_speed_m_s=limit)
    rig.command(1.0, 0.0)
    rig.spin_until(lambda: rig.received['power/predicted'], timeout_s=120.0)
    predicted = rig.received['power/predicted'][-1]
    assert list(predicted.velocity)[:2] == pytest.approx([motor_rad_s, motor_rad_s])  # left, right motor


def test_the_suite_gives_the_estimator_the_drivers_limits() -> None:
    suite = object.__new__(Suite)  # the parameter plumbing only: no nodes, no ports
    suite.options = SuiteOptions(driver_params={'max_speed_m_s': 0.5, 'max_motor_rpm': 3000.0})
    suite.vehicle = load_vehicle('test_robot_track')
    limits = suite._driver_limits()
    assert limits['drive_max_speed_m_s'] == 0.5
    assert limits['drive_max_yaw_rate_rad_s'] == 2.0  # des_driver's default
    # 3000 rpm x 2 pi / 60 / 12 = 26.18 rad/s at the sprocket
    assert limits['drive_max_wheel_rad_s'] == pytest.approx(3000 * 2 * 3.141592653589793 / 60 / 12)
