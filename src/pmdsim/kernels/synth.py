"""Phase-shifted fringe images from the per-pixel complex sums (the exact identity
sum_p f_p cos(k u_p + delta) = C cos(delta) - S sin(delta), C + iS = sum_p f_p exp(i k u_p))."""

from __future__ import annotations

from numba import prange

from ._jit import parallel_jit

_CHUNK = 4096  # pixels per parallel chunk


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
    nchunk = (n + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunk):  # a chunk's output rows stay in cache across the blocks
        p0 = ch * _CHUNK
        p1 = min(n, p0 + _CHUNK)
        for b in range(cols.shape[0]):
            col = cols[b]
            for p in range(p0, p1):
                sums[b, p] = complex(sums_raw[p, col] * norm[p], sums_raw[p, col + 1] * norm[p])
            for k in range(cos_d.shape[0]):
                ck = 0.5 * span * cos_d[k]
                sk = 0.5 * span * sin_d[k]
                for p in range(p0, p1):
                    z = sums[b, p]
                    base = (black + 0.5 * span) * f_hit[p]
                    out[b, k, p] = base + (ck * z.real - sk * z.imag)
