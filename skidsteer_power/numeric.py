"""Numeric helpers the physics layers share: one formula for a Python float and for a numpy array,
and the distinct rows of a table.

The powertrain's formulas (eqs. 7.1-7.4, the EC-45 and the DES 70/10) run on arrays in maps,
missions and calibration, and on one float per side per message in the estimator node, at up to
1 kHz (issue 18). Numpy costs about a microsecond per operation on a single value, plain float
arithmetic a few tens of nanoseconds: both sides of the powertrain took 11.6 us through numpy and
0.5 us in floats (measured on this project's machine). So those formulas are written once, with
arithmetic that works on both: a float in gives a float out, an array in an array out. The two steps
plain arithmetic cannot write for both, a sign and a choice by sign, are here.
"""

from __future__ import annotations

import math
from typing import TypeVar, cast

import numpy as np

Real = TypeVar('Real', float, np.ndarray)
"""A Python float (one value, per message) or a float array (batches, broadcast)."""


def real(value: Real) -> Real:
    """``value`` as the formulas want it: a Python float (or a float subclass such as np.float64) as
    it is, anything else as a float array; an int becomes a 0-d float array, so a formula never
    computes in integers."""
    return value if isinstance(value, float) else np.asarray(value, dtype=float)


def sign(x: Real) -> Real:
    """-1, 0 or 1 by the sign of ``x``, NaN for NaN (``np.sign`` of an array)."""
    if isinstance(x, np.ndarray):
        signs: np.ndarray = np.sign(x)
        return signs
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x if x != x else 0.0  # NaN stays NaN; -0.0 gives +0.0, as np.sign does


def by_sign(x: Real, nonnegative: Real, negative: Real) -> Real:
    """``nonnegative`` where ``x >= 0``, else ``negative`` (``np.where`` for arrays; NaN is not >= 0)."""
    if isinstance(x, np.ndarray):
        return np.where(x >= 0.0, nonnegative, negative)
    return nonnegative if x >= 0.0 else negative


def where(condition: bool | np.bool_ | np.ndarray, a: Real, b: float | np.ndarray) -> Real:
    """``a`` where ``condition``, else ``b`` (``np.where`` for an array condition). Both are evaluated:
    neither may raise for a float (guard a denominator, never rely on the choice)."""
    if isinstance(condition, np.ndarray):
        return cast(Real, np.where(condition, a, b))
    return a if condition else cast(Real, b)


def maximum(a: Real, b: float | np.ndarray) -> Real:
    """The larger of ``a`` and ``b``, NaN if either is NaN (``np.maximum``; Python's ``max`` drops a
    NaN in second place)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        larger: Real = np.maximum(a, b)
        return larger
    return a if (a >= b or a != a) else b


def minimum(a: Real, b: float | np.ndarray) -> Real:
    """The smaller of ``a`` and ``b``, NaN if either is NaN (``np.minimum``)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        smaller: Real = np.minimum(a, b)
        return smaller
    return a if (a <= b or a != a) else b


def hypot(a: Real, b: Real) -> Real:
    """sqrt(a^2 + b^2) without overflow: ``math.hypot`` of two floats, ``np.hypot`` otherwise."""
    if isinstance(a, float) and isinstance(b, float):
        return math.hypot(a, b)
    length: Real = np.hypot(a, b)
    return length


def distinct_rows(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of a float table (n, k), sorted, shape (m, k), and each row's index among
    them: what ``np.unique(table, axis=0, return_inverse=True)`` gives, through a lexsort of the
    columns (``np.unique`` over rows sorts a structured view, 10x slower for a few thousand rows).
    inf equals inf, so straights (turn radius inf) group together."""
    if len(table) == 0:
        return table[:0], np.zeros(0, dtype=np.intp)
    order = np.lexsort(table.T[::-1])  # np.lexsort's last key is the primary one
    ordered = table[order]
    new = np.r_[True, np.any(ordered[1:] != ordered[:-1], axis=1)]
    inverse = np.empty(order.size, dtype=np.intp)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse
