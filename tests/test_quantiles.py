"""pmdsim.quantiles gives NumPy's percentiles and medians, bit for bit."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pmdsim.quantiles import median, nanmedian, percentile

SIZES = [*range(1, 40), 64, 101, 1000, 1001, 65536, 65537]
QS = (0, 1, 5, 25, 33.3, 50, 75, 95, 99, 99.5, 100)


def _samples(rng, n):
    """Smooth values, many ties (the neighbours equal), and heavy tails."""
    yield rng.normal(size=n) * 3.7 + 0.25
    yield rng.integers(0, 4, n).astype(np.float64)
    yield np.abs(rng.standard_cauchy(n))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("n", SIZES)
def test_same_bits_as_numpy(n, dtype):
    rng = np.random.default_rng(n)
    for a in _samples(rng, n):
        a = a.astype(dtype)
        keep = a.copy()
        for q in QS:
            assert percentile(a, q) == float(np.percentile(keep, q)), (n, q)
        assert median(a) == float(np.median(keep)), n
        np.testing.assert_array_equal(a, keep)  # without overwrite the input is untouched


def test_overwrite_reorders_in_place_and_keeps_the_result():
    rng = np.random.default_rng(7)
    a = rng.normal(size=(37, 29))  # 2-D: over all values, as NumPy without an axis
    want_p, want_m = float(np.percentile(a, 95)), float(np.median(a))
    b = a.copy()
    assert percentile(b, 95, overwrite=True) == want_p
    assert sorted(b.ravel()) == sorted(a.ravel())  # the same values, reordered
    c = a.copy()
    assert median(c, overwrite=True) == want_m
    assert not np.array_equal(c, a)


def test_nan_empty_and_other_types():
    a = np.array([3.0, np.nan, 1.0, 2.0])
    assert math.isnan(percentile(a, 50)) and math.isnan(float(np.percentile(a, 50)))
    assert math.isnan(median(a)) and math.isnan(float(np.median(a)))
    with pytest.raises(ValueError, match="empty"):
        percentile(np.zeros(0), 95)
    with pytest.raises(ValueError, match="empty"):
        median(np.zeros(0))
    with pytest.raises(ValueError, match="within"):
        percentile(np.ones(3), 101)
    ints = np.arange(10)  # NumPy's own path
    assert median(ints) == 4.5 and percentile(ints, 95) == float(np.percentile(ints, 95))


def test_nanmedian_same_bits_as_numpy():
    rng = np.random.default_rng(11)
    for n, dtype in itertools.product((1, 2, 3, 10, 101, 1000, 4097), (np.float64, np.float32)):
        a = rng.normal(size=n).astype(dtype)
        a[rng.random(n) < 0.3] = np.nan
        if n > 3:
            a[1], a[2] = np.inf, -np.inf  # infinities are values, as in NumPy
        m = a.reshape(-1, 1) if n % 2 else a  # any shape: over all values
        if np.isnan(a).all():
            assert math.isnan(nanmedian(m))
        else:
            assert nanmedian(m) == float(np.nanmedian(m)), n
    assert math.isnan(nanmedian(np.full(5, np.nan)))
