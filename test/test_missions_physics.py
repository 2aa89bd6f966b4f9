"""Physics checks behind the chapter 8 track-vs-wheel comparison (see docs/PHYSICS_NOTES.md).

These pin the readings the mission energies rest on: the Table 8.1 vehicle files, the 6-wheel
wheelbase, where and how the internal resistance of eqs. 7.1-7.4 enters, and how both sides' power is
integrated over a route. They do not pin the dissertation's track-vs-6-wheel energy ordering, which
this model does not reproduce (PHYSICS_NOTES.md, 'Known disagreements with the dissertation').
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from skidsteer_power.errors import ConfigError
from skidsteer_power.missions import Route, Segment, run_mission
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain
from skidsteer_power.vehicle import TrackGear, load_vehicle

KT = 0.114  # EC-45 torque constant [N m/A], Appendix B line 12
G = 12.0  # 4.8:1 planetary x 2.5:1 roller chain, ch. 7.1.1
# Table 7.1, left and right drivetrains, columns (first, second) per component
TABLE_7_1 = {
    'left': {
        'motor': (0.0001, 0.0617),
        'gear_train': (0.00008, 0.0177),
        'roller_chain': (0.0001, 0.0448),
        'track': (0.00012, 0.6489),
    },
    'right': {
        'motor': (0.0001, 0.0499),
        'gear_train': (0.00009, 0.0248),
        'roller_chain': (0.0001, 0.0497),
        'track': (0.00013, 0.6314),
    },
}


@pytest.fixture(scope='module')
def sandy() -> Terrain:
    return load_terrain('sandy_soil')  # Table 8.2


@pytest.fixture(scope='module')
def short_route() -> Route:
    """10 m straight and a 180-degree U-turn of R = 1 m at 0.2 m/s (the ch. 8.1 patrol's two states)."""
    return Route(
        'straight+uturn',
        (Segment.along(0.2, math.inf, length_m=10.0), Segment.along(0.2, 1.0, length_m=math.pi)),
    )


def test_packbot_files_match_table_8_1() -> None:
    track, four, six = (load_vehicle(f'packbot_{k}') for k in ('track', '4wheel', '6wheel'))
    for v in (track, four, six):  # Table 8.1 chassis parameters, shared by all three (ch. 8.1)
        assert (v.mass_kg, v.cg_height_m, v.tread_m) == (15.8, 0.08, 0.4)
    assert track.gear == TrackGear(track_length_m=0.7, track_width_m=0.074, sprocket_radius_m=0.1)
    for v in (four, six):
        assert (v.wheels().wheel_width_m, v.wheels().wheel_radius_m) == (0.074, 0.1)
    assert (four.wheels().n_wheels, four.wheels().wheelbase_m) == (4, 0.7)  # 'Wheel Base (4-Wheel) 0.7'
    assert six.wheels().n_wheels == 6
    for v in (track, four, six):  # ch. 8.1: the test robot's powertrain for all three
        assert v.powertrain == {'preset': 'test_robot'}


def test_six_wheel_base_is_the_adjacent_axle_spacing() -> None:
    # Table 8.1: 'Axle Base 0.35' for a 0.7 m track and 'Wheel Base (6-Wheel) 0.35': on a 0.7 m track
    # with 0.1 m sprockets 0.35 m can only be the spacing of adjacent axles (three axles per side).
    # Read as front-to-rear, adjacent 6-wheel axles would be 0.175 m apart, less than the 0.2 m wheel
    # diameter: the wheels would overlap. So front-to-rear is 2 x 0.35 = 0.7 m.
    six = load_vehicle('packbot_6wheel')
    assert six.wheels().wheelbase_m == pytest.approx(2 * 0.35)
    assert six.axle_positions_m() == pytest.approx((0.35, 0.0, -0.35))
    with pytest.raises(ConfigError, match='overlap'):
        dataclasses.replace(six.wheels(), wheelbase_m=0.35)


def _internal_hand(side: str, omega_axle: float, running_gear: str, scale: float) -> float:
    """Eq. 7.2 summed over the drivetrain's components at the motor shaft: b w_m^2 + c |w_m| [W]."""
    names = ('motor', 'gear_train', 'roller_chain') + (('track',) if running_gear == 'track' else ())
    b = scale * sum(TABLE_7_1[side][n][0] for n in names)
    c = scale * sum(TABLE_7_1[side][n][1] for n in names)
    w_m = G * abs(omega_axle)
    return b * w_m**2 + c * w_m


@pytest.mark.parametrize('name', ['packbot_track', 'packbot_6wheel'])
def test_internal_power_is_eq_7_2_at_motor_speed(name: str, sandy: Terrain, short_route: Route) -> None:
    """Internal power of each mission state is eq. 7.2 at w_m = 12 w_axle: chain for both, track term
    only for tracks (ch. 7.2.3), Table 7.1 as torques (the project's reading, internal.py)."""
    vehicle = load_vehicle(name)
    result = run_mission(vehicle, sandy, short_route, source='direct')
    from skidsteer_power.models import solve

    state = solve(vehicle, sandy, np.array([0.2, 0.2]), np.array([math.inf, 1.0]), model='fess')
    for k in range(2):
        hand = sum(
            _internal_hand(s, float(state.side('omega', s)[k]), vehicle.running_gear, 1.0)
            for s in ('left', 'right')
        )
        assert result.power_internal_W[k] == pytest.approx(hand, rel=1e-9)
    # the straight state: both sides at V / r (small slip) -> 12 x 2 rad/s at the motor
    straight = _internal_hand('left', 2.0, vehicle.running_gear, 1.0) + _internal_hand(
        'right', 2.0, vehicle.running_gear, 1.0
    )
    assert result.power_internal_W[0] == pytest.approx(straight, rel=0.2)


def test_mission_energy_is_both_sides_signed_times_duration(sandy: Terrain, short_route: Route) -> None:
    """Energy = sum over segments of (P_left + P_right) x length / V; the inner track brakes in the
    1 m turn and its (negative) power is credited: the DES 70/10 is 4-quadrant and 'can absorb power
    from the motor when the vehicle is performing regenerative braking' (ch. 7.1.2)."""
    result = run_mission(load_vehicle('packbot_track'), sandy, short_route, source='direct')
    durations = np.array([10.0 / 0.2, math.pi / 0.2])
    np.testing.assert_allclose(result.duration_s, durations)
    total = result.power_left_W + result.power_right_W
    np.testing.assert_allclose(result.power_W, total, rtol=1e-12)
    assert result.energy_J == pytest.approx(float(np.sum(total * durations)), rel=1e-12)
    turn = 1
    # the inner track brakes: the terrain power of the turn is less than the outer side's alone, so the
    # inner side's negative terrain power is credited in the signed sum
    from skidsteer_power.models import solve

    state = solve(load_vehicle('packbot_track'), sandy, 0.2, 1.0, model='fess')
    assert float(state.power_inner_W) < 0
    assert result.power_terrain_W[turn] == pytest.approx(
        float(state.power_outer_W + state.power_inner_W), rel=1e-6
    )
    assert result.energy_internal_J + result.energy_terrain_J == pytest.approx(result.energy_J, rel=1e-12)


def test_table_7_1_reading_scales_only_the_internal_energy(sandy: Terrain, short_route: Route) -> None:
    """The alternative reading (Table 7.1 as motor currents, A s/rad and A) is the project's literal
    eq. 7.1 reading (N m s/rad, N m) times K_t: internal energy x K_t, terrain energy unchanged.
    This is the basis of the comparison of readings in docs/PHYSICS_NOTES.md (the only model input
    that decides track vs 6-wheel there)."""
    current_cfg = {
        'preset': 'test_robot',
        'internal_resistance': {
            side: {n: {'viscous_A_s': a, 'coulomb_A': b} for n, (a, b) in comps.items()}
            for side, comps in TABLE_7_1.items()
        },
    }
    for name in ('packbot_track', 'packbot_6wheel'):
        vehicle = load_vehicle(name)
        ours = run_mission(vehicle, sandy, short_route, source='direct')
        current = run_mission(
            vehicle,
            sandy,
            short_route,
            source='direct',
            powertrain=Powertrain.from_config(current_cfg, vehicle.running_gear),
        )
        assert current.energy_terrain_J == pytest.approx(ours.energy_terrain_J, rel=1e-12)
        assert current.energy_internal_J == pytest.approx(ours.energy_internal_J * KT, rel=1e-9)
