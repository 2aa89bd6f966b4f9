"""The estimator never dies on a measurement, and never loses or overwrites its energy state (issue 13).

Pure core first, then the real node over rclpy/DDS, then the whole suite under ``run`` in a subprocess.

The reading of the issue: both motors at 1100 rad/s with Kt I = 4.9 N m (inside the input limits of
1200 rad/s and 5 N m). By hand with the EC-45 (Appendix B: Kt 0.114 N m/A, R 0.710 ohm) and the
DES 70/10 (efficiency 0.92): I = 4.9 / 0.114 = 42.98 A, Kt I w = 5390 W, terminal = 5390 + 0.71 I^2
= 6701.7 W, bus = 6701.7 / 0.92 = 7284.5 W per side, 14569 W in all. The test robot's battery
(config/batteries/test_robot.yaml: 12 cells in series, 3.27 V per cell at its lowest, 4 mOhm per
cell) delivers at most OCV^2 / 4R = (12 * 3.27)^2 / (4 * 12 * 0.004) = 8019.7 W at any charge.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from rclpy.context import Context
from sensor_msgs.msg import JointState
from test_estimator_core import FixedPowerPredictor, make_core
from test_nodes_estimator import Rig

from skidsteer_power.estimator.core import IMPLAUSIBLE_WARN_S, RejectedInput
from skidsteer_power.estimator.persistence import load_or_quarantine, save_state
from skidsteer_power.powertrain import Battery

IMPOSSIBLE = ((1100.0, 1100.0), (4.9, 4.9))  # the reading: 14569 W at the battery
LIMIT_W = (12 * 3.27) ** 2 / (4 * 12 * 0.004)  # 8019.7 W, by hand (module docstring)
NAMES = ['left_motor', 'right_motor']


def test_battery_power_bound_by_hand() -> None:
    assert Battery.default_test_robot().max_power_W() == pytest.approx(LIMIT_W, rel=1e-9)


def test_an_impossible_reading_is_skipped_counted_and_flagged_never_fatal() -> None:
    core = make_core(100.0)
    core.on_joint_state(NAMES, (300.0, 300.0), (0.228, 0.228), 0.0)  # 154.9 W: plausible
    with pytest.raises(RejectedInput, match='implausible reading skipped: battery-side power 14569 W'):
        core.on_joint_state(NAMES, *IMPOSSIBLE, 0.1)
    assert core.implausible['joint_states'] == 1 and core.rejects.counts['joint_states'] == 1
    for t in (0.2, 0.3, 5.0):  # the publish timer: must not raise
        core.tick(t)
    level, message, values = core.diagnostics(5.0)
    assert level == 1 and 'implausible power' in message
    assert values['implausible_joint_states'] == '1'
    # skipped, not integrated: measured energy is the plausible 154.9 W over its 0.5 s of freshness
    assert core.energy.energy_J['measured'] < 200.0
    assert core.diagnostics(0.1 + IMPLAUSIBLE_WARN_S + 1.0)[0] == 1  # still WARN: stale inputs
    assert 'implausible' not in core.diagnostics(0.1 + IMPLAUSIBLE_WARN_S + 1.0)[1]


@pytest.mark.parametrize('battery_W', [2e4, -2e4, math.nan])
def test_an_impossible_prediction_is_clamped_and_counted(battery_W: float) -> None:
    core = make_core(battery_W)
    core.on_command(0.2, 0.0, 0.0)
    core.tick(0.4)  # would raise 'battery cannot deliver' without the clamp
    assert core.implausible['predictions'] == 1
    integrated = core.energy.energy_J['predicted']
    expected = 0.0 if math.isnan(battery_W) else math.copysign(LIMIT_W, battery_W) * 0.4
    assert integrated == pytest.approx(expected, rel=1e-9)


# --- the state file -------------------------------------------------------------------------------
def _state_bytes(soc: str = '0.5', measured: str = '100.0') -> bytes:
    """A state file of the test robot, with the given raw JSON for soc and the measured tally."""
    text = (
        '{"format_version": 1, "vehicle": "test_robot_track", "battery": {"state": {"soc": SOC, '
        '"elapsed_s": 10.0, "drawn_J": 50.0}}, "energy_J": {"measured": MEASURED, "predicted": 90.0}}'
    )
    return text.replace('SOC', soc).replace('MEASURED', measured).encode()


DAMAGED = {
    'garbage bytes': b'\x89\xff\x00garbage\xfe' * 20,
    'truncated JSON': b'{"format_version": 1, "batt',
    'wrong schema': b'{"format_version": 1, "vehicle": "test_robot_track", "battery": [1, 2]}',
    'other format': b'[1, 2, 3]',
    # issue 28: a RecursionError once stopped the node; "nan" and 1e308 tallies were accepted
    'nested 40 KB': b'[' * 20_000 + b']' * 20_000,
    'nested 400 KB (over the size limit)': b'[' * 200_000 + b']' * 200_000,
    'nan tally': _state_bytes(measured='"nan"'),
    'NaN tally': _state_bytes(measured='NaN'),
    'tally out of range': _state_bytes(measured='1e308'),
    'soc out of range': _state_bytes(soc='1.5'),
}


@pytest.mark.parametrize('content', DAMAGED.values(), ids=DAMAGED.keys())
def test_a_damaged_state_file_is_moved_aside_with_one_warning(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / 'energy.json'
    path.write_bytes(content)
    core = make_core()
    state, warning = load_or_quarantine(path, core.restore)
    moved = list(tmp_path.glob('energy.json.corrupt-*'))
    assert state is None and not path.exists() and len(moved) == 1
    assert moved[0].read_bytes() == content  # kept byte for byte
    assert str(path) in warning and str(moved[0]) in warning and '\n' not in warning


def test_a_good_state_file_is_restored_and_a_missing_one_is_no_warning(tmp_path: Path) -> None:
    path = tmp_path / 'energy.json'
    assert load_or_quarantine(path, make_core().restore) == (None, '')
    saved = make_core()
    saved.energy.battery = Battery.default_test_robot(soc=0.4)
    save_state(path, saved.state_dict())
    core = make_core()
    state, warning = load_or_quarantine(path, core.restore)
    assert warning == '' and state is not None and core.battery.soc == pytest.approx(0.4)


@pytest.mark.parametrize('capacity', ['10', '1e308'])
def test_the_battery_configuration_comes_from_the_vehicle_not_the_state_file(
    tmp_path: Path, capacity: str
) -> None:
    """A state file carrying a battery configuration (the old format did) keeps its tallies only:
    capacity_Ah 10 once made the test robot's battery 449.7 Wh, 1e308 inf Wh."""
    path = tmp_path / 'energy.json'
    reference = make_core()
    reference.energy.battery = Battery.default_test_robot(soc=0.5)  # the vehicle's battery at 50 %
    state = json.loads(_state_bytes())
    assert isinstance(reference.battery, Battery)
    state['battery']['config'] = dict(reference.battery.to_dict()['config'], capacity_Ah=float(capacity))
    path.write_text(json.dumps(state))
    core = make_core()
    restored, warning = load_or_quarantine(path, core.restore)
    assert warning == '' and restored is not None
    assert core.battery.config == reference.battery.config
    assert core.battery.remaining_wh == pytest.approx(reference.battery.remaining_wh)
    assert core.energy.energy_J == {'measured': 100.0, 'predicted': 90.0}
    assert core.battery.state.drawn_J == 50.0 and core.battery.state.elapsed_s == 10.0


def test_the_state_file_keeps_tallies_only(tmp_path: Path) -> None:
    core = make_core()
    saved = core.state_dict()
    assert set(saved['battery']) == {'state'} and set(saved['battery']['state']) == {
        'soc',
        'elapsed_s',
        'drawn_J',
    }


# --- the node, over real rclpy ----------------------------------------------------------------------
# (fixture rig_factory: test/conftest.py)


def test_node_survives_an_impossible_reading_and_saves_on_a_short_run(
    rig_factory: Callable[..., Rig], tmp_path: Path
) -> None:
    """Wall clock, default 10 s save period: the run is far shorter, the file must still appear."""
    rig = rig_factory(FixedPowerPredictor(80.0), save_period_s=10.0)
    msg = JointState(name=NAMES, velocity=list(IMPOSSIBLE[0]), effort=list(IMPOSSIBLE[1]))
    rig.pub_joint.publish(msg)
    rig.spin_until(lambda: rig.node.core.implausible['joint_states'] == 1)
    count = len(rig.received['battery/state'])
    rig.spin_until(lambda: len(rig.received['battery/state']) > count + 3)  # the timer keeps running
    rig.spin_until(lambda: 'implausible' in rig.received['diagnostics'][-1].status[0].message if
                   rig.received['diagnostics'] else False)  # fmt: skip
    status = rig.received['diagnostics'][-1].status[0]
    assert status.level == bytes([1]) and rig.latest_diagnostics()['implausible_joint_states'] == '1'
    rig.stop()
    saved = json.loads((tmp_path / 'energy.json').read_text())
    assert saved['vehicle'] == 'test_robot_track' and saved['battery']['state']['soc'] == 1.0


