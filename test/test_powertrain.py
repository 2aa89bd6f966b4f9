"""Powertrain: EC-45 constants (Appendix B), internal resistance (eqs. 7.1-7.4, Table 7.1), the
4-quadrant motor/amplifier power and the least-squares fit of ch. 7.2."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.powertrain import EC45, GEAR_RATIO, Powertrain, fit_internal
from skidsteer_power.powertrain.internal import components_from_stages
from skidsteer_power.powertrain.motor import DES_70_10, bus_power, terminal_power


def test_ec45_constants_in_si() -> None:
    # Appendix B: Kt 114 mNm/A, R 0.710 ohm, speed constant 84.0 rpm/V, no-load current 193 mA.
    assert EC45.torque_constant_Nm_A == pytest.approx(0.114)
    assert EC45.terminal_resistance_ohm == pytest.approx(0.710)
    assert EC45.speed_constant_rad_s_V == pytest.approx(84.0 * 2 * math.pi / 60)
    assert EC45.no_load_current_A == pytest.approx(0.193)
    # Consistency of the datasheet: back-EMF constant 1/Kn ~= Kt (SI motors: Ke = Kt), and the
    # starting current is nominal voltage / terminal resistance (48 / 0.710 = 67.6 A, line 8).
    assert EC45.back_emf_constant_V_s == pytest.approx(EC45.torque_constant_Nm_A, rel=0.01)
    assert EC45.nominal_voltage_V / EC45.terminal_resistance_ohm == pytest.approx(
        EC45.starting_current_A, rel=0.01
    )
    assert pytest.approx(4.8 * 2.5) == GEAR_RATIO  # ch. 7.1.1


def test_table_7_1_is_read_as_eq_7_1_torques_at_the_motor_shaft() -> None:
    """Table 7.1 read literally as eq. 7.1's b [N m s/rad] and c [N m] (see internal.py docstring)."""
    pt = Powertrain.default_test_robot('wheel')
    motor = pt.left.components['motor']
    omega = EC45.no_load_speed_rad_s
    # hand calculation: 0.0617 N m + 0.0001 N m s/rad * 419.9 rad/s = 0.1037 N m
    assert motor.torque(omega) == pytest.approx(0.0617 + 0.0001 * 4010 * 2 * math.pi / 60, rel=1e-9)
    # recorded conflict with Appendix B: that torque needs more current than the no-load 193 mA
    assert motor.torque(omega) / EC45.torque_constant_Nm_A > EC45.no_load_current_A


def test_current_reading_of_table_7_1_stays_available() -> None:
    """The alternative reading (motor currents, converted with K_t) is a data-only change."""
    from skidsteer_power.powertrain.internal import side_from_config

    entries = {
        'motor': {'viscous_A_s': 0.0001, 'coulomb_A': 0.0617},  # Table 7.1, left drivetrain
        'gear_train': {'viscous_A_s': 0.00008, 'coulomb_A': 0.0177},
        'roller_chain': {'viscous_A_s': 0.0001, 'coulomb_A': 0.0448},
    }
    side = side_from_config(entries, EC45.torque_constant_Nm_A, 'wheel')
    # hand calculation: K_t * (0.0617 A + 0.0001 A s/rad * 419.9 rad/s) = 0.114 * 0.1037 A
    expected = EC45.torque_constant_Nm_A * (0.0617 + 0.0001 * EC45.no_load_speed_rad_s)
    assert side.components['motor'].torque(EC45.no_load_speed_rad_s) == pytest.approx(expected)


def test_track_has_more_internal_resistance_than_wheels() -> None:
    # ch. 7.2.3: "the track configuration has a much larger internal resistance ... than the wheel"
    track = Powertrain.default_test_robot('track')
    wheel = Powertrain.default_test_robot('wheel')
    assert set(track.left.components) == {'motor', 'gear_train', 'roller_chain', 'track'}
    assert 'track' not in wheel.left.components
    omega_axle = 500 * 2 * math.pi / 60 / GEAR_RATIO  # Figure 7.14's 500 rpm motor speed
    assert track.internal_torque('left', omega_axle) > 3 * wheel.internal_torque('left', omega_axle)
    # Figure 7.14: the track dominates the internal power loss
    parts = track.left.component_power(500 * 2 * math.pi / 60)
    assert max(parts, key=lambda k: float(parts[k])) == 'track'


