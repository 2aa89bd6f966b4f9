"""Single track (section 2.3): sinkage, compaction resistance, tractive effort, drawbar pull."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import quad

from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics import PRESETS
from skidsteer_power.terramechanics.soil import shear_fraction
from skidsteer_power.terramechanics.track import (
    compaction_resistance,
    drawbar_pull,
    single_track,
    track_sinkage,
    tractive_effort,
)

DRY_SAND = PRESETS['dry_sand']
B, L = 0.07, 0.7  # Packbot-like track of Figures 2.9 and 2.10


def test_figure_2_9_dry_sand_hand_evaluation() -> None:
    # Hand evaluation of eq. 2.6, dry sand (Table 2.1), b = 0.07 m, l = 0.7 m:
    #   k = kc/b + kphi = 900/0.07 + 1523400 = 1536257.14 N/m^3.1
    #   W = 100 N:  W/(bl) = 2040.816 Pa; z0 = (2040.816/1536257.14)^(1/1.1) = exp(-6.62366/1.1)
    #               = 2.4258e-3 m
    #   W = 1000 N: z0 = (20408.16/1536257.14)^(1/1.1) = exp(-4.32108/1.1) = 1.9676e-2 m
    # Eq. 2.10 equals eq. 2.7 / l: R_c = b k z0^(n+1)/(n+1) = 0.07 * 1536257.14 * z0^2.1 / 2.1
    #   W = 100 N:  107538 * exp(2.1 * -6.02151) / 2.1 = 107538 * 3.2197e-6 / 2.1 = 0.16488 N
    #   W = 1000 N: 107538 * exp(2.1 * -3.92825) / 2.1 = 107538 * 2.6138e-4 / 2.1 = 13.385 N
    z0 = track_sinkage(DRY_SAND, [100.0, 1000.0], B, L)
    rc = compaction_resistance(DRY_SAND, [100.0, 1000.0], B, L)
    np.testing.assert_allclose(z0, [2.4258e-3, 1.9676e-2], rtol=2e-4)
    np.testing.assert_allclose(rc, [0.16488, 13.385], rtol=2e-3)
    # Text under Figure 2.9: "the sinkage is from 3mm to 20mm with normal load from 100N to 1000N and
    # the corresponding compaction resistance is from less than 1N to 13N" (rounded numbers).
    assert z0[0] == pytest.approx(0.003, abs=0.001)
    assert z0[1] == pytest.approx(0.020, abs=0.001)
    assert rc[0] < 1.0
    assert rc[1] == pytest.approx(13.0, abs=0.5)


def test_figure_2_9_harder_soils_sink_less() -> None:
    # Text under Figure 2.9: on sandy loam and clay "the sinkage and the compaction resistance are much
    # smaller and the sensitive to normal load is also lower".
    loads = np.array([100.0, 1000.0])
    sand_z = track_sinkage(DRY_SAND, loads, B, L)
    for name in ('sandy_loam', 'clay'):
        z = track_sinkage(PRESETS[name], loads, B, L)
        assert np.all(z < sand_z)
        assert np.all(
            compaction_resistance(PRESETS[name], loads, B, L) < compaction_resistance(DRY_SAND, loads, B, L)
        )
        assert z[1] - z[0] < sand_z[1] - sand_z[0]


@pytest.mark.parametrize('name', ['dry_sand', 'sandy_loam', 'clay'])
def test_figure_2_10_drawbar_pull_saturates_near_20_percent(name: str) -> None:
    # Text under Figure 2.10 (W = 100 N, b = 0.07 m, l = 0.7 m): "On all 3 types of soils, drawbar pull
    # saturates at about 20% slip." Read as: at 20 % slip at least 80 % of the pull at 100 % slip is
    # reached, while at 2 % slip less than half of it is.
    terrain = PRESETS[name]
    pull = drawbar_pull(terrain, 100.0, B, L, [0.02, 0.2, 1.0])
    assert pull[1] / pull[2] > 0.8
    assert pull[0] / pull[2] < 0.5
    assert np.all(np.diff(drawbar_pull(terrain, 100.0, B, L, np.linspace(0, 1, 101))) > 0)


@pytest.mark.parametrize('name', ['dry_sand', 'sandy_loam', 'clay'])
def test_driving_and_braking_branches_meet_at_zero(name: str) -> None:
    terrain = PRESETS[name]
    eps = np.array([-1e-9, 0.0, 1e-9])
    effort = tractive_effort(terrain, 100.0, B, L, eps)
    assert effort[1] == 0.0
    # slope at s = 0 from eq. 2.17: F_max l / (2K) on both sides (1 - (1 - e^-u)/u ~ u/2)
    f_max = B * L * terrain.c + 100.0 * math.tan(terrain.phi)
    slope = f_max * L / (2 * terrain.K)
    np.testing.assert_allclose(effort, slope * eps, rtol=1e-6, atol=1e-15)
    sweep = tractive_effort(terrain, 100.0, B, L, np.linspace(-1, 1, 2001))
    assert np.all(np.diff(sweep) > 0)


def test_eq_2_17_closed_form_hand_value() -> None:
    # Dry sand, W = 100 N, s = 0.2 (eq. 2.17 driving):
    #   F_max = A c + W tan phi = 0.049 * 1000 + 100 * 0.577350 = 106.735 N
    #   sl/K = 0.2 * 0.7 / 0.025 = 5.6; bracket = 1 - (1 - e^-5.6)/5.6 = 1 - 0.996302/5.6 = 0.822089
    #   F = 87.746 N
    # Braking s = -0.2: sl/(K(1+s)) = -0.14/0.02 = -7; bracket = 1 - (e^-7 - 1)/(-7) = 0.857273
    #   F = -91.501 N
    np.testing.assert_allclose(
        tractive_effort(DRY_SAND, 100.0, B, L, [0.2, -0.2]), [87.746, -91.501], rtol=1e-4
    )
    # Locked track (s = -1): full shear strength backwards
    assert float(tractive_effort(DRY_SAND, 100.0, B, L, -1.0)) == pytest.approx(-106.735, rel=1e-5)


def test_type_b_track_by_quadrature_matches_eq_2_16() -> None:
    # eq. 2.16 with the type B curve (eq. 2.4), integrated by scipy.integrate.quad along x (j = s x)
    terrain = dataclasses.replace(DRY_SAND, shear_type='B', Kw=0.05)
    f_max = B * L * terrain.c + 100.0 * math.tan(terrain.phi)
    for s in (0.05, 0.3, -0.3):
        j_rate = s if s > 0 else s / (1 + s)  # eq. 2.15
        mean = quad(lambda x, r=j_rate: float(shear_fraction(terrain, r * x)), 0, L)[0] / L
        assert float(tractive_effort(terrain, 100.0, B, L, s)) == pytest.approx(f_max * mean, rel=1e-9)


def test_single_track_bundles_eq_2_18() -> None:
    state = single_track(DRY_SAND, [100.0, 500.0], B, L, 0.2)
    np.testing.assert_allclose(state.drawbar_pull_N, state.tractive_effort_N - state.compaction_resistance_N)
    assert state.sinkage_m.shape == (2,)


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'load': -1.0}, 'load'),
        ({'width': 0.0}, 'width'),
        ({'length': -0.7}, 'length'),
        ({'slip': 1.5}, 'slip'),
        ({'slip': -1.01}, 'slip'),
        ({'slip': float('nan')}, 'slip'),
    ],
)
def test_bad_input(kwargs: dict[str, float], match: str) -> None:
    args = {'load': 100.0, 'width': B, 'length': L, 'slip': 0.2} | kwargs
    with pytest.raises(InputError, match=match):
        single_track(DRY_SAND, **args)
