"""FESS for wheels (section 6.3): quadratic normal stress on a flattened contact, and agreement with
this project's chapter 4 wheel model for turning radii R >= 2 m."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from skidsteer_power.models import fess, wong_wheel
from skidsteer_power.models.fess_contact import _free_wheel_table, wheel_contact
from skidsteer_power.terramechanics.terrain import PRESETS
from skidsteer_power.terramechanics.wheel import quadratic_normal_stress, solve_wheel
from skidsteer_power.vehicle import load_vehicle

WHEELED = load_vehicle('chapter4_4wheel')  # section 4.2: Table 3.3 with 4 wheels r 0.1, b 0.074, wb 0.45
SIX = load_vehicle('test_robot_6wheel')


def test_contact_uses_the_free_wheel_geometry_and_quadratic_stress() -> None:
    """Each wheel's contact comes from the single-wheel model at zero drawbar pull (eq. 2.28) and its
    normal stress from the quadratic approximation (eqs. 6.8-6.10)."""
    terrain = PRESETS['dry_sand']
    per_wheel = WHEELED.weight_N / 4
    loads = np.array([[2 * per_wheel, 2 * per_wheel]])
    contact = wheel_contact(WHEELED, terrain, loads, n=40)
    wheel = solve_wheel(terrain, per_wheel, 0.0, 0.1, 0.074)
    # the geometry is interpolated in log(load) from a 25-load table: 0.5 % allowed
    assert contact.sinkage[0, 0] == pytest.approx(float(wheel.sinkage_m), rel=5e-3)
    assert contact.entry[0, 0, 0, 0] == pytest.approx(0.1 * np.sin(float(wheel.theta_f)), rel=5e-3)
    theta = np.arcsin(contact.fwd[0, 0, 0] / 0.1)
    sigma = (contact.tau_max[0, 0, 0] - terrain.c) / np.tan(terrain.phi)
    z = contact.sinkage[0, 0]
    log_loads, _, slips = _free_wheel_table(terrain, 0.1, 0.074, per_wheel)
    slip = np.interp(np.log(per_wheel), log_loads, slips)
    expected = quadratic_normal_stress(terrain, theta, z, slip, 0.1, 0.074)
    assert sigma == pytest.approx(expected, rel=1e-6, abs=1e-6)


def test_straight_running_wheels_balance_their_resistance() -> None:
    sol = fess.FessSolver(WHEELED, PRESETS['clay'], n=30).solve_twist(0.5, 0.0)
    prob = fess.FessSolver(WHEELED, PRESETS['clay'], n=30).problem(np.array([0.5]), np.array([0.0]))
    assert sol.converged[0]
    assert sol.thrust[0] == pytest.approx(prob.contact.resistance[0], rel=1e-3)  # eq. 3.18, R = inf
    assert sol.torque[0, 0] == pytest.approx(sol.torque[0, 1], rel=1e-6)


def test_six_wheels_solve_and_mirror() -> None:
    sol = fess.FessSolver(SIX, PRESETS['sandy_loam'], n=20).solve_twist([0.4, 0.4], [0.2, -0.2])
    assert sol.converged.all()
    assert sol.torque[1] == pytest.approx(sol.torque[0][::-1], rel=1e-6)


@pytest.mark.parametrize('terrain_name', ['dry_sand', 'sandy_loam', 'clay'])
def test_within_10_percent_of_the_chapter_4_model_for_r_at_least_2m(terrain_name: str) -> None:
    """Section 6.4 / Figures 6.9-6.11: close at big radii. 5 speeds x the 13 radii >= 2 m of the
    8 x 16 grid (R = 1 ... 500 m, geometric) keep the test fast; benchmarks/bench_fess.py reports the
    full grid and the small-radius differences. Tolerance: 10 % of the larger side torque."""
    terrain = PRESETS[terrain_name]
    v = np.linspace(0.2, 1.5, 5)[:, None]
    radii = np.geomspace(1.0, 500.0, 16)
    r = radii[radii >= 2.0][None, :]
    ref = wong_wheel.solve(WHEELED, terrain, v, r, raise_on_failure=False)
    got = fess.solve(WHEELED, terrain, v, r)
    ok = ref.converged & got.converged
    assert ok.mean() > 0.9
    scale = np.maximum(np.abs(ref.torque_outer_Nm), np.abs(ref.torque_inner_Nm))[ok]
    assert np.max(np.abs(got.torque_outer_Nm - ref.torque_outer_Nm)[ok] / scale) < 0.10
    assert np.max(np.abs(got.torque_inner_Nm - ref.torque_inner_Nm)[ok] / scale) < 0.10


@pytest.mark.parametrize('name', ['test_robot_4wheel', 'test_robot_6wheel'])
def test_straight_running_capacity_is_mohr_coulomb_over_all_wheels_of_a_side(name: str) -> None:
    """The available thrust behind the traction margin is F_max = c A + W tan(phi) (eqs. 2.2 / 2.12)
    summed over EVERY wheel of a side (it once summed a single wheel, so a 6-wheel robot of the same
    weight reported a third of its capacity). Hand check, sand_bin (Table 7.2: c = 200 Pa, phi = 27
    deg), 30 kg, straight running (no load transfer, eq. 6.12): each wheel carries W = m g / n_wheels
    (73.6 N of 4, 49.1 N of 6); its flattened contact spans x = r sin(theta_r) ... r sin(theta_f)
    (eq. 6.11), area A = b r (sin theta_f - sin theta_r); per side k (c A + W tan phi) = 77.5 N
    (4 wheels) and 78.4 N (6 wheels). The model integrates c + sigma tan(phi) over the horizontal
    contact, where sum sigma dA carries W less the tau sin(theta) share of eq. 2.27: within 3 %."""
    vehicle = load_vehicle(name)
    terrain = PRESETS['sand_bin']
    solver = fess.FessSolver(vehicle, terrain, n=40)
    contact = solver.problem(np.array([0.1]), np.array([0.0])).contact
    x_front, x_rear = contact.fwd[0, 0, 0, 0], contact.fwd[0, 0, 0, -1]
    wheels = vehicle.wheels()
    area = wheels.wheel_width_m * (x_front - x_rear)
    per_wheel = terrain.c * area + vehicle.weight_N / wheels.n_wheels * np.tan(terrain.phi)
    hand = vehicle.wheels_per_side * per_wheel
    assert hand == pytest.approx(77.5 if wheels.n_wheels == 4 else 78.4, abs=0.1)  # numbers above
    sol = solver.solve_twist(0.1, 0.0)
    assert sol.converged[0]
    capacity = np.abs(sol.thrust[0, 0]) / (1.0 - sol.traction_margin[0])  # margin = 1 - |F| / F_max
    assert capacity == pytest.approx(hand, rel=0.03)


def test_four_and_six_wheels_of_equal_weight_have_equal_capacity_and_drive_table_7_3_turns() -> None:
    """Same mass and wheels: F_max = c A + W tan(phi) hardly depends on how the weight is split over
    the axles, so the two capacities agree within 5 %. Table 7.3: both wheeled robots ran on the sand
    bin at 0.1 m/s up to 0.2 rad/s and at 0.2 m/s up to 0.35 rad/s (only smaller radii stuck), so
    the model must not call those turns stuck (margin > 0)."""
    terrain = PRESETS['sand_bin']
    speed = np.array([0.1, 0.1, 0.2])
    yaw = np.array([0.0, 0.2, 0.35])
    caps = []
    for name in ('test_robot_4wheel', 'test_robot_6wheel'):
        sol = fess.FessSolver(load_vehicle(name), terrain, n=20).solve_twist(speed, yaw)
        assert sol.converged.all()
        assert np.all(sol.traction_margin > 0), name
        caps.append(np.abs(sol.thrust[0, 0]) / (1.0 - sol.traction_margin[0]))
    assert caps[1] == pytest.approx(caps[0], rel=0.05)


def test_a_batch_on_soil_too_weak_to_roll_free_is_unsolved_and_a_scalar_raises() -> None:
    """On sandy_soil with phi = 20 deg and c = 200 Pa no slip in [-1, 1] gives a 0.08 m x 0.05 m wheel
    zero drawbar pull (eq. 2.29 has no root), so FESS's free-wheel table cannot be built: a batch
    marks every point unsolved (NaN, converged False), a single point raises."""
    import dataclasses
    import math

    from skidsteer_power.errors import ConvergenceError
    from skidsteer_power.terramechanics.terrain import load_terrain

    weak = dataclasses.replace(load_terrain('sandy_soil'), phi=math.radians(20.0), c=200.0)
    four = load_vehicle('test_robot_4wheel')
    small = dataclasses.replace(
        four, gear=dataclasses.replace(four.wheels(), wheel_radius_m=0.08, wheel_width_m=0.05)
    )
    state = fess.solve(small, weak, [0.2, 0.2], [math.inf, 2.0])
    assert not state.converged.any() and np.isnan(state.torque_outer_Nm).all()
    assert state.speed_m_s.tolist() == [0.2, 0.2] and state.turn_radius_m.tolist() == [math.inf, 2.0]
    with pytest.raises(ConvergenceError):
        fess.solve(small, weak, 0.2, math.inf)


def test_free_wheel_table_on_a_soil_with_sinkage_exponent_3_or_more() -> None:
    """Eq. 2.32's first guess needs n < 3; on a stiffer-exponent soil (a user's terrain: validation
    allows any n > 0) the table comes from the bracketed solve, as solve_wheel does, and agrees
    with solve_wheel at every load; a FESS wheel solve there runs instead of raising."""
    terrain = dataclasses.replace(PRESETS['dry_sand'], n=3.2, kphi=1e10)
    log_w, sink, slip = fess._free_wheel_table(terrain, 0.1, 0.08, 200.0)
    for k in (0, 12, 24):
        state = solve_wheel(terrain, float(np.exp(log_w[k])), 0.0, 0.1, 0.08)
        assert sink[k] == pytest.approx(float(state.sinkage_m), rel=1e-4)
        assert slip[k] == pytest.approx(float(state.slip), abs=1e-5)
    fess.FessSolver(WHEELED, terrain, n=30).solve_twist(0.3, 0.2)  # no InputError
