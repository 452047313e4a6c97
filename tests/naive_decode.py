"""Slow, obvious NumPy references of the decoding kernels (``pmdsim.kernels.decode``).

Written for clarity, not speed: complex arithmetic for phase shifting, explicit wrapped beat
phases for heterodyne, a brute-force table of order pairs for the number-theoretic method and
per-pixel Python loops where that is the plainest way to say it.
"""

from __future__ import annotations

import math

import numpy as np

NAN_INPUT, LOW_AMPLITUDE, ORDER_RESIDUAL, OUT_OF_RANGE = 1, 2, 4, 8


def phase_shift(frames):
    """frames (K, H, W) -> wrapped phase, amplitude B, offset A, modulation B/A (float64)."""
    frames = np.asarray(frames, dtype=np.float64)
    n_shifts = frames.shape[0]
    delta = 2 * np.pi * np.arange(n_shifts) / n_shifts
    z = np.tensordot(np.exp(-1j * delta), frames, axes=1)
    phase = np.angle(z)
    phase[phase <= -np.pi] = np.pi
    amplitude = 2 * np.abs(z) / n_shifts
    offset = frames.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        modulation = np.where(offset > 0, amplitude / offset, np.nan)
    bad = ~np.all(np.isfinite(frames), axis=0)
    for arr in (phase, amplitude, offset, modulation):
        arr[bad] = np.nan
    return phase, amplitude, offset, modulation


def _window_lo(extent, period):
    return (extent - period - 1) / 2


def _order_step(coarse_u, phase_fine, w_fine):
    """One hierarchical step in monitor px: returns (u_fine_absolute, Phi_fine, residual)."""
    u_fine = phase_fine * w_fine / (2 * np.pi)
    x = (coarse_u - u_fine) / w_fine
    m = np.floor(x + 0.5)
    return u_fine + m * w_fine, phase_fine + 2 * np.pi * m, np.abs(x - m)


def _rewrap(big_phi, w_fine, period, extent):
    """If period is a multiple of w_fine, wrap the final position into the window again."""
    ratio = period / w_fine
    if abs(ratio - round(ratio)) > 1e-9 * ratio:
        return big_phi
    u = big_phi * w_fine / (2 * np.pi)
    lo = _window_lo(extent, period)
    return 2 * np.pi * (lo + np.mod(u - lo, period)) / w_fine


def _finish(big_phi, w_fine, residual, extent, max_residual, bad):
    coord = big_phi * w_fine / (2 * np.pi)
    flags = np.zeros(coord.shape, np.uint8)
    flags[residual > max_residual] |= ORDER_RESIDUAL
    flags[~((coord >= -0.5) & (coord < extent - 0.5))] |= OUT_OF_RANGE
    flags[bad] = NAN_INPUT
    for arr in (big_phi, coord, residual):
        arr[bad] = np.nan
    return big_phi, coord, residual, flags


def unwrap_hierarchical(phase, widths, extent, max_residual=0.25):
    """phase (n, H, W) of widths (n,) -> absolute phase of the finest, coord px, residual, flags."""
    phase = np.asarray(phase, dtype=np.float64)
    widths = np.asarray(widths, dtype=np.float64)
    bad = ~np.all(np.isfinite(phase), axis=0)
    phase = np.where(bad, 0.0, phase)
    order = np.argsort(-widths)
    w0 = widths[order[0]]
    lo = _window_lo(extent, w0)
    u = lo + np.mod(phase[order[0]] * w0 / (2 * np.pi) - lo, w0)
    big_phi = 2 * np.pi * u / w0
    residual = np.zeros(u.shape)
    for j in order[1:]:
        u, big_phi, r = _order_step(u, phase[j], widths[j])
        residual = np.maximum(residual, r)
    big_phi = _rewrap(big_phi, widths[order[-1]], w0, extent)
    return _finish(big_phi, widths[order[-1]], residual, extent, max_residual, bad)


def unwrap_heterodyne(phase, widths, extent, max_residual=0.25):
    """Beat tree with explicitly wrapped beat phases in [0, 2 pi), then hierarchical steps."""
    phase = np.asarray(phase, dtype=np.float64)
    widths = np.asarray(widths, dtype=np.float64)
    bad = ~np.all(np.isfinite(phase), axis=0)
    phase = np.where(bad, 0.0, phase)
    idx = np.argsort(widths)
    levels = [([phase[i] for i in idx], [widths[i] for i in idx])]
    while len(levels[-1][0]) > 1:
        phis, lams = levels[-1]
        new_phis, new_lams = [], []
        for i in range(len(phis) - 1):
            if lams[i] < lams[i + 1]:
                beat = phis[i] - phis[i + 1]
            else:
                beat = phis[i + 1] - phis[i]
            new_phis.append(np.mod(beat, 2 * np.pi))
            new_lams.append(lams[i] * lams[i + 1] / abs(lams[i] - lams[i + 1]))
        levels.append((new_phis, new_lams))
    top_phi, top_lam = levels[-1][0][0], levels[-1][1][0]
    lo = _window_lo(extent, top_lam)
    u = lo + np.mod(top_phi * top_lam / (2 * np.pi) - lo, top_lam)
    residual = np.zeros(u.shape)
    big_phi = 2 * np.pi * u / top_lam
    for phis, lams in levels[-2::-1]:
        u, big_phi, r = _order_step(u, phis[0], lams[0])
        residual = np.maximum(residual, r)
    big_phi = _rewrap(big_phi, levels[0][1][0], top_lam, extent)
    return _finish(big_phi, levels[0][1][0], residual, extent, max_residual, bad)


