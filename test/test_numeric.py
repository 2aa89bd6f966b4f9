"""skidsteer_power.numeric: one formula for floats and arrays, and the distinct rows of a table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from skidsteer_power.numeric import by_sign, distinct_rows, real, sign


def test_floats_stay_floats_and_agree_with_numpy() -> None:
    values = [2.5, -0.25, 0.0, -0.0, math.nan, math.inf]
    array = np.array(values)
    assert [type(real(v)) for v in values] == [float] * len(values)
    three: object = real(3)  # an int (typed as float by mypy) becomes an array
    assert isinstance(three, np.ndarray) and three.dtype == float  # no integer arithmetic
    for i, v in enumerate(values):
        for got, want in (
            (sign(v), np.sign(array)[i]),
            (by_sign(v, 1.0, -1.0), np.where(array >= 0, 1.0, -1.0)[i]),
        ):
            assert type(got) is float
            assert got == want or (math.isnan(got) and math.isnan(want)), (v, got, want)
            assert math.copysign(1.0, got) == math.copysign(1.0, want), (v, got, want)  # -0.0 too


def test_distinct_rows_is_numpy_unique_over_rows() -> None:
    """Against ``np.unique(axis=0, return_inverse=True)``: sorted rows, the same inverse; repeated
    rows, rows equal in the first column only, and inf (a straight's radius) included."""
    rng = np.random.default_rng(0)
    table = rng.choice([0.1, 0.2, 0.3], size=(500, 2))
    table[rng.random(500) < 0.3, 1] = np.inf
    table[::7, 1] = -1.5
    rows, inverse = distinct_rows(table)
    want_rows, want_inverse = np.unique(table, axis=0, return_inverse=True)
    np.testing.assert_array_equal(rows, want_rows)
    np.testing.assert_array_equal(inverse, want_inverse.ravel())
    np.testing.assert_array_equal(rows[inverse], table)


@pytest.mark.parametrize('columns', [1, 3])
def test_distinct_rows_of_any_width(columns: int) -> None:
    rows, inverse = distinct_rows(np.zeros((0, columns)))
    assert rows.shape == (0, columns) and inverse.size == 0
    table = np.repeat(np.arange(4.0 * columns).reshape(4, columns), 3, axis=0)[::-1]
    rows, inverse = distinct_rows(table)
    assert rows.shape == (4, columns)
    np.testing.assert_array_equal(rows[inverse], table)