def test_internal_torque_hand_calculation_and_sign() -> None:
    pt = Powertrain.default_test_robot('track')
    b = 0.0001 + 0.00008 + 0.0001 + 0.00012  # Table 7.1, left column 1 [N m s/rad at the motor]
    c = 0.0617 + 0.0177 + 0.0448 + 0.6489  # Table 7.1, left column 2 [N m at the motor]
    w = 2.0  # axle rad/s -> motor 24 rad/s
    expected = 12 * (b * 24 + c)
    assert pt.internal_torque('left', w) == pytest.approx(expected)
    assert pt.internal_torque('left', -w) == pytest.approx(-expected)  # resists both directions
    assert pt.internal_torque('left', 0.0) == 0.0
    assert pt.internal_torque('right', w) != pytest.approx(expected)  # Motor 2 differs (Table 7.1)


def test_motor_side_power_balance() -> None:
    pt = Powertrain.default_test_robot('track')
    torque = np.array([0.0, 2.0, 5.0])
    omega = np.array([1.0, 2.0, 3.0])
    mp = pt.motor_side('right', torque, omega)
    np.testing.assert_allclose(mp.mechanical_power_W, mp.terrain_power_W + mp.internal_power_W, rtol=1e-12)
    copper = EC45.terminal_resistance_ohm * mp.current_A**2
    np.testing.assert_allclose(mp.terminal_power_W, mp.mechanical_power_W + copper, rtol=1e-12)
    np.testing.assert_allclose(mp.electrical_power_W, mp.terminal_power_W / DES_70_10.efficiency)
    np.testing.assert_allclose(mp.current_A * EC45.torque_constant_Nm_A, mp.motor_torque_Nm)
    np.testing.assert_allclose(mp.motor_omega_rad_s, 12 * omega)


def test_motor_side_on_floats_is_motor_side_on_arrays() -> None:
    """Floats in, floats out (the estimator's per-message path, skidsteer_power.numeric), with the
    same numbers to the last bit as the array path: one formula, two types. Table 7.1's two sides
    differ (Motor 2), and the points cover braking (generating), standstill and reverse, so both
    branches of the amplifier and of the Coulomb sign are taken."""
    pt = Powertrain.default_test_robot('track')
    torque = np.array([4.0, -2.5, 0.0, 1.0, -3.0, -0.0, 0.0])
    omega = np.array([1.5, 2.0, -0.5, 0.0, -1.0, -0.0, -0.0])
    for side in ('left', 'right'):
        batch = pt.motor_side(side, torque, omega)
        for i in range(torque.size):
            one = pt.motor_side(side, float(torque[i]), float(omega[i]))
            for field in dataclasses.fields(one):
                value = getattr(one, field.name)
                assert type(value) is float, field.name
                array_value = getattr(batch, field.name)[i]
                assert value == array_value and np.signbit(value) == np.signbit(array_value), (side, i)
    assert pt.right.total != pt.left.total


def test_regeneration_never_creates_energy() -> None:
    """4-quadrant operation: braking returns at most the braking power, less losses."""
    pt = Powertrain.default_test_robot('wheel')
    omega = np.linspace(0.5, 8.0, 40)
    braking_torque = -np.linspace(0.5, 30.0, 40)
    mp = pt.motor_side('left', braking_torque[:, None], omega[None, :])
    braking_power = -(braking_torque[:, None] * omega[None, :])  # > 0, power the terrain pushes in
    returned = -mp.electrical_power_W
    assert np.all(returned < braking_power)
    assert np.any(returned > 0)  # and it does regenerate somewhere
    no_regen = Powertrain.from_config({'preset': 'test_robot', 'regen_efficiency': 0.0}, 'wheel')
    assert np.all(no_regen.motor_side('left', braking_torque, omega).electrical_power_W >= 0)


def test_bus_power_quadrants() -> None:
    p = bus_power(np.array([100.0, -100.0]), DES_70_10)
    np.testing.assert_allclose(p, [100 / 0.92, -92.0])
    assert terminal_power(EC45, 0.114, 0.0) == pytest.approx(0.710)  # 1 A at stall: R i^2


def test_axle_from_motor_inverts_motor_side() -> None:
    pt = Powertrain.default_test_robot('track')
    mp = pt.motor_side('left', 3.0, 1.5)
    torque, omega = pt.axle_from_motor('left', mp.motor_torque_Nm, mp.motor_omega_rad_s)
    assert torque == pytest.approx(3.0)
    assert omega == pytest.approx(1.5)


