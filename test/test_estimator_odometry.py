"""Dead reckoning of the predicted twist (skidsteer_power.estimator.odometry).

References: a constant twist traces a circle of radius V / w_z (hand geometry); a straight twist a
line of length V t.
"""

from __future__ import annotations

import math

import pytest

from skidsteer_power.estimator.odometry import MAX_STEP_S, PredictedOdometry


def test_a_constant_turn_closes_its_circle() -> None:
    odo = PredictedOdometry()
    odo.set_twist(0.2, 0.1, 0.0)  # R = 2 m, one lap in 2 pi / 0.1 s
    lap = 2 * math.pi / 0.1
    t = 0.0
    while t < lap / 4 - 1e-9:
        t = min(t + 0.37, lap / 4)
        odo.advance(t)
    assert (odo.x_m, odo.y_m) == pytest.approx((2.0, 2.0), abs=1e-9)  # a quarter: (R, R)
    assert odo.yaw_rad == pytest.approx(math.pi / 2)


def test_straight_and_reset() -> None:
    odo = PredictedOdometry()
    odo.set_twist(0.5, 0.0, 10.0)
    odo.advance(10.8)
    assert (odo.x_m, odo.y_m, odo.yaw_rad) == pytest.approx((0.4, 0.0, 0.0))
    odo.reset(10.8)
    odo.advance(11.0)
    assert odo.x_m == pytest.approx(0.1)


def test_a_long_gap_is_cut_and_bad_twists_stop() -> None:
    odo = PredictedOdometry()
    odo.set_twist(1.0, 0.0, 0.0)
    odo.advance(100.0)
    assert odo.x_m == pytest.approx(MAX_STEP_S)
    odo.set_twist(math.nan, 0.0, 100.0)
    odo.advance(100.5)
    assert odo.x_m == pytest.approx(MAX_STEP_S)
    assert odo.quaternion() == pytest.approx((0.0, 0.0, 0.0, 1.0))
