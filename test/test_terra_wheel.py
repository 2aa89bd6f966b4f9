"""Single wheel, Wong-Reece (section 2.4, eqs. 2.19-2.34), and the quadratic normal stress (6.8-6.10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.terramechanics import PRESETS
from skidsteer_power.terramechanics.soil import shear_stress
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.terramechanics.wheel import (
    BALANCE_TOL_N,
    bekker_wheel_sinkage,
    normal_stress,
    quadratic_normal_stress,
    shear_displacement,
    sinkage_at_slip,
    solve_wheel,
    solve_wheel_bracketed,
    wheel_angles,
    wheel_at_slip,
    wheel_forces,
)

R, B = 0.1, 0.07  # wheel of Figures 2.12 and 2.13
SOILS = ('dry_sand', 'sandy_loam', 'clay')
DRY_SAND = PRESETS['dry_sand']


def _quad_forces(terrain: Terrain, z: float, s: float) -> tuple[float, float, float]:
    """Eqs. 2.27 and 2.34 by adaptive scipy.integrate.quad, point by point (independent reference)."""
    tf, tm, tr = (float(a) for a in wheel_angles(terrain, z, s, R))

    def sigma(th: float) -> float:
        return float(normal_stress(terrain, th, tf, tm, tr, R, B))

    def tau(th: float) -> float:
        return float(shear_stress(terrain, sigma(th), shear_displacement(th, tf, s, R)))

    opts = {'points': [tm, 0.0], 'epsabs': 1e-12, 'epsrel': 1e-10, 'limit': 200}
    fx = R * B * quad(lambda th: -sigma(th) * math.sin(th) + tau(th) * math.cos(th), tr, tf, **opts)[0]
    fz = R * B * quad(lambda th: sigma(th) * math.cos(th) + tau(th) * math.sin(th), tr, tf, **opts)[0]
    my = -(R**2) * B * quad(tau, tr, tf, **opts)[0]
    return fx, fz, my


@pytest.mark.parametrize('name', SOILS)
@pytest.mark.parametrize(('z', 's'), [(0.02, 0.3), (0.01, -0.5), (0.03, 0.9), (0.015, -1.0), (0.015, -0.02)])
def test_gauss_legendre_matches_adaptive_quad(name: str, z: float, s: float) -> None:
    terrain = PRESETS[name]
    state = wheel_forces(terrain, z, s, R, B)
    fx, fz, my = _quad_forces(terrain, z, s)
    scale = abs(fz)
    assert float(state.Fx_N) == pytest.approx(fx, abs=1e-6 * scale)
    assert float(state.Fz_N) == pytest.approx(fz, abs=1e-6 * scale)
    assert float(state.My_Nm) == pytest.approx(my, abs=1e-6 * scale * R)


def test_angles_eqs_2_19_to_2_22() -> None:
    # z = 0.02 m, r = 0.1 m: theta_f = acos(0.8) = 0.643501 rad; s = 0.5 with Table 2.4:
    # theta_m = (0.24 + 0.32 * 0.5) * 0.643501 = 0.257400; theta_r = -0.45 * 0.643501 = -0.289576
    tf, tm, tr = wheel_angles(DRY_SAND, 0.02, 0.5, R)
    assert (float(tf), float(tm), float(tr)) == pytest.approx((0.643501, 0.257400, -0.289576), rel=1e-5)


def test_normal_stress_peak_and_edges() -> None:
    # eq. 2.21: zero at entry and exit, maximum r^n k (cos theta_m - cos theta_f)^n at theta_m
    tf, tm, tr = wheel_angles(DRY_SAND, 0.02, 0.2, R)
    theta = np.linspace(float(tr), float(tf), 4001)
    sigma = normal_stress(DRY_SAND, theta, tf, tm, tr, R, B)
    peak = R**1.1 * (900 / B + 1523400) * (math.cos(tm) - math.cos(tf)) ** 1.1
    assert sigma.max() == pytest.approx(peak, rel=1e-5)
    assert theta[np.argmax(sigma)] == pytest.approx(float(tm), abs=1e-3)
    assert sigma[0] == 0.0
    assert sigma[-1] == 0.0


def test_bekker_first_guess_eq_2_32() -> None:
    # eq. 2.32, dry sand, W = 100 N, r = 0.1 m, b = 0.07 m:
    #   3W / (b (3 - n) k sqrt(2r)) = 300 / (0.07 * 1.9 * 1536257.14 * 0.4472136) = 3.28315e-3
    #   z0 = (3.28315e-3)^(2/3.2) = exp(0.625 * -5.71894) = 0.028034 m
    assert float(bekker_wheel_sinkage(DRY_SAND, 100.0, R, B)) == pytest.approx(0.028034, rel=1e-4)


@pytest.mark.parametrize('name', SOILS)
def test_vertical_balance_at_slip(name: str) -> None:
    terrain = PRESETS[name]
    slips = np.linspace(-1, 1, 41)
    state = wheel_at_slip(terrain, 100.0, slips, R, B)
    assert np.all(np.abs(state.Fz_N - 100.0) < BALANCE_TOL_N)
    assert np.all((state.sinkage_m > 0) & (state.sinkage_m < R))


@pytest.mark.parametrize('name', SOILS)
def test_sinkage_grows_with_load(name: str) -> None:
    # Text under Figure 2.12: "sinkage always increases with the vertical load"
    loads = np.linspace(20.0, 300.0, 15)
    for s in (-0.5, 0.0, 0.3):
        z = sinkage_at_slip(PRESETS[name], loads, s, R, B)
        assert np.all(np.diff(z) > 0)


def test_dry_sand_sinks_most() -> None:
    # Text under Figure 2.12: on dry sand "the sinkage is much larger than on sandy loam ... or clay"
    z = {name: float(sinkage_at_slip(PRESETS[name], 100.0, 0.2, R, B)) for name in SOILS}
    assert z['dry_sand'] > 2 * z['sandy_loam']
    assert z['dry_sand'] > 2 * z['clay']


@pytest.mark.parametrize('name', SOILS)
def test_drawbar_pull_asymmetric_and_torque_follows_slip(name: str) -> None:
    # Figure 2.13 setting (W = 100 N) and its text: unlike the near-symmetric track (Figure 2.10), the
    # wheel's bulldozing (entry angle > exit angle) always opposes motion, so braking pull is larger in
    # magnitude than driving pull at the same |s|; the shaft torque rises with slip.
    terrain = PRESETS[name]
    slips = np.linspace(-1, 1, 81)
    state = wheel_at_slip(terrain, 100.0, slips, R, B)
    pull, torque = state.drawbar_pull_N, state.drive_torque_Nm
    for s in (0.25, 0.5, 1.0):
        i_pos, i_neg = np.argmin(np.abs(slips - s)), np.argmin(np.abs(slips + s))
        assert -pull[i_neg] > pull[i_pos]
    assert np.all(state.theta_f > -state.theta_r)
    assert pull[40] < 0  # free rolling (s = 0) still bulldozes and compacts
    assert np.all(np.diff(torque) > 0)
    assert torque[-1] > 0 > torque[0]


@pytest.mark.parametrize('name', SOILS)
@pytest.mark.parametrize(('load', 'pull'), [(50.0, 0.0), (100.0, 5.0), (100.0, -20.0), (200.0, 10.0)])
def test_solve_wheel_meets_both_balances(name: str, load: float, pull: float) -> None:
    state = solve_wheel(PRESETS[name], load, pull, R, B)
    assert abs(float(state.Fx_N) - pull) < BALANCE_TOL_N  # eq. 2.29, stopping rule 0.001 N
    assert abs(float(state.Fz_N) - load) < BALANCE_TOL_N
    assert -1 <= float(state.slip) <= 1


@pytest.mark.parametrize('method', ['hybr', 'bracket'])
@pytest.mark.parametrize(('load', 'slip'), [(200.0, -0.5), (100.0, -0.8), (50.0, 0.4)])
def test_both_methods_recover_slip_of_braking_and_driving_points(
    method: str, load: float, slip: float
) -> None:
    # (200 N, s = -0.5) on dry sand is a point where hybr from s = 0.2 fails on its own and the
    # bracketed fallback takes over; F_x(s) is monotonic around these points, so the root is unique.
    ref = wheel_at_slip(DRY_SAND, load, slip, R, B)
    state = solve_wheel(DRY_SAND, load, float(ref.Fx_N), R, B, method=method)
    assert float(state.slip) == pytest.approx(slip, abs=1e-5)
    assert abs(float(state.Fz_N) - load) < BALANCE_TOL_N
    assert abs(float(state.Fx_N - ref.Fx_N)) < BALANCE_TOL_N


def test_bracketed_solver_is_vectorized_and_picks_smallest_slip() -> None:
    loads = np.array([[50.0], [150.0]])
    pulls = np.array([-30.0, 0.0, 8.0])
    state = solve_wheel_bracketed(DRY_SAND, loads, pulls, R, B)
    assert state.slip.shape == (2, 3)
    assert np.all(np.abs(state.Fx_N - pulls) < BALANCE_TOL_N)
    assert np.all(np.abs(state.Fz_N - loads) < BALANCE_TOL_N)
    # no smaller |s| gives the same pull: F_x - F_d keeps its sign between 0 and the root
    for i in range(2):
        for k in range(3):
            s = float(state.slip[i, k])
            between = np.linspace(0.0, s, 50)[:-1]
            gap = wheel_at_slip(DRY_SAND, loads[i, 0], between, R, B).Fx_N - pulls[k]
            assert np.all(gap < 0) or np.all(gap > 0)


def test_figure_2_12_equilibrium_over_load() -> None:
    # Figure 2.12 setting (r = 0.1 m, b = 0.07 m, free-running wheel: F_d = 0) and its text:
    # "sinkage always increases with the vertical load, yet slip ratio can increase or decrease with
    # the vertical load".
    loads = np.linspace(20.0, 300.0, 8)
    trends = set()
    for name in SOILS:
        state = solve_wheel_bracketed(PRESETS[name], loads, 0.0, R, B)
        assert np.all(np.diff(state.sinkage_m) > 0)
        steps = np.sign(np.diff(state.slip))
        trends.update(steps.tolist())
    assert {-1.0, 1.0} <= trends


def test_solve_wheel_agrees_with_slip_sweep() -> None:
    # Two independent solvers: the vertical balance at s = 0.3 gives (z, Fx); asking the 2-unknown
    # solver for that Fx must give back s = 0.3 and the same sinkage.
    ref = wheel_at_slip(DRY_SAND, 120.0, 0.3, R, B)
    state = solve_wheel(DRY_SAND, 120.0, float(ref.Fx_N), R, B)
    assert float(state.slip) == pytest.approx(0.3, abs=1e-6)
    assert float(state.sinkage_m) == pytest.approx(float(ref.sinkage_m), rel=1e-6)


def test_impossible_pull_raises_naming_inputs() -> None:
    with pytest.raises(ConvergenceError, match=r"drawbar pull 500 N on 'dry_sand': load 100 N"):
        solve_wheel(DRY_SAND, 100.0, 500.0, R, B)
    with pytest.raises(InputError, match='method'):
        solve_wheel(DRY_SAND, 100.0, 5.0, R, B, method='newton')


def test_load_beyond_capacity_raises() -> None:
    with pytest.raises(ConvergenceError, match='load 50000 N'):
        sinkage_at_slip(DRY_SAND, [100.0, 50000.0], 0.2, R, B)


@pytest.mark.parametrize(
    ('args', 'match'),
    [
        ((-5.0, 0.2, R, B), 'load'),
        ((100.0, 1.2, R, B), 'slip'),
        ((100.0, 0.2, 0.0, B), 'radius'),
        ((100.0, 0.2, R, 0.0), 'width'),
    ],
)
def test_bad_input(args: tuple[float, ...], match: str) -> None:
    with pytest.raises(InputError, match=match):
        wheel_at_slip(DRY_SAND, *args)


def test_forces_reject_sinkage_beyond_radius() -> None:
    with pytest.raises(InputError, match='sinkage'):
        wheel_forces(DRY_SAND, 0.2, 0.0, R, B)


def test_zero_load_means_no_contact() -> None:
    state = wheel_at_slip(DRY_SAND, 0.0, 0.5, R, B)
    assert (float(state.sinkage_m), float(state.Fx_N), float(state.My_Nm)) == (0.0, 0.0, 0.0)


# Quadratic approximation (eqs. 6.8-6.10). Measured error (maximum over the contact, relative to the
# peak stress; W = 100 N, r = 0.1 m, b = 0.07 m, s in {-0.5, 0, 0.3, 0.9}): dry sand 2.4 %, sandy loam
# 9.2 %, clay 19.6 % (n = 0.5: the exact stress rises like a square root at the entry, which a parabola
# cannot follow), LETE sand 5.9 %. The normal load it carries (integral of sigma cos theta) is off by
# 0.45 %, 2.4 %, 5.1 % and 1.6 %.
QUADRATIC_BOUNDS = {'dry_sand': (0.025, 0.005), 'sandy_loam': (0.095, 0.025), 'clay': (0.20, 0.052)}


@pytest.mark.parametrize('name', sorted(QUADRATIC_BOUNDS))
def test_quadratic_normal_stress_error(name: str) -> None:
    terrain = PRESETS[name]
    max_bound, load_bound = QUADRATIC_BOUNDS[name]
    worst_max = worst_load = 0.0
    for s in (-0.5, 0.0, 0.3, 0.9):
        z = float(sinkage_at_slip(terrain, 100.0, s, R, B))
        tf, tm, tr = (float(a) for a in wheel_angles(terrain, z, s, R))
        theta = np.linspace(tr, tf, 4001)
        exact = normal_stress(terrain, theta, tf, tm, tr, R, B)
        approx = quadratic_normal_stress(terrain, theta, z, s, R, B)
        worst_max = max(worst_max, np.abs(approx - exact).max() / exact.max())
        load_exact = float(np.trapezoid(exact * np.cos(theta), theta))
        worst_load = max(worst_load, abs(float(np.trapezoid(approx * np.cos(theta), theta)) / load_exact - 1))
    print(f'{name}: quadratic stress max error {worst_max:.2%} of peak, normal load error {worst_load:.2%}')
    assert worst_max < max_bound
    assert worst_load < load_bound
    assert worst_max > 0.001  # it is an approximation, not the exact curve


def test_quadratic_interpolates_eq_6_10_nodes() -> None:
    # eq. 6.10: each parabola passes through (theta_m, sigma_m), (theta_im, sigma_im), (theta_i, 0)
    z, s = 0.02, 0.2
    tf, tm, tr = (float(a) for a in wheel_angles(DRY_SAND, z, s, R))
    nodes = np.array([tm, 0.5 * (tf + tm), 0.5 * (tr + tm), tf, tr])
    np.testing.assert_allclose(
        quadratic_normal_stress(DRY_SAND, nodes, z, s, R, B),
        normal_stress(DRY_SAND, nodes, tf, tm, tr, R, B),
        rtol=1e-9,
        atol=1e-6,
    )
