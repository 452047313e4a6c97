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


@pytest.mark.parametrize("n", [1, 2, 3, 5, 20, 21, 400])
@pytest.mark.parametrize("ties", [True, False])
def test_one_value_change_bounds_every_set_one_value_larger_or_smaller(n, ties):
    """The percentile of the set with any one value removed, or any value within the set's
    range added (at and between the values; ties included), stays within one_value_change
    of the set's own percentile, and one of them reaches it: brute force over every such
    set."""
    from pmdsim.quantiles import one_value_change

    rng = np.random.default_rng(n)
    a = rng.gamma(2.0, 1.0, n)
    if ties:
        a = np.round(a, 1)
    for q in (50, 95):
        p = np.percentile(a, q)
        bound = one_value_change(a, q)
        changed = [np.percentile(np.delete(a, i), q) for i in range(n)] if n > 1 else []
        s = np.sort(a)
        extra = np.concatenate([s, (s[1:] + s[:-1]) / 2])
        changed += [np.percentile(np.append(a, y), q) for y in extra]
        worst = max(abs(c - p) for c in changed)
        assert worst == pytest.approx(bound, rel=1e-9, abs=1e-12), (q, worst, bound)


def _large_samples(rng, n):
    """Samples for the window of large samples: an image-like smooth field with noise, sorted
    both ways, ties, infinities, and one whose strided subsample (the window's guide) is
    unlike the rest (every subsample value huge: the window misses, the whole sample is
    partitioned)."""
    from pmdsim.quantiles import SUBSAMPLE

    x = np.linspace(-1.0, 1.0, n)
    yield np.sin(7.0 * x) + 0.01 * rng.normal(size=n)
    yield np.sort(rng.normal(size=n))
    yield np.sort(rng.normal(size=n))[::-1].copy()
    yield rng.integers(0, 3, n).astype(np.float64)
    a = rng.normal(size=n)
    a[rng.random(n) < 0.01] = np.inf
    a[rng.random(n) < 0.01] = -np.inf
    yield a
    b = np.abs(rng.normal(size=n))
    b[:: n // SUBSAMPLE] = 1e6
    yield b


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("n", [65536, 200_003])
def test_large_samples_same_bits_as_numpy(n, dtype):
    """Samples of WINDOW_MIN values or more take the window (or, where it misses, the whole
    partition): NumPy's bits either way, the input untouched without overwrite."""
    from pmdsim.quantiles import WINDOW_MIN

    assert n >= WINDOW_MIN
    rng = np.random.default_rng(n + 1)
    for a in _large_samples(rng, n):
        a = a.astype(dtype)
        keep = a.copy()
        # (with infinities only inner percentiles: at 0 and 100 NumPy's interpolation
        # gives NaN from inf - inf, and these give the infinity)
        inner = not np.isfinite(a).all()
        for q in (5, 50, 95) if inner else (0, 0.1, 5, 50, 95, 99.9, 100):
            assert percentile(a, q) == float(np.percentile(keep, q)), (n, q)
        assert median(a) == float(np.median(keep))
        assert median(a[:-1]) == float(np.median(keep[:-1]))  # the other parity
        np.testing.assert_array_equal(a, keep)
        assert percentile(a.copy(), 95, overwrite=True) == float(np.percentile(keep, 95))


def test_large_samples_with_a_nan_anywhere():
    from pmdsim.quantiles import SUBSAMPLE

    n = 100_000
    for at in (0, n // SUBSAMPLE, 5, n // 2 + 1, n - 1):  # in the subsample and beside it
        a = np.random.default_rng(at).normal(size=n)
        a[at] = np.nan
        assert math.isnan(percentile(a, 95)) and math.isnan(median(a)), at
        assert math.isnan(percentile(a, 100)), at


def test_window_values_against_numpy():
    """The compiled window pass: NumPy's selection and counts; a NaN reported; an output
    too small leaves the count right (the caller then partitions the whole sample)."""
    from pmdsim.kernels.select import window_values

    rng = np.random.default_rng(3)
    for dtype in (np.float64, np.float32):
        v = rng.normal(size=10_001).astype(dtype)
        v[::97] = 0.25  # ties at the window's edge
        low, high = dtype(-0.5), dtype(0.25)
        want = v[(v >= low) & (v <= high)]
        out = np.empty(v.size, dtype)
        below, inside, nan = window_values(v, low, high, out)
        assert (below, inside, nan) == (np.count_nonzero(v < low), want.size, False)
        np.testing.assert_array_equal(out[:inside], want)
        small = np.empty(10, dtype)
        assert window_values(v, low, high, small)[:2] == (below, inside)
        v[5000] = np.nan
        assert window_values(v, low, high, out)[2]
