"""Operating points and load transfer (eqs. 3.1 / 6.12)."""

from __future__ import annotations

import numpy as np
import pytest

from skidsteer_power.errors import InputError
from skidsteer_power.models import loads
from skidsteer_power.vehicle import load_vehicle

CH3 = load_vehicle('chapter3_track')


def test_eq_3_1_hand_calculation() -> None:
    # Table 3.3: m 30 kg, B 0.4 m, h 0.15 m; V = 1 m/s, R = 2 m:
    #   m g / 2 = 30 * 9.81 / 2 = 147.15 N;  m V^2 h / (R B) = 30 * 1 * 0.15 / (2 * 0.4) = 5.625 N
    points = loads.operating_points(1.0, 2.0)
    outer, inner = loads.side_loads(CH3, points)
    assert outer[0] == pytest.approx(147.15 + 5.625)
    assert inner[0] == pytest.approx(147.15 - 5.625)
    assert loads.centrifugal_force(CH3, points)[0] == pytest.approx(15.0)  # m V^2 / R


def test_straight_and_mirror() -> None:
    points = loads.operating_points([0.5, 0.5, 0.5], [np.inf, -2.0, 2.0])
    outer, inner = loads.side_loads(CH3, points)
    assert outer[0] == inner[0] == pytest.approx(147.15)  # no transfer when straight, no 0 * inf
    assert outer[1] == outer[2] and inner[1] == inner[2]  # R and -R: same outer/inner loads
    assert points.yaw_rate.tolist() == [0.0, 0.25, 0.25]
    assert points.straight.tolist() == [True, False, False]
    v_o, v_i = points.side_speeds(CH3.tread_m)
    assert v_o[2] == pytest.approx(0.25 * 2.2) and v_i[2] == pytest.approx(0.25 * 1.8)  # (R +- B/2) yaw


def test_broadcast_shape_and_labels() -> None:
    points = loads.operating_points(np.array([[0.1], [0.2]]), np.array([1.0, 2.0, np.inf]))
    assert points.shape == (2, 3) and points.speed.size == 6
    assert points.label(5) == 'V = 0.2 m/s, R = inf m'


@pytest.mark.parametrize(
    ('speed', 'radius'), [(0.0, 1.0), (-1.0, 1.0), (np.nan, 1.0), (1.0, 0.0), (1.0, np.nan)]
)
def test_bad_operating_points(speed: float, radius: float) -> None:
    with pytest.raises(InputError):
        loads.operating_points(speed, radius)


def test_slip_definitions_round_trip() -> None:
    # eq. 2.13: driving s = (r w - V)/(r w), braking s = (r w - V)/V
    side_speed = np.array([1.0, 1.0])
    omega = np.array([12.5, 8.0])  # r = 0.1: rim speeds 1.25 (driving) and 0.8 (braking)
    slip = loads.slip_ratio(side_speed, omega, 0.1)
    np.testing.assert_allclose(slip, [0.2, -0.2])
    np.testing.assert_allclose(loads.omega_for_slip(side_speed, slip, 0.1), omega)
