"""Phase-shifted fringe images from the per-pixel complex sums (the exact identity
sum_p f_p cos(k u_p + delta) = C cos(delta) - S sin(delta), C + iS = sum_p f_p exp(i k u_p)).

:func:`fringe_rows` finishes one block of pixels (a render tile's camera rows, called in the
tile's own task right after the bundle kernel wrote them, while they are in cache): the
estimator's normalisation, f_total and f_hit, the normalised complex sums and the K shifted
images of every fringe block. No pass over the whole (H, W, C) output follows the render.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from ._jit import jit, parallel_jit

#: Floating point of :func:`fringe_rows`: contraction to FMA as before (bit-identical images),
#: but no ``nnan``/``ninf``: its pixels off the plate are NaN and must stay NaN.
_FINISH_FLAGS = {"contract", "nsz", "reassoc"}

_FTOTAL = 0  # the bundle kernels' output columns (kernels.bundle.OUT_FTOTAL, OUT_FHIT)
_FHIT = 1


@jit(fastmath=_FINISH_FLAGS)
def fringe_rows(sums_raw, cols, ratio, inv_n, cos_d, sin_d, black, white, norm, f_total,
                f_hit, sums, out):
    """Estimator values of one block of pixels from the bundle kernel's sums.

    Parameters
    ----------
    sums_raw : (P, n_columns) float64
        The kernel's output rows; block ``b`` has C in column ``cols[b]``, S in the next.
    cols : (B,) int64
        The blocks' first columns.
    ratio : bool
        The ``weighted_mean`` estimator: normalise by 1 / sum f (NaN where sum f <= 0 or
        NaN); else by ``inv_n`` (1 / N).
    cos_d, sin_d : (K,) float64
        cos and sin of the phase shifts.
    norm, f_total, f_hit : (P,) float64
        Written: the normalisation, and the normalised sums of all weights and of the
        weights of rays that hit the monitor.
    sums : (B, P) complex128
        Written: norm * (C + iS).
    out : (B, K, P) float32
        Written: black f_hit + (white - black)(0.5 f_hit + 0.5 (C cos_d - S sin_d)) norm.
    """
    n = sums_raw.shape[0]
    span = white - black
    for p in range(n):
        ft = sums_raw[p, _FTOTAL]
        if ratio:
            nm = 1.0 / ft if ft > 0.0 else math.nan
        else:
            nm = inv_n
        norm[p] = nm
        f_total[p] = ft * nm
        f_hit[p] = sums_raw[p, _FHIT] * nm
    for b in range(cols.shape[0]):
        col = cols[b]
        for p in range(n):
            sums[b, p] = complex(sums_raw[p, col] * norm[p], sums_raw[p, col + 1] * norm[p])
        for k in range(cos_d.shape[0]):
            ck = 0.5 * span * cos_d[k]
            sk = 0.5 * span * sin_d[k]
            for p in range(n):
                z = sums[b, p]
                base = (black + 0.5 * span) * f_hit[p]
                out[b, k, p] = base + (ck * z.real - sk * z.imag)


@jit
def fringe_error_rows(d1, d2, cols, norm, sums, err, ratio, rel):
    """The numerical error of the normalised complex sums of one block of pixels, from the
    render's signed differences to the embedded rules (``d1``, and ``d2`` or an empty
    (0, 0) array), reading each pixel's difference rows once.

    Writes ``err[b, p] = |norm[p]| (D1_C + i D1_S)`` for every fringe block ``b`` (C in
    column ``cols[b]`` of ``d1``, S in the next) and, with ``d2``, the inputs of the
    observed convergence (:func:`pmdsim.render.results.convergence_of_ratios`):
    ``ratio = |dS1| / |dS2|`` and ``rel = |dS1| / |S|`` (``sums`` the normalised sums).
    Strict IEEE arithmetic; ``err`` has the bytes of the NumPy expressions it replaced,
    the ratios (which only enter medians) are taken from squared moduli, within a few ulp
    of the moduli's ratios.
    """
    n = d1.shape[0]
    second = d2.shape[0] > 0
    for b in range(cols.shape[0]):
        col = cols[b]
        for p in range(n):
            a = abs(norm[p])
            e1 = complex(d1[p, col] * a, d1[p, col + 1] * a)
            err[b, p] = e1
            if second:  # the moduli's ratios from their squares: one root, no hypot
                x2, y2 = d2[p, col] * a, d2[p, col + 1] * a
                q1 = e1.real * e1.real + e1.imag * e1.imag
                s = sums[b, p]
                ratio[b, p] = math.sqrt(q1 / (x2 * x2 + y2 * y2))
                rel[b, p] = math.sqrt(q1 / (s.real * s.real + s.imag * s.imag))


@jit
def phase_error_rows(sums, err, mag, roundoff, p0, p1, out):
    """The replicates' phase error of :func:`pmdsim.render.results.phase_error` for sums
    ``p0:p1`` of ``sums`` and their half-widths ``err`` (1-D complex each) into ``out``:
    ``hypot(err.real sin, err.imag cos) / |S|``, at least ``roundoff``, NaN where
    ``|S| = 0``, the same arithmetic in the same order as its NumPy expressions (strict
    IEEE: the same bytes), given ``mag = |sums|`` as NumPy computes it (its complex
    absolute value is not the C library's ``hypot`` in the last place)."""
    nan = math.nan
    for p in range(p0, p1):
        m = mag[p]
        c = sums[p].real / m
        s = sums[p].imag / m
        v = math.hypot(err[p].real * s, err[p].imag * c) / m
        if v < roundoff:  # np.maximum: NaN stays NaN
            v = roundoff
        out[p] = v if m > 0 else nan


@jit
def phase_error_embedded_rows(sums, err, mag, emag, q, floor, safety, roundoff, p0, p1, out):
    """The embedded rule's phase error of :func:`pmdsim.render.results.phase_error` for
    fringe ``f`` = row of ``sums`` (F, P), pixels ``p0:p1``, into ``out`` (F, P):
    ``|Im(dS conj S)| / |S|^2 + floor |dS| / |S|``, scaled as ``safety q`` and ``floor q``
    where the fringe's convergence factor ``q[f] < 1`` (``q`` empty: no factors), at least
    ``roundoff``, NaN where ``|S| = 0``; the same arithmetic in the same order as its NumPy
    expressions (strict IEEE), given ``mag = |sums|`` and ``emag = |err|`` as NumPy
    computes them, except ``Im(err conj S)``, which NumPy's SIMD complex product may round
    through an FMA (the statement then agrees to 1e-13 of itself)."""
    nan = math.nan
    for f in range(sums.shape[0]):
        fast = False
        if q.shape[0] > 0:
            qf = q[f]
            fast = qf < 1.0
            a_scale = safety * qf
            r_scale = floor * qf
        for p in range(p0, p1):
            m = mag[f, p]
            s = sums[f, p]
            e = err[f, p]
            im = e.real * -s.imag + e.imag * s.real  # (err * conj(sums)).imag
            across = abs(im) / (m * m)
            rel = emag[f, p] / m
            if fast:
                v = a_scale * across + r_scale * rel
            else:
                v = across + floor * rel
            if v < roundoff:  # np.maximum: NaN stays NaN
                v = roundoff
            out[f, p] = v if m > 0 else nan


@jit
def replicate_update_rows(t, h, hcols, tcols, r, mean_res, mean_s, m2_re, m2_im):
    """One rqmc replicate of the nearest monitor's control variate for one block of pixels
    on a linear display (:func:`pmdsim.render.tile_tasks.replicates_fused`): the residual
    ``res = t - to_tables(h)`` (the table columns ``tcols[f], tcols[f] + 1`` of fringe
    ``f`` take ``h``'s ``hcols[f], hcols[f] + 1``, the first two columns its first two,
    the rest zero), its first two columns zeroed (f_total, f_hit: the rule's), the running
    mean ``mean_res`` (P, C) of the residuals, and Welford's update of the fringe sums
    ``S = res[tc] + i res[tc + 1]``: ``mean_s`` (F, P) complex, ``m2_re``/``m2_im`` (F, P),
    replicate ``r`` (0: the first). The same arithmetic in the same order as the NumPy
    expressions it replaces (complex sums and quotients written out as NumPy evaluates
    them: the same bytes). (A linear display's box rule leaves no replicates.)"""
    n, ncols = t.shape
    nf = tcols.shape[0]
    den = float(r + 1)
    scl = 1.0 / (den + 0.0 * 0.0)  # NumPy's complex quotient by (r + 1) + 0i (Smith)
    res = np.empty(ncols)
    for p in range(n):
        for c in range(2, ncols):  # t - 0.0: the table columns without a harmonic twin
            res[c] = t[p, c]
        for f in range(nf):
            tc, hc = tcols[f], hcols[f]
            res[tc] = t[p, tc] - h[p, hc]
            res[tc + 1] = t[p, tc + 1] - h[p, hc + 1]
        res[0] = 0.0  # f_total, f_hit: the rule's (the NumPy path zeroes t - h there)
        res[1] = 0.0
        for c in range(ncols):
            mean_res[p, c] += (res[c] - mean_res[p, c]) / den
        for f in range(nf):
            a, x = res[tcols[f]], res[tcols[f] + 1]
            sr = a + (0.0 * x - 1.0 * 0.0)  # a + 1j * x, as NumPy computes it
            si = 0.0 + (0.0 * 0.0 + 1.0 * x)
            if r == 0:
                mean_s[f, p] = complex(sr, si)
                continue
            m = mean_s[f, p]
            dr, di = sr - m.real, si - m.imag
            nr = m.real + (dr + di * 0.0) * scl
            ni = m.imag + (di - dr * 0.0) * scl
            mean_s[f, p] = complex(nr, ni)
            m2_re[f, p] += dr * (sr - nr)
            m2_im[f, p] += di * (si - ni)


@jit
def complex_of_columns(t, cols, p0, p1, out):
    """``out[f, p] = t[p, cols[f]] + 1j * t[p, cols[f] + 1]`` for pixels ``p0:p1`` (``t``
    (P, C) float32 or float64, each value taken exactly as float64; ``out`` (F, P)
    complex128), with NumPy's arithmetic for a float plus an imaginary float (signed zeros,
    inf and NaN as NumPy gives them: the same bytes)."""
    for f in range(cols.shape[0]):
        c = cols[f]
        for p in range(p0, p1):
            a = np.float64(t[p, c])
            x = np.float64(t[p, c + 1])
            out[f, p] = complex(a + (0.0 * x - 1.0 * 0.0), 0.0 + (0.0 * 0.0 + 1.0 * x))


@jit
def half_width_rows(m2_re, m2_im, half, p0, p1, out):
    """``out = half * sqrt(m2_re) + 1j * half * sqrt(m2_im)`` for elements ``p0:p1`` of the
    1-D arrays (the rqmc replicates' half-widths of the sums' real and imaginary parts),
    with NumPy's arithmetic for it (the same bytes)."""
    hr, hi = 0.0 * half, 1.0 * half  # the Python scalar 1j * half
    for p in range(p0, p1):
        a = half * math.sqrt(m2_re[p])
        x = math.sqrt(m2_im[p])
        out[p] = complex(a + (hr * x - hi * 0.0), 0.0 + (hr * 0.0 + hi * x))


#: ``numpy.spacing`` of a non-negative float32 by its 8 exponent bits ``E``: ``2^(E - 150)``
#: for normal values, ``2^-149`` for zero and subnormals, NaN for inf and NaN.
F32_SPACING = np.array([2.0**-149] + [2.0 ** (e - 150) for e in range(1, 255)] + [math.nan])


@jit(fastmath=_FINISH_FLAGS)
def _floor_edge(imgs, bits, p, cos_d, sin_d, w, lmax, sigmas):
    """``(floor, edge)`` of pixel ``p`` (:func:`phase_floor_rows`)."""
    k = imgs.shape[0]
    zr = 0.0
    zi = 0.0
    for j in range(k):
        v = np.float64(imgs[j, p])
        zr += v * cos_d[j]
        zi -= v * sin_d[j]
    a2 = zr * zr + zi * zi
    a = math.sqrt(a2)
    var = 0.0
    for j in range(k):
        u = F32_SPACING[(bits[j, p] >> 23) & 0xFF]
        if a2 > 0.0:
            t = (zi * cos_d[j] + zr * sin_d[j]) / a
        else:
            t = sin_d[j]
        var += (u * u / 12.0) * t * t
    return sigmas * math.sqrt(var) / a, (k * w * lmax / a if w > 0.0 else 0.0)


@parallel_jit(fastmath=_FINISH_FLAGS)
def phase_floor_rows(imgs, cos_d, sin_d, weight, lmax, sigmas, floor, edge):
    """The phase floors of one fringe's K shifted float32 images ``imgs`` (K, P), in
    parallel over pixels.

    ``Z = sum_k I_k exp(-i delta_k)``; ``floor[p]`` is ``sigmas`` times the standard
    deviation of ``arg Z`` that rounding every image to nearest float32 gives (errors
    uniform within half the value's spacing ``u_k``, independent):
    ``sqrt(sum_k (u_k^2 / 12) sin^2(arg Z + delta_k)) / |Z|``, with
    ``sin(arg Z + delta) = (Im Z cos delta + Re Z sin delta) / |Z|`` (``arg 0 = 0``, as
    NumPy's angle); ``edge[p]`` is the phase change that moving ``weight[p]`` of the lobe's
    weight at luminance up to ``lmax`` can give, ``K weight lmax / |Z|`` (0 where
    ``weight`` is not > 0). NaN images give NaN.
    """
    n = imgs.shape[1]
    bits = imgs.view(np.uint32)
    for p in prange(n):
        floor[p], edge[p] = _floor_edge(imgs, bits, p, cos_d, sin_d, weight[p], lmax, sigmas)


@parallel_jit(fastmath={"nsz"})
def add_phase_floors(imgs, cos_d, sin_d, weight, lmax, sigmas, roundoff, unknown, ok, stated):
    """Finish a stated phase error (P,) in place with the floors of its fringe's images
    (K, P) (:func:`phase_floor_rows`), in parallel over pixels, with no (P,) temporaries:
    ``stated + floor + roundoff + edge`` (in that order), pi where ``unknown`` and finite,
    at most pi, NaN where not ``ok``: the same values as those steps on whole arrays."""
    n = imgs.shape[1]
    bits = imgs.view(np.uint32)
    for p in prange(n):
        if not ok[p]:
            stated[p] = math.nan
            continue
        f, e = _floor_edge(imgs, bits, p, cos_d, sin_d, weight[p], lmax, sigmas)
        v = stated[p] + f
        v = v + roundoff
        v = v + e
        if unknown and math.isfinite(v):
            v = math.pi
        if v > math.pi:
            v = math.pi
        stated[p] = v


@jit
def decodable_values(err, sums, f_hit, f_total, min_modulation, max_off, out):
    """Gather into ``out`` (P,) the finite values of ``err`` (P,) (one fringe's stated
    phase error) at the pixels whose fringe keeps a modulation ``|sums| / f_hit >=
    min_modulation`` and whose lobe puts at most ``max_off`` of its weight off the monitor
    (``1 - |f_hit| / |f_total|``; NaN counts as at most), in pixel order; returns how many.
    The NumPy reference is the whole-array expression of
    :func:`pmdsim.render.results.worst_phase_error`."""
    n = 0
    for p in range(err.shape[0]):
        e = err[p]
        if not math.isfinite(e):
            continue
        fh = f_hit[p]
        off = 1.0 - abs(fh) / abs(f_total[p])
        if off > max_off:
            continue  # modulation 0
        s = sums[p]
        mod = math.hypot(s.real, s.imag) / fh
        if mod >= min_modulation:
            out[n] = e
            n += 1
    return n


@parallel_jit
def fill_blocks(values, s, out):
    """``out[b, r, c] = values[b, r // s, c // s]`` (``values`` (B, gh, gw), ``out`` (B, H,
    W) with ``H <= gh s``, ``W <= gw s``), in parallel over rows: every pixel takes its
    ``s x s`` block's value (the pilot's envelope on the camera)."""
    nb, h, w = out.shape
    for rr in prange(nb * h):
        b = rr // h
        r = rr - b * h
        i = r // s
        for c in range(w):
            out[b, r, c] = values[b, i, c // s]
