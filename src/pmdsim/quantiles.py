"""Percentiles and medians of large samples: NumPy's numbers, in a third of the time.

``np.percentile(a, q)`` (method ``"linear"``) partitions a copy of the sample at four
indices at once (0, -1 and the two neighbours of the virtual index ``(n - 1) q / 100``),
and ``np.median`` at three; NumPy's introselect takes 20-27 ms for that on the 1.3 M
values of a Fig. 3 map, against 4-6 ms for one partition. A run takes about a hundred
such statistics (the Fig. 3 run without its figures: 103, 47 of them over more than
100 000 values). :func:`percentile` and :func:`median` partition the sample once, in
place, at the lower neighbour, take the upper one as the minimum of the part above it,
and interpolate with NumPy's own formula (``_lerp``: ``a + (b - a) t``, or ``b - (b - a)
(1 - t)`` for ``t >= 0.5``): the same order statistics and the same arithmetic, so the
same bits as NumPy (``tests/test_quantiles.py`` compares them bit for bit).

Only float32 and float64 samples take the fast path (taken over all their values, as NumPy
without an ``axis``); anything else is handed to NumPy.
"""

from __future__ import annotations

import math

import numpy as np

#: The types of the fast path (the arithmetic stays in the sample's type, as NumPy's).
FLOATS = (np.float32, np.float64)


def _sample(a, overwrite: bool) -> np.ndarray | None:
    """``a`` as a 1-D float32/float64 array the caller lets us reorder, or None for NumPy."""
    arr = np.asarray(a)
    if arr.dtype not in FLOATS:
        return None
    arr = arr.ravel()  # a view where it can be: reordered in place with overwrite
    return arr if overwrite and arr.flags.writeable else arr.copy()


def percentile(a, q: float, *, overwrite: bool = False) -> float:
    """``np.percentile(a, q)`` (method ``"linear"``, over all values) as a float, the same
    bits. ``overwrite``: ``a`` may be reordered (no copy). NaN where ``a`` holds a NaN;
    ``a`` must not be empty."""
    s = _sample(a, overwrite)
    if s is None:
        return float(np.percentile(a, q))
    n = s.size
    if n == 0:
        raise ValueError("percentile of an empty sample")
    if not 0 <= q <= 100:
        raise ValueError(f"percentile: q must be within [0, 100], got {q}")
    if np.isnan(s).any():
        return math.nan
    qf = np.true_divide(q, 100)  # as NumPy: q / 100 in float64, then the virtual index
    virtual = (n - 1) * qf
    if virtual >= n - 1:  # NumPy takes the last value for both neighbours
        return float(s.max())
    lo = int(np.floor(virtual))
    gamma = float(virtual - lo)  # a Python float (NumPy's for a Python q): the sample's type
    s.partition(lo)
    a_lo = s[lo]
    a_hi = s[lo + 1:].min()
    diff = a_hi - a_lo
    if gamma >= 0.5:
        return float(a_hi - diff * (1 - gamma))
    return float(a_lo + diff * gamma)


def one_value_change(a, q: float) -> float:
    """The largest change of ``percentile(a, q)`` when one value leaves the finite set ``a``
    (finite values, not empty) or one within its range enters it: the resolution of a
    percentile of a finite set, which no numerical error of the values themselves contains
    (a pixel that enters or leaves the valid set moves it by up to this). The percentile
    grows with every value, so the extremes are the sets without the smallest or the
    largest value and with one more smallest or largest: their percentiles, from the four
    order statistics around the percentile's (one partition; tests/test_quantiles.py checks
    it against every set one value larger or smaller)."""
    s = np.asarray(a, np.float64).ravel()
    n = s.size
    if n == 0:
        raise ValueError("one_value_change of an empty sample")
    qf = q / 100.0
    lo = int(np.floor((n - 1) * qf))
    kth = sorted({min(max(k, 0), n - 1) for k in range(lo - 2, lo + 4)})
    part = np.partition(s, kth)

    def order(k):  # the k-th smallest value (k within the window around lo)
        return float(part[min(max(k, 0), n - 1)])

    def pct(get, m):  # NumPy's linear percentile of m sorted values get(0..m-1)
        v = (m - 1) * qf
        k = int(np.floor(v))
        x0, x1 = get(k), get(min(k + 1, m - 1))
        return x0 + (x1 - x0) * (v - k)

    p = pct(order, n)
    new = [pct(lambda k: order(max(k - 1, 0)), n + 1),   # one more smallest value
           pct(lambda k: order(min(k, n - 1)), n + 1)]   # one more largest value
    if n > 1:
        new += [pct(lambda k: order(k + 1), n - 1),      # without the smallest
                pct(order, n - 1)]                       # without the largest
    return float(max(abs(x - p) for x in new))


def median(a, *, overwrite: bool = False) -> float:
    """``np.median(a)`` (over all values) as a float, the same bits. ``overwrite``: ``a``
    may be reordered (no copy). NaN where ``a`` holds a NaN; ``a`` must not be empty."""
    s = _sample(a, overwrite)
    if s is None:
        return float(np.median(a))
    n = s.size
    if n == 0:
        raise ValueError("median of an empty sample")
    if np.isnan(s).any():
        return math.nan
    k = (n - 1) // 2
    s.partition(k)
    if n % 2:
        return float(s[k])
    return float((s[k] + s[k + 1:].min()) / s.dtype.type(2))  # NumPy's mean of the two


def nanmedian(a) -> float:
    """``np.nanmedian(a)`` (over all values) as a float, the same bits: the median of the
    values that are not NaN (infinities count), NaN where all are (without NumPy's
    warning)."""
    arr = np.asarray(a)
    if arr.dtype not in FLOATS:
        return float(np.nanmedian(a))
    kept = arr[~np.isnan(arr)]  # a copy: reordered in place
    return median(kept, overwrite=True) if kept.size else math.nan
