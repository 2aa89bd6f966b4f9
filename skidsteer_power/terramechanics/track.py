"""Single track on deformable terrain, uniform contact pressure (section 2.3, eqs. 2.6-2.18).

Every function broadcasts over load W [N], width b [m], contact length l [m] and slip s [-].
Slip follows eq. 2.13: s = (r w - V)/(r w) when driving (s > 0), (r w - V)/V when braking (s < 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import roots_legendre

from skidsteer_power.errors import InputError
from skidsteer_power.numeric import Real
from skidsteer_power.terramechanics.soil import FloatArray, check_length, shear_fraction
from skidsteer_power.terramechanics.terrain import Terrain


@dataclass(frozen=True)
class TrackState:
    """Single-track steady state (eq. 2.18). Arrays broadcast over the inputs."""

    sinkage_m: FloatArray  # z0, eq. 2.6
    compaction_resistance_N: FloatArray  # R_c, eq. 2.10
    tractive_effort_N: FloatArray  # F_s, eq. 2.17
    drawbar_pull_N: FloatArray  # F_d = F_s - R_c, eq. 2.18


def check_load(load: ArrayLike) -> FloatArray:
    """Normal load W [N] as an array; InputError unless finite and >= 0."""
    w = np.asarray(load, dtype=float)
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise InputError(f'load must be finite and >= 0 N, got {load!r}')
    return w


def check_slip(slip: ArrayLike) -> FloatArray:
    """Slip ratio s [-] as an array; InputError unless in [-1, 1] (eq. 2.13)."""
    s = np.asarray(slip, dtype=float)
    if np.any(~np.isfinite(s)) or np.any(np.abs(s) > 1):
        raise InputError(f'slip must lie in [-1, 1], got {slip!r}')
    return s


def track_sinkage(terrain: Terrain, load: ArrayLike, width: ArrayLike, length: ArrayLike) -> FloatArray:
    """Sinkage z0 [m] of a track, load W [N], contact width b and length l [m] (eq. 2.6)."""
    w, b, l = check_load(load), check_length(width, 'width'), check_length(length, 'length')  # noqa: E741
    return track_sinkage_unchecked(terrain, w, b, l)


def track_sinkage_unchecked(terrain: Terrain, w: FloatArray, b: Real, l: Real) -> FloatArray:  # noqa: E741
    """:func:`track_sinkage` for inputs the caller has checked (W >= 0 finite, b, l > 0): FESS's
    per-command contact (a tenth of a cold solve_point went to the checks)."""
    sinkage: FloatArray = ((w / (b * l)) / terrain.k_eq(b)) ** (1.0 / terrain.n)
    return sinkage


def compaction_resistance(
    terrain: Terrain, load: ArrayLike, width: ArrayLike, length: ArrayLike
) -> FloatArray:
    """Motion resistance R_c [N] from compacting a rut (eq. 2.10); W [N], b, l [m]."""
    w, b, l = check_load(load), check_length(width, 'width'), check_length(length, 'length')  # noqa: E741
    return compaction_resistance_unchecked(terrain, w, b, l)


def compaction_resistance_unchecked(terrain: Terrain, w: FloatArray, b: Real, l: Real) -> FloatArray:  # noqa: E741
    """:func:`compaction_resistance` for inputs the caller has checked (as
    :func:`track_sinkage_unchecked`)."""
    n = terrain.n
    resistance: FloatArray = b / ((n + 1.0) * terrain.k_eq(b) ** (1.0 / n)) * (w / (b * l)) ** ((n + 1.0) / n)
    return resistance


def _mean_fraction(u: FloatArray) -> FloatArray:
    """1 - (1 - e^-u)/u: mean of 1 - e^(-|j|/K) over the contact, u = |j_rear|/K (eq. 2.17)."""
    u = np.asarray(u, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        exact = 1.0 + np.expm1(-u) / u
    small = np.minimum(u, 1e-4)
    series = small / 2.0 - small**2 / 6.0 + small**3 / 24.0  # avoids 0/0 at s = 0
    return np.where(u < 1e-4, series, np.where(np.isinf(u), 1.0, exact))


def rear_shear_displacement(slip: ArrayLike, length: ArrayLike) -> FloatArray:
    """Shear displacement j [m] at the rear of the contact, x = l (eq. 2.15); -inf at s = -1."""
    s, l = check_slip(slip), check_length(length, 'length')  # noqa: E741
    with np.errstate(divide='ignore'):
        braking = np.where(s == -1.0, -np.inf, s * l / (1.0 + np.where(s == -1.0, 0.0, s)))
    return np.where(s >= 0, s * l, braking)


_GL_NODES, _GL_WEIGHTS = roots_legendre(64)


def tractive_effort(
    terrain: Terrain, load: ArrayLike, width: ArrayLike, length: ArrayLike, slip: ArrayLike
) -> FloatArray:
    """Tractive effort F_s [N] of a track (eqs. 2.16-2.17), signed like the slip.

    Type A soil: the closed form of eq. 2.17 (driving and braking branches share one expression in
    u = |j_rear|/K). Types B and C: eq. 2.16 by 64-point Gauss-Legendre quadrature along the track.
    """
    w, b, l = check_load(load), check_length(width, 'width'), check_length(length, 'length')  # noqa: E741
    j_rear = rear_shear_displacement(slip, l)
    f_max = b * l * terrain.c + w * math.tan(terrain.phi)  # eq. 2.11
    if terrain.shear_type == 'A':
        return np.sign(j_rear) * f_max * _mean_fraction(np.abs(j_rear) / terrain.K)
    # j grows linearly from the front (eq. 2.15): mean over x of the shear fraction
    t = 0.5 * (_GL_NODES + 1.0)
    j = np.asarray(j_rear)[..., None] * t
    mean = 0.5 * np.sum(_GL_WEIGHTS * shear_fraction(terrain, j), axis=-1)
    effort: FloatArray = f_max * mean
    return effort


def drawbar_pull(
    terrain: Terrain, load: ArrayLike, width: ArrayLike, length: ArrayLike, slip: ArrayLike
) -> FloatArray:
    """Drawbar pull F_d = F_s - R_c [N] (eq. 2.18)."""
    return tractive_effort(terrain, load, width, length, slip) - compaction_resistance(
        terrain, load, width, length
    )


def single_track(
    terrain: Terrain, load: ArrayLike, width: ArrayLike, length: ArrayLike, slip: ArrayLike = 0.0
) -> TrackState:
    """Steady state of one track (eq. 2.18): sinkage, compaction resistance, effort, drawbar pull.

    load W [N], width b [m], contact length l [m], slip s [-] in [-1, 1]; arrays broadcast.
    """
    z0 = track_sinkage(terrain, load, width, length)
    rc = compaction_resistance(terrain, load, width, length)
    fs = tractive_effort(terrain, load, width, length, slip)
    return TrackState(z0, rc, fs, fs - rc)