@pytest.mark.parametrize('content', DAMAGED.values(), ids=DAMAGED.keys())
def test_node_starts_fresh_from_a_damaged_state_file(
    rig_factory: Callable[..., Rig], tmp_path: Path, capfd: pytest.CaptureFixture[str], content: bytes
) -> None:
    (tmp_path / 'energy.json').write_bytes(content)
    rig = rig_factory(FixedPowerPredictor(80.0), initial_soc=0.5)
    assert rig.node.core.battery.soc == 0.5  # fresh, as the parameters say
    moved = list(tmp_path.glob('energy.json.corrupt-*'))
    assert len(moved) == 1 and moved[0].read_bytes() == content
    rig.stop()
    err = capfd.readouterr().err
    assert err.count('unusable energy state') == 1 and str(moved[0]) in err and 'Traceback' not in err
    assert json.loads((tmp_path / 'energy.json').read_text())['vehicle'] == 'test_robot_track'


# --- the suite under `run` -----------------------------------------------------------------------
@pytest.mark.slow
def test_run_survives_an_impossible_reading_and_a_garbage_state_file(
    ros_context: Context, tmp_path: Path
) -> None:
    """``run --simulate`` for a few seconds (shorter than the 10 s save period) with a garbage state
    file, while this process publishes the impossible reading: no traceback, one warning naming the
    file, exit 0 on SIGTERM, a valid state file afterwards and the garbage kept aside."""
    import rclpy

    state = tmp_path / 'e.json'
    state.write_bytes(DAMAGED['garbage bytes'])
    command = [
        sys.executable, '-m', 'skidsteer_power.cli.main', 'run', '--simulate', '--duration', '60',
        '--speed', '0.2', '--json', '--quiet', '--map-cache', str(tmp_path), '--state-file', str(state),
    ]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    node = rclpy.create_node('impossible_probe', context=ros_context)
    publisher = node.create_publisher(JointState, 'joint_states', 10)
    msg = JointState(name=NAMES, velocity=list(IMPOSSIBLE[0]), effort=list(IMPOSSIBLE[1]))
    try:
        deadline = time.monotonic() + 90.0
        while publisher.get_subscription_count() < 2 and time.monotonic() < deadline:  # estimator + run_cli
            time.sleep(0.1)
            assert process.poll() is None, process.communicate()[1][-2000:]
        for _ in range(30):  # 3 s of impossible readings mixed into the driver's
            publisher.publish(msg)
            time.sleep(0.1)
        assert process.poll() is None  # still running
        process.send_signal(signal.SIGTERM)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
        node.destroy_node()
    assert process.returncode == 0, stderr[-2000:]
    assert 'Traceback' not in stderr and stderr.count('unusable energy state') == 1 and str(state) in stderr
    assert json.loads(stdout)['rejected_inputs'] >= 1
    assert json.loads(state.read_text())['format_version'] == 1
    assert [p.read_bytes() for p in tmp_path.glob('e.json.corrupt-*')] == [DAMAGED['garbage bytes']]
