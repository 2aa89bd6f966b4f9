"""Uncertain parameters (issue 19, issue 15's --from-calibration): spreads from defaults, a sigma YAML
and a calibration's covariance; reproducible Sobol samples; Monte Carlo missions and design study on a
real Dask LocalCluster."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from skidsteer_power.cli.main import main
from skidsteer_power.errors import ConfigError
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.studies import uncertainty as u
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain


@pytest.fixture(scope='module')
def sandy() -> Terrain:
    return load_terrain('sandy_soil')


@pytest.fixture(scope='module')
def pt() -> Powertrain:
    return Powertrain.default_test_robot('track')


def test_default_sigmas_are_relative_to_the_nominal(sandy: Terrain, pt: Powertrain) -> None:
    spread = u.default_spread(sandy, pt)
    sigma = spread.sigma
    # Table 8.2: kphi 1523.4 kN/m^(n+2), phi 30 deg; defaults 10 % and 5 %
    assert sigma['kphi'] == pytest.approx(0.10 * 1523400)
    assert sigma['phi'] == pytest.approx(0.05 * math.radians(30))
    assert sigma['internal_scale'] == pytest.approx(0.10)


def test_sigma_yaml_relative_and_absolute_in_the_keys_unit(
    tmp_path: Path, sandy: Terrain, pt: Powertrain
) -> None:
    path = tmp_path / 'u.yaml'
    path.write_text(
        'terrain:\n  kphi_kN: {sigma: 100}\n  phi_deg: {sigma: 1.5}\n  n: 0.02\n'
        'powertrain:\n  internal_scale: 0.2\n'
    )
    sigma = u.spread_from_yaml(path, sandy, pt).sigma
    assert sigma == pytest.approx(
        {'kphi': 100e3, 'phi': math.radians(1.5), 'n': 0.02 * 1.1, 'internal_scale': 0.2}
    )
    path.write_text('terrain:\n  phi: 0.1\n  lava: 0.1\n')
    with pytest.raises(ConfigError, match='lava'):
        u.spread_from_yaml(path, sandy, pt)


def _calibrated_file(
    tmp_path: Path, cov: Sequence[Sequence[float]], names: Sequence[str] = ('kphi', 'phi', 'n')
) -> Path:
    data = {
        'name': 'calibrated',
        'n': 1.1,
        'kc': 900,
        'kphi_kN': 1523.4,
        'c': 1000,
        'phi_deg': 30,
        'K': 0.025,
        'calibration': {'parameters': list(names), 'covariance': cov},
    }
    path = tmp_path / 'cal.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def test_calibration_covariance_is_read_in_the_terrain_files_units(tmp_path: Path) -> None:
    """kphi is written as kphi_kN and phi as phi_deg: covariance in kN^2 and deg^2 -> SI."""
    cov = [[100.0**2, 0.5 * 100.0 * 2.0, 0.0], [0.5 * 100.0 * 2.0, 2.0**2, 0.0], [0.0, 0.0, 0.01]]
    spread = u.spread_from_calibration(_calibrated_file(tmp_path, cov))
    assert spread.names == ('kphi', 'phi', 'n')
    assert spread.sigma == pytest.approx({'kphi': 100e3, 'phi': math.radians(2.0), 'n': 0.1})
    rho = spread.cov[0, 1] / math.sqrt(spread.cov[0, 0] * spread.cov[1, 1])
    assert rho == pytest.approx(0.5)  # a correlation survives the unit change


@pytest.mark.parametrize(
    ('cov', 'match'),
    [([[1.0, 2.0, 0], [2.0, 1.0, 0], [0, 0, 1]], 'positive semi-definite'), ([[1.0]], '3 x 3')],
)
def test_bad_calibration_covariance_is_a_config_error(
    tmp_path: Path, cov: list[list[float] | list[int]] | list[list[float]], match: str
) -> None:
    with pytest.raises(ConfigError, match=match):
        u.spread_from_calibration(_calibrated_file(tmp_path, cov))


def test_sobol_samples_are_reproducible_correlated_and_clipped(sandy: Terrain, pt: Powertrain) -> None:
    cov = np.array([[0.04, 0.03], [0.03, 0.04]]) * np.outer([1523400, 0.5236], [1523400, 0.5236])
    spread = u.ParameterSpread(('kphi', 'phi'), cov, 'test')
    a = u.draw(spread, sandy, pt, 512, seed=3)
    assert a == u.draw(spread, sandy, pt, 512, seed=3)
    assert a != u.draw(spread, sandy, pt, 512, seed=4)
    values = np.array([[s['kphi'], s['phi']] for s in a])
    assert np.corrcoef(values.T)[0, 1] == pytest.approx(0.75, abs=0.03)  # 0.03 / 0.04
    assert values[:, 0].std() / 1523400 == pytest.approx(0.2, rel=0.05)
    wide = u.ParameterSpread(('n',), np.array([[4.0]]), 'wide')
    n = np.array([s['n'] for s in u.draw(wide, sandy, pt, 256, seed=0, method='random')])
    assert n.min() == u.BOUNDS['n'][0] and n.max() == u.BOUNDS['n'][1]


def test_internal_scale_scales_internal_power_exactly(pt: Powertrain) -> None:
    doubled = u.apply_powertrain(pt, {'internal_scale': 2.0})
    omega = np.array([10.0, 300.0])
    for side in ('left', 'right'):
        assert doubled.resistance(side).power(omega) == pytest.approx(2 * pt.resistance(side).power(omega))
    totals = u.apply_powertrain(pt, {'left_b': 1e-3, 'left_c': 0.5})
    assert totals.resistance('left').total.coulomb_Nm == 0.5 and totals.right == pt.right


def _mission(capsys: pytest.CaptureFixture[str], *extra: str) -> dict[str, Any]:
    argv = ['mission', '--vehicle', 'test_robot_track', '--terrain', 'sandy_soil', '--route', 'patrol']
    assert main([*argv, '--no-cache', '--json', *extra]) == 0
    mission: dict[str, Any] = json.loads(capsys.readouterr().out)
    return mission


def test_mission_samples_on_a_local_cluster(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Zero sigmas: every sample is the nominal mission, so p05 = p50 = p95 = energy_J (the samples
    go through the same route-energy code). Default sigmas: an ordered, non-degenerate band."""
    zero = tmp_path / 'zero.yaml'
    zero.write_text('terrain: {kphi: 0.0, n: 0.0}\n')
    out = _mission(capsys, '--samples', '3', '--uncertainty', str(zero), '--workers', '1')
    for p in ('p05', 'p50', 'p95'):
        assert out[f'energy_J_{p}'] == pytest.approx(out['energy_J'], rel=1e-12)
    out = _mission(capsys, '--samples', '8', '--seed', '1', '--workers', '2')
    assert out['energy_J_p05'] < out['energy_J_p50'] < out['energy_J_p95']
    assert out['uncertainty']['samples'] == 8 and 'in-process' in out['uncertainty']['engine']  # 8 light


def test_mission_from_calibration(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cov = [[150.0**2, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0025]]
    out = _mission(capsys, '--samples', '4', '--from-calibration', str(_calibrated_file(tmp_path, cov)))
    assert out['uncertainty']['spread'].startswith('calibration')
    assert out['uncertainty']['sigma_SI']['phi'] == pytest.approx(math.radians(1.0))
    assert out['energy_J_p05'] <= out['energy_J_p95']


def test_options_without_samples_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    zero = tmp_path / 'zero.yaml'
    zero.write_text('terrain: {kphi: 0.0}\n')
    argv = ['mission', '--vehicle', 'test_robot_track', '--terrain', 'sandy_soil', '--route', 'patrol']
    assert main([*argv, '--no-cache', '--uncertainty', str(zero)]) == 2
    assert 'need --samples' in capsys.readouterr().err
