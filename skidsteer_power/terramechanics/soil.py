"""Soil constitutive laws: Bekker pressure-sinkage (eq. 2.1), Mohr-Coulomb strength (eq. 2.2) and
shear stress vs shear displacement for soil types A, B and C (eqs. 2.3-2.5).

Every function broadcasts over numpy arrays; SI units (m, Pa).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from skidsteer_power.errors import InputError
from skidsteer_power.terramechanics.terrain import Terrain

FloatArray = NDArray[np.float64]


def pressure_sinkage(terrain: Terrain, z: ArrayLike, b: ArrayLike) -> FloatArray:
    """Pressure p = (kc/b + kphi) z^n [Pa] at sinkage z [m] under a plate of width b [m] (eq. 2.1).

    A sinkage z <= 0 means no contact and gives 0 Pa.
    """
    z = np.asarray(z, dtype=float)
    b = check_length(b, 'width b')
    pressure: FloatArray = terrain.k_eq(b) * np.maximum(z, 0.0) ** terrain.n
    return pressure


def sinkage_for_pressure(terrain: Terrain, p: ArrayLike, b: ArrayLike) -> FloatArray:
    """Sinkage z = (p / (kc/b + kphi))^(1/n) [m] under pressure p [Pa], plate width b [m] (eq. 2.1)."""
    p = np.asarray(p, dtype=float)
    if np.any(~np.isfinite(p)) or np.any(p < 0):
        raise InputError('pressure must be finite and >= 0 Pa')
    b = check_length(b, 'width b')
    sinkage: FloatArray = (p / terrain.k_eq(b)) ** (1.0 / terrain.n)
    return sinkage


def shear_strength(terrain: Terrain, sigma: ArrayLike) -> FloatArray:
    """Maximum shear stress tau_max = c + sigma tan(phi) [Pa] at normal stress sigma [Pa] (eq. 2.2)."""
    return terrain.c + np.asarray(sigma, dtype=float) * math.tan(terrain.phi)


def shear_fraction(terrain: Terrain, j: ArrayLike) -> FloatArray:
    """tau / tau_max [-] at shear displacement j [m] (eqs. 2.3-2.5), odd in j.

    The stress acts in the direction of the displacement, so the sign of j carries over (for a track
    sign(j) = sign(s), which is the sign(s) factor of eqs. 2.16 and 2.26). |j| = inf is allowed
    (fully developed shear, e.g. a locked wheel at s = -1).
    """
    j = np.asarray(j, dtype=float)
    signed: FloatArray = np.sign(j) * shear_fraction_magnitude(terrain, np.abs(j))
    return signed


def shear_fraction_magnitude(terrain: Terrain, a: FloatArray) -> FloatArray:
    """tau / tau_max [-] at a shear displacement magnitude a = |j| >= 0 [m] (eqs. 2.3-2.5): the
    fraction of :func:`shear_fraction` without the sign (FESS's one-point residual, whose |j| is a
    hypot, saves the abs and sign per call)."""
    if terrain.shear_type == 'A':
        return -np.expm1(-a / terrain.K)  # eq. 2.3
    if terrain.shear_type == 'B':
        assert terrain.Kw is not None  # type B: validated by Terrain
        x = a / terrain.Kw
        with np.errstate(invalid='ignore', over='ignore'):
            frac: FloatArray = np.where(np.isinf(x), 0.0, x * np.exp(1.0 - x))  # eq. 2.4
        return frac
    assert terrain.Kr is not None and terrain.Kw is not None  # type C: both validated by Terrain
    return _type_c_fraction(a, terrain.Kr, terrain.Kw)


def _type_c_fraction(a: FloatArray, kr: float, kw: float) -> FloatArray:
    # eq. 2.5 as printed has exp(-j/Kw) in the first bracket; then tau(Kw) != tau_max, which
    # contradicts the text ("Kw is the shear displacement where the maximum shear stress occurs").
    # Wong (Theory of Ground Vehicles, ref. [10]) writes exp(1 - j/Kw) there; with it tau(Kw) equals
    # tau_max exactly. We use Wong's form.
    e = math.e
    decay = np.exp(-a / kw)
    return kr * (1.0 + (1.0 / (kr * (1.0 - 1.0 / e)) - 1.0) * e * decay) * (1.0 - decay)


def shear_stress(terrain: Terrain, sigma: ArrayLike, j: ArrayLike) -> FloatArray:
    """Shear stress tau [Pa] at normal stress sigma [Pa] and shear displacement j [m] (eqs. 2.2-2.5).

    Signed like j (see :func:`shear_fraction`).
    """
    return shear_strength(terrain, sigma) * shear_fraction(terrain, j)


def check_length(value: ArrayLike, what: str) -> FloatArray:
    """A width, length or radius [m] as an array; InputError unless finite and > 0."""
    arr = np.asarray(value, dtype=float)
    if np.any(~np.isfinite(arr)) or np.any(arr <= 0):
        raise InputError(f'{what} must be finite and > 0 m, got {value!r}')
    return arr
