"""Phase-shifted fringe images from the per-pixel complex sums (the exact identity
sum_p f_p cos(k u_p + delta) = C cos(delta) - S sin(delta), C + iS = sum_p f_p exp(i k u_p))."""

from __future__ import annotations

import numpy as np
from numba import prange

from ._jit import parallel_jit


@parallel_jit
def shifted_images(c, s, f_hit, cos_d, sin_d, black, white, out):
    """out[k] = black f_hit + (white - black)(0.5 f_hit + 0.5 (c cos_d[k] - s sin_d[k])).

    c, s, f_hit : (P,) float64 normalised sums; out : (K, P) float32.
    """
    n = c.shape[0]
    span = white - black
    for p in prange(n):
        base = black * f_hit[p] + span * 0.5 * f_hit[p]
        for k in range(cos_d.shape[0]):
            out[k, p] = base + span * 0.5 * (c[p] * cos_d[k] - s[p] * sin_d[k])
