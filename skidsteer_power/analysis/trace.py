"""Circle fit of a planar trace and mean forward speed (dissertation chapter 7.3.3, eqs. 7.8-7.10).

The robot drives at a constant commanded turning radius, so its trace is taken to be a circle
``a (x^2 + y^2) + b x + c y + d = 0`` (eq. 7.8), solved in the least-squares sense by SVD; the centre
and radius follow from eqs. 7.9 and 7.10.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from skidsteer_power.errors import InputError

# Radius beyond which the points are taken as collinear (a straight run has no finite circle),
# relative to the spread of the points.
_MAX_RADIUS_PER_SPREAD = 1e6


@dataclass(frozen=True)
class CircleFit:
    """A fitted circle [m] and the RMS of the points' radial residuals [m]."""

    center_x_m: float
    center_y_m: float
    radius_m: float
    rms_residual_m: float


def _as_points(x: ArrayLike, y: ArrayLike, *, minimum: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    xs = np.asarray(x, dtype=float).ravel()
    ys = np.asarray(y, dtype=float).ravel()
    if xs.shape != ys.shape:
        raise InputError(f'{what}: x and y differ in length ({xs.size} vs {ys.size})')
    if xs.size < minimum:
        raise InputError(f'{what}: needs at least {minimum} points, got {xs.size}')
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise InputError(f'{what}: coordinates must be finite (got NaN or inf)')
    return xs, ys


def fit_circle(x: ArrayLike, y: ArrayLike) -> CircleFit:
    """Least-squares circle through points (x, y) [m] by the SVD method of eqs. 7.8-7.10.

    Parameters
    ----------
    x, y : array_like, point coordinates in a plane [m]; at least 3 points, not all collinear.

    Returns
    -------
    CircleFit with centre (x_c, y_c) [m], radius r [m] and RMS radial residual [m].

    Notes
    -----
    Eq. (7.8): ``a (x^2 + y^2) + b x + c y + d = 0``; the coefficient vector (a, b, c, d) is the right
    singular vector of the design matrix ``[x^2 + y^2, x, y, 1]`` with the smallest singular value.
    Eq. (7.9): ``x_c = -b / 2a``, ``y_c = -c / 2a``; eq. (7.10): ``r = sqrt(x_c^2 + y_c^2 - d / a)``.
    The points are first shifted to their mean and scaled to unit spread, which leaves the fitted
    circle unchanged but keeps the design matrix well conditioned for traces far from the origin.

    Raises
    ------
    InputError for fewer than 3 points, non-finite values, coincident or collinear points.
    """
    xs, ys = _as_points(x, y, minimum=3, what='circle fit')
    x0, y0 = xs.mean(), ys.mean()
    u, v = xs - x0, ys - y0
    spread = float(np.sqrt(np.mean(u**2 + v**2)))
    if len(np.unique(np.column_stack([xs, ys]), axis=0)) < 3:
        raise InputError('circle fit: needs at least 3 distinct points')
    u, v = u / spread, v / spread
    design = np.column_stack([u**2 + v**2, u, v, np.ones_like(u)])  # eq. 7.8
    # all four right singular vectors; the n x n left ones only when n < 4 gives fewer otherwise
    # (0.29 s for 2,700 poses against 0.2 ms, the same vectors bit for bit on 820 random traces)
    _, _, vt = np.linalg.svd(design, full_matrices=len(u) < 4)
    a, b, c, d = vt[-1]
    if abs(a) * _MAX_RADIUS_PER_SPREAD <= np.hypot(b, c):
        raise InputError('circle fit: points are collinear (straight trace, no finite radius)')
    uc, vc = -b / (2 * a), -c / (2 * a)  # eq. 7.9
    r_squared = uc**2 + vc**2 - d / a  # eq. 7.10
    if r_squared <= 0:
        raise InputError('circle fit: no real circle fits these points')
    radius = float(np.sqrt(r_squared)) * spread
    center_x, center_y = x0 + uc * spread, y0 + vc * spread
    residual = np.hypot(xs - center_x, ys - center_y) - radius
    return CircleFit(
        center_x_m=float(center_x),
        center_y_m=float(center_y),
        radius_m=radius,
        rms_residual_m=float(np.sqrt(np.mean(residual**2))),
    )


def mean_speed(t: ArrayLike, x: ArrayLike, y: ArrayLike) -> float:
    """Mean forward speed [m/s]: length of the polyline through (x, y) [m] over the elapsed time [s].

    ``t`` must be strictly increasing. Sampled sparsely on a circle of radius r, each chord is shorter
    than its arc by the factor ``sin(theta/2) / (theta/2)`` (theta: angle per sample); at 5 Hz on the
    dissertation's runs (0.1 m/s, r >= 0.3 m) that is below 0.1 %.

    Raises
    ------
    InputError for fewer than 2 samples, mismatched lengths, non-finite or non-increasing times.
    """
    xs, ys = _as_points(x, y, minimum=2, what='mean speed')
    ts = np.asarray(t, dtype=float).ravel()
    if ts.shape != xs.shape:
        raise InputError(f'mean speed: t and x differ in length ({ts.size} vs {xs.size})')
    if not np.all(np.isfinite(ts)):
        raise InputError('mean speed: times must be finite')
    if np.any(np.diff(ts) <= 0):
        raise InputError('mean speed: times must be strictly increasing')
    path_length = float(np.sum(np.hypot(np.diff(xs), np.diff(ys))))
    return path_length / float(ts[-1] - ts[0])
