"""Chapter 5 fast model: the thrusts of eq. 5.2, the slip of eq. 5.3, the mu_t / s0 tables made
from Wong's model, and agreement with Wong's model itself."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from skidsteer_power.errors import InputError
from skidsteer_power.models import fast, wong_track
from skidsteer_power.terramechanics.terrain import PRESETS
from skidsteer_power.terramechanics.track import compaction_resistance, tractive_effort
from skidsteer_power.vehicle import load_vehicle

TRACK = load_vehicle('chapter3_track')


@pytest.fixture(autouse=True)
def _private_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv('SKIDSTEER_POWER_CACHE', str(tmp_path))
    fast.turning_tables.cache_clear()


def test_eq_5_2_by_hand_at_one_point() -> None:
    """A1 = m V^2/R sin(beta) + R_to + R_ti; A2 = (W L mu_t + (R_to - R_ti) B/2 - s0 cos(beta)
    m V^2/R) 2/B (5.1; the printed + in 5.2 is a typo); F_o,i = (A1 +- A2)/2; T = F r."""
    terrain = PRESETS['dry_sand']
    tables = fast.TurningTables(
        speeds=np.array([0.0, 2.0]),
        curvatures=np.array([0.0, 1.0]),
        mu_t=np.full((2, 2), 0.2),
        s0=np.full((2, 2), 0.1),
        source='hand',
    )
    v, r = 1.0, 2.0
    state = fast.solve(TRACK, terrain, v, r, tables=tables)
    m, h, b_tread, length = 30.0, 0.15, 0.4, 0.7
    weight = m * 9.81
    fc = m * v**2 / r  # 15 N
    lo, li = weight / 2 + fc * h / b_tread, weight / 2 - fc * h / b_tread  # eq. 3.1
    rto = float(compaction_resistance(terrain, lo, 0.07, length))
    rti = float(compaction_resistance(terrain, li, 0.07, length))
    beta = math.atan(0.1 / r)
    a1 = fc * math.sin(beta) + rto + rti
    a2 = (weight * length * 0.2 + (rto - rti) * b_tread / 2 - 0.1 * math.cos(beta) * fc) * 2 / b_tread
    assert float(state.thrust_outer_N) == pytest.approx((a1 + a2) / 2, rel=1e-9)
    assert float(state.thrust_inner_N) == pytest.approx((a1 - a2) / 2, rel=1e-9)
    assert float(state.torque_outer_Nm) == pytest.approx(0.1 * (a1 + a2) / 2, rel=1e-9)
    # eq. 5.3: the slip reproduces the thrust through the single-track closed form (2.17)
    back = float(tractive_effort(terrain, lo, 0.07, length, float(state.slip_outer)))
    assert back == pytest.approx(float(state.thrust_outer_N), rel=1e-8)
    # omega from the slip definition (2.13) at the outer side's speed (R + B/2) V / R
    v_outer = v * (r + b_tread / 2) / r
    assert float(state.omega_outer_rad_s) == pytest.approx(v_outer / (0.1 * (1 - float(state.slip_outer))))


def test_straight_running_needs_only_compaction_resistance() -> None:
    terrain = PRESETS['clay']
    state = fast.solve(TRACK, terrain, 0.6, np.inf)
    rc = float(compaction_resistance(terrain, TRACK.weight_N / 2, 0.07, 0.7))
    assert float(state.thrust_outer_N) == pytest.approx(rc, rel=1e-6)
    assert float(state.thrust_inner_N) == pytest.approx(rc, rel=1e-6)


def test_slip_for_thrust_inverts_eq_2_17_both_ways() -> None:
    terrain = PRESETS['sandy_loam']
    load = np.full(4, 147.0)
    slips = np.array([-0.5, -0.05, 0.02, 0.4])
    thrust = tractive_effort(terrain, load, 0.07, 0.7, slips)
    back, ok = fast.slip_for_thrust(terrain, load, 0.07, 0.7, thrust)
    assert ok.all()
    assert back == pytest.approx(slips, abs=1e-9)
    _, ok = fast.slip_for_thrust(terrain, load[:1], 0.07, 0.7, np.array([1e4]))  # beyond A c + W tan(phi)
    assert not ok[0]


def test_tables_come_from_wong_and_match_it() -> None:
    """Figure 5.2: the fast model reproduces Wong's torques closely (here within 5 % of the larger
    side torque over 4 speeds x 6 radii); mu_t and s0 in the tables are Wong's own."""
    terrain = PRESETS['dry_sand']
    tables = fast.turning_tables(TRACK, terrain, 'wong')
    ref_tab = wong_track.solve(TRACK, terrain, fast.TABLE_SPEEDS[2], fast.TABLE_RADII[3])
    assert tables.source == 'wong'
    assert tables.s0[2, -4] == pytest.approx(float(ref_tab.s0_m), rel=1e-9)  # curvature 1/R, ascending
    v = np.linspace(0.3, 1.4, 4)[:, None]
    r = np.array([1.2, 3.0, 7.0, 20.0, 80.0, 300.0])[None, :]
    got = fast.solve(TRACK, terrain, v, r)
    ref = wong_track.solve(TRACK, terrain, v, r)
    scale = np.maximum(np.abs(ref.torque_outer_Nm), np.abs(ref.torque_inner_Nm))
    assert np.max(np.abs(got.torque_outer_Nm - ref.torque_outer_Nm) / scale) < 0.05
    assert np.max(np.abs(got.torque_inner_Nm - ref.torque_inner_Nm) / scale) < 0.05


def test_tables_are_cached_on_disk(tmp_path: Path) -> None:
    terrain = PRESETS['clay']
    fast.turning_tables(TRACK, terrain, 'fess')
    assert len(list(tmp_path.glob('fast_*_fess_*.npz'))) == 1
    fast.turning_tables.cache_clear()
    again = fast.turning_tables(TRACK, terrain, 'fess')  # read back from the file
    assert again.mu_t.shape == (8, 17)


def test_wheels_and_bad_sources_are_refused() -> None:
    with pytest.raises(InputError, match='tracked'):
        fast.solve(load_vehicle('chapter4_4wheel'), PRESETS['clay'], 0.5, 2.0)
    with pytest.raises(InputError, match='wong or fess'):
        fast.generate_tables(TRACK, PRESETS['clay'], 'icr')
