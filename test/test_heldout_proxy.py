"""The path a new user takes with a robot whose motor nobody modelled (issue 35's held-out check, as
the proxy of benchmarks/heldout_proxy.py): twin bags -> `calibrate --fit auto --out-vehicle` on one
-> `validate` with the written vehicle on the other, through the real command line in subprocesses.
The figures are the bench's (`python -m benchmarks.run heldout`); this checks the path holds."""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from benchmarks.heldout_proxy import Case, run_case
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.vehicle import load_vehicle


def test_an_unknown_robot_calibrates_on_one_bag_and_predicts_the_other(tmp_path: Path) -> None:
    outcome = run_case(Case('grass', 5, seconds=40.0), tmp_path)
    # a twin Husky on grass draws tens of watts: 40 s is kilojoules, positive (BatteryState's sign)
    assert 500.0 < outcome.measured_J < 20_000.0
    for pct in (outcome.start_pct, outcome.calibrated_pct, outcome.linear_pct):
        assert math.isfinite(pct)
    # the watts-vs-newton-metres bug read +4135 % here; any sane fit is within a factor of two
    assert abs(outcome.calibrated_pct) < 50.0
    written = tmp_path / 'calibrated_vehicle.yaml'
    vehicle = load_vehicle(str(written))
    powertrain = Powertrain.for_vehicle(vehicle)
    assert powertrain.is_effective
    # a whole-robot total fits one b, c for both sides: the two sides are written alike
    sides = yaml.safe_load(written.read_text())['powertrain']['internal_resistance']
    assert sides['left'] == sides['right']
    # step 6 (calibration/reconcile.py) ran on every sample of the first bag and says what it did
    record = yaml.safe_load(written.read_text())['powertrain']
    reconciled = record.get('calibration', {}).get('reconciled')
    if reconciled is not None:  # fitted: the efficiency is in the file and the loaded powertrain
        values = dict(zip(reconciled['parameters'], reconciled['values'], strict=True))
        assert 0.3 <= values['amplifier_efficiency'] <= 1.0
        assert powertrain.amplifier.efficiency == values['amplifier_efficiency']
        assert reconciled['report']['samples'] > 100
    else:  # kept: the reason is in the terrain file's warnings
        warnings = yaml.safe_load((tmp_path / 'calibrated_terrain.yaml').read_text())['calibration']
        assert any('steady-window fit is kept' in w for w in warnings['correlations_warnings'])
