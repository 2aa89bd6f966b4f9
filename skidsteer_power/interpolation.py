"""Bilinear interpolation on a rectilinear grid, with clamping (used by the power maps and the fast
model's tables; a neutral module so that models and maps need not import each other).

Hand-written rather than ``scipy.interpolate.RegularGridInterpolator``, because it measured faster
on the same table (``benchmarks/bench_maps.py``, kernels alone): one point ~2-4 us against ~40 us
(pure-Python arithmetic on precomputed lists, no array set-up), and 1e6 points ~1.5x faster (one
gather of the four corners for all fields at once). Both give the same numbers to rounding
(test_maps_power_map.py checks one against the other).
"""

from __future__ import annotations

import math

import numpy as np

from skidsteer_power.errors import InputError


class Axis:
    """One strictly increasing grid axis; index/fraction lookup with clamping."""

    def __init__(self, values: np.ndarray, name: str) -> None:
        v = np.asarray(values, dtype=float)
        if v.ndim != 1 or len(v) < 2 or not np.all(np.isfinite(v)) or not np.all(np.diff(v) > 0):
            raise InputError(f'map axis {name!r} must hold >= 2 finite, strictly increasing values')
        self.values = v
        self.name = name
        self.lo, self.hi = float(v[0]), float(v[-1])
        steps = np.diff(v)
        self.uniform = bool(np.allclose(steps, steps[0], rtol=1e-9, atol=0.0))
        self.step = float(steps[0])
        self.size = len(v)
        self._list = v.tolist()

    def locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cell index i, fraction in [0, 1], clamped flag) for an array of coordinates."""
        clamped = (x < self.lo) | (x > self.hi)
        xc = np.clip(x, self.lo, self.hi)
        if self.uniform:
            pos = (xc - self.lo) / self.step
            i = np.minimum(pos.astype(np.intp), self.size - 2)
            frac = pos - i
        else:
            i = np.clip(np.searchsorted(self.values, xc, side='right') - 1, 0, self.size - 2)
            frac = (xc - self.values[i]) / (self.values[i + 1] - self.values[i])
        return i, frac, clamped

    def locate_scalar(self, x: float) -> tuple[int, float, bool]:
        """Scalar :meth:`locate` in plain Python (no numpy overhead)."""
        clamped = x < self.lo or x > self.hi or math.isnan(x)
        xc = self.lo if x < self.lo else self.hi if x > self.hi else x
        if self.uniform:
            pos = (xc - self.lo) / self.step
            i = min(int(pos), self.size - 2)
            return i, pos - i, clamped
        vals = self._list
        lo, hi = 0, self.size - 2
        while lo < hi:  # bisection for the cell holding xc
            mid = (lo + hi + 1) // 2
            if vals[mid] <= xc:
                lo = mid
            else:
                hi = mid - 1
        return lo, (xc - vals[lo]) / (vals[lo + 1] - vals[lo]), clamped


class BilinearGrid:
    """Bilinear interpolation of F fields tabulated on (axis0 x axis1), values (N0, N1, F)."""

    def __init__(self, axis0: Axis, axis1: Axis, values: np.ndarray) -> None:
        self.axis0, self.axis1 = axis0, axis1
        self.values = np.ascontiguousarray(values, dtype=float)
        n0, n1, f = self.values.shape
        self.flat = self.values.reshape(n0 * n1, f)
        self.rows = [row.tolist() for row in self.flat]  # scalar path: Python lists are fastest
        self.n1 = n1

    def __call__(self, x0: np.ndarray, x1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Interpolated fields (P, F), clamped flags (P,) and cell numbers (P,) at points (x0, x1) of
        shape (P,); cell (i, j), between nodes i, i+1 of axis 0 and j, j+1 of axis 1, is number
        i (N1 - 1) + j."""
        i, a, c0 = self.axis0.locate(x0)
        j, b, c1 = self.axis1.locate(x1)
        k = i * self.n1 + j
        v = self.flat
        a, b = a[:, None], b[:, None]
        low = v[k] + b * (v[k + 1] - v[k])
        high = v[k + self.n1] + b * (v[k + self.n1 + 1] - v[k + self.n1])
        return low + a * (high - low), c0 | c1, k - i

    def scalar(self, x0: float, x1: float) -> tuple[list[float], bool, int]:
        """One point, in plain Python: fields (list of F floats), the clamped flag and the cell number."""
        i, a, c0 = self.axis0.locate_scalar(x0)
        j, b, c1 = self.axis1.locate_scalar(x1)
        k = i * self.n1 + j
        r00, r01, r10, r11 = (
            self.rows[k],
            self.rows[k + 1],
            self.rows[k + self.n1],
            self.rows[k + self.n1 + 1],
        )
        wa, wb = 1.0 - a, 1.0 - b
        w00, w01, w10, w11 = wa * wb, wa * b, a * wb, a * b
        out = [w00 * p + w01 * q + w10 * r + w11 * s for p, q, r, s in zip(r00, r01, r10, r11, strict=True)]
        return out, c0 or c1, k - i
