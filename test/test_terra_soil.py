"""Terrains (presets, YAML loading and validation) and the soil laws of eqs. 2.1-2.5."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.terramechanics import (
    PRESETS,
    Terrain,
    load_terrain,
    pressure_sinkage,
    shear_strength,
    shear_stress,
    sinkage_for_pressure,
)
from skidsteer_power.terramechanics.soil import shear_fraction

TERRAIN_DIR = Path(__file__).resolve().parents[1] / 'config' / 'terrains'
DRY_SAND = PRESETS['dry_sand']


def test_table_2_1_to_2_3_converted_to_si() -> None:
    # Table 2.1: dry sand n 1.1, kc 0.90 kN/m^(n+1), kphi 1523.4 kN/m^(n+2); clay 0.5, 13.2, 692.2.
    # Table 2.2: c 1000 Pa, phi 30 deg (dry sand); 4140 Pa, 13 deg (clay). Table 2.3: K 0.025 / 0.01 m.
    assert DRY_SAND.n == 1.1
    assert DRY_SAND.kc == pytest.approx(900.0)
    assert DRY_SAND.kphi == pytest.approx(1_523_400.0)
    assert DRY_SAND.c == 1000.0
    assert DRY_SAND.phi == pytest.approx(math.pi / 6)
    assert DRY_SAND.K == 0.025
    clay = PRESETS['clay']
    assert (clay.kc, clay.kphi, clay.c, clay.K) == pytest.approx((13_200.0, 692_200.0, 4140.0, 0.01))
    assert clay.phi == pytest.approx(math.radians(13))


def test_chapter_7_and_8_presets() -> None:
    # Table 7.2 sand bin: n 1.08, c 200 Pa, phi 27 deg, kc 1000, kphi 1528600, K 0.024 (already N units).
    bin_ = PRESETS['sand_bin']
    assert (bin_.n, bin_.c, bin_.kc, bin_.kphi, bin_.K) == (1.08, 200.0, 1000.0, 1_528_600.0, 0.024)
    assert bin_.phi_deg == pytest.approx(27.0)
    # Table 8.3 LETE sand: n 0.79, c 1300 Pa, phi 31.1 deg, kc 102000, kphi 5301000, K 0.005.
    lete = PRESETS['lete_sand']
    assert (lete.n, lete.c, lete.kc, lete.kphi, lete.K) == (0.79, 1300.0, 102_000.0, 5_301_000.0, 0.005)
    assert lete.phi_deg == pytest.approx(31.1)
    # Table 8.2 sandy soil is the dry sand of Tables 2.1-2.3 in N units.
    assert dataclasses.replace(PRESETS['sandy_soil'], name='dry_sand') == DRY_SAND
    # Table 2.4 wheel coefficients.
    assert (DRY_SAND.a0, DRY_SAND.a1, DRY_SAND.b0, DRY_SAND.b1) == (0.24, 0.32, -0.45, 0.0)


@pytest.mark.parametrize('name', sorted(PRESETS))
def test_yaml_copy_of_each_preset_loads_equal(name: str) -> None:
    assert load_terrain(TERRAIN_DIR / f'{name}.yaml') == PRESETS[name]


def test_example_yaml_is_dry_sand() -> None:
    example = load_terrain(str(TERRAIN_DIR / 'example_terrain.yaml'))
    assert dataclasses.replace(example, name='dry_sand') == DRY_SAND


def test_unknown_name_is_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown terrain 'mud'"):
        load_terrain('mud')


def test_missing_file_is_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='not found'):
        load_terrain(tmp_path / 'nope.yaml')


GOOD = 'name: t\nn: 1.1\nkc: 900\nkphi: 1523400\nc: 1000\nphi_deg: 30\nK: 0.025\n'


@pytest.mark.parametrize(
    ('edit', 'field'),
    [
        (('n: 1.1', ''), "'n' is missing"),
        (('n: 1.1', 'n: 0'), "'n' must be > 0"),
        (('n: 1.1', 'n: -0.5'), "'n' must be > 0"),
        (('K: 0.025', 'K: 0'), "'K' must be > 0"),
        (('phi_deg: 30', 'phi_deg: 90'), "'phi' must lie in \\(0, 90\\)"),
        (('phi_deg: 30', 'phi_deg: 0'), "'phi' must lie in \\(0, 90\\)"),
        (('phi_deg: 30', 'phi: 30'), "'phi' is not a terrain field"),
        (('kc: 900', 'kc: -900'), "'kc' must be >= 0"),
        (('kphi: 1523400', 'kphi: -1'), "'kphi' must be >= 0"),
        (('c: 1000', 'c: -1'), "'c' must be >= 0"),
        (('c: 1000', 'c: soft'), "'c' must be a number"),
        (('K: 0.025', 'K: 0.025\nshear_type: B'), "'Kw' must be > 0"),
        (('K: 0.025', 'K: 0.025\nshear_type: C\nKw: 0.01'), "'Kr' must lie in"),
        (('K: 0.025', 'K: 0.025\nshear_type: D'), "'shear_type' must be"),
        (('K: 0.025', 'K: 0.025\nb0: 0.5'), "'b0/b1'"),
        (('c: 1000', 'c: 1000\nc_kPa: 1'), "'c' is given twice"),
    ],
)
def test_yaml_validation_names_the_field(tmp_path: Path, edit: tuple[str, str], field: str) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text(GOOD.replace(*edit))
    with pytest.raises(ConfigError, match=field):
        load_terrain(path)


def test_good_yaml_and_kilo_units(tmp_path: Path) -> None:
    path = tmp_path / 'good.yaml'
    path.write_text(GOOD.replace('kc: 900', 'kc_kN: 0.9').replace('c: 1000', 'c_kPa: 1.0'))
    terrain = load_terrain(path)
    assert (terrain.kc, terrain.c) == pytest.approx((900.0, 1000.0))


def test_malformed_yaml_is_config_error(tmp_path: Path) -> None:
    path = tmp_path / 'broken.yaml'
    path.write_text('n: [1.1\n')
    with pytest.raises(ConfigError, match='cannot read terrain file'):
        load_terrain(path)
    path.write_text('- 1\n- 2\n')
    with pytest.raises(ConfigError, match='expected a mapping'):
        load_terrain(path)


def test_terrain_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        DRY_SAND.n = 2.0  # type: ignore[misc]


def test_pressure_sinkage_hand_value() -> None:
    # eq. 2.1, dry sand, b = 0.07 m, z = 0.01 m: (900/0.07 + 1523400) * 0.01^1.1
    # = 1536257.14 * exp(1.1 * ln 0.01) = 1536257.14 * 0.0063096 = 9693.1 Pa
    assert pressure_sinkage(DRY_SAND, 0.01, 0.07) == pytest.approx(9693.1, rel=1e-4)
    assert pressure_sinkage(DRY_SAND, [-0.01, 0.0], 0.07).tolist() == [0.0, 0.0]


def test_sinkage_for_pressure_inverts_eq_2_1() -> None:
    z = np.linspace(0.0, 0.05, 11)
    for terrain in PRESETS.values():
        p = pressure_sinkage(terrain, z, 0.1)
        np.testing.assert_allclose(sinkage_for_pressure(terrain, p, 0.1), z, atol=1e-15, rtol=1e-12)
    with pytest.raises(InputError, match='pressure'):
        sinkage_for_pressure(DRY_SAND, -1.0, 0.1)
    with pytest.raises(InputError, match='width'):
        pressure_sinkage(DRY_SAND, 0.01, 0.0)


def test_mohr_coulomb() -> None:
    # eq. 2.2, dry sand: 1000 + 2000 tan 30 deg = 1000 + 1154.70 = 2154.70 Pa
    assert shear_strength(DRY_SAND, 2000.0) == pytest.approx(2154.70, rel=1e-5)


def test_type_a_shear_curve() -> None:
    # eq. 2.3 at j = K: tau = tau_max (1 - 1/e) = 0.63212 tau_max; odd in j; saturates at tau_max
    tau_max = float(shear_strength(DRY_SAND, 2000.0))
    tau = shear_stress(DRY_SAND, 2000.0, [DRY_SAND.K, -DRY_SAND.K, 1.0, np.inf])
    np.testing.assert_allclose(tau, [0.632121 * tau_max, -0.632121 * tau_max, tau_max, tau_max], rtol=1e-6)


def test_type_b_peaks_at_kw() -> None:
    # eq. 2.4: tau = tau_max (j/Kw) e^(1 - j/Kw) peaks at j = Kw with tau = tau_max, then decays
    terrain = dataclasses.replace(DRY_SAND, shear_type='B', Kw=0.02)
    best = minimize_scalar(lambda j: -float(shear_fraction(terrain, j)), bounds=(0, 0.2), method='bounded')
    assert best.x == pytest.approx(0.02, rel=1e-4)
    assert -best.fun == pytest.approx(1.0, rel=1e-9)
    assert float(shear_fraction(terrain, 0.2)) < 0.01


def test_type_c_residual_and_peak() -> None:
    # eq. 2.5 (with Wong's e^(1 - j/Kw), see soil.py): tau(Kw) = tau_max, tau(inf) = Kr tau_max
    terrain = dataclasses.replace(DRY_SAND, shear_type='C', Kr=0.6, Kw=0.02)
    np.testing.assert_allclose(shear_fraction(terrain, [0.0, 0.02, np.inf]), [0.0, 1.0, 0.6], atol=1e-12)
    assert float(shear_fraction(terrain, -0.02)) == pytest.approx(-1.0)


def test_construction_validates() -> None:
    with pytest.raises(ConfigError, match="'K'"):
        Terrain('x', n=1.0, kc=0.0, kphi=1e6, c=0.0, phi=0.5, K=-1.0)


def test_k_eq_is_eq_2_1s_modulus_on_floats_and_arrays() -> None:
    # sandy_soil.yaml: kc = 900 N/m^(n+1), kphi = 1 523 400 N/m^(n+2); b = 0.1 m:
    # k_eq = 900 / 0.1 + 1 523 400 = 1 532 400 (hand calculation), and at z = 1 m eq. 2.1 gives p = k_eq.
    terrain = load_terrain('sandy_soil')
    assert terrain.k_eq(0.1) == pytest.approx(1_532_400.0)
    widths = np.array([0.05, 0.1, 0.2])
    np.testing.assert_allclose(terrain.k_eq(widths), [1_541_400.0, 1_532_400.0, 1_527_900.0])
    np.testing.assert_allclose(pressure_sinkage(terrain, 1.0, widths), terrain.k_eq(widths))
