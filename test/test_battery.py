"""Battery: two 6-cell 5000 mAh LiPo packs in series (ch. 7.1.2), OCV, resistance, coulomb counting."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.powertrain import Battery
from skidsteer_power.powertrain.motor import DES_70_10


def test_test_robot_pack_is_12s_5ah_within_des_supply_range() -> None:
    bat = Battery.default_test_robot()
    cfg = bat.config
    assert cfg.cells_in_series == 12
    assert cfg.capacity_C == pytest.approx(5.0 * 3600)  # 5000 mAh
    # full and empty open-circuit voltages stay inside the DES 70/10's 24-70 V (Appendix A)
    assert DES_70_10.min_supply_V <= cfg.ocv(0.0) and cfg.ocv(1.0) <= DES_70_10.max_supply_V
    # one 6S pack alone would be below 24 V when nearly empty: the reason for series
    assert cfg.ocv(0.0) / 2 < DES_70_10.min_supply_V


def test_remaining_energy_is_ocv_integral() -> None:
    bat = Battery.default_test_robot()
    soc = np.linspace(0, 1, 100001)
    expected = np.trapezoid(bat.config.ocv(soc), soc) * bat.config.capacity_C / 3600
    assert bat.remaining_wh == pytest.approx(expected, rel=1e-6)
    assert 200 < bat.remaining_wh < 260  # ~ 12 cells x 3.8 V x 5 Ah = 228 Wh


def test_curve_pieces_are_the_table_points_inside_the_range() -> None:
    """config/batteries/test_robot.yaml's OCV table bends at SoC 0, 0.05, 0.1, 0.2, ..., 0.9, 1."""
    cfg = Battery.default_test_robot().config
    assert cfg.pieces(0.0, 0.73).tolist() == [0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.73]
    assert cfg.pieces(0.05, 0.2).tolist() == [0.05, 0.1, 0.2]  # ends on table points: no repeats
    assert cfg.pieces(0.31, 0.32).tolist() == [0.31, 0.32]
    assert cfg.pieces(0.4, 0.4).tolist() == [0.4]


def test_constant_power_drain_empties_at_computed_time() -> None:
    bat = Battery.default_test_robot(soc=0.8)
    power = 150.0
    t_empty = bat.time_to_empty_s(power)
    dt = 10.0
    steps = 0
    while not bat.is_empty:
        bat.step(power, dt)
        steps += 1
        assert steps < 10_000
    # it empties during the step that crosses t_empty
    assert (steps - 1) * dt < t_empty <= steps * dt
    # drawn energy = P x time actually delivered
    assert bat.state.drawn_J == pytest.approx(power * t_empty, rel=1e-3)


def test_time_to_empty_hand_check_against_ideal_source() -> None:
    """With tiny resistance the time is (OCV energy) / P (energy balance)."""
    bat = Battery.from_config({'preset': 'test_robot', 'cell_resistance_ohm': 1e-9})
    assert bat.time_to_empty_s(100.0) == pytest.approx(bat.remaining_wh * 3600 / 100.0, rel=1e-6)
    # with real resistance the loss shortens it
    assert Battery.default_test_robot().time_to_empty_s(100.0) < bat.time_to_empty_s(100.0)


@pytest.mark.parametrize('soc', [1.0, 0.8, 0.37, 0.06])
@pytest.mark.parametrize('power', [5.0, 150.0, 900.0])
def test_closed_form_time_to_empty_equals_numerical_quadrature(soc: float, power: float) -> None:
    """The closed form (module doc) against scipy's adaptive quadrature of the same integral,
    t = integral_{SOC_empty}^{SOC} Q / i(P, SOC') dSOC' with i from the equivalent circuit."""
    from scipy.integrate import quad

    bat = Battery.default_test_robot(soc=soc)
    cfg = bat.config
    breaks = [p for p in cfg.soc_points if cfg.soc_empty < p < soc]
    expected, _ = quad(
        lambda s: cfg.capacity_C / bat.current_for_power(power, s),
        cfg.soc_empty,
        soc,
        points=breaks or None,
        limit=200,
        epsabs=1e-9,
        epsrel=1e-11,
    )
    assert bat.time_to_empty_s(power) == pytest.approx(expected, rel=1e-9)


def test_time_to_empty_refuses_a_power_the_pack_cannot_deliver() -> None:
    bat = Battery.default_test_robot(soc=0.5)
    v_empty = float(bat.config.ocv(bat.config.soc_empty))
    too_much = 1.01 * v_empty**2 / (4 * bat.config.resistance_ohm)  # beyond max power at empty
    with pytest.raises(InputError, match='cannot deliver'):
        bat.time_to_empty_s(too_much)


def test_regeneration_charges_but_not_above_full() -> None:
    bat = Battery.default_test_robot(soc=0.5)
    bat.step(-50.0, 60.0)
    assert bat.soc > 0.5
    full = Battery.default_test_robot(soc=1.0)
    full.step(-50.0, 60.0)
    assert full.soc == 1.0
    assert bat.time_to_empty_s(-10.0) == math.inf


def test_distance_to_empty_and_terminal_voltage() -> None:
    bat = Battery.default_test_robot()
    assert bat.distance_to_empty_m(50.0, 0.5) == pytest.approx(bat.time_to_empty_s(50.0) * 0.5)
    bat.step(200.0, 1.0)
    assert bat.state.voltage_V == pytest.approx(
        bat.state.ocv_V - bat.config.resistance_ohm * bat.state.current_A
    )
    assert bat.state.current_A * bat.state.voltage_V == pytest.approx(200.0, rel=1e-9)


def test_round_trip_through_json() -> None:
    bat = Battery.default_test_robot(soc=0.9)
    bat.step(80.0, 120.0)
    restored = Battery.from_dict(json.loads(json.dumps(bat.to_dict())))
    assert restored.soc == bat.soc
    assert restored.remaining_wh == pytest.approx(bat.remaining_wh)
    assert restored.config == bat.config


def test_bad_battery_inputs() -> None:
    with pytest.raises(ConfigError, match='state of charge'):
        Battery.default_test_robot(soc=1.5)
    with pytest.raises(ConfigError, match='ocv_curve'):
        Battery.from_config({'preset': 'test_robot', 'ocv_curve': {'soc': [0, 1], 'cell_V': [3.0]}})
    with pytest.raises(InputError, match='cannot deliver'):
        Battery.default_test_robot().current_for_power(1e6)
    with pytest.raises(InputError, match='finite'):
        Battery.default_test_robot().step(float('nan'), 1.0)
    with pytest.raises(ConfigError, match='restore'):
        Battery.from_dict({'state': {}})
