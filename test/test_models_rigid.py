"""Rigid ground (issue 35): Coulomb friction and rolling resistance behind FESS's solver interface.

References are hand calculations written out here: straight running (thrust = rolling resistance),
the spin of a track on Coulomb ground (Steeds' moment of turning resistance, eq. 3.6 at s0 = 0:
M_r = mu_t W l / 4), and the friction ceiling (a side cannot push more than mu x its load).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skidsteer_power.cli.main import main
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.models import solve
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.models.rigid_contact import TYRE_DEFLECTION, patch_length_m
from skidsteer_power.models.setpoint import SetpointSolver
from skidsteer_power.terramechanics.terrain import (
    PRESETS,
    load_terrain,
    rigid_terrain,
    terrain_fields,
    terrain_fingerprint,
    terrain_from_mapping,
)
from skidsteer_power.vehicle import GRAVITY_M_S2, load_vehicle

TRACK = load_vehicle('test_robot_track')  # 30 kg, l = 0.45 m, B = 0.426 m, r = 0.1 m
WHEELS = load_vehicle('packbot_4wheel')
RIGID_FILES = ('asphalt', 'concrete', 'flooring', 'grass', 'ice', 'packed_snow')


@pytest.mark.parametrize('vehicle', [TRACK, WHEELS], ids=['track', 'wheels'])
def test_straight_driving_torque_is_rolling_resistance_times_load_times_radius(vehicle: object) -> None:
    """Straight at constant speed on level rigid ground: each side's thrust equals its rolling
    resistance f_r W / 2, so its axle torque is f_r (W / 2) r (the drive torque of a rolling wheel)."""
    asphalt = load_terrain('asphalt')
    veh = TRACK if vehicle is TRACK else WHEELS
    state = solve(veh, asphalt, np.array([0.2, 0.8]), np.inf)
    assert state.converged.all()
    f_r = 0.015  # config/terrains/asphalt.yaml
    by_hand = f_r * veh.mass_kg * GRAVITY_M_S2 / 2 * veh.drive_radius_m  # 30 kg: 0.2207 N m
    np.testing.assert_allclose(state.torque_outer_Nm, by_hand, rtol=1e-4)
    np.testing.assert_allclose(state.torque_inner_Nm, by_hand, rtol=1e-4)
    assert np.all(state.sinkage_m == 0.0)
    assert np.all(state.slip_outer > 0) and np.all(state.slip_outer < 0.01)  # a small driving slip


def test_spin_of_a_track_meets_steeds_moment_of_turning_resistance() -> None:
    """Spin in place (V = 0, s0 = 0 by symmetry) of a track with uniform pressure: the lateral
    friction mu_t p on every element, pointing against its sideways slip (sign of x), gives the
    moment M_r = mu_t (W / 2) l / 4 per track (eq. 3.6 at s0 = 0), mu_t W l / 4 for both. The
    sprockets supply it: (F_o - F_i) B / 2 = mu_t W l / 4. With mu_longitudinal >> mu_lateral the
    longitudinal slip that builds each track's thrust is small against the sideways slip, so the
    lateral friction is mu_t p to within a few per cent (the text's assumption); K small: saturated."""
    mu_t = 0.05
    ground = rigid_terrain('coulomb', mu_longitudinal=1.0, mu_lateral=mu_t, rolling_resistance=0.0, K=1e-4)
    sol = FessSolver(TRACK, ground, n=200).solve_twist(0.0, 0.5)
    assert sol.converged.all()
    weight = TRACK.mass_kg * GRAVITY_M_S2
    moment_by_hand = mu_t * weight * 0.45 / 4  # 1.655 N m for the 30 kg robot, l = 0.45 m
    thrust = sol.torque[0] / TRACK.drive_radius_m  # (left, right) [N]
    moment = (thrust[1] - thrust[0]) * TRACK.tread_m / 2
    assert moment == pytest.approx(moment_by_hand, rel=0.03)
    assert abs(sol.s0[0]) < 1e-6  # the turning centre at the CG
    assert thrust[1] == pytest.approx(-thrust[0], rel=1e-6)  # sum F_x = 0


def test_a_side_never_pushes_more_than_friction_times_its_load() -> None:
    """Coulomb's ceiling: |F_side| <= mu_x W_side (the mobilised fraction 1 - exp(-j/K) < 1)."""
    ice = load_terrain('ice')
    sol = FessSolver(TRACK, ice).solve_twist(np.full(5, 0.4), np.linspace(0.0, 1.2, 5))
    ok = sol.converged
    assert ok.sum() >= 3
    weight = TRACK.mass_kg * GRAVITY_M_S2
    assert np.all(np.abs(sol.thrust[ok]) <= 0.10 * weight)  # each side carries about W / 2 at most


def test_pressure_patch_of_a_wheel_by_hand() -> None:
    """Tyre patch length 2 sqrt(r^2 - (r - d r)^2): r = 0.1 m, d = 5 %: 2 x 0.1 x sqrt(0.0975)."""
    assert TYRE_DEFLECTION == 0.05
    assert patch_length_m(0.1) == pytest.approx(0.2 * math.sqrt(1 - 0.95**2), rel=1e-12)
    assert patch_length_m(0.1) == pytest.approx(0.062450, abs=1e-6)


@settings(max_examples=12, deadline=None)
@given(st.floats(0.05, 0.8), st.floats(0.05, 1.0))
def test_mirror_symmetry_in_yaw_rate(speed: float, yaw: float) -> None:
    """The robot is symmetric left/right: (V, -w) is the mirror image of (V, w), the sides swapped."""
    solver = FessSolver(TRACK, load_terrain('asphalt'))
    sol = solver.solve_twist([speed, speed], [yaw, -yaw])
    if not sol.converged.all():
        assert not sol.converged.any()  # both or neither
        return
    np.testing.assert_allclose(sol.torque[0], sol.torque[1][::-1], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(sol.omega[0], sol.omega[1][::-1], rtol=1e-6, atol=1e-9)
    assert sol.s0[0] == pytest.approx(sol.s0[1], rel=1e-6, abs=1e-9)


@settings(max_examples=10, deadline=None)
@given(st.floats(0.05, 0.8), st.floats(0.0, 0.8))
def test_torque_is_continuous_in_yaw_rate(speed: float, yaw: float) -> None:
    """A 1e-4 rad/s step in yaw rate changes each side's torque by a small amount (the slip law
    mu (1 - exp(-j/K)) is smooth: no jump at the onset of turning as in saturated Coulomb friction)."""
    solver = FessSolver(TRACK, load_terrain('concrete'))
    sol = solver.solve_twist([speed, speed], [yaw, yaw + 1e-4])
    if not sol.converged.all():
        return
    scale = 0.75 * TRACK.mass_kg * GRAVITY_M_S2 / 2 * TRACK.drive_radius_m  # the friction torque ceiling
    assert np.all(np.abs(sol.torque[1] - sol.torque[0]) < 1e-2 * scale)


def test_setpoint_solve_on_rigid_ground_turns_the_way_the_wheels_ask() -> None:
    """The set-point path (predict, maps) on rigid ground: a turn with the right side faster turns
    left, a bit less than without slip; a reversed pair is the fore-aft mirror image."""
    solver = SetpointSolver(FessSolver(WHEELS, load_terrain('asphalt')))
    sol = solver.solve(np.array([[3.0, 6.0], [-6.0, -3.0]]))
    assert not sol.limited.any()
    no_slip_yaw = (6.0 - 3.0) * WHEELS.drive_radius_m / WHEELS.tread_m
    assert 0 < sol.yaw_rate[0] < no_slip_yaw
    assert sol.speed[1] == pytest.approx(-sol.speed[0], rel=1e-6)
    assert sol.yaw_rate[1] == pytest.approx(sol.yaw_rate[0], rel=1e-6)


def test_models_for_soil_reject_rigid_ground() -> None:
    with pytest.raises(InputError, match='rigid ground'):
        solve(TRACK, load_terrain('asphalt'), 0.5, 2.0, model='wong')


@pytest.mark.parametrize('name', RIGID_FILES)
def test_rigid_files_load_with_their_contact(name: str) -> None:
    terrain = load_terrain(name)
    assert terrain.is_rigid
    fields = terrain_fields(terrain)
    assert fields['contact'] == 'rigid' and set(fields) == {
        'contact',
        'mu_longitudinal',
        'mu_lateral',
        'rolling_resistance',
        'K',
    }
    again = terrain_from_mapping({'name': name, **fields})  # round trip of the file fields
    numbers = {k: v for k, v in fields.items() if k != 'contact'}
    assert {k: terrain_fields(again)[k] for k in numbers} == pytest.approx(numbers, rel=1e-12)
    assert again.contact == 'rigid' and dataclasses.replace(again, name=name) == terrain


def test_snow_is_a_deformable_soil() -> None:
    snow = load_terrain('snow')
    assert not snow.is_rigid
    assert (snow.n, snow.kc, snow.kphi, snow.c) == (1.6, 4370.0, 196720.0, 1030.0)  # Wong, Snow (U.S.)


@pytest.mark.parametrize(
    ('extra', 'message'),
    [
        ({'kphi': 1e6}, "'kphi' is not a field of rigid ground"),
        ({'mu_lateral': 3.0}, "'mu_lateral' = 3 is outside its range"),
        ({'rolling_resistance': -0.1}, 'rolling_resistance'),
        ({'K': 0.0}, "'K' = 0 is outside"),
        ({'contact': 'gravel'}, "'contact' must be 'soil' or 'rigid'"),
    ],
)
def test_bad_rigid_files_name_the_field(extra: dict[str, object], message: str) -> None:
    data = {'name': 'x', 'contact': 'rigid', 'mu_longitudinal': 0.7, 'mu_lateral': 0.7}
    data.update(rolling_resistance=0.01, K=0.003)
    data.update(extra)
    with pytest.raises(ConfigError, match=message):
        terrain_from_mapping(data)


def test_missing_rigid_field_is_an_error() -> None:
    with pytest.raises(ConfigError, match="'mu_lateral' is missing"):
        terrain_from_mapping(
            {'contact': 'rigid', 'mu_longitudinal': 0.7, 'rolling_resistance': 0.01, 'K': 1e-3}
        )


def test_soil_fingerprints_are_unchanged_by_rigid_ground() -> None:
    """Cached maps key on the terrain's digest: a soil's must not change (values from the main
    checkout before rigid ground existed, ``terrain_fingerprint(PRESETS[name])``)."""
    assert terrain_fingerprint(PRESETS['sand_bin']) == 'ff860aca2bc43c18'
    assert terrain_fingerprint(PRESETS['clay']) == 'f47b978b654ff283'
    assert terrain_fingerprint(load_terrain('asphalt')) != terrain_fingerprint(load_terrain('concrete'))


def test_terrains_command_lists_rigid_files(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['terrains', '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out['presets']) == set(PRESETS)
    for name in RIGID_FILES:
        assert out['files'][name]['values']['contact'] == 'rigid'
        assert out['files'][name]['source']
    assert out['files']['snow']['values']['contact'] == 'soil'
