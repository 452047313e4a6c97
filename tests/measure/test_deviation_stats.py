"""The deviation statistics' compiled gather (:func:`pmdsim.measure.deviation.finite_values`,
:func:`pmdsim.kernels.images.gather_finite`) against the NumPy expressions it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.measure.deviation import deviation_stats, finite_median, finite_values
from pmdsim.quantiles import median, percentile


def _maps(dtype, seed=5):
    rng = np.random.default_rng(seed)
    d = rng.normal(0.3, 2.0, (29, 41)).astype(dtype)  # H != W, a non-zero mean
    d[rng.uniform(size=d.shape) < 0.1] = np.nan
    d[0, :3] = [np.inf, -np.inf, np.nan]
    given = rng.uniform(size=d.shape) < 0.8
    given[0, :3] = True  # marked valid, not finite: considered, not in the statistics
    return d, given


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_finite_values_is_the_masked_gather(dtype):
    d, given = _maps(dtype)
    got, either = finite_values(d, given)
    want = d[given & np.isfinite(d)].astype(np.float64)
    assert got.dtype == np.float64 and np.array_equal(got, want)
    assert either == np.count_nonzero(given | np.isfinite(d))
    every, either_all = finite_values(d)  # no mask: every finite value, in order
    assert np.array_equal(every, d[np.isfinite(d)].astype(np.float64))
    assert either_all == d.size
    ints, _ = finite_values(np.arange(6).reshape(2, 3), np.array([True, False, True]))
    assert ints.tolist() == [0.0, 2.0, 3.0, 5.0]  # a mask broadcast over rows, integers


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_deviation_stats_against_numpy(dtype):
    """Every statistic as the whole-array NumPy expressions give it (the same bytes), with
    the default considered pixels (valid or finite) and with given ones."""
    d, given = _maps(dtype)
    x = d.astype(np.float64)[given & np.isfinite(d)]
    for considered in (None, given | (np.arange(d.size).reshape(d.shape) % 3 == 0)):
        s = deviation_stats(d, given, considered)
        n_cons = np.count_nonzero(given | np.isfinite(d) if considered is None else considered)
        assert s.mean == float(x.mean()) and s.std == float(x.std())
        assert s.rms == float(np.sqrt(np.mean(x**2))) and s.max == float(np.abs(x).max())
        assert s.p95 == percentile(np.abs(x), 95)
        assert (s.n_valid, s.n_masked) == (x.size, n_cons - x.size)
        assert s.valid_fraction == x.size / n_cons
    empty = deviation_stats(d, np.zeros_like(given))
    assert empty.n_valid == 0 and np.isnan(empty.mean)
    assert empty.n_masked == np.count_nonzero(np.isfinite(d))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_finite_median_of_the_masked_values(dtype):
    """The chain's, the sweep's and the decoder's modulation medians: the median of the
    finite masked values (NumPy's median of the gather), None where there is none."""
    d, given = _maps(dtype)
    assert finite_median(d, given) == median(d[given & np.isfinite(d)].astype(np.float64))
    assert finite_median(d, given) == pytest.approx(np.median(d[given & np.isfinite(d)]),
                                                    rel=1e-6)
    assert finite_median(d, np.zeros_like(given)) is None
    assert finite_median(np.full(3, np.nan)) is None
