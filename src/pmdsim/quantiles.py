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

A sample of at least :data:`WINDOW_MIN` values is not partitioned whole: a strided
subsample of :data:`SUBSAMPLE` values, sorted, gives a window of values that holds the two
order statistics wanted with a margin of :data:`WINDOW_SIGMAS` binomial standard
deviations; one compiled pass (:func:`pmdsim.kernels.select.window_values`) counts the
values below the window and gathers those inside it, and partitioning those few gives the
same two order statistics (2-3 ms instead of 6-10 ms on a Fig. 3 map). Where the window
misses them (a subsample unlike the sample), the whole sample is partitioned as before: the
window decides only the time, never the value.
"""

from __future__ import annotations

import math

import numpy as np

#: The types of the fast path (the arithmetic stays in the sample's type, as NumPy's).
FLOATS = (np.float32, np.float64)
#: Samples of at least this many values take the window (:func:`_order_pair`).
WINDOW_MIN = 1 << 16
#: Values of the strided subsample that places the window.
SUBSAMPLE = 2048
#: The window's margin about the wanted rank in the subsample, in binomial standard
#: deviations of that rank (plus :data:`WINDOW_PAD` ranks).
WINDOW_SIGMAS = 6.0
WINDOW_PAD = 8


def _order_pair(s: np.ndarray, k: int, reorder: bool):
    """``(s_(k), s_(k+1))``: the k-th and (k+1)-th smallest values of the 1-D float sample
    ``s`` (0-based, ``k + 1 < s.size``), as NumPy scalars of its type; None where ``s``
    holds a NaN. ``reorder``: ``s`` may be reordered (else a partition works on a copy)."""
    n = s.size
    if n >= WINDOW_MIN:
        from .kernels.select import window_values

        stride = n // SUBSAMPLE
        sub = np.sort(s[::stride])
        if np.isnan(sub[-1]):
            return None
        m = sub.size
        p = (k + 0.5) / n
        margin = int(WINDOW_SIGMAS * math.sqrt(m * p * (1.0 - p))) + WINDOW_PAD
        r = int(p * m)
        low = sub[r - margin] if r - margin >= 0 else s.dtype.type(-np.inf)
        high = sub[r + 1 + margin] if r + 1 + margin < m else s.dtype.type(np.inf)
        buf = np.empty(min(n, 2 * (2 * margin + 2) * stride + 1024), s.dtype)
        below, inside, nan = window_values(s, low, high, buf)
        if nan:
            return None
        if below <= k and k + 1 < below + inside and inside < buf.size:
            part = buf[:inside]
            j = k - below
            part.partition(j)
            return part[j], part[j + 1:].min()
    elif np.isnan(s).any():
        return None
    if not reorder:
        s = s.copy()
    s.partition(k)
    return s[k], s[k + 1:].min()


def _sample(a, overwrite: bool) -> tuple[np.ndarray | None, bool]:
    """``(a as a 1-D float32/float64 array, whether it may be reordered)``: a view where
    it can be, reordered in place only with ``overwrite`` (else copied before a partition);
    ``(None, False)`` for NumPy."""
    arr = np.asarray(a)
    if arr.dtype not in FLOATS:
        return None, False
    flat = arr.ravel()
    own = not np.may_share_memory(flat, arr)  # ravel copied
    return flat, own or (overwrite and flat.flags.writeable)


def percentile(a, q: float, *, overwrite: bool = False) -> float:
    """``np.percentile(a, q)`` (method ``"linear"``, over all values) as a float, the same
    bits. ``overwrite``: ``a`` may be reordered (no copy). NaN where ``a`` holds a NaN;
    ``a`` must not be empty."""
    s, reorder = _sample(a, overwrite)
    if s is None:
        return float(np.percentile(a, q))
    n = s.size
    if n == 0:
        raise ValueError("percentile of an empty sample")
    if not 0 <= q <= 100:
        raise ValueError(f"percentile: q must be within [0, 100], got {q}")
    qf = np.true_divide(q, 100)  # as NumPy: q / 100 in float64, then the virtual index
    virtual = (n - 1) * qf
    if virtual >= n - 1:  # NumPy takes the last value for both neighbours
        return math.nan if np.isnan(s).any() else float(s.max())
    lo = int(np.floor(virtual))
    gamma = float(virtual - lo)  # a Python float (NumPy's for a Python q): the sample's type
    pair = _order_pair(s, lo, reorder)
    if pair is None:
        return math.nan
    a_lo, a_hi = pair
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
    s, reorder = _sample(a, overwrite)
    if s is None:
        return float(np.median(a))
    n = s.size
    if n == 0:
        raise ValueError("median of an empty sample")
    k = (n - 1) // 2
    if n == 1:
        return float(s[0])
    pair = _order_pair(s, k, reorder)
    if pair is None:
        return math.nan
    if n % 2:
        return float(pair[0])
    return float((pair[0] + pair[1]) / s.dtype.type(2))  # NumPy's mean of the two


def nanmedian(a) -> float:
    """``np.nanmedian(a)`` (over all values) as a float, the same bits: the median of the
    values that are not NaN (infinities count), NaN where all are (without NumPy's
    warning)."""
    arr = np.asarray(a)
    if arr.dtype not in FLOATS:
        return float(np.nanmedian(a))
    kept = arr[~np.isnan(arr)]  # a copy: reordered in place
    return median(kept, overwrite=True) if kept.size else math.nan
