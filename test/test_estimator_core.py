"""Pure estimator core: input checks, measured power, energy integration, persistence, diagnostics.

No ROS here. The energy tests use a predictor with a fixed battery power so the integral has a closed
form; the real FESS map is exercised in test_estimator_map.py.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import pytest

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator import (
    EnergyTracker,
    Freshness,
    InputLimits,
    RejectCounter,
    measure_motor_power,
)
from skidsteer_power.estimator.core import EstimatorCore, EstimatorSettings, RejectedInput
from skidsteer_power.estimator.inputs import TEST_ROBOT_JOINTS, JointReader, check_command, check_joint_state
from skidsteer_power.estimator.persistence import load_state, save_state
from skidsteer_power.estimator.prediction import Prediction
from skidsteer_power.estimator.summary import SUMMARY_FIELDS, summary_dict, summary_values
from skidsteer_power.powertrain import EC45, Battery, Powertrain

LIMITS = InputLimits()


class FixedPowerPredictor:
    """Predicts a fixed battery power (split evenly) for any command: a closed-form energy source."""

    description = 'fixed power'

    def __init__(self, battery_W: float, traction_margin: float = 0.5) -> None:
        self.battery_W = battery_W
        self.traction_margin = traction_margin

    def predict(self, speed_m_s: float, yaw_rate_rad_s: float) -> Prediction:
        half = self.battery_W / 2
        pair = (half, half)
        return Prediction(
            speed_m_s,
            yaw_rate_rad_s,
            (1.0, 1.0),
            (1.0, 1.0),
            pair,
            (0.0, 0.0),
            (12.0, 12.0),
            (0.1, 0.1),
            (0.9, 0.9),
            pair,
            pair,
            self.traction_margin,
            False,
        )


def make_core(battery_W: float = 100.0, **settings: Any) -> EstimatorCore:
    return EstimatorCore(
        FixedPowerPredictor(battery_W),
        Battery.default_test_robot(),
        Powertrain.default_test_robot(),
        EstimatorSettings(**settings),
    )


# --- input checks -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('speed', 'yaw', 'match'),
    [
        (math.nan, 0.0, 'linear.x is NaN'),
        (0.1, math.inf, 'angular.z is infinite'),
        (-math.inf, 0.0, 'linear.x is infinite'),
        (50.0, 0.0, 'exceeds the plausible limit'),
        (0.1, -1e6, 'angular.z = -1e\\+06 rad/s exceeds'),
    ],
)
def test_bad_command_is_rejected_with_its_reason(speed: float, yaw: float, match: str) -> None:
    with pytest.raises(InputError, match=match):
        check_command(speed, yaw, LIMITS)


@pytest.mark.parametrize(('speed', 'yaw'), [(0.2, 0.0), (-0.2, 0.1), (0.0, 0.35), (0.0, 0.0)])
def test_plausible_commands_pass_unchanged(speed: float, yaw: float) -> None:
    """Reverse (V < 0) and spinning in place (V = 0, r != 0) are valid commands."""
    assert check_command(speed, yaw, LIMITS) == (speed, yaw)


@pytest.mark.parametrize(
    ('names', 'velocity', 'effort', 'match'),
    [
        (['left_motor'], [1.0], [0.1], 'lacks right_motor'),
        (['left_motor', 'right_motor'], [1.0], [0.1, 0.1], 'no velocity for right_motor'),
        (['left_motor', 'right_motor'], [1.0, 2.0], [math.nan, 0.1], 'left_motor effort is NaN'),
        (['left_motor', 'right_motor'], [1.0, -math.inf], [0.1, 0.1], 'right_motor velocity is infinite'),
        (['left_motor', 'right_motor'], [1.0, 5000.0], [0.1, 0.1], 'right_motor velocity = 5000'),
        (['left_motor', 'right_motor'], [1.0, 1.0], [0.1, 80.0], 'right_motor effort = 80'),
        # finite but huge (issue 28): the old test sum(out) - sum(out) overflowed to inf - inf
        (['left_motor', 'right_motor'], [1.0, 1.0], [9e307, 9e307], 'left_motor effort = 9e\\+307'),
        (['left_motor', 'right_motor'], [1e308, 1e308], [0.1, 0.1], 'left_motor velocity = 1e\\+308'),
    ],
)
def test_bad_joint_state_is_rejected_with_its_reason(
    names: list[str], velocity: list[float], effort: list[float], match: str
) -> None:
    with pytest.raises(InputError, match=match):
        check_joint_state(names, velocity, effort, LIMITS)


def test_joint_state_is_read_by_name_not_position() -> None:
    omega, torque = check_joint_state(
        ['right_motor', 'x', 'left_motor'], [2.0, 9.0, 1.0], [0.2, 0.0, 0.1], LIMITS
    )
    assert omega == (1.0, 2.0) and torque == (0.1, 0.2)


def test_one_reader_follows_the_joint_names_of_every_message() -> None:
    """The reader keeps where the joints were while the names stay the same; a message with another
    order, or without a joint, is read by its own names."""
    reader = JointReader(TEST_ROBOT_JOINTS, 1.0, 1.0, LIMITS)
    assert reader.read(('left_motor', 'right_motor'), (), [1.0, 2.0], [0.1, 0.2], 0.0) == (
        (1.0, 2.0),
        (0.1, 0.2),
    )
    names = ['right_motor', 'left_motor']
    assert reader.read(names, (), [1.0, 2.0], [0.1, 0.2], 0.0) == ((2.0, 1.0), (0.2, 0.1))
    names[:] = ['left_motor', 'right_motor']  # the same list, changed by its owner
    assert reader.read(names, (), [1.0, 2.0], [0.1, 0.2], 0.0) == ((1.0, 2.0), (0.1, 0.2))
    with pytest.raises(InputError, match='lacks right_motor'):
        reader.read(['left_motor', 'x'], (), [1.0, 2.0], [0.1, 0.2], 0.0)
    assert reader.read(['x', 'right_motor', 'left_motor'], (), [9, 2.0, 1.0], [0, 0.2, 0.1], 0.0) == (
        (1.0, 2.0),
        (0.1, 0.2),
    )


def test_limits_must_be_positive() -> None:
    with pytest.raises(InputError, match='max_speed_m_s'):
        InputLimits(max_speed_m_s=0.0)


def test_reject_counter_counts_every_rejection_but_warns_once_per_period() -> None:
    counter = RejectCounter(period_s=2.0)
    warned = [counter.reject('cmd_vel', t) for t in (0.0, 0.5, 1.9, 2.0, 2.1)]
    assert warned == [True, False, False, True, False]
    assert counter.counts['cmd_vel'] == 5
    assert counter.reject('joint_states', 0.1) is True  # topics are throttled separately


def test_freshness() -> None:
    fresh = Freshness(timeout_s=0.5)
    assert not fresh.is_fresh(0.0) and fresh.age_s(0.0) == math.inf
    fresh.mark(1.0)
    assert fresh.is_fresh(1.5) and not fresh.is_fresh(1.51)


# --- measured power -----------------------------------------------------------------------------
def test_measured_power_by_hand() -> None:
    """EC-45 (Appendix B): Kt = 0.114 N m/A, R = 0.710 ohm; DES 70/10 efficiency 0.92 (Appendix A).

    Left motoring: omega 300 rad/s, Kt I = 0.228 N m -> I = 2 A, Kt I omega = 68.4 W,
    terminal = 68.4 + 0.71 * 2^2 = 71.24 W, bus = 71.24 / 0.92 = 77.4348 W.
    Right braking: omega 300, Kt I = -0.114 -> I = -1 A, Kt I omega = -34.2 W,
    terminal = -34.2 + 0.71 = -33.49 W, bus = -33.49 * 0.92 = -30.8108 W (4-quadrant regeneration).
    """
    m = measure_motor_power((300.0, 300.0), (0.228, -0.114), EC45)
    assert m.current_A == pytest.approx((2.0, -1.0))
    assert m.mechanical_W == pytest.approx((68.4, -34.2))
    assert m.electrical_W == pytest.approx((71.24, -33.49))
    assert m.bus_W == pytest.approx((71.24 / 0.92, -33.49 * 0.92))
    assert m.bus_total_W == pytest.approx(77.43478 - 30.8108, rel=1e-5)


# --- energy integration -------------------------------------------------------------------------
def test_constant_measured_power_drains_the_analytic_energy() -> None:
    """100 W at the bus for 10 s is 1000 J at the terminals. The battery's open-circuit energy falls by
    that plus its I^2 R loss: I = 2P / (V + sqrt(V^2 - 4RP)) with V = 12 x 4.20 V = 50.4 V (full 12S
    LiPo, config/batteries/test_robot.yaml) and R = 12 x 4 mOhm = 0.048 ohm gives I = 1.98789 A, so the
    loss is I^2 R t = 1.8968 J. Since P = V_ocv I - I^2 R, the open-circuit energy falls by exactly
    P t + I^2 R t = 1001.897 J = 0.278305 Wh (the current rises by < 3e-4 as the OCV falls over the
    0.11 % of charge used, which changes the loss term only).
    """
    battery = Battery.default_test_robot()
    start_wh = battery.remaining_wh
    tracker = EnergyTracker(battery, measured_timeout_s=0.5)
    for k in range(1000):  # 100 Hz for 10 s
        tracker.set_measured(100.0, k * 0.01)
    tracker.advance(10.0)
    tracker.flush()
    assert tracker.energy_J['measured'] == pytest.approx(1000.0, rel=1e-12)
    assert battery.state.drawn_J == pytest.approx(1000.0, rel=1e-9)
    v, r, p = 50.4, 0.048, 100.0
    current = 2 * p / (v + math.sqrt(v * v - 4 * r * p))
    assert current == pytest.approx(1.98789, rel=1e-5)
    assert start_wh - battery.remaining_wh == pytest.approx((1000.0 + current**2 * r * 10.0) / 3600, rel=1e-4)


def test_sources_switch_when_measured_data_stops() -> None:
    """Measured 50 W at 10 Hz until t = 1.9 s, predicted 80 W at 10 Hz until 4.9 s, timeouts 0.5 s:
    measured covers [0, 2.4] -> 120 J; predicted covers [2.4, 5.4] -> 240 J; nothing after 5.4 s."""
    tracker = EnergyTracker(Battery.default_test_robot(), measured_timeout_s=0.5, predicted_timeout_s=0.5)
    for k in range(50):
        t = k * 0.1
        tracker.set_predicted(80.0, t)
        if k < 20:
            tracker.set_measured(50.0, t)
    assert [tracker.source(t) for t in (1.0, 3.0, 5.8)] == ['measured', 'predicted', 'none']
    for t in (2.0, 2.5, 3.7, 6.0):  # timer calls at arbitrary times must not change the result
        tracker.advance(t)
    assert tracker.energy_J['measured'] == pytest.approx(120.0)
    assert tracker.energy_J['predicted'] == pytest.approx(240.0)


def test_time_to_empty_is_inf_at_rest_and_finite_under_load() -> None:
    tracker = EnergyTracker(Battery.default_test_robot(), filter_s=0.0)
    tracker.advance(0.0)
    assert tracker.time_to_empty_s() == math.inf
    tracker.set_measured(200.0, 0.0)
    tracker.advance(0.1)
    # 12S 5 Ah LiPo holds about 5 Ah x 45 V ~ 225 Wh -> roughly 4000 s at 200 W
    assert 3000 < tracker.time_to_empty_s() < 5000


# --- core ---------------------------------------------------------------------------------------
def test_core_rejects_and_counts_bad_inputs() -> None:
    core = make_core(warn_period_s=10.0)
    with pytest.raises(RejectedInput) as first:
        core.on_command(math.nan, 0.0, 0.0)
    with pytest.raises(RejectedInput) as second:
        core.on_command(0.1, math.inf, 0.1)
    with pytest.raises(RejectedInput, match='joint_states: left_motor velocity'):
        core.on_joint_state(['left_motor', 'right_motor'], [1e9, 0.0], [0.0, 0.0], 0.2)
    with pytest.raises(RejectedInput, match='effort = 9e\\+307'):  # finite, huge: counted, no crash
        core.on_joint_state(['left_motor', 'right_motor'], [1.0, 1.0], [9e307, 9e307], 0.2)
    assert first.value.warn and not second.value.warn
    level, _, values = core.diagnostics(0.3)
    assert values['rejected_cmd_vel'] == '2' and values['rejected_joint_states'] == '2'
    assert core.prediction is None and level == 1  # nothing accepted: both inputs stale


def test_core_names_the_energy_source_and_stale_inputs() -> None:
    core = make_core(battery_W=60.0)
    core.on_command(0.2, 0.0, 0.0)
    assert core.diagnostics(0.1)[2]['energy_source'] == 'predicted'
    core.on_joint_state(['left_motor', 'right_motor'], [240.0, 240.0], [0.2, 0.2], 0.2)
    level, message, values = core.diagnostics(0.3)
    assert values['energy_source'] == 'measured' and values['cmd_vel_stale'] == 'false'
    assert level == 0 and 'measured' in message
    level, message, values = core.diagnostics(5.0)
    assert (
        values['energy_source'] == 'none' and 'cmd_vel stale' in message and 'joint_states stale' in message
    )


def test_prediction_error_is_measured_minus_predicted() -> None:
    core = make_core(battery_W=60.0)
    core.on_command(0.2, 0.0, 0.0)
    comparison = core.on_joint_state(['left_motor', 'right_motor'], [240.0, 240.0], [0.2, 0.3], 0.01)
    assert comparison is not None
    # FixedPowerPredictor: motor torque 0.1 N m, terminal power 30 W per side
    assert comparison.torque_error_Nm == pytest.approx((0.1, 0.2))
    assert comparison.power_error_W[0] == pytest.approx(comparison.measured.electrical_W[0] - 30.0)


def test_traction_warning_follows_the_margin() -> None:
    core = EstimatorCore(
        FixedPowerPredictor(50.0, traction_margin=0.05),
        Battery.default_test_robot(),
        Powertrain.default_test_robot(),
        EstimatorSettings(traction_warning_margin=0.1),
    )
    core.on_command(0.2, 0.3, 0.0)
    assert core.traction_warning()
    assert 'get stuck' in core.diagnostics(0.1)[1]


def test_summary_has_every_field_in_order() -> None:
    core = make_core()
    core.on_command(0.1, 0.0, 0.0)
    values = summary_values(core, 0.0)
    named = summary_dict(core, 0.0)
    assert len(values) == len(SUMMARY_FIELDS)
    assert named['predicted_battery_W'] == pytest.approx(100.0)
    assert math.isnan(named['measured_left_W'])  # no joint_states yet
    assert named['energy_source'] == 1.0  # predicted


def test_settings_are_validated() -> None:
    with pytest.raises(ConfigError, match='cmd_timeout_s'):
        EstimatorSettings(cmd_timeout_s=-1.0)


# --- persistence --------------------------------------------------------------------------------
def test_state_round_trips_through_a_file(tmp_path: Path) -> None:
    core = make_core(battery_W=150.0)
    for k in range(100):
        core.on_command(0.2, 0.0, k * 0.1)
    core.tick(10.0)
    path = tmp_path / 'sub' / 'energy.json'
    save_state(path, core.state_dict())
    restored = make_core()
    state = load_state(path)
    assert state is not None
    restored.restore(state)
    assert restored.battery.remaining_wh == pytest.approx(core.battery.remaining_wh, rel=1e-12)
    assert restored.battery.remaining_wh < Battery.default_test_robot().remaining_wh
    assert restored.energy.energy_J['predicted'] == pytest.approx(150.0 * 10.0)
    assert [p.name for p in path.parent.iterdir()] == ['energy.json']  # no temporary file left


def test_failed_write_leaves_the_old_state(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / 'energy.json'
    save_state(path, {'x': 1})

    def broken_fsync(fd: int) -> None:
        raise OSError(5, 'disk gone')

    monkeypatch.setattr(os, 'fsync', broken_fsync)
    with pytest.raises(OSError, match='disk gone'):
        save_state(path, {'x': 2})
    state = load_state(path)
    assert state is not None and state['x'] == 1
    assert [p.name for p in tmp_path.iterdir()] == ['energy.json']


def test_missing_state_is_none_and_bad_state_is_a_config_error(tmp_path: Path) -> None:
    assert load_state(tmp_path / 'none.json') is None
    (tmp_path / 'torn.json').write_text('{"format_version": 1, "batt')
    with pytest.raises(ConfigError, match='not valid JSON'):
        load_state(tmp_path / 'torn.json')
    (tmp_path / 'other.json').write_text(json.dumps({'format_version': 99}))
    with pytest.raises(ConfigError, match='unknown format'):
        load_state(tmp_path / 'other.json')
    core = make_core()
    with pytest.raises(ConfigError, match='does not fit'):
        core.restore({'format_version': 1, 'battery': {}})
