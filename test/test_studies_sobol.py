"""Sobol indices (SALib) next to the one-at-a-time table: ``sensitivity --method sobol`` on a real
mission (Steeds' closed form, so 144 missions run in seconds) on a Dask LocalCluster."""

from __future__ import annotations

import json
from typing import Any

import pytest

from skidsteer_power.cli.main import main


@pytest.fixture(scope='module')
def table(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    import contextlib
    import io

    argv = ['sensitivity', '--vehicle', 'packbot_track', '--route', 'patrol', '--model', 'steeds']
    stream = io.StringIO()
    with contextlib.redirect_stdout(stream):
        assert main([*argv, '--method', 'sobol', '--samples', '16', '--workers', '1', '--json']) == 0
    loaded: dict[str, Any] = json.loads(stream.getvalue())
    return loaded


def test_sobol_runs_n_times_d_plus_2_missions_next_to_the_oat_table(table: dict[str, Any]) -> None:
    sobol = table['sobol']
    d = len(sobol['parameters'])  # 6 soil parameters + internal_scale (default spread)
    assert d == 7 and sobol['runs'] == 16 * (d + 2)
    assert set(table['results']['packbot_track']['changes_percent']) >= {'n+', 'c-', 'all+'}  # OAT kept


def test_drawbar_pull_does_not_depend_on_the_powertrain(table: dict[str, Any]) -> None:
    """Max drawbar pull is a terrain-vehicle quantity (ch. 8.2): the internal resistance cannot
    explain any of its variance, exactly (every A/AB pair differing in it gives the same value)."""
    dp = table['sobol']['indices']['packbot_track']['drawbar_pull_ratio']
    assert dp['internal_scale']['ST'] == pytest.approx(0.0, abs=1e-12)
    assert dp['internal_scale']['S1'] == pytest.approx(0.0, abs=1e-12)


def test_sobol_ranking_agrees_with_one_at_a_time(table: dict[str, Any]) -> None:
    """The parameter whose one-at-a-time change (+-1 %) times its spread (default relative sigma) moves
    the drawbar pull most -- the linearized variance share, (dY/dp sigma_p)^2 -- has the largest total
    index; energy of a tracked Packbot on the patrol is mostly internal resistance (ch. 8.1: straight
    running, test_missions.py), so internal_scale carries its variance."""
    oat = table['results']['packbot_track']['changes_percent']
    soil = table['parameters']
    from skidsteer_power.studies.uncertainty import DEFAULT_RELATIVE_SIGMA

    swing = {
        p: abs(oat[f'{p}+']['drawbar_pull_ratio'] - oat[f'{p}-']['drawbar_pull_ratio'])
        * DEFAULT_RELATIVE_SIGMA[p]
        for p in soil
    }
    indices = table['sobol']['indices']['packbot_track']
    st = {p: indices['drawbar_pull_ratio'][p]['ST'] for p in soil}
    assert max(st, key=lambda k: st[k]) == max(swing, key=lambda k: swing[k])
    energy = indices['energy_J']
    assert energy['internal_scale']['ST'] > 0.8
    assert all(energy[p]['ST'] < 0.05 for p in soil)
