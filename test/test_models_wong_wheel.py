"""Wheeled skid steering (chapter 4, eqs. 4.1-4.14)."""

from __future__ import annotations

import numpy as np
import pytest

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import loads, wong, wong_wheel
from skidsteer_power.terramechanics import wheel as single_wheel
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

CH4 = load_vehicle('chapter4_4wheel')  # section 4.2: Table 3.3 with r 0.1, b 0.074, wb 0.45
SIX = load_vehicle('test_robot_6wheel')
SAND, LOAM, CLAY = (load_terrain(n) for n in ('dry_sand', 'sandy_loam', 'clay'))
RADII = np.logspace(0.0, np.log10(500.0), 16)
SPEEDS = np.linspace(0.1, 1.5, 5)[:, None]  # Figure 4.2's 5 x 16 map


def test_displacement_without_yaw_is_wong_reece_eq_2_25() -> None:
    rules = wong_wheel._rules(wong_wheel.DEFAULT_RESOLUTION)
    theta = np.linspace(-0.2, 0.6, 7)[None, :]
    tf, omega, v = np.array([0.6]), np.array([6.0]), np.array([0.5])
    jx, jy = wong_wheel._displacement(rules, theta, tf, omega, v, np.zeros(1), np.zeros(1), 0.225, 0.1)
    slip = 1 - 0.5 / 0.6  # eq. 2.13, driving
    expected = single_wheel.shear_displacement(theta, tf[:, None], slip, 0.1)  # eq. 2.25
    np.testing.assert_allclose(-jx, expected, rtol=1e-10, atol=1e-15)  # j_x < 0: the rim slips back
    assert np.all(jy == 0.0)


def test_straight_running_is_the_single_wheel_of_chapter_2() -> None:
    # eq. 4.12's single wheel: load W/4, zero drawbar pull (2.28), solved by terramechanics.wheel
    single = single_wheel.solve_wheel(SAND, CH4.weight_N / 4, 0.0, 0.1, 0.074)
    state = wong.solve(CH4, SAND, 0.5, np.inf)
    assert state.sinkage_m == pytest.approx(single.sinkage_m, rel=1e-4)
    assert state.slip_outer == pytest.approx(single.slip, rel=1e-3)
    assert state.torque_outer_Nm == pytest.approx(2 * single.drive_torque_Nm, rel=1e-3)  # two wheels a side


def test_every_solution_satisfies_eq_4_10() -> None:
    state = wong.solve(CH4, SAND, SPEEDS, RADII)
    assert state.converged.all()
    assert np.all(state.extra['residual_max'] < 1e-3)
    m, h, half_b = 30.0, 0.15, 0.2
    f_c = m * SPEEDS**2 / RADII
    beta = np.arctan2(state.s0_m, RADII)
    ex = state.extra
    np.testing.assert_allclose(ex['vertical_outer_N'] + ex['vertical_inner_N'], CH4.weight_N, atol=1e-3)
    np.testing.assert_allclose((ex['vertical_outer_N'] - ex['vertical_inner_N']) * half_b, f_c * h, atol=1e-3)
    np.testing.assert_allclose(
        ex['longitudinal_outer_N'] + ex['longitudinal_inner_N'], f_c * np.sin(beta), atol=1e-3
    )
    np.testing.assert_allclose(ex['lateral_outer_N'] + ex['lateral_inner_N'], f_c * np.cos(beta), atol=1e-3)
    # and the residual function itself at the reported unknowns
    points = loads.operating_points(SPEEDS, RADII)
    setup = wong_wheel._Setup(
        CH4, SAND, points, wong_wheel._rules(wong_wheel.DEFAULT_RESOLUTION), 30.0 * points.centripetal_accel
    )
    x = np.stack(
        [
            state.omega_outer_rad_s.ravel(),
            state.omega_inner_rad_s.ravel(),
            ex['sinkage_outer_m'].ravel(),
            ex['sinkage_inner_m'].ravel(),
            state.s0_m.ravel(),
        ],
        axis=1,
    )
    assert np.max(np.abs(wong_wheel.equilibrium(setup, x, np.arange(x.shape[0])))) < 1e-3


def test_figure_4_5_findings() -> None:
    # "torque and power consumption increase significantly when the turning radius becomes small";
    # "dry sand requires the highest torque and power, while clay soil requires the least"
    v, radius = 0.5, np.array([1.0, 5.0, 50.0])
    by_soil = [wong.solve(CH4, soil, v, radius) for soil in (SAND, LOAM, CLAY)]
    for state in by_soil:
        assert np.all(np.diff(state.torque_outer_Nm) < 0) and np.all(np.diff(state.total_power_W) < 0)
        assert state.torque_outer_Nm[0] > 1.5 * state.torque_outer_Nm[-1]
    sand, loam, clay = by_soil
    assert np.all(sand.torque_outer_Nm > loam.torque_outer_Nm) and np.all(
        loam.torque_outer_Nm > clay.torque_outer_Nm
    )
    assert np.all(sand.total_power_W > loam.total_power_W) and np.all(loam.total_power_W > clay.total_power_W)


def test_mirror_symmetry_and_large_radius() -> None:
    state = wong.solve(SIX, SAND, 0.2, [3.0, -3.0])
    np.testing.assert_allclose(state.side('torque', 'right')[0], state.side('torque', 'left')[1])
    np.testing.assert_allclose(state.side('omega', 'left')[0], state.side('omega', 'right')[1])
    far = wong.solve(SIX, SAND, 0.2, [1e2, 1e3, 1e4, np.inf])
    gap = np.abs(far.torque_outer_Nm[:-1] - far.torque_outer_Nm[-1])
    assert np.all(np.diff(gap) < 0)
    assert gap[-1] < 1e-3 * far.torque_outer_Nm[-1]


def test_six_wheels_share_the_load() -> None:
    six = wong.solve(SIX, SAND, 0.2, 2.0)
    four = wong.solve(load_vehicle('test_robot_4wheel'), SAND, 0.2, 2.0)
    assert six.converged and four.converged
    assert six.sinkage_m < four.sinkage_m  # the same weight on more wheels sinks less


def test_resolution_is_converged() -> None:
    coarse = wong.solve(CH4, SAND, [0.3, 1.5], [1.0, 20.0])
    fine = wong.solve(CH4, SAND, [0.3, 1.5], [1.0, 20.0], resolution=(32, 12))
    np.testing.assert_allclose(coarse.torque_outer_Nm, fine.torque_outer_Nm, rtol=5e-3)


def test_failures_are_named_or_flagged() -> None:
    with pytest.raises(ConvergenceError, match=r'V = 0\.5 m/s, R = 2 m'):
        wong.solve(CH4, SAND, 0.5, 2.0, max_iter=1, tol=1e-12)
    batch = wong.solve(CH4, SAND, [0.5, 3.0], [2.0, 0.25])  # the second tips over (see track test)
    assert batch.converged.tolist() == [True, False]
    with pytest.raises(InputError, match='wheeled vehicle'):
        wong_wheel.solve(load_vehicle('chapter3_track'), SAND, 0.5, 2.0)
