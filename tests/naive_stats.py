"""Slow, obvious references for the statistics the measurement chain reports (issue 9).

Plain Python loops and textbook formulas, written without looking at how
``pmdsim.measure.deviation`` / ``pmdsim.studies`` compute the same numbers: the tests compare
the fast code with these, so a bug must be made twice to pass.
"""

from __future__ import annotations

import math

import numpy as np


def mean(values) -> float:
    vals = [float(x) for x in values]
    return sum(vals) / len(vals)


def population_std(values) -> float:
    """sqrt(sum (x - mean)^2 / n): the spread of the map itself (not an estimate of a
    population's spread from a sample, which would divide by n - 1)."""
    vals = [float(x) for x in values]
    m = mean(vals)
    return math.sqrt(sum((x - m) ** 2 for x in vals) / len(vals))


def rms(values) -> float:
    vals = [float(x) for x in values]
    return math.sqrt(sum(x * x for x in vals) / len(vals))


def percentile_linear(values, q: float) -> float:
    """The q-th percentile with linear interpolation between closest ranks (the definition
    NumPy's default uses: rank h = (n - 1) q / 100, 0-based)."""
    vals = sorted(float(x) for x in values)
    h = (len(vals) - 1) * q / 100.0
    lo = int(math.floor(h))
    hi = min(lo + 1, len(vals) - 1)
    return vals[lo] + (h - lo) * (vals[hi] - vals[lo])


def circular_std_about_mean(phases, ddof: int = 1) -> float:
    """Spread of angles about their circular mean: each angle's difference from the mean
    direction is taken the short way round (|.| <= pi), then sqrt(sum d^2 / (n - ddof))."""
    c = sum(math.cos(p) for p in phases)
    s = sum(math.sin(p) for p in phases)
    centre = math.atan2(s, c)
    devs = []
    for p in phases:
        d = (p - centre) % (2 * math.pi)
        if d > math.pi:
            d -= 2 * math.pi
        devs.append(d)
    return math.sqrt(sum(d * d for d in devs) / (len(devs) - ddof))


def thresholded_gaussian_variance_factor(t: float) -> float:
    """Per-axis variance, in units of sigma^2, of the weight ``max(g - t, 0)`` for a unit-peak
    isotropic Gaussian ``g = exp(-r^2 / (2 sigma^2))`` and a threshold ``0 <= t < 1``.

    With Q = -ln t the cut radius is R^2 = 2 Q sigma^2 and (sigma = 1)
    M0 = int (g - t) dA = 2 pi (1 - t - Q t),
    M2 = int (g - t) r^2 dA = 2 pi (2 - 2 (1 + Q) t - Q^2 t),
    variance per axis = M2 / (2 M0).
    """
    if t <= 0.0:
        return 1.0
    q = -math.log(t)
    m0 = 1.0 - t - q * t
    m2 = 2.0 - 2.0 * (1.0 + q) * t - q * q * t
    return m2 / (2.0 * m0)


def image_second_moments_loop(img, threshold: float = 0.0):
    """Centroid (col, row) and covariance [[cc, cr], [cr, rr]] of ``max(img - threshold, 0)``
    over finite pixels, by explicit loops."""
    h, w = img.shape
    tot = sx = sy = 0.0
    for r in range(h):
        for c in range(w):
            v = float(img[r, c])
            if math.isfinite(v) and v > threshold:
                wt = v - threshold
                tot += wt
                sx += wt * c
                sy += wt * r
    cx, cy = sx / tot, sy / tot
    cxx = cyy = cxy = 0.0
    for r in range(h):
        for c in range(w):
            v = float(img[r, c])
            if math.isfinite(v) and v > threshold:
                wt = v - threshold
                cxx += wt * (c - cx) ** 2
                cyy += wt * (r - cy) ** 2
                cxy += wt * (c - cx) * (r - cy)
    return (cx, cy), np.array([[cxx, cxy], [cxy, cyy]]) / tot


def gaussian_spot(shape, centre, sigma_major, sigma_minor, angle, peak=1.0, supersample=1):
    """Image of an elliptical Gaussian (major axis at ``angle`` from +col towards +row),
    point-sampled at pixel centres, or averaged over ``supersample`` x ``supersample``
    mid-points of each pixel (a pixel-integrated spot)."""
    h, w = shape
    n = supersample
    offs = (np.arange(n) + 0.5) / n - 0.5
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    c, s = math.cos(angle), math.sin(angle)
    out = np.zeros(shape)
    for oy in offs:
        for ox in offs:
            x = cols + ox - centre[0]
            y = rows + oy - centre[1]
            a = c * x + s * y
            b = -s * x + c * y
            out += np.exp(-0.5 * ((a / sigma_major) ** 2 + (b / sigma_minor) ** 2))
    return peak * out / (n * n)
