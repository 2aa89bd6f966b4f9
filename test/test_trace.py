"""Circle fit of a trace (eqs. 7.8-7.10) and mean speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidsteer_power.analysis.trace import CircleFit, fit_circle, mean_speed
from skidsteer_power.errors import InputError


def circle_points(
    cx: float, cy: float, r: float, start: float, stop: float, n: int
) -> tuple[np.ndarray, np.ndarray]:
    angles = np.linspace(start, stop, n)
    return cx + r * np.cos(angles), cy + r * np.sin(angles)


@pytest.mark.parametrize(
    ('cx', 'cy', 'r', 'arc'),
    [
        (0.0, 0.0, 1.0, 2 * math.pi),  # full unit circle at the origin
        (3.0, -2.0, 1.83, 1.0),  # the text's example radius 1.83 m (Figure 7.35), a 1 rad arc
        (1000.0, 2000.0, 0.3, math.pi / 2),  # far from the origin: conditioning of the design matrix
        (-0.5, 0.25, 50.0, 0.05),  # nearly straight: 2.5 m of a 50 m circle
    ],
)
def test_exact_circle_is_recovered(cx: float, cy: float, r: float, arc: float) -> None:
    x, y = circle_points(cx, cy, r, 0.3, 0.3 + arc, 25)
    fit = fit_circle(x, y)
    assert isinstance(fit, CircleFit)
    assert fit.center_x_m == pytest.approx(cx, abs=1e-7 * max(1.0, r))
    assert fit.center_y_m == pytest.approx(cy, abs=1e-7 * max(1.0, r))
    assert fit.radius_m == pytest.approx(r, rel=1e-8)
    assert fit.rms_residual_m < 1e-8 * max(1.0, r)


def test_three_points_define_the_circle() -> None:
    # (0,0), (2,0), (0,2): by hand the circumcentre is (1, 1) and the radius sqrt(2).
    fit = fit_circle([0.0, 2.0, 0.0], [0.0, 0.0, 2.0])
    assert (fit.center_x_m, fit.center_y_m) == pytest.approx((1.0, 1.0), abs=1e-12)
    assert fit.radius_m == pytest.approx(math.sqrt(2.0), rel=1e-12)


def test_noisy_circle_within_noise_bounds() -> None:
    # 200 points round r = 1.83 m with 5 mm Gaussian noise in x and y: the radius is a mean over 200
    # radial errors of ~5 mm, so its standard error is ~5 mm / sqrt(200) = 0.35 mm; allow 2 mm.
    rng = np.random.default_rng(7)
    x, y = circle_points(0.4, -0.7, 1.83, 0.0, 2 * math.pi, 200)
    x = x + rng.normal(0, 0.005, x.size)
    y = y + rng.normal(0, 0.005, y.size)
    fit = fit_circle(x, y)
    assert fit.radius_m == pytest.approx(1.83, abs=0.002)
    assert (fit.center_x_m, fit.center_y_m) == pytest.approx((0.4, -0.7), abs=0.002)
    assert fit.rms_residual_m == pytest.approx(0.005, rel=0.2)


def test_noisy_short_arc_stays_close() -> None:
    # Half a circle of r = 0.55 m with 1 mm noise (the motion-capture case): radius within 1 %.
    rng = np.random.default_rng(11)
    x, y = circle_points(0.2, 0.1, 0.55, -0.9, 1.4, 26)
    fit = fit_circle(x + rng.normal(0, 0.001, 26), y + rng.normal(0, 0.001, 26))
    assert fit.radius_m == pytest.approx(0.55, rel=0.01)


@pytest.mark.parametrize(
    ('x', 'y', 'message'),
    [
        ([0.0, 1.0], [0.0, 1.0], 'at least 3 points'),
        ([], [], 'at least 3 points'),
        ([0.0, 1.0, 2.0, 3.0], [1.0, 2.0, 3.0, 4.0], 'collinear'),
        ([0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0], '3 distinct points'),
        ([0.0, 1.0, math.nan], [0.0, 1.0, 0.0], 'finite'),
        ([0.0, 1.0, 2.0], [0.0, 1.0], 'differ in length'),
    ],
)
def test_degenerate_input_is_a_clear_error(x: list[float], y: list[float], message: str) -> None:
    with pytest.raises(InputError, match=message):
        fit_circle(x, y)


def test_mean_speed_on_a_straight_line() -> None:
    # 1.2 m covered in 6 s at constant speed: 0.2 m/s.
    t = np.linspace(0.0, 6.0, 31)
    assert mean_speed(t, 0.2 * t, np.full_like(t, 0.5)) == pytest.approx(0.2, rel=1e-12)


def test_mean_speed_on_a_circle_is_the_chord_length_over_time() -> None:
    # r = 0.5 m, 0.1 rad per sample at 5 Hz -> arc speed 0.25 m/s; each chord is
    # 2 r sin(0.05) = 0.0499792 m, so the polyline speed is 0.0499792 * 5 = 0.249896 m/s.
    t = np.arange(30) / 5.0
    x, y = 0.5 * np.cos(0.5 * t), 0.5 * np.sin(0.5 * t)
    assert mean_speed(t, x, y) == pytest.approx(2 * 0.5 * math.sin(0.05) * 5.0, rel=1e-12)
    assert mean_speed(t, x, y) == pytest.approx(0.25, rel=5e-4)


@pytest.mark.parametrize(
    ('t', 'message'),
    [
        ([0.0, 1.0, 1.0], 'strictly increasing'),
        ([0.0, 1.0], 'differ in length'),
        ([0.0, math.inf, 3.0], 'finite'),
    ],
)
def test_mean_speed_bad_times(t: list[float], message: str) -> None:
    with pytest.raises(InputError, match=message):
        mean_speed(t, [0.0, 1.0, 2.0], [0.0, 0.0, 0.0])


def test_mean_speed_needs_two_samples() -> None:
    with pytest.raises(InputError, match='at least 2'):
        mean_speed([0.0], [0.0], [0.0])
