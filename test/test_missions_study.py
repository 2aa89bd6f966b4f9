"""Sensitivity (ch. 8.2) and the Table 8.4 design study (ch. 8.3)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from skidsteer_power.cli.main import main
from skidsteer_power.missions.design import design_study, grid
from skidsteer_power.missions.routes import patrol
from skidsteer_power.missions.sensitivity import SOIL_PARAMETERS, sensitivity
from skidsteer_power.terramechanics.terrain import Terrain, load_terrain
from skidsteer_power.vehicle import load_vehicle


@pytest.fixture(scope='module')
def sandy() -> Terrain:
    return load_terrain('sandy_soil')


@pytest.fixture(scope='module')
def track_sensitivity(sandy: Terrain) -> dict[str, Any]:
    return sensitivity([load_vehicle('packbot_track')], sandy, patrol(), workers=2)


def test_sensitivity_cases_and_parallel_equals_serial(
    track_sensitivity: dict[str, Any], sandy: Terrain
) -> None:
    changes = track_sensitivity['results']['packbot_track']['changes_percent']
    assert set(changes) == {f'{p}{s}' for p in SOIL_PARAMETERS for s in '+-'} | {'all+', 'all-'}
    serial = sensitivity([load_vehicle('packbot_track')], sandy, patrol(), workers=1)
    assert serial['results'] == track_sensitivity['results']


def test_sensitivity_sinkage_to_kphi_hand_calculation(track_sensitivity: dict[str, Any]) -> None:
    # eq. 2.6: z0 = (p / (kc/b + kphi))^(1/n); +1 % kphi on Table 8.2's sandy soil, b = 0.074 m
    k0 = 900 / 0.074 + 1523400
    k1 = 900 / 0.074 + 1.01 * 1523400
    expected = 100 * ((k0 / k1) ** (1 / 1.1) - 1)  # = -0.90 %
    changes = track_sensitivity['results']['packbot_track']['changes_percent']
    assert changes['kphi+']['max_sinkage_m'] == pytest.approx(expected, rel=1e-6)
    assert changes['c+']['max_sinkage_m'] == pytest.approx(0.0, abs=1e-9)  # cohesion does not sink
    # eq. 2.11: more cohesion or friction -> more drawbar pull
    assert changes['c+']['drawbar_pull_ratio'] > 0 > changes['c-']['drawbar_pull_ratio']
    assert changes['phi+']['drawbar_pull_ratio'] > 0


def test_sensitivity_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / 'sens.png'
    argv = ['sensitivity', '--vehicle', 'packbot_6wheel', '--route', 'patrol', '--workers', '1',
            '--plot', str(png), '--json']  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['delta'] == 0.01 and out['terrain'] == 'sandy_soil'
    assert set(out['results']['packbot_6wheel']['baseline']) == {
        'energy_J',
        'drawbar_pull_ratio',
        'max_sinkage_m',
    }
    assert png.read_bytes()[:4] == b'\x89PNG'
    with pytest.raises(SystemExit) as exit_:  # argparse: the range of --workers
        main(['sensitivity', '--workers', '0'])
    assert exit_.value.code == 2


def test_grid_is_table_8_4() -> None:
    rows = grid()
    assert len(rows) == 729  # 3^6
    assert {r['configuration'] for r in rows} == {'track', '4-wheel', '6-wheel'}
    assert sorted({r['mass_kg'] for r in rows}) == [10.0, 20.0, 30.0]
    assert sorted({r['width_m'] for r in rows}) == [0.05, 0.125, 0.2]
    assert sorted({r['radius_m'] for r in rows}) == [0.08, 0.1, 0.12]
    assert sorted({r['length_or_wheelbase_m'] for r in rows}) == [0.5, 0.7, 0.9]
    assert sorted({r['tread_m'] for r in rows}) == [0.3, 0.4, 0.5]


@pytest.mark.slow
def test_design_study_deterministic_and_chapter_8_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], sandy: Terrain
) -> None:
    png = tmp_path / 'design.png'
    assert main(['design-study', '--plot', str(png), '--json']) == 0
    first = json.loads(capsys.readouterr().out)
    second = design_study(sandy)
    assert json.loads(json.dumps(second['candidates'])) == first['candidates']  # deterministic
    assert png.read_bytes()[:4] == b'\x89PNG'
    assert first['n_candidates'] == 729
    for config in ('track', '4-wheel', '6-wheel'):
        best = first['best'][config]
        assert best['configuration'] == config
        for key in ('mass_kg', 'width_m', 'radius_m', 'length_or_wheelbase_m', 'tread_m'):
            assert isinstance(best[key], float)
        eligible = [c for c in first['candidates'] if c['configuration'] == config and c['merit'] is not None]
        assert best['merit'] == max(c['merit'] for c in eligible)
    # ch. 8.3: driving straight, wheel base and tread do not change a wheeled design's power and
    # mobility, nor tread a tracked design's (Figure 8.16 has fewer distinct points)
    groups: dict[tuple[object, ...], list[float]] = {}
    for c in first['candidates']:
        if c['converged']:
            group: tuple[object, ...] = (c['configuration'], c['mass_kg'], c['width_m'], c['radius_m'])
            if c['configuration'] == 'track':
                group += (c['length_or_wheelbase_m'],)
            groups.setdefault(group, []).append(c['power_straight_W'])
    for powers in groups.values():
        assert np.ptp(powers) <= 1e-4 * max(powers)
    # turning: some 4-wheel designs consume more than every track design (ch. 8.3)
    converged = [c for c in first['candidates'] if c['converged']]
    turning = {
        cfg: [c['power_turning_W'] for c in converged if c['configuration'] == cfg]
        for cfg in ('track', '4-wheel')
    }
    assert max(turning['4-wheel']) > max(turning['track'])
    # the tracked designs have the best mobility
    ratio = {cfg: max(c['drawbar_pull_ratio'] for c in first['candidates'] if c['configuration'] == cfg)
             for cfg in ('track', '4-wheel', '6-wheel')}  # fmt: skip
    assert ratio['track'] > max(ratio['4-wheel'], ratio['6-wheel'])


def test_sensitivity_derivative_is_central_and_flags_non_smooth_cases() -> None:
    from skidsteer_power.missions.sensitivity import derivatives

    base = dict.fromkeys(('energy_J', 'drawbar_pull_ratio', 'max_sinkage_m'), 100.0)
    # smooth: f(+1 %) = 101, f(-1 %) = 99 -> (101 - 99) / 100 / 0.02 = +1.0 % per %
    smooth = derivatives(base, dict.fromkeys(base, 101.0), dict.fromkeys(base, 99.0), 0.01)
    assert smooth['energy_J'] == {'derivative': pytest.approx(1.0), 'status': 'ok'}
    # issue 18: both +1 % and -1 % lowered the energy: not smooth, no number reported
    rough = derivatives(base, dict.fromkeys(base, 89.7), dict.fromkeys(base, 97.3), 0.01)
    assert rough['energy_J'] == {'derivative': None, 'status': 'non_smooth'}
    assert derivatives(base, None, dict.fromkeys(base, 99.0), 0.01)['energy_J']['status'] == 'failed'


def test_sensitivity_reports_smooth_derivatives(track_sensitivity: dict[str, Any]) -> None:
    derivs = track_sensitivity['results']['packbot_track']['derivatives']
    assert set(derivs) == {*SOIL_PARAMETERS, 'all'}
    # eq. 2.6 above: sinkage falls with kphi, about -0.90 % per % (central difference)
    assert derivs['kphi']['max_sinkage_m']['status'] == 'ok'
    assert derivs['kphi']['max_sinkage_m']['derivative'] == pytest.approx(-0.9, abs=0.02)


def test_a_wheel_that_cannot_roll_free_is_an_unsolved_candidate_not_a_failed_study() -> None:
    """A sampled soil can be too weak for a small wheel to roll free: on sandy_soil with phi = 20 deg
    and c = 200 Pa no slip in [-1, 1] gives a 0.08 m x 0.05 m wheel zero drawbar pull (eq. 2.29 has no
    root; FESS's free-wheel load table, models/fess.py, cannot be built). The candidate is reported
    unsolved for that soil; the other candidates of the chunk are still solved."""
    import dataclasses
    import math

    from skidsteer_power.errors import ConvergenceError
    from skidsteer_power.missions.design import evaluate_chunk
    from skidsteer_power.terramechanics.wheel import solve_wheel

    weak = dataclasses.replace(load_terrain('sandy_soil'), phi=math.radians(20.0), c=200.0)
    with pytest.raises(ConvergenceError):
        solve_wheel(weak, 50.0, 0.0, 0.08, 0.05)
    small = next(
        c for c in grid() if c['configuration'] == '4-wheel' and (c['radius_m'], c['width_m']) == (0.08, 0.05)
    )
    track = next(c for c in grid() if c['configuration'] == 'track')
    out = evaluate_chunk(([small, track], weak, 'fess'))
    assert out[0]['converged'] is False and out[0]['power_straight_W'] is None
    assert out[1]['index'] == track['index'] and 'power_straight_W' in out[1]