def test_fit_recovers_coefficients_from_noisy_no_load_runs() -> None:
    rng = np.random.default_rng(7)
    omega = np.r_[np.linspace(-400, -20, 30), np.linspace(20, 400, 30)]
    b_true, c_true = 1.1e-5, 7.0e-3
    torque = b_true * omega + c_true * np.sign(omega) + rng.normal(0, 2e-4, omega.size)
    fit = fit_internal(np.r_[omega, 0.0], np.r_[torque, 0.0])
    assert fit.n_samples == 60  # the omega = 0 sample is dropped
    assert fit.viscous_Nm_s == pytest.approx(b_true, rel=0.05)
    assert fit.coulomb_Nm == pytest.approx(c_true, rel=0.02)
    assert fit.rms_residual_Nm == pytest.approx(2e-4, rel=0.3)


def test_components_from_cumulative_stages() -> None:
    omega = np.linspace(10, 300, 20)
    stages = {}
    cumulative_b, cumulative_c = 0.0, 0.0
    for name, (b, c) in {'motor': (1e-5, 0.007), 'gear_train': (1e-5, 0.002), 'track': (2e-5, 0.07)}.items():
        cumulative_b += b
        cumulative_c += c
        stages[name] = fit_internal(omega, cumulative_b * omega + cumulative_c)
    parts = components_from_stages(stages)
    assert parts['gear_train'].coulomb_Nm == pytest.approx(0.002, abs=1e-12)
    assert parts['track'].viscous_Nm_s == pytest.approx(2e-5, abs=1e-15)


def test_fit_rejects_degenerate_input() -> None:
    with pytest.raises(InputError, match='two or more distinct speeds'):
        fit_internal([100.0, 100.0], [0.01, 0.01])
    with pytest.raises(InputError, match='NaN'):
        fit_internal([1.0, np.nan], [0.01, 0.02])
    with pytest.raises(InputError, match='differ'):
        fit_internal([1.0, 2.0], [0.01])


def test_bad_config_errors() -> None:
    with pytest.raises(ConfigError, match=r'no such file or shipped powertrain \(shipped: .*test_robot'):
        Powertrain.from_config({'preset': 'no_such_robot'})
    with pytest.raises(ConfigError, match='gear_ratio'):
        Powertrain.from_config({'preset': 'test_robot', 'gear_ratio': -1})
    with pytest.raises(ConfigError, match='running_gear'):
        Powertrain.from_config({'preset': 'test_robot'}, running_gear='legs')
    with pytest.raises(ConfigError, match='left and right'):
        Powertrain.from_config({'preset': 'test_robot', 'internal_resistance': {'left': {}}})
    with pytest.raises(InputError, match='side'):
        Powertrain.default_test_robot().internal_torque('middle', 1.0)


# --------------------------------------------------------------------------- motor presets


def test_motor_presets_and_overrides_from_the_powertrain_file() -> None:
    from skidsteer_power.powertrain.motor import MOTORS, motor_from_config

    assert Powertrain.default_test_robot().motor is EC45 is MOTORS['EC45'] is motor_from_config('EC45')
    # A mapping replaces the named fields of its preset and keeps the rest (Appendix B for EC-45).
    doubled = Powertrain.from_config(
        {'preset': 'test_robot', 'motor': {'preset': 'EC45', 'torque_constant_Nm_A': 0.228}}
    )
    assert doubled.motor.torque_constant_Nm_A == 0.228
    assert doubled.motor.terminal_resistance_ohm == EC45.terminal_resistance_ohm == 0.710
    # Kt enters eq. 7.1's current: the same axle load draws half the current (0.114 / 0.228).
    base = Powertrain.default_test_robot().motor_side('left', 2.0, 10.0)
    assert doubled.motor_side('left', 2.0, 10.0).current_A == pytest.approx(base.current_A / 2.0)
    # A full motor without a preset: every field, SI units.
    full = {f.name: getattr(EC45, f.name) for f in dataclasses.fields(EC45)}
    assert motor_from_config({**full, 'name': 'copy'}) == dataclasses.replace(EC45, name='copy')


@pytest.mark.parametrize(
    'motor, message',
    [
        ('EC46', "unknown motor 'EC46'"),
        ({'preset': 'EC45', 'torque_constant': 0.1}, 'unknown motor fields'),
        ({'preset': 'EC45', 'torque_constant_Nm_A': 0.0}, 'must be a number > 0'),
        ({'preset': 'EC45', 'torque_constant_Nm_A': '0.1'}, 'must be a number > 0'),
        ({'torque_constant_Nm_A': 0.1}, 'without a preset needs'),
        (3, 'preset name or a mapping'),
    ],
)
def test_bad_motor_entries_are_one_config_error(motor: object, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Powertrain.from_config({'preset': 'test_robot', 'motor': motor})
