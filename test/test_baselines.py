"""The simple power models of issue 27 on synthetic data whose answer is known by hand."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numpy.typing import ArrayLike

from skidsteer_power.analysis.baselines import CmdVelConsumer, IcrRlsPower, LinearPower, Samples, energy_J


def _samples(
    speed_cmd: ArrayLike, yaw_cmd: ArrayLike, power: ArrayLike, weight: ArrayLike | None = None, **kw: Any
) -> Samples:
    speed, yaw, power_W = (np.asarray(x, dtype=float) for x in (speed_cmd, yaw_cmd, power))
    weight_s = np.ones_like(speed) if weight is None else np.asarray(weight, dtype=float)
    return Samples(weight_s, speed, yaw, power_W, **kw)


def test_linear_fit_recovers_the_coefficients_of_exact_data() -> None:
    # P = 5 |V| + 3 |yaw rate| + 2 by hand: (0.1, 0) -> 2.5 W; (-0.2, 0.1) -> 1 + 0.3 + 2 = 3.3 W;
    # (0, -0.5) -> 1.5 + 2 = 3.5 W; (0.3, 0.2) -> 1.5 + 0.6 + 2 = 4.1 W
    s = _samples([0.1, -0.2, 0.0, 0.3], [0.0, 0.1, -0.5, 0.2], [2.5, 3.3, 3.5, 4.1], weight=[1, 2, 3, 4])
    model = LinearPower().fit(s)
    assert model.coef == pytest.approx([5.0, 3.0, 2.0], abs=1e-9)
    # (0.4, 0.4): 2 + 1.2 + 2 = 5.2 W
    assert model.predict(_samples([0.4], [0.4], [0.0])) == pytest.approx([5.2], abs=1e-9)


def test_cmd_vel_consumer_is_idle_power_or_rates_times_speeds() -> None:
    # at rest 4 W held 1 s and 6 W held 3 s: idle = (4 + 18) / 4 = 5.5 W; moving P = 10 |V| + 20 |yaw|:
    # (0.2, 0) -> 2 W... below idle in the plugin's max(), but the rates are fitted on moving samples
    s = _samples(
        [0.0, 0.0, 0.2, 0.5, 0.0],
        [0.0, 0.0, 0.0, 0.1, -0.4],
        [4.0, 6.0, 2.0, 7.0, 8.0],
        weight=[1, 3, 1, 1, 1],
    )
    model = CmdVelConsumer().fit(s)
    assert model.idle_W == pytest.approx(5.5)
    assert (model.rate_speed, model.rate_yaw) == pytest.approx((10.0, 20.0), abs=1e-9)
    # (0.2, 0): max(2, 5.5) = 5.5 W; (0.5, 0.3): 5 + 6 = 11 W
    assert model.predict(_samples([0.2, 0.5], [0.0, -0.3], [0, 0])) == pytest.approx([5.5, 11.0])


def test_energy_is_power_times_hold() -> None:
    assert energy_J(np.array([2.0, 4.0]), np.array([0.5, 0.25])) == pytest.approx(2.0)


def test_icr_rls_learns_the_icrs_and_the_power_parameters_on_line() -> None:
    """A robot whose sides' ICRs lie at +-0.3 m (tread 0.4 m: they slip), two contact points per side
    at x = +-0.1 m. By hand, each side's sliding speed is |yaw| sqrt(0.1^2 + 0.1^2) = 0.1414 |yaw|
    (dy = 0.3 - 0.2 = 0.1 m), so P = 7 (|v_l| + |v_r|) + 40 x 0.2828 |yaw| + 2 W."""
    rng = np.random.default_rng(1)
    n = 3000
    v_l, v_r = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n)
    y_l, y_r = 0.3, -0.3
    yaw = (v_r - v_l) / (y_l - y_r)  # ICR kinematics
    speed = v_l + y_l * yaw  # V - v_l = y_l yaw
    power = 7.0 * (np.abs(v_l) + np.abs(v_r)) + 40.0 * 2 * np.sqrt(0.02) * np.abs(yaw) + 2.0
    s = _samples(np.zeros(n), np.zeros(n), power, 0.02 * np.ones(n), side_speed=np.column_stack([v_l, v_r]),
                 speed=speed, yaw=yaw)  # fmt: skip
    model = IcrRlsPower(tread_m=0.4, contact_x_m=np.array([0.1, -0.1]))
    predicted = model.predict(s)
    assert model.icr == pytest.approx([0.3, -0.3], abs=1e-3)
    # 60 s of samples against a 60 s memory: the early, wrong-ICR samples still weigh a little
    assert model.theta == pytest.approx([7.0, 40.0, 2.0], rel=5e-3)
    # one sample ahead: late predictions match the measurement; the first (nothing learned) is 0 W
    assert predicted[0] == 0.0
    assert predicted[-100:] == pytest.approx(power[-100:], rel=5e-3)


def test_icr_rls_without_slip_keeps_the_icrs_at_the_tread() -> None:
    rng = np.random.default_rng(2)
    n = 500
    v_l, v_r = rng.uniform(0.0, 0.3, n), rng.uniform(0.0, 0.3, n)
    yaw, speed = (v_r - v_l) / 0.5, 0.5 * (v_l + v_r)  # no slip, tread 0.5 m
    s = _samples(np.zeros(n), np.zeros(n), 3.0 * (v_l + v_r), 0.02 * np.ones(n),
                 side_speed=np.column_stack([v_l, v_r]), speed=speed, yaw=yaw)  # fmt: skip
    model = IcrRlsPower(tread_m=0.5, contact_x_m=np.linspace(-0.2, 0.2, 5))
    model.fit(s)
    assert model.icr == pytest.approx([0.25, -0.25], abs=1e-9)
    assert model.theta[0] == pytest.approx(3.0, rel=1e-3)
