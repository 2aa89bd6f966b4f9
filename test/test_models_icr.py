"""ICR model (section 3.4, eqs. 3.23-3.26)."""

from __future__ import annotations

import numpy as np
import pytest

from skidsteer_power.models import icr
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.terramechanics.track import compaction_resistance
from skidsteer_power.vehicle import load_vehicle

CH3 = load_vehicle('chapter3_track')
SAND = load_terrain('dry_sand')
RADII = np.logspace(0.0, np.log10(500.0), 16)
SPEEDS = np.linspace(0.1, 1.5, 8)[:, None]


def test_saturated_at_every_radius() -> None:
    # Section 3.4: "in the ICR model the shear force on the contact surface is assumed to be
    # saturated regardless of turning radius and slip ratio"
    state = icr.solve(CH3, SAND, SPEEDS, RADII)
    assert state.converged.all()
    np.testing.assert_allclose(state.extra['saturation'], 1.0, atol=1e-12)
    # hence the turning resistance hardly depends on R (Figure 3.12): mu_t varies by < 10 %
    mu_t = state.extra['mu_t']
    assert np.ptp(mu_t) / np.mean(mu_t) < 0.1


def test_equilibrium_to_tolerance() -> None:
    v, radius = 0.7, np.array([1.0, 4.0, 40.0, 400.0])
    state = icr.solve(CH3, SAND, v, radius)
    assert np.all(state.extra['residual_max'] < 1e-3)
    # independent check of the longitudinal balance (3.18): thrusts = compaction + m V^2/R sin(beta)
    transfer = 30 * v**2 * 0.15 / (radius * 0.4)
    r_t = compaction_resistance(SAND, 147.15 + transfer, 0.07, 0.7) + compaction_resistance(
        SAND, 147.15 - transfer, 0.07, 0.7
    )
    beta = np.arctan2(state.s0_m, radius)
    balance = state.thrust_outer_N + state.thrust_inner_N - r_t - 30 * v**2 / radius * np.sin(beta)
    np.testing.assert_allclose(balance, 0.0, atol=1e-3)


def test_icr_kinematics_eq_3_23() -> None:
    # omega r = V - yaw * y_ICR (eq. 3.23 in the hull frame of models/base.py)
    state = icr.solve(CH3, SAND, 0.5, 2.0)
    yaw = 0.25
    assert state.omega_outer_rad_s * 0.1 == pytest.approx(0.5 - yaw * state.extra['icr_outer_y_m'])
    assert state.extra['icr_outer_y_m'] < -0.2 < 0.2 < state.extra['icr_inner_y_m']  # both outside the tracks
    assert state.slip_outer > 0 > state.slip_inner


def test_mirror_and_straight() -> None:
    state = icr.solve(CH3, SAND, 0.5, [3.0, -3.0, np.inf])
    np.testing.assert_allclose(state.side('torque', 'right')[0], state.side('torque', 'left')[1])
    np.testing.assert_allclose(state.side('omega', 'left')[0], state.side('omega', 'right')[1])
    # straight: static Coulomb friction, no slip, thrust = compaction resistance of each side
    assert state.omega_outer_rad_s[2] == pytest.approx(5.0)
    assert state.thrust_outer_N[2] == pytest.approx(compaction_resistance(SAND, 147.15, 0.07, 0.7))


def test_friction_coefficient_scales_the_turning_moment() -> None:
    low = icr.solve(CH3, SAND, 0.5, 5.0, mu=0.8)
    high = icr.solve(CH3, SAND, 0.5, 5.0, mu=1.12)
    assert high.extra['turning_moment_Nm'] > low.extra['turning_moment_Nm']
    assert high.torque_outer_Nm > low.torque_outer_Nm


def test_wheeled_extension() -> None:
    state = icr.solve(load_vehicle('test_robot_4wheel'), SAND, 0.2, [1.0, 10.0])
    assert state.converged.all()
    np.testing.assert_allclose(state.extra['saturation'], 1.0, atol=1e-12)
    assert np.all(state.torque_outer_Nm > state.torque_inner_Nm)
