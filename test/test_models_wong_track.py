"""Wong's general theory for tracks (section 3.3, eqs. 3.8-3.22)."""

from __future__ import annotations

import numpy as np
import pytest

from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models import loads, wong, wong_track
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.terramechanics.track import compaction_resistance, tractive_effort
from skidsteer_power.vehicle import load_vehicle

CH3 = load_vehicle('chapter3_track')
SAND = load_terrain('dry_sand')  # Table 3.3's soil
RADII = np.logspace(0.0, np.log10(500.0), 16)
SPEEDS = np.linspace(0.1, 1.5, 8)[:, None]


def _ground_frame_displacement(
    x: float, y: float, s0: float, omega: float, speed: float, radius: float, length: float, r: float
) -> np.ndarray:
    """Shear displacement by following the element on the ground (independent of the sinc forms).

    Hull pose at time t: heading a = yaw t about the fixed turning centre O; CG at Rot(a) (-s0, -R)
    from O. The element touched down at hull position (l/2, y) and is now at (x, y).
    """
    yaw = speed / radius
    t = (length / 2 - x) / (r * omega)
    a = yaw * t

    def rot(angle: float, vec: np.ndarray) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        return np.array([c * vec[0] - s * vec[1], s * vec[0] + c * vec[1]])

    now = rot(a, np.array([x - s0, y - radius]))
    then = np.array([length / 2 - s0, y - radius])
    return rot(-a, now - then)  # in the current hull frame


def test_displacement_matches_ground_frame_kinematics() -> None:
    for x, y in [(0.3, -0.2), (-0.35, -0.23), (0.0, 0.17)]:
        jx, jy = wong_track.track_shear_displacement(
            np.array(x), np.array(y), 0.1, 6.0, 0.5, 0.5 / 1.5, 0.7, 0.1
        )
        expected = _ground_frame_displacement(x, y, 0.1, 6.0, 0.5, 1.5, 0.7, 0.1)
        np.testing.assert_allclose([jx, jy], expected, rtol=1e-10, atol=1e-14)
    # straight running: j = (V - r omega) t along the track (eq. 2.15), no lateral part
    jx, jy = wong_track.track_shear_displacement(np.array(-0.35), np.array(0.2), 0.0, 6.0, 0.5, 0.0, 0.7, 0.1)
    assert jx == pytest.approx((0.5 - 0.6) * 0.7 / 0.6) and jy == 0.0


def test_every_solution_satisfies_eq_3_18() -> None:
    state = wong.solve(CH3, SAND, SPEEDS, RADII)
    assert state.converged.all()
    assert np.all(state.extra['residual_max'] < 1e-3)
    # re-evaluate the residuals at the reported unknowns
    points = loads.operating_points(SPEEDS, RADII)
    setup = wong_track._setup(CH3, SAND, points, wong_track.DEFAULT_RESOLUTION)
    x = np.stack(
        [state.s0_m.ravel(), state.omega_outer_rad_s.ravel(), state.omega_inner_rad_s.ravel()], axis=1
    )
    residual = wong_track.equilibrium(setup, x, np.arange(x.shape[0]))
    assert np.max(np.abs(residual)) < 1e-3
    # and the lateral balance independently: sum of lateral forces = m V^2/R cos(beta)
    beta = np.arctan2(state.s0_m, RADII)
    lateral = state.extra['lateral_outer_N'] + state.extra['lateral_inner_N']
    np.testing.assert_allclose(lateral, 30 * SPEEDS**2 / RADII * np.cos(beta), atol=1e-3)
    # s0 lies between 0 and l/2 (section 3.3.1)
    assert np.all((state.s0_m > 0) & (state.s0_m < 0.35))


def test_straight_running_is_the_single_track_of_chapter_2() -> None:
    state = wong.solve(CH3, SAND, 0.5, np.inf)
    r_c = compaction_resistance(SAND, 147.15, 0.07, 0.7)  # eq. 2.10, each side carries W/2
    assert state.thrust_outer_N == pytest.approx(r_c, abs=1e-3)
    # the slip at which eq. 2.17 gives that thrust is the slip of the solution
    assert tractive_effort(SAND, 147.15, 0.07, 0.7, state.slip_outer) == pytest.approx(r_c, abs=1e-3)
    assert state.s0_m == 0.0 and state.omega_outer_rad_s == state.omega_inner_rad_s


