"""Phase-shifted fringe images from the per-pixel complex sums (the exact identity
sum_p f_p cos(k u_p + delta) = C cos(delta) - S sin(delta), C + iS = sum_p f_p exp(i k u_p))."""

from __future__ import annotations

from numba import prange

from ._jit import parallel_jit


@parallel_jit
def shifted_images(sums_raw, cols, norm, f_hit, cos_d, sin_d, black, white, sums, out):
    """Normalised complex sums and the K shifted camera images of every fringe block
    (direction and width), reading each pixel's kernel output row once.

    Parameters
    ----------
    sums_raw : (P, n_columns) float64
        The kernel's output rows; block ``b`` has C in column ``cols[b]``, S in the next.
    cols : (B,) int64
        The blocks' first columns.
    norm : (P,) float64
        Estimator normalisation per pixel (1/N or 1/sum f).
    f_hit : (P,) float64
        Normalised sum of the weights of rays that hit the monitor.
    cos_d, sin_d : (K,) float64
        cos and sin of the phase shifts.
    sums : (B, P) complex128
        Written: norm * (C + iS).
    out : (B, K, P) float32
        Written: black f_hit + (white - black)(0.5 f_hit + 0.5 (C cos_d - S sin_d)) norm.
    """
    n = sums_raw.shape[0]
    span = white - black
    for p in prange(n):
        base = black * f_hit[p] + span * 0.5 * f_hit[p]
        for b in range(cols.shape[0]):
            c = sums_raw[p, cols[b]] * norm[p]
            s = sums_raw[p, cols[b] + 1] * norm[p]
            sums[b, p] = complex(c, s)
            for k in range(cos_d.shape[0]):
                out[b, k, p] = base + span * 0.5 * (c * cos_d[k] - s * sin_d[k])
