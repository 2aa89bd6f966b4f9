"""Steeds' model (section 3.2, eqs. 3.2-3.7)."""

from __future__ import annotations

import numpy as np
import pytest

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import steeds
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.terramechanics.track import compaction_resistance, tractive_effort
from skidsteer_power.vehicle import load_vehicle

CH3 = load_vehicle('chapter3_track')
SAND = load_terrain('dry_sand')  # Table 3.3's soil values
RADII = np.logspace(0.0, np.log10(500.0), 16)  # Figure 3.3's 1-500 m


def test_eq_3_7_hand_calculation() -> None:
    # Table 3.2: V = 0.5 m/s; take R = 2 m, mu_t = 0.5, g = 9.81:
    #   s0 = V^2 l / (2 R mu_t g) = 0.25 * 0.7 / (2 * 2 * 0.5 * 9.81) = 0.0089195 m
    #   M_ro + M_ri = mu_t W / (2 l) (l^2/2 + 2 s0^2) = 0.5 * 294.3 / 1.4 * (0.245 + 1.5912e-4) = 25.768 N m
    #   m V^2 / R * s0 = 30 * 0.125 * 0.0089195 = 0.033448 N m
    #   F_o - R_o = (25.768 - 0.0334) / 0.4 = 64.336 N
    state = steeds.solve(CH3, SAND, 0.5, 2.0, mu_t=0.5)
    assert state.s0_m == pytest.approx(0.0089195, rel=1e-4)
    loads_o = 147.15 + 30 * 0.25 * 0.15 / (2.0 * 0.4)  # eq. 3.1
    r_o = compaction_resistance(SAND, loads_o, 0.07, 0.7)  # eq. 3.2 = 2.10
    assert state.thrust_outer_N == pytest.approx(r_o + 64.336, rel=1e-4)
    assert state.torque_outer_Nm == pytest.approx(0.1 * (r_o + 64.336), rel=1e-4)  # T = F r


def test_equilibrium_eq_3_4() -> None:
    v, radius = 0.8, np.array([1.5, 7.0, 60.0])
    state = steeds.solve(CH3, SAND, v, radius, mu_t=0.6)
    m, length, big_b, g = 30.0, 0.7, 0.4, 9.81
    f_c = m * v**2 / radius
    transfer = m * v**2 * 0.15 / (radius * big_b)
    r_o = compaction_resistance(SAND, 147.15 + transfer, 0.07, length)
    r_i = compaction_resistance(SAND, 147.15 - transfer, 0.07, length)
    s0 = state.s0_m
    lateral = 2 * 0.6 * (m * g) / length * s0  # R_lo + R_li, eq. 3.5
    np.testing.assert_allclose(lateral, f_c, rtol=1e-9)  # second line of 3.4 (small beta)
    np.testing.assert_allclose(state.thrust_outer_N + state.thrust_inner_N, r_o + r_i, rtol=1e-9)
    moments = 0.6 * m * g / (2 * length) * (length**2 / 2 + 2 * s0**2)  # eq. 3.6
    yaw = (
        (state.thrust_outer_N - state.thrust_inner_N) * big_b / 2
        - (r_o - r_i) * big_b / 2
        + f_c * s0
        - moments
    )
    np.testing.assert_allclose(yaw, 0.0, atol=1e-9)


def test_figure_3_3_findings() -> None:
    # Figure 3.3 text: s0 grows as R shrinks; larger mu_t needs larger torques; the torques stay
    # almost constant over R.
    low = steeds.solve(CH3, SAND, 0.5, RADII, mu_t=0.5)
    high = steeds.solve(CH3, SAND, 0.5, RADII, mu_t=0.9)
    assert np.all(np.diff(low.s0_m) < 0)
    assert np.all(high.torque_outer_Nm > low.torque_outer_Nm)
    for state in (low, high):
        spread = np.ptp(state.torque_outer_Nm) / np.mean(state.torque_outer_Nm)
        assert spread < 0.01  # measured 0.2 %: 'nearly constant'


def test_slip_inverts_the_track_law() -> None:
    state = steeds.solve(CH3, SAND, 0.5, 5.0)
    loads_o = 147.15 + 30 * 0.25 / 5.0 * 0.15 / 0.4
    effort = tractive_effort(SAND, loads_o, 0.07, 0.7, state.slip_outer)  # eq. 2.17 at the reported slip
    assert effort == pytest.approx(state.thrust_outer_N, rel=1e-6)
    assert state.slip_outer > 0 > state.slip_inner  # outer drives, inner brakes
    np.testing.assert_allclose(state.power_outer_W, state.torque_outer_Nm * state.omega_outer_rad_s)


def test_mirror_and_straight() -> None:
    left, right = steeds.solve(CH3, SAND, 0.5, [3.0, -3.0]).as_dict()['torque_outer_Nm']
    assert left == right
    state = steeds.solve(CH3, SAND, 0.5, [3.0, -3.0])
    np.testing.assert_allclose(state.side('torque', 'right')[0], state.side('torque', 'left')[1])
    straight = steeds.solve(CH3, SAND, 0.5, np.inf)
    assert straight.s0_m == 0.0
    r_c = compaction_resistance(SAND, 147.15, 0.07, 0.7)
    assert straight.thrust_outer_N == pytest.approx(r_c) and straight.thrust_inner_N == pytest.approx(r_c)


def test_sliding_out_is_reported() -> None:
    # V^2 / R = 4 > mu_t g = 0.3 * 9.81: the lateral friction cannot hold the turn
    with pytest.raises(ConvergenceError, match=r'V = 2 m/s, R = 1 m.*slides out'):
        steeds.solve(CH3, SAND, 2.0, 1.0, mu_t=0.3)
    batch = steeds.solve(CH3, SAND, [0.5, 2.0], 1.0, mu_t=0.3)
    assert batch.converged.tolist() == [True, False]
    with pytest.raises(InputError, match='mu_t'):
        steeds.solve(CH3, SAND, 0.5, 1.0, mu_t=0.0)


def test_wheeled_extension_balances() -> None:
    vehicle = load_vehicle('packbot_6wheel')
    lete = load_terrain('lete_sand')
    state = steeds.solve(vehicle, lete, 0.3, [2.0, 20.0], mu_t=0.3)
    assert state.converged.all() and np.all(state.traction_margin > 0)
    # the lateral friction of the patches ahead of / behind s0 balances the centrifugal force
    assert np.all(state.s0_m > 0) and np.all(np.diff(state.s0_m) < 0)
    strong = steeds.solve(vehicle, lete, 0.3, 2.0, mu_t=0.6, raise_on_failure=False)
    assert not strong.converged and strong.traction_margin <= 0  # beyond the terrain: reported
    assert strong.extra['failure'] == 4

    assert np.all(state.torque_outer_Nm > state.torque_inner_Nm)
    assert np.all(state.omega_outer_rad_s > state.omega_inner_rad_s)
