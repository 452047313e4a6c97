"""Compiled passes over camera images: the brightest finite value (the run's exposure), the
integer image of a float one, the finite values of a masked map (the statistics of a
deviation), whether any value is lit and the float32 parts of complex sums, each one pass
without temporaries. The NumPy references
are the expressions they replace (:func:`pmdsim.store.images.exposure_factor`,
:func:`pmdsim.store.images.to_integer_image`, :func:`pmdsim.measure.deviation.deviation_stats`, :func:`pmdsim.studies.coverage.check_rendered`, :func:`pmdsim.store.schema.build_dataset`);
``tests/store/test_io.py`` and ``tests/measure/test_deviation_stats.py`` compare them.
"""

from __future__ import annotations

import math

import numpy as np

from numba import prange

from ._jit import jit, parallel_jit


@jit
def finite_max(a):
    """The largest finite value of ``a`` (1-D, any float type) as float64, and whether
    there is one (``(-inf, False)`` where none is finite)."""
    best = -math.inf
    found = False
    for i in range(a.shape[0]):
        v = np.float64(a[i])
        if math.isfinite(v) and (not found or v > best):
            best = v
            found = True
    return best, found


@jit
def to_integer(values, exposure, top, out):
    """``out = rint(clip(values * exposure, 0, top))`` with NaN and inf products as 0
    (``values`` 1-D, any float type, each product in float64; ``out`` 1-D integers):
    NumPy's ``multiply(values, exposure, dtype=float64)``, ``clip``, ``rint`` (half to
    even) and the cast, in one pass."""
    for i in range(values.shape[0]):
        v = np.float64(values[i]) * exposure
        if not math.isfinite(v):
            v = 0.0
        elif v < 0.0:
            v = 0.0
        elif v > top:
            v = top
        out[i] = np.rint(v)


@jit
def gather_finite(values, mask, out):
    """Gather into ``out`` (float64) the finite values of ``values`` (1-D, any float type)
    where ``mask`` (1-D bool, or an empty array: everywhere) holds, in order; returns
    ``(n, n_either)``: how many were gathered, and how many elements are in ``mask`` or
    finite (a deviation's considered pixels). The NumPy reference is
    ``values[mask & isfinite(values)]`` and ``count_nonzero(mask | isfinite(values))``."""
    n = 0
    either = 0
    everywhere = mask.shape[0] == 0
    for i in range(values.shape[0]):
        v = np.float64(values[i])
        fin = math.isfinite(v)
        m = everywhere or mask[i]
        if m or fin:
            either += 1
        if m and fin:
            out[n] = v
            n += 1
    return n, either


@jit
def any_positive(values):
    """Whether any value of ``values`` (1-D, any float type) is > 0 (NaN is not); stops at
    the first. The NumPy reference is ``numpy.any(values > 0)``."""
    for i in range(values.shape[0]):
        if values[i] > 0:
            return True
    return False


@parallel_jit
def parts_float32(z, re, im):
    """``re, im = z.real, z.imag`` as float32 (``z`` 1-D complex128), one parallel pass:
    NumPy's ``z.real.astype(float32)`` and ``z.imag.astype(float32)`` (round to nearest)."""
    for i in prange(z.shape[0]):
        v = z[i]
        re[i] = np.float32(v.real)
        im[i] = np.float32(v.imag)