def unwrap_number_theoretic(phase, widths, extent, max_residual=0.25):
    """Pairwise coprime integer widths; orders looked up in a brute-force table, pixel by pixel.

    Widths are joined finest first: the position ``U`` known modulo ``P g`` and the position
    ``V`` of the next width ``b g`` (both in [0, period)) satisfy ``(V - U)/g = m1 P - m2 b``
    for the unique pair ``m1 in [0, b)``, ``m2 in [0, P)``, found in a table of all pairs.
    """
    phase = np.asarray(phase, dtype=np.float64)
    widths = np.asarray(widths, dtype=np.float64)
    ints = [int(round(w)) for w in widths]
    unit = math.gcd(*ints)
    order = np.argsort(widths)
    bad = ~np.all(np.isfinite(phase), axis=0)
    height, width = phase.shape[1:]
    big_phi = np.empty((height, width))
    residual = np.empty((height, width))
    total = unit * math.prod(i // unit for i in ints)
    lo = _window_lo(extent, total)
    tables = []
    big_p = ints[order[0]] // unit
    for j in order[1:]:
        b = ints[j] // unit
        table = {}
        for m1 in range(b):
            for m2 in range(big_p):
                table[(m1 * big_p - m2 * b) % (big_p * b)] = m1
        tables.append((j, b, big_p, table))
        big_p *= b
    fine = order[0]
    w_fine = widths[fine]
    for r in range(height):
        for c in range(width):
            if bad[r, c]:
                big_phi[r, c] = residual[r, c] = np.nan
                continue
            u_raw = phase[fine, r, c] * w_fine / (2 * np.pi)
            u = u_raw % w_fine
            worst = 0.0
            for j, b, big_p, table in tables:
                v = (phase[j, r, c] * widths[j] / (2 * np.pi)) % widths[j]
                d = (v - u) / unit
                t = math.floor(d + 0.5)
                worst = max(worst, abs(d - t))
                u = u + table[t % (big_p * b)] * big_p * unit
            u = lo + (u - lo) % total
            m = math.floor((u - u_raw) / w_fine + 0.5)
            big_phi[r, c] = phase[fine, r, c] + 2 * np.pi * m
            residual[r, c] = worst
    return _finish(big_phi, w_fine, residual, extent, max_residual, bad)


UNWRAP = {
    "hierarchical": unwrap_hierarchical,
    "heterodyne": unwrap_heterodyne,
    "number_theoretic": unwrap_number_theoretic,
}


def low_amplitude(amplitude, min_amplitude=0.0, min_relative_amplitude=0.1):
    """(H, W) bool: some width's amplitude below max(absolute, relative * median)."""
    low = np.zeros(amplitude.shape[1:], bool)
    for amp in amplitude:
        threshold = min_amplitude
        if min_relative_amplitude > 0 and np.any(np.isfinite(amp)):
            threshold = max(threshold, min_relative_amplitude * np.nanmedian(amp))
        with np.errstate(invalid="ignore"):
            low |= amp < threshold
    return low


def decode_sequence(frames, widths, extent, method="hierarchical", min_amplitude=0.0,
                    min_relative_amplitude=0.1, max_order_residual=0.25):
    """frames (n, K, H, W) -> dict of the DecodeResult fields."""
    per_width = [phase_shift(f) for f in frames]
    wrapped, amplitude, offset, modulation = (np.array(a) for a in zip(*per_width))
    big_phi, coord, residual, flags = UNWRAP[method](wrapped, widths, extent, max_order_residual)
    flags = flags | np.where(low_amplitude(amplitude, min_amplitude, min_relative_amplitude),
                             LOW_AMPLITUDE, 0).astype(np.uint8)
    return dict(absolute_phase=big_phi, monitor_coord_px=coord, wrapped_phase=wrapped,
                amplitude=amplitude, offset=offset, modulation=modulation,
                order_residual=residual, flags=flags, valid=flags == 0)


# --------------------------------------------------------------------------- gamma (issue 9)
def gamma_cosine_coefficients(gamma: float, n: int = 1 << 14) -> np.ndarray:
    """a_m of ((1 + cos x) / 2)^gamma = sum_m a_m cos(m x) (FFT of the profile)."""
    x = 2 * np.pi * np.arange(n) / n
    c = np.fft.rfft(((1 + np.cos(x)) / 2) ** gamma).real / n
    a = 2 * c
    a[0] = c[0]
    return a


def gamma_phase_error(phi: np.ndarray, gamma: float, k: int, n_harmonics: int = 512) -> np.ndarray:
    """Decoded minus true phase (rad) of a gamma-``gamma`` fringe with ``k`` equal shifts:
    the harmonics m = 1 (mod k) enter as e^{i m phi}, m = -1 (mod k) as e^{-i m phi}, so the
    error is arg(sum_{m=1 mod k} a_m e^{i (m-1) phi} + sum_{m=-1 mod k} a_m e^{-i (m+1) phi})."""
    a = gamma_cosine_coefficients(gamma)[:n_harmonics]   # a_m ~ m^-5.4: 512^-5.4 ~ 1e-15
    z = np.zeros(phi.shape, complex)
    for m in range(1, a.size):
        if m % k == 1 % k:
            z += a[m] * np.exp(1j * (m - 1) * phi)
        if m % k == (k - 1) % k:
            z += a[m] * np.exp(-1j * (m + 1) * phi)
    return np.angle(z)
