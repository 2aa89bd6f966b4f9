"""Step 6 of a calibration (calibration/reconcile.py): the amplifier efficiency and idle power fitted
to every sample's battery power, and the block check that keeps the steady-window fit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from skidsteer_power.calibration import reconcile
from skidsteer_power.calibration.fit import Model
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

B_NM_S, C_NM = 0.4, 2.0  # the drive's viscous and Coulomb loss at the axle (this test's own numbers)


def effective_model() -> Model:
    """A Husky's geometry on grass with an effective powertrain (gear ratio 1, no copper loss) and the
    loss terms above, efficiency 1 and no idle power: a steady-window fit's result."""
    vehicle = load_vehicle('husky_a200')
    powertrain = Powertrain.from_config({'preset': 'effective', 'bus_voltage_V': 24.0}, 'wheel')
    model = Model(vehicle, load_terrain('grass'), powertrain, np.zeros(0), np.zeros(0))
    losses = {'sides_b': B_NM_S, 'sides_c': C_NM, 'copper_loss_W_per_Nm2': 1e-4}
    _, model.powertrain = model.with_values(losses)
    return model


def drive(seconds: float = 120.0, rate_hz: float = 20.0, seed: int = 3) -> reconcile.PowerSamples:
    """Samples of a drive: axle torques 2-20 N m, speeds 0-6 rad/s per side (all motoring)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    torque = rng.uniform(2.0, 20.0, (n, 2))
    omega = rng.uniform(0.0, 6.0, (n, 2))
    hold = np.full(n, 1.0 / rate_hz)
    return reconcile.PowerSamples(torque, omega, np.zeros(n), hold, np.arange(n) / rate_hz)


def by_hand(samples: reconcile.PowerSamples, eta: float, idle_W: float) -> np.ndarray:
    """The battery power of both sides by hand (drivetrain.py's module doc, every side motoring):
    P = (T w + b w^2 + c w + k_cu (T + b w + c)^2) / eta + P_idle / 2 per side [W]."""
    t, w = samples.axle_torque_Nm, samples.axle_omega_rad_s
    motor_torque = t + B_NM_S * w + C_NM
    terminal = motor_torque * w + 1e-4 * motor_torque**2
    total: np.ndarray = np.sum(terminal / eta + idle_W / 2.0, axis=1)
    return total


def test_the_efficiency_and_idle_power_of_a_drive_come_back_from_its_samples() -> None:
    model = effective_model()
    samples = drive()
    samples = dataclasses.replace(samples, measured_W=by_hand(samples, eta=0.8, idle_W=12.0))
    found = reconcile.reconcile(model, samples, allowed={'idle_power_W'})
    assert not found.kept
    assert found.names == ['amplifier_efficiency', 'idle_power_W']
    assert found.values['amplifier_efficiency'] == pytest.approx(0.8, rel=1e-6)
    assert found.values['idle_power_W'] == pytest.approx(12.0, rel=1e-6)
    assert found.all_before < -0.15  # efficiency 1 and no idle: the start predicts too little
    assert abs(found.all_after) < 1e-6


def test_without_the_idle_power_among_the_candidates_only_the_efficiency_is_fitted() -> None:
    samples = drive()
    samples = dataclasses.replace(samples, measured_W=by_hand(samples, eta=0.9, idle_W=0.0))
    found = reconcile.reconcile(effective_model(), samples, allowed=set())
    assert found.names == ['amplifier_efficiency']
    assert found.values['amplifier_efficiency'] == pytest.approx(0.9, rel=1e-6)


def test_a_fit_that_predicts_the_check_blocks_worse_keeps_the_steady_fit() -> None:
    """The start is exact in every third 10 s block; the other blocks measured twice as much (a
    drive whose first blocks were something else): the fit must not carry that into the check."""
    samples = drive()
    exact = by_hand(samples, eta=1.0, idle_W=0.0)
    checked = np.floor(samples.t_s / reconcile.BLOCK_S).astype(int) % reconcile.CHECK_EVERY == 2
    samples = dataclasses.replace(samples, measured_W=np.where(checked, exact, 2.0 * exact))
    found = reconcile.reconcile(effective_model(), samples, allowed={'idle_power_W'})
    assert found.names == []
    assert 'steady-window fit is kept' in found.kept
    assert abs(found.check_before) < 1e-9
    assert found.check_after == pytest.approx(1.0, abs=1e-3)  # efficiency 0.5: twice the check blocks


def test_too_few_samples_are_no_reconciliation() -> None:
    samples = drive(seconds=0.5)
    found = reconcile.reconcile(effective_model(), samples, allowed={'idle_power_W'})
    assert found.names == [] and 'samples' in found.kept


def test_samples_without_a_measurement_are_left_out() -> None:
    samples = drive(seconds=5.0)
    measured = by_hand(samples, eta=1.0, idle_W=0.0)
    measured[::2] = np.nan
    kept = dataclasses.replace(samples, measured_W=measured)
    assert len(kept) == len(samples) // 2
