"""Missions are driven as the robot's drive controller carries them out (issue 36: "the one model
that ... missions use"): a segment the controller cannot carry out is driven on the same path,
slower (DriveController.path_scale, missions.energy.driven_route)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidsteer_power.commands import Segment
from skidsteer_power.drive import DriveController, controller_for_vehicle
from skidsteer_power.missions.energy import driven_route, run_mission
from skidsteer_power.missions.routes import Route, patrol
from skidsteer_power.models.predict import max_axle_speed
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

# a controller with round numbers (ASSUMED, for the hand calculations below): B = 0.5 m, r = 0.1 m
CONTROLLER = DriveController(
    wheel_separation_m=0.5,
    wheel_radius_m=0.1,
    max_speed_m_s=1.0,
    max_yaw_rate_rad_s=2.0,
    max_wheel_rad_s=8.0,
)


def test_path_scale_by_hand() -> None:
    v = np.array([0.5, 2.0, 0.5, 0.8, 0.0])
    w = np.array([0.0, 0.0, 1.0, 1.6, 3.0])
    # wheel speeds (V -+ w B / 2) / r:
    # (0.5, 0):   5, 5 rad/s; nothing binds                                  -> 1
    # (2.0, 0):   V limit 1.0 / 2.0 = 0.5, but wheels 20: ceiling 8 / 20       -> 0.4
    # (0.5, 1.0): wheels 2.5, 7.5 <= 8; w 1.0 <= 2                            -> 1
    # (0.8, 1.6): wheels 4, 12: ceiling 8 / 12                                -> 2/3
    # (0, 3.0):   w limit 2 / 3 (wheels -+7.5, at 2/3 5 <= 8)                 -> 2/3
    expected = [1.0, 0.4, 1.0, 8.0 / 12.0, 2.0 / 3.0]
    assert CONTROLLER.path_scale(v, w) == pytest.approx(expected, rel=1e-12)
    # a further ceiling (the motors' no-load speed) binds the same way: 6 rad/s on (0.5, 1.0) -> 6 / 7.5
    assert CONTROLLER.path_scale(0.5, 1.0, ceiling_rad_s=6.0) == pytest.approx([0.8], rel=1e-12)
    with pytest.raises(Exception, match='finite'):
        CONTROLLER.path_scale(math.nan, 0.0)


def test_driven_route_keeps_the_path_and_takes_longer() -> None:
    route = Route(
        'two',
        (Segment.along(2.0, math.inf, length_m=4.0), Segment.along(0.8, 0.5, length_m=1.0, payload_kg=3.0)),
        'test',
    )
    powertrain = Powertrain.default_test_robot()  # its no-load axle speed (36.9 rad/s) does not bind here
    driven, slowed = driven_route(route, CONTROLLER, powertrain)
    assert slowed.tolist() == [True, True]
    first, second = driven.segments
    assert (first.speed_m_s, first.duration_s) == pytest.approx((0.8, 5.0))  # 4 m at 0.8 m/s
    assert second.speed_m_s == pytest.approx(0.8 * 2 / 3)
    assert second.turn_radius_m == pytest.approx(0.5)  # the same curvature
    assert second.length_m == pytest.approx(1.0) and second.payload_kg == 3.0
    assert driven.length_m == pytest.approx(route.length_m)
    unchanged, none = driven_route(patrol(), CONTROLLER, powertrain)  # 0.2 m/s, R = 1 m: nothing binds
    assert unchanged is not None and not none.any()


def test_a_mission_above_the_robots_speed_is_driven_at_its_limit() -> None:
    """Leo Rover (its vehicle file): max_speed_m_s 0.4, r 0.0625 m, B = 1.76 x 0.358 m, and the wheel
    speed ceiling the lower of the controller's and the motors' no-load axle speed. A 0.5 m/s route
    is driven at 0.4 m/s straight and, on R = 1 m, at the speed that puts the outer wheel at the
    ceiling: V = ceiling x r / (1 + B / (2 R)). The result equals that path asked at those speeds (an
    independent route) and says it was slowed."""
    vehicle = load_vehicle('leo_rover')
    terrain = load_terrain('sandy_loam')
    powertrain = Powertrain.for_vehicle(vehicle)
    ceiling = min(controller_for_vehicle(vehicle, powertrain).max_wheel_rad_s, max_axle_speed(powertrain))
    v_turn = ceiling * 0.0625 / (1.0 + 1.76 * 0.358 / 2.0)
    assert 0.3 < v_turn < 0.4  # the ceiling binds on the turn, the speed limit on the straight

    def route(v_straight: float, v_turn: float) -> Route:
        legs = (Segment.along(v_straight, math.inf, length_m=2.0), Segment.along(v_turn, 1.0, length_m=1.0))
        return Route('r', legs, 'test')

    driven = run_mission(vehicle, terrain, route(0.5, 0.5), source='direct', model='fess')
    asked = run_mission(vehicle, terrain, route(0.4, v_turn * (1 - 1e-12)), source='direct', model='fess')
    assert driven.summary()['slowed_segments'] == 2 and asked.summary()['slowed_segments'] == 0
    assert driven.route.duration_s == pytest.approx(2.0 / 0.4 + 1.0 / v_turn, rel=1e-9)
    assert driven.energy_battery_J == pytest.approx(asked.energy_battery_J, rel=1e-6)
