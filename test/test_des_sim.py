"""The simulator's EC-45 motor model: steady states against hand calculations from Appendix B."""

from __future__ import annotations

import math

import pytest

from skidsteer_power.des.simulator import RPM, AxleLoad, MotorModel, ViscousCoulombLoad
from skidsteer_power.powertrain.motor import EC45

KT = 0.114  # Appendix B line 12: torque constant 114 mNm/A
I0 = 0.193  # Appendix B line 3: no-load current 193 mA


def run(
    model: MotorModel, seconds: float, *, setpoint_rpm: float = 0.0, current_A: float | None = None
) -> None:
    steps = round(seconds / model.STEP_S)
    for k in range(steps):
        model.step(
            model.STEP_S,
            k * model.STEP_S,
            powered=True,
            current_mode=current_A is not None,
            speed_setpoint_rad_s=setpoint_rpm * RPM,
            current_setpoint_A=current_A or 0.0,
            peak_current_A=10.0,
            acceleration_rad_s2=10_000 * RPM,
        )


def test_model_uses_the_powertrain_constants() -> None:
    assert EC45.torque_constant_Nm_A == KT
    assert MotorModel().inertia_kg_m2 > EC45.rotor_inertia_kg_m2  # rotor + reflected robot inertia


def test_default_load_at_no_load_speed_draws_the_no_load_current() -> None:
    # Coulomb part = Kt I0 by construction, so at speed the current is I0 + b w / Kt:
    # 2000 rpm = 209.44 rad/s; (0.022002 + 1e-5 * 209.44) / 0.114 = 0.21137 A.
    model = MotorModel()
    run(model, 1.5, setpoint_rpm=2000)
    assert model.omega_rad_s / RPM == pytest.approx(2000, abs=2)
    assert model.current_A == pytest.approx((KT * I0 + 1e-5 * 2000 * RPM) / KT, abs=0.005)


def test_constant_load_torque_sets_the_current() -> None:
    # Load 0.3 N m at the motor shaft, e.g. a 3.6 N m axle torque / 12:1: i = (0.3 + friction) / Kt.
    model = MotorModel(load_torque=0.3 + ViscousCoulombLoad()(1000 * RPM, 0.0))
    run(model, 1.5, setpoint_rpm=1000)
    expected = (0.3 + ViscousCoulombLoad()(1000 * RPM, 0.0)) / KT
    assert model.current_A == pytest.approx(expected, rel=0.01)


def test_callable_load_follows_speed() -> None:
    # A purely viscous load 1e-3 N m s/rad at 1500 rpm (157.08 rad/s): 0.15708 N m -> 1.3779 A.
    model = MotorModel(load_torque=lambda omega, t: 1e-3 * omega)
    run(model, 2.0, setpoint_rpm=1500)
    assert model.current_A == pytest.approx(1e-3 * 1500 * RPM / KT, rel=0.01)


def test_current_mode_accelerates_by_newton() -> None:
    # No load, 1 A for 0.1 s from rest: w = Kt i t / J.
    model = MotorModel(load_torque=0.0)
    run(model, 0.1, current_A=1.0)
    assert model.omega_rad_s == pytest.approx(KT * 1.0 * 0.1 / model.inertia_kg_m2, rel=0.01)


def test_back_emf_limits_the_speed() -> None:
    # 20 V supply: the output reaches 0.9 * 20 V = 18 V (Appendix A), so the no-load speed is about
    # 18 V * 84 rpm/V = 1512 rpm (Appendix B line 13), far below the 3000 rpm set point.
    model = MotorModel(supply_voltage_V=20.0)
    run(model, 2.0, setpoint_rpm=3000)
    assert model.omega_rad_s / RPM == pytest.approx(18.0 * 84.0, rel=0.03)
    assert model.current_limited


def coast(model: MotorModel, seconds: float) -> None:
    for k in range(round(seconds / model.STEP_S)):
        model.step(
            model.STEP_S,
            k * model.STEP_S,
            powered=False,
            current_mode=False,
            speed_setpoint_rad_s=0.0,
            current_setpoint_A=0.0,
            peak_current_A=10.0,
            acceleration_rad_s2=1e6,
        )


def test_unpowered_motor_coasts_down_by_its_friction_and_stops() -> None:
    # J dw/dt = -(c + b w) (tanh = 1 above 1 rad/s): w(t) = (w0 + c/b) exp(-b t / J) - c/b, with
    # c = Kt I0 = 0.022002 N m, b = 1e-5 N m s/rad, J = 368 g cm^2 + 15 kg (0.1 m)^2 / 12^2.
    model = MotorModel()
    c, b, inertia = KT * I0, 1e-5, 368e-7 + 15.0 * 0.1**2 / 144.0
    assert model.inertia_kg_m2 == pytest.approx(inertia)
    model.omega_rad_s = 100.0
    coast(model, 1.0)
    assert model.omega_rad_s == pytest.approx((100.0 + c / b) * math.exp(-b / inertia) - c / b, rel=0.01)
    coast(model, 5.0)  # about 4.6 s to stop from 100 rad/s
    assert model.omega_rad_s == 0.0
    assert model.current_A == 0.0


def test_axle_load_from_terramechanics_torque() -> None:
    # An axle torque of 12 N m (e.g. a map's torque_left_Nm) through 12:1 at 90 % efficiency is
    # 12 / (12 * 0.9) = 1.1111 N m at the motor, plus friction; driving backwards it still resists.
    load = AxleLoad(12.0, gear_ratio=12.0, efficiency=0.9)
    friction = ViscousCoulombLoad()
    assert load(200.0, 0.0) == pytest.approx(1.1111 + friction(200.0, 0.0), abs=1e-4)
    assert load(-200.0, 0.0) == pytest.approx(-load(200.0, 0.0))
    model = MotorModel(load_torque=load)
    run(model, 2.0, setpoint_rpm=1000)
    assert model.current_A == pytest.approx(load(model.omega_rad_s, 0.0) / KT, rel=0.01)
