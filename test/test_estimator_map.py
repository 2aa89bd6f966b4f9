"""The estimator's prediction on a real FESS map (small grid) and the real test-robot powertrain."""

from __future__ import annotations

from pathlib import Path

import pytest

from skidsteer_power.estimator.factory import map_predictor
from skidsteer_power.estimator.prediction import MapPredictor
from skidsteer_power.maps import PowerMap
from skidsteer_power.powertrain import GEAR_RATIO, Powertrain
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import Vehicle, load_vehicle


@pytest.fixture(scope='module')
def vehicle() -> Vehicle:
    return load_vehicle('test_robot_track')


@pytest.fixture(scope='module')
def predictor(vehicle: Vehicle) -> MapPredictor:
    power_map = PowerMap.build(vehicle, load_terrain('dry_sand'), shape=(6, 11))
    return MapPredictor(power_map, Powertrain.for_vehicle(vehicle), description='test map')


def test_prediction_adds_the_powertrain_to_the_map(predictor: MapPredictor) -> None:
    """Eqs. 7.1-7.4 via Powertrain.motor_side: motor speed = 12 x axle speed (7.1.1), motor torque =
    axle torque / 12 + internal resistance at the motor shaft."""
    p = predictor.predict(0.2, 0.1)
    q = predictor.power_map.query(0.2, 0.1)
    assert p.axle_omega_rad_s == pytest.approx((q.omega_left_rad_s, q.omega_right_rad_s))
    # terrain power is torque x speed of the interpolated values, so terrain + internal is exactly the
    # motor's mechanical power; the map's own interpolated power agrees to interpolation error
    assert p.terrain_W == pytest.approx(
        tuple(t * w for t, w in zip(p.terrain_torque_Nm, p.axle_omega_rad_s, strict=True))
    )
    assert p.terrain_W == pytest.approx((q.power_left_W, q.power_right_W), rel=0.05)
    assert p.motor_omega_rad_s == pytest.approx(tuple(GEAR_RATIO * w for w in p.axle_omega_rad_s))
    assert isinstance(predictor.powertrain, Powertrain)
    internal = [
        predictor.powertrain.resistance(side).torque(p.motor_omega_rad_s[i])
        for i, side in enumerate(('left', 'right'))
    ]
    expected = tuple(p.terrain_torque_Nm[i] / GEAR_RATIO + internal[i] for i in range(2))
    assert p.motor_torque_Nm == pytest.approx(expected)
    assert all(w > 0 for w in p.internal_W)  # internal resistance always dissipates (eq. 7.2)
    assert 0 < p.terrain_share < 1
    assert p.bus_total_W > p.terrain_total_W + p.internal_total_W  # copper and amplifier losses on top
    assert not p.clamped


def test_reverse_is_the_mirrored_forward_solution(predictor: MapPredictor) -> None:
    """Backing at (-V, r) = forward at (V, r) seen turned 180 degrees: sides swap, speeds and torques
    change sign, terrain power does not (prediction module docstring)."""
    fwd, rev = predictor.predict(0.2, 0.1), predictor.predict(-0.2, 0.1)
    assert rev.axle_omega_rad_s == pytest.approx((-fwd.axle_omega_rad_s[1], -fwd.axle_omega_rad_s[0]))
    assert rev.terrain_torque_Nm == pytest.approx((-fwd.terrain_torque_Nm[1], -fwd.terrain_torque_Nm[0]))
    assert rev.terrain_W == pytest.approx((fwd.terrain_W[1], fwd.terrain_W[0]))
    assert rev.traction_margin == pytest.approx(fwd.traction_margin)
    # internal power is dissipated in either direction; the two sides differ slightly (Table 7.1)
    assert all(w > 0 for w in rev.internal_W)


def test_spin_in_place_drives_the_sides_in_opposite_directions(predictor: MapPredictor) -> None:
    p = predictor.predict(0.0, 0.5)
    assert p.axle_omega_rad_s[0] < 0 < p.axle_omega_rad_s[1]  # + yaw rate = left turn (REP 103)
    assert p.bus_total_W > 0 and p.traction_margin < 1


def test_rest_draws_nothing(predictor: MapPredictor) -> None:
    p = predictor.predict(0.0, 0.0)
    assert p.terrain_W == (0.0, 0.0) and p.internal_W == (0.0, 0.0) and p.bus_total_W == 0.0


def test_tighter_turns_leave_less_traction(predictor: MapPredictor) -> None:
    """Chapter 7.3.4: on dry sand the robot got stuck when the turning radius was small. The margin
    must fall as the yaw rate grows at V = 0.2 m/s (Table 7.3's second row)."""
    margins = [predictor.predict(0.2, r).traction_margin for r in (0.0, 0.1, 0.35)]
    assert margins[0] > margins[1] > margins[2]


def test_commands_beyond_the_map_are_flagged(predictor: MapPredictor) -> None:
    assert predictor.predict(3.0, 0.0).clamped


def test_factory_builds_and_caches_the_map(vehicle: Vehicle, tmp_path: Path) -> None:
    first, built, where = map_predictor(vehicle, 'dry_sand', tmp_path)
    second, built_again, _ = map_predictor(vehicle, 'dry_sand', tmp_path)
    assert built and not built_again and where.startswith(str(tmp_path))
    assert second.predict(0.2, 0.1).bus_total_W == pytest.approx(first.predict(0.2, 0.1).bus_total_W)


def test_the_default_predictor_works_at_the_set_points(tmp_path: Path) -> None:
    """Issue 25: a command is a pair of wheel speed set points. Reference: the direct set-point solve
    (CommandPredictor, test_fess_setpoint.py) at a node of the set-point map, where the map is exact."""
    from skidsteer_power.estimator.prediction import SetpointPredictor
    from skidsteer_power.models.predict import CommandPredictor
    from skidsteer_power.terramechanics.terrain import load_terrain

    six = load_vehicle('test_robot_6wheel')
    predictor, built, _ = map_predictor(six, 'sand_bin', tmp_path)
    assert built and isinstance(predictor, SetpointPredictor)
    grid = predictor.setpoint_map.grid
    m, d = grid.axis0.values[3], grid.axis1.values[2]  # a node: (mean, half difference) [rad/s]
    v, w = m * six.drive_radius_m, 2 * d * six.drive_radius_m / six.tread_m
    got = predictor.predict(float(v), float(w))
    direct = CommandPredictor(six, load_terrain('sand_bin')).predict(v, w)
    assert got.axle_omega_rad_s == pytest.approx(
        tuple(direct.setpoint[0])
    )  # the wheels hold their set points
    assert got.terrain_torque_Nm == pytest.approx(tuple(direct.torque[0]), rel=1e-9)
    assert got.bus_total_W == pytest.approx(direct.battery_power[0], rel=1e-9)
    assert got.achieved_speed_m_s == pytest.approx(direct.speed[0], rel=1e-9)
    assert got.achieved_speed_m_s < v  # six wheels on sand slip: slower than commanded
    twist, _, _ = map_predictor(six, 'sand_bin', tmp_path, kinematics='twist')
    assert twist.predict(float(v), float(w)).achieved_speed_m_s == v  # the old reading: motion = command
