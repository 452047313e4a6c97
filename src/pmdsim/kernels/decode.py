"""Compiled kernels for phase-shift decoding and temporal phase unwrapping.

Plain NumPy arrays in and out; the validated public API is :mod:`pmdsim.decode`. Every kernel
has a slow NumPy reference in ``tests/naive_decode.py`` and is compared with it.

Sign convention (``docs/conventions.md``): frames ``I_k = A + B cos(phi + delta_k)`` with
``delta_k = 2 pi k / K`` decode as ``Z = sum_k I_k exp(-i delta_k)``,
``phi = arg Z`` in (-pi, pi], ``B = 2 |Z| / K``, ``A = sum_k I_k / K``.

Fast-math flags: the kernels reassociate and contract floating-point arithmetic, but do **not**
assume finite values (no ``nnan``/``ninf``), because NaN input pixels must be detected and
flagged, and a NaN test under ``nnan`` may be folded to ``False``.

Temporal unwrapping works in monitor pixels: a wrapped phase ``phi`` of period ``w`` gives the
position ``u = phi w / (2 pi)`` modulo ``w``. All methods end with the position of the finest
width and its absolute phase ``Phi = phi_fine + 2 pi m``.

Flag bits written by the kernels (uint8, see :data:`pmdsim.decode.DecodeFlag`):
``1`` non-finite input, ``2`` low fringe amplitude, ``4`` order residual above the threshold,
``8`` monitor coordinate outside ``[-0.5, extent - 0.5)``.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from ._jit import fastjit, parallel_jit

# Fast-math without nnan/ninf: NaN pixels must stay detectable.
_FASTMATH = {"nsz", "arcp", "contract", "reassoc"}

FLAG_NAN_INPUT = np.uint8(1)
FLAG_LOW_AMPLITUDE = np.uint8(2)
FLAG_ORDER_RESIDUAL = np.uint8(4)
FLAG_OUT_OF_RANGE = np.uint8(8)

_TWO_PI = 2.0 * np.pi
_INV_TWO_PI = 1.0 / (2.0 * np.pi)


@fastjit(fastmath=_FASTMATH)
def _accumulate_row(frames, r, cos_d, sin_d, re, im, total):
    """Sums over the K frames of row ``r``: ``re = sum I cos d``, ``im = -sum I sin d``,
    ``total = sum I`` (float64 whatever the frame dtype). ``frames`` is (K, H, W)."""
    n_shifts = frames.shape[0]
    width = frames.shape[2]
    for c in range(width):
        re[c] = 0.0
        im[c] = 0.0
        total[c] = 0.0
    for k in range(n_shifts):
        ck = cos_d[k]
        sk = sin_d[k]
        row = frames[k, r]
        for c in range(width):
            value = np.float64(row[c])
            re[c] += value * ck
            im[c] -= value * sk
            total[c] += value
    return


# Cephes atan rational approximation (|t| <= 0.66), relative error ~2e-16.
_ATAN_P0 = -8.750608600031904122785e-1
_ATAN_P1 = -1.615753718733365076637e1
_ATAN_P2 = -7.500855792314704667340e1
_ATAN_P3 = -1.228866684490136173410e2
_ATAN_P4 = -6.485021904942025371773e1
_ATAN_Q0 = 2.485846490142306297962e1
_ATAN_Q1 = 1.650270098316988542046e2
_ATAN_Q2 = 4.328810604912902668951e2
_ATAN_Q3 = 4.853903996359136964868e2
_ATAN_Q4 = 1.945506571482613964425e2
_PI_4_MOREBITS = 0.25 * np.pi + 0.5 * 6.123233995736765886130e-17


@fastjit(fastmath=_FASTMATH, inline="always")
def atan2(y, x):
    """Branch-free ``arctan2(y, x)`` in (-pi, pi] that LLVM can vectorise (no SVML here).

    Octant reduction to ``t = min/max`` in [0, 1], then ``atan(t)`` by the Cephes rational
    approximation, with ``atan(t) = pi/4 + atan((t - 1)/(t + 1))`` for ``t > 0.66``. Absolute
    error below 1e-15 (tested against ``np.arctan2``); ``atan2(0, 0) = 0``; results that round
    to ``-pi`` (``y`` zero or tiny negative with ``x < 0``) give ``+pi``.
    """
    ax = np.abs(x)
    ay = np.abs(y)
    hi = max(ax, ay)
    lo = min(ax, ay)
    big = lo > 0.66 * hi
    num = lo - hi if big else lo
    den = lo + hi if big else hi
    t = num / den if den > 0.0 else 0.0
    z = t * t
    p = (((_ATAN_P0 * z + _ATAN_P1) * z + _ATAN_P2) * z + _ATAN_P3) * z + _ATAN_P4
    q = ((((z + _ATAN_Q0) * z + _ATAN_Q1) * z + _ATAN_Q2) * z + _ATAN_Q3) * z + _ATAN_Q4
    r = t + t * (z * p / q)
    r = r + _PI_4_MOREBITS if big else r
    r = 0.5 * np.pi - r if ay > ax else r
    r = np.pi - r if x < 0.0 else r
    r = -r if y < 0.0 else r
    return np.pi if r <= -np.pi else r


@fastjit(fastmath=_FASTMATH)
def _finish_row(re, im, total, n_shifts, phase64, phase, amplitude, offset, modulation):
    """phi = atan2(Im Z, Re Z) in (-pi, pi], B = 2|Z|/K, A = sum/K, B/A (NaN where A <= 0).

    Writes the phase twice: float64 into ``phase64`` (for unwrapping) and into ``phase`` (the
    output dtype). Non-finite sums (NaN or inf in any frame) give NaN everywhere."""
    scale = 2.0 / n_shifts
    inv_k = 1.0 / n_shifts
    for c in range(re.shape[0]):
        x = re[c]
        y = im[c]
        s = total[c]
        ok = np.isfinite(x) and np.isfinite(y) and np.isfinite(s)
        phi = atan2(y, x) if ok else np.nan
        b = scale * np.sqrt(x * x + y * y) if ok else np.nan
        a = s * inv_k if ok else np.nan
        phase64[c] = phi
        phase[c] = phi
        amplitude[c] = b
        offset[c] = a
        modulation[c] = b / a if a > 0.0 else np.nan
    return


@parallel_jit(fastmath=_FASTMATH)
def phase_shift(frames, cos_d, sin_d, phase, amplitude, offset, modulation):
    """N-step phase shifting of one width, in parallel over rows.

    frames (K, H, W) float32/float64; cos_d, sin_d (K,) cos/sin of the shifts; outputs
    (H, W): wrapped phase (rad), amplitude B, offset A, modulation B/A (written in place).
    """
    n_shifts, height, width = frames.shape
    for r in prange(height):
        re = np.empty(width)
        im = np.empty(width)
        total = np.empty(width)
        phase64 = np.empty(width)
        _accumulate_row(frames, r, cos_d, sin_d, re, im, total)
        _finish_row(re, im, total, n_shifts, phase64,
                    phase[r], amplitude[r], offset[r], modulation[r])
    return


# --------------------------------------------------------------------------- unwrapping rows


@fastjit(fastmath=_FASTMATH, inline="always")
def _all_finite(phase, c):
    """True if the wrapped phases of every width are finite at column c."""
    for j in range(phase.shape[0]):
        if not np.isfinite(phase[j, c]):
            return False
    return True


@fastjit(fastmath=_FASTMATH, inline="always")
def _store_pixel(c, big_phi, u, worst, f, abs_phase, coord, residual, flags):
    """Write one unwrapped pixel: absolute phase, monitor coordinate, residual, flags."""
    abs_phase[c] = big_phi
    coord[c] = u
    residual[c] = worst
    flags[c] = f


@fastjit(fastmath=_FASTMATH)
def _chain_row(phase, coef, chain_w, window_lo, rewrap_period, extent, max_residual,
               abs_phase, coord, residual, flags):
    """Coarse-to-fine order rounding along a chain (hierarchical and heterodyne).

    phase (n, W): wrapped phases (rad) of the n widths for one row. Chain element L has the
    phase ``sum_j coef[L, j] phase[j]`` (integer coefficients: one-hot for hierarchical,
    beat combinations for heterodyne) and the period ``chain_w[L]`` monitor px; ``chain_w``
    decreases and its last element is a measured width (one-hot row). The first element is
    absolute once wrapped into ``[window_lo, window_lo + chain_w[0])`` monitor px. If
    ``rewrap_period > 0`` (``chain_w[0]``, when it is a multiple of the finest width) the final
    position is wrapped into that window once more: the cut is then decided by the precise
    fine position, not by the noisy coarse one, so monitor-edge pixels do not alias. Writes the
    absolute phase of the last element (rad), its monitor coordinate (px), the largest order
    residual and the flags (1 NaN, 4 residual, 8 out of range; bit 2 is left to the caller).
    """
    n = phase.shape[0]
    n_chain = chain_w.shape[0]
    width = phase.shape[1]
    hi = extent - 0.5
    for c in range(width):
        if not _all_finite(phase, c):
            _store_pixel(c, np.nan, np.nan, np.nan, FLAG_NAN_INPUT, abs_phase, coord, residual, flags)
            continue
        # coarsest element: absolute after wrapping into the window
        p = 0.0
        for j in range(n):
            p += coef[0, j] * phase[j, c]
        lam = chain_w[0]
        u = p * lam * _INV_TWO_PI
        u -= lam * np.floor((u - window_lo) / lam)
        big_phi = u * _TWO_PI / lam
        worst = 0.0
        for step in range(1, n_chain):
            p = 0.0
            for j in range(n):
                p += coef[step, j] * phase[j, c]
            lam = chain_w[step]
            u_fine = p * lam * _INV_TWO_PI
            x = (u - u_fine) / lam  # = (Phi_c w_c / w_f - phi_f) / (2 pi)
            m = np.floor(x + 0.5)
            rr = np.abs(x - m)
            if rr > worst:
                worst = rr
            u = u_fine + m * lam
            big_phi = p + _TWO_PI * m
        if rewrap_period > 0.0:
            big_phi -= _TWO_PI * (rewrap_period / lam) * np.floor(
                (big_phi * lam * _INV_TWO_PI - window_lo) / rewrap_period)
        u = big_phi * lam * _INV_TWO_PI
        f = np.uint8(0)
        if worst > max_residual:
            f |= FLAG_ORDER_RESIDUAL
        if not (u >= -0.5 and u < hi):
            f |= FLAG_OUT_OF_RANGE
        _store_pixel(c, big_phi, u, worst, f, abs_phase, coord, residual, flags)
    return


@fastjit(fastmath=_FASTMATH)
def _coprime_row(phase, order, widths, step_factor, step_inverse, step_period, unit,
                 window_lo, extent, max_residual, abs_phase, coord, residual, flags):
    """Number-theoretic (Chinese-remainder) unwrapping of one row.

    Widths ``w_j = p_j * unit`` with pairwise coprime integers ``p_j``. ``order`` lists the
    widths finest first. Step ``s >= 1`` joins width ``order[s]`` (factor ``b = p``) to the
    position ``U`` known modulo ``step_period[s] = P * unit``: with
    ``t = round((V - U) / unit)``, the order of the period is
    ``m = t * step_inverse[s] mod b`` (``step_inverse`` = P^-1 mod b) and ``U += m P unit``.
    The order residual is ``|(V - U) / unit - t|``. After the last step, ``U`` (known modulo
    ``step_period[-1] * b``) is wrapped into ``[window_lo, window_lo + period)``.
    """
    n = phase.shape[0]
    width = phase.shape[1]
    hi = extent - 0.5
    fine = order[0]
    w_fine = widths[fine]
    total_period = step_period[n - 1] * step_factor[n - 1] if n > 1 else w_fine
    for c in range(width):
        if not _all_finite(phase, c):
            _store_pixel(c, np.nan, np.nan, np.nan, FLAG_NAN_INPUT, abs_phase, coord, residual, flags)
            continue
        u_raw = phase[fine, c] * w_fine * _INV_TWO_PI
        u = u_raw - w_fine * np.floor(u_raw / w_fine)
        worst = 0.0
        for step in range(1, n):
            j = order[step]
            wj = widths[j]
            v = phase[j, c] * wj * _INV_TWO_PI
            v -= wj * np.floor(v / wj)
            d = (v - u) / unit
            t = np.floor(d + 0.5)
            rr = np.abs(d - t)
            if rr > worst:
                worst = rr
            b = step_factor[step]
            q = t * step_inverse[step]
            m = q - b * np.floor(q / b)
            u += m * step_period[step]
        u -= total_period * np.floor((u - window_lo) / total_period)
        m_fine = np.floor((u - u_raw) / w_fine + 0.5)
        big_phi = phase[fine, c] + _TWO_PI * m_fine
        u = big_phi * w_fine * _INV_TWO_PI
        f = np.uint8(0)
        if worst > max_residual:
            f |= FLAG_ORDER_RESIDUAL
        if not (u >= -0.5 and u < hi):
            f |= FLAG_OUT_OF_RANGE
        _store_pixel(c, big_phi, u, worst, f, abs_phase, coord, residual, flags)
    return


# --------------------------------------------------------------------------- parallel drivers


@parallel_jit(fastmath=_FASTMATH)
def unwrap_chain(phase, coef, chain_w, window_lo, rewrap_period, extent, max_residual,
                 abs_phase, coord, residual, flags):
    """Chain unwrapping (hierarchical / heterodyne) of wrapped phases (n, H, W), rows in
    parallel; outputs (H, W). See :func:`_chain_row`."""
    n, height, width = phase.shape
    for r in prange(height):
        rows = np.empty((n, width))
        for j in range(n):
            for c in range(width):
                rows[j, c] = phase[j, r, c]
        _chain_row(rows, coef, chain_w, window_lo, rewrap_period, extent, max_residual,
                   abs_phase[r], coord[r], residual[r], flags[r])
    return


@parallel_jit(fastmath=_FASTMATH)
def unwrap_coprime(phase, order, widths, step_factor, step_inverse, step_period, unit,
                   window_lo, extent, max_residual, abs_phase, coord, residual, flags):
    """Number-theoretic unwrapping of wrapped phases (n, H, W), rows in parallel; outputs
    (H, W). See :func:`_coprime_row`."""
    n, height, width = phase.shape
    for r in prange(height):
        rows = np.empty((n, width))
        for j in range(n):
            for c in range(width):
                rows[j, c] = phase[j, r, c]
        _coprime_row(rows, order, widths, step_factor, step_inverse, step_period, unit,
                     window_lo, extent, max_residual,
                     abs_phase[r], coord[r], residual[r], flags[r])
    return


@fastjit(fastmath=_FASTMATH)
def _shift_widths_row(frames, r, cos_d, sin_d, re, im, total, rows,
                      wrapped, amplitude, offset, modulation):
    """Phase shifting of row ``r`` for all widths of frames (n, K, H, W): float64 phases
    into ``rows`` (n, W), all four maps into the (n, H, W) outputs."""
    n = frames.shape[0]
    n_shifts = frames.shape[1]
    for j in range(n):
        _accumulate_row(frames[j], r, cos_d, sin_d, re, im, total)
        _finish_row(re, im, total, n_shifts, rows[j],
                    wrapped[j, r], amplitude[j, r], offset[j, r], modulation[j, r])
    return


@parallel_jit(fastmath=_FASTMATH)
def decode_chain(frames, cos_d, sin_d, coef, chain_w, window_lo, rewrap_period, extent,
                 max_residual,
                 wrapped, amplitude, offset, modulation, abs_phase, coord, residual, flags):
    """Fused phase shifting + chain unwrapping of frames (n, K, H, W), one pass per row."""
    n, n_shifts, height, width = frames.shape
    for r in prange(height):
        re = np.empty(width)
        im = np.empty(width)
        total = np.empty(width)
        rows = np.empty((n, width))
        _shift_widths_row(frames, r, cos_d, sin_d, re, im, total, rows,
                          wrapped, amplitude, offset, modulation)
        _chain_row(rows, coef, chain_w, window_lo, rewrap_period, extent, max_residual,
                   abs_phase[r], coord[r], residual[r], flags[r])
    return


@parallel_jit(fastmath=_FASTMATH)
def decode_coprime(frames, cos_d, sin_d, order, widths, step_factor, step_inverse,
                   step_period, unit, window_lo, extent, max_residual,
                   wrapped, amplitude, offset, modulation, abs_phase, coord, residual, flags):
    """Fused phase shifting + number-theoretic unwrapping of frames (n, K, H, W)."""
    n, n_shifts, height, width = frames.shape
    for r in prange(height):
        re = np.empty(width)
        im = np.empty(width)
        total = np.empty(width)
        rows = np.empty((n, width))
        _shift_widths_row(frames, r, cos_d, sin_d, re, im, total, rows,
                          wrapped, amplitude, offset, modulation)
        _coprime_row(rows, order, widths, step_factor, step_inverse, step_period, unit,
                     window_lo, extent, max_residual,
                     abs_phase[r], coord[r], residual[r], flags[r])
    return


@parallel_jit(fastmath=_FASTMATH)
def flag_low_amplitude(amplitude, min_amplitude, flags):
    """OR bit 2 into flags (H, W) where amplitude (n, H, W) < min_amplitude[j] for any j.

    NaN amplitudes compare False and are left to the NaN bit."""
    n, height, width = amplitude.shape
    for r in prange(height):
        for j in range(n):
            threshold = min_amplitude[j]
            for c in range(width):
                if amplitude[j, r, c] < threshold:
                    flags[r, c] |= FLAG_LOW_AMPLITUDE
    return