def test_mirror_symmetry_and_large_radius() -> None:
    state = wong.solve(CH3, SAND, 0.5, [4.0, -4.0])
    np.testing.assert_allclose(state.side('torque', 'right')[0], state.side('torque', 'left')[1])
    np.testing.assert_allclose(state.side('torque', 'left')[0], state.side('torque', 'right')[1])
    assert state.s0_m[0] == state.s0_m[1]
    far = wong.solve(CH3, SAND, 0.5, [1e2, 1e3, 1e4, 1e5, np.inf])
    gap = np.abs(far.torque_outer_Nm[:-1] - far.torque_outer_Nm[-1])
    assert np.all(np.diff(gap) < 0)  # approaches straight running monotonically
    assert gap[-1] < 0.01 * far.torque_outer_Nm[-1]
    np.testing.assert_allclose(far.total_power_W[-2], far.total_power_W[-1], rtol=1e-3)


def test_figures_3_9_and_3_10_findings() -> None:
    # "skid steering can consume a large amount of power when the turning radius is small":
    # outer torque and total power fall monotonically with R at every speed, steeply at small R.
    state = wong.solve(CH3, SAND, SPEEDS, RADII)
    assert np.all(np.diff(state.torque_outer_Nm, axis=1) < 0)
    assert np.all(np.diff(state.total_power_W, axis=1) < 0)
    assert np.all(state.torque_outer_Nm[:, 0] > 5 * state.torque_outer_Nm[:, -1])
    assert np.all(state.torque_inner_Nm[:, 0] < 0)  # the inner track brakes in tight turns


def test_soil_saturates_only_in_tight_turns() -> None:
    # Section 3.4: in Wong's model the soil fails (shear saturates) at small R, not at large R
    state = wong.solve(CH3, SAND, 1.5, [1.0, 500.0])
    saturation = state.extra['saturation']
    assert saturation[0] > 10 * saturation[1]
    assert saturation[1] < 0.05


def test_resolution_is_converged() -> None:
    coarse = wong.solve(CH3, SAND, [0.3, 1.5], [1.0, 20.0])
    fine = wong.solve(CH3, SAND, [0.3, 1.5], [1.0, 20.0], resolution=(64, 8))
    np.testing.assert_allclose(coarse.torque_outer_Nm, fine.torque_outer_Nm, rtol=5e-3)


def test_non_convergence_names_the_point_and_grids_report_failures() -> None:
    with pytest.raises(ConvergenceError, match=r'wong model: no steady state at V = 0\.5 m/s, R = 2 m'):
        wong.solve(CH3, SAND, 0.5, 2.0, max_iter=1, tol=1e-12)
    batch = wong.solve(CH3, SAND, [[0.5], [3.0]], [2.0, 0.25])
    # V = 0.5 m/s, R = 0.25 m: no steady state (the residual norm stalls far from 0; scipy's
    # hybr and lm stall there too): the dry sand cannot give the turning moment.
    # V = 3 m/s, R = 0.25 m: m V^2 h / (R B) = 30*9*0.15/(0.25*0.4) = 405 N > m g / 2: tips over
    assert batch.converged.shape == (2, 2)
    assert batch.converged.tolist() == [[True, False], [True, False]]
    assert batch.extra['failure'][:, 1].tolist() == [1, 2]
    assert np.isfinite(batch.torque_outer_Nm[0, 1])  # last iterate kept, flagged, not dropped
    with pytest.raises(ConvergenceError, match='tips over'):
        wong.solve(CH3, SAND, [1.0, 3.0], [2.0, 0.25], raise_on_failure=True)


def test_bad_inputs() -> None:
    with pytest.raises(InputError, match='B/2'):
        wong.solve(CH3, SAND, 0.5, 0.1)
    with pytest.raises(InputError, match='resolution'):
        wong.solve(CH3, SAND, 0.5, 1.0, resolution=(1, 1))
    with pytest.raises(InputError, match='tracked vehicle'):
        wong_track.solve(load_vehicle('chapter4_4wheel'), SAND, 0.5, 1.0)
