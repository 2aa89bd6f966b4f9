"""The power map's turn-angle axis: the warped grid coordinate of the turn angle psi [rad] and the
refined angles near the smallest turning radius (split from :mod:`skidsteer_power.maps.power_map`,
whose module doc explains the choice; the map both builds and queries through these)."""

from __future__ import annotations

import math

import numpy as np

REFINE_SPAN = 3.0  # refined angles cover the turns of radius min_radius ... REFINE_SPAN x min_radius

_HALF_PI = 0.5 * math.pi


ANGLE_WARP = 3.0  # c in psi = (pi/2) sinh(c u) / sinh(c)


def _angle_coordinate(psi: np.ndarray) -> np.ndarray:
    """Grid coordinate u in [-1, 1] of the turn angle psi [rad]: psi = (pi/2) sinh(c u) / sinh(c).

    The grid is uniform in u: about 7x denser near straight running (where torque rises fastest
    with psi, R going from infinity to a few metres) than towards spinning in place (flat in the
    small-radius limit), and linear in psi near psi = 0, where the side torques are linear in the
    curvature (a square-root warp was tried: it bent that linear part and was 38 % off there).
    """
    return np.arcsinh(np.asarray(psi) / _HALF_PI * math.sinh(ANGLE_WARP)) / ANGLE_WARP


def _angle_coordinate_scalar(psi: float) -> float:
    return math.asinh(psi / _HALF_PI * math.sinh(ANGLE_WARP)) / ANGLE_WARP


def _angle_from_coordinate(u: np.ndarray) -> np.ndarray:
    return _HALF_PI * np.sinh(ANGLE_WARP * np.asarray(u)) / math.sinh(ANGLE_WARP)


def _refined_angles(n_psi: int, refine: int, length: float, r_min: float) -> np.ndarray:
    """The warped turn angles [rad] plus ``refine`` more per side, evenly spaced in psi over the turns
    of radius min_radius ... REFINE_SPAN x min_radius, where the outer side's slip rises steeply
    towards the traction limit (measured: most of the remaining map error was there). Symmetric."""
    base = _angle_from_coordinate(np.linspace(-1.0, 1.0, n_psi))
    if refine <= 0:
        return base
    hi, lo = math.atan2(length, r_min), math.atan2(length, REFINE_SPAN * r_min)
    extra = np.linspace(lo, hi, refine + 2)[1:-1]
    merged = np.unique(np.concatenate([base, extra, -extra]))
    gaps = np.diff(_angle_coordinate(merged))
    distinct: np.ndarray = merged[np.concatenate([[True], gaps > 1e-9])]
    return distinct
