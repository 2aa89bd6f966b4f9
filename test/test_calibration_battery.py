"""Battery-side (V x I) calibration of a real driver's loss terms (issue 35): Coulomb loss per side,
the copper-loss coefficient k_cu (k_cu T^2 = R i^2) and the electronics' idle power, from an effective
powertrain's neutral start. The recordings are made by the same model with known terms (a recovery
test: the truth is the test's own numbers), so the fit must find them inside their ranges and its
95 % intervals must hold them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidsteer_power.calibration import calibrate
from skidsteer_power.calibration.fit import auto_fit_names, motor_points
from skidsteer_power.calibration.segments import SteadyWindow
from skidsteer_power.models.predict import CommandPredictor
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle

VEHICLE = load_vehicle('husky_a200')
ASPHALT = load_terrain('asphalt')
TRUTH = {'left_c': 0.8, 'right_c': 1.1, 'copper_loss_W_per_Nm2': 0.05, 'idle_power_W': 20.0}
NAN2 = (math.nan, math.nan)


def _effective(**terms: float) -> Powertrain:
    side = {'left': terms.get('left_c', 0.0), 'right': terms.get('right_c', 0.0)}
    return Powertrain.from_config(
        {
            'preset': 'effective',
            'bus_voltage_V': 24.0,
            'idle_power_W': terms.get('idle_power_W', 0.0),
            'copper_loss_W_per_Nm2': terms.get('copper_loss_W_per_Nm2', 0.0),
            'internal_resistance': {
                s: {'lumped': {'viscous_Nm_s': 0.0, 'coulomb_Nm': c}} for s, c in side.items()
            },
        },
        'wheel',
    )


def _segments(powertrain: Powertrain, noise_W: float = 0.0) -> list[SteadyWindow]:
    """Steady holds over the Husky's envelope (straight at three speeds, gentle and tight turns, spot
    turns), each with the battery-side power per side that ``powertrain`` draws there, plus seeded
    normal noise of ``noise_W`` [W] (a window mean's scatter)."""
    v = np.array([0.2, 0.5, 0.8, 0.2, 0.5, 0.3, 0.3, 0.0, 0.0, 0.6, 0.1])
    w = np.array([0.0, 0.0, 0.0, 0.3, -0.3, 0.8, -0.8, 0.5, -1.0, 0.2, 0.6])
    pred = CommandPredictor(VEHICLE, ASPHALT, powertrain).predict(v, w)
    _, _, power = motor_points(powertrain, pred.torque, pred.setpoint)
    power = power + np.random.default_rng(7).normal(0.0, noise_W, power.shape)
    return [
        SteadyWindow(
            source='synthetic',
            start_s=10.0 * k,
            duration_s=5.0,
            command=(float(v[k]), float(w[k])),
            speed_m_s=math.nan,
            yaw_rate_rad_s=math.nan,
            motion_source='command',
            samples=50,
            motor_torque_Nm=NAN2,
            motor_omega_rad_s=NAN2,
            torque_std_Nm=NAN2,
            battery_W=(float(power[k, 0]), float(power[k, 1])),
        )
        for k in range(len(v))
    ]


def test_auto_names_the_battery_side_terms_only_where_battery_power_is_measured() -> None:
    segments = _segments(_effective(**TRUTH))
    names, fixed = auto_fit_names(segments, ASPHALT)
    assert {'idle_power_W', 'copper_loss_W_per_Nm2', 'left_c', 'right_c'} <= set(names)
    torque_only = [
        s.__class__(**{**s.__dict__, 'battery_W': NAN2, 'motor_torque_Nm': (1.0, 1.0)}) for s in segments
    ]
    names, fixed = auto_fit_names(torque_only, ASPHALT)
    assert (
        'copper_loss_W_per_Nm2' not in names
        and 'motor current cannot see it' in fixed['copper_loss_W_per_Nm2']
    )


def test_coulomb_copper_and_idle_terms_are_recovered_inside_their_ranges() -> None:
    """From the neutral effective start (every loss 0: the linear pre-fit gives the fit a start),
    noise-free: the truth to 0.1 %; with 0.5 W of noise: fitted, inside the 95 % intervals."""
    exact = calibrate(
        VEHICLE, ASPHALT, _effective(), _segments(_effective(**TRUTH)), list(TRUTH), holdout=0.0
    )
    for name, truth in TRUTH.items():
        assert exact.status(name) == 'fitted', (name, exact.status(name))
        assert exact.values[name] == pytest.approx(truth, rel=1e-3), name
    assert exact.powertrain.copper_loss_W_per_Nm2 == pytest.approx(TRUTH['copper_loss_W_per_Nm2'], rel=1e-3)
    assert any('linear least-squares estimate' in w for w in exact.correlations_warnings)
    noisy = calibrate(
        VEHICLE, ASPHALT, _effective(), _segments(_effective(**TRUTH), noise_W=0.5), list(TRUTH), holdout=0.0
    )
    for name, truth in TRUTH.items():
        assert noisy.status(name) == 'fitted', (name, noisy.status(name))
        lo, hi = noisy.ci95[name] or (math.nan, math.nan)
        assert lo <= truth <= hi, (name, lo, noisy.values[name], hi)
