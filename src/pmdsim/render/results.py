"""What a render returns: :class:`FringeResult` (with the numerical error of its sums) and
:class:`Geometry`, and the phase error of sums and the observed convergence of a rule."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..quantiles import median, percentile


def phase_error(sums: np.ndarray, sums_err: np.ndarray, kind: str | None,
                convergence: np.ndarray | None = None) -> np.ndarray:
    """Phase error (rad) of ``arg sums`` for the sums' errors (:attr:`FringeResult.sums_err`);
    ``kind``: ``"embedded"`` (signed differences) or ``"replicates"`` (half-widths).

    ``"embedded"``: ``|Im(dS conj S)| / |S|^2 + FLOOR |dS| / |S|`` (the two rules' phase
    difference and :data:`EMBEDDED_FLOOR`: the embedded rule's error, a bound on the rendered
    rule's); where ``convergence`` (per fringe, the leading axes of ``sums`` without the
    pixel axes: :func:`convergence_factor`) is ``q < 1``, the rule is in its asymptotic
    regime and the statement is ``SAFETY q |Im(dS conj S)| / |S|^2 + FLOOR q |dS| / |S|``
    (:data:`CONVERGENCE_SAFETY`). Never below :data:`ROUNDOFF_PHASE`.

    Whole-camera arrays (complex128, ``sums_err`` of the same shape) take one compiled
    pass in pixel blocks on a thread pool (:func:`_phase_error_compiled`: the NumPy
    expressions below, to the bit for the replicates and within 1e-13 of themselves for the
    embedded rules, in a fraction of their time and without whole-camera temporaries)."""
    if (sums.size >= _COMPILED_MIN and sums.dtype == np.complex128
            and getattr(sums_err, "dtype", None) == np.complex128
            and sums_err.shape == sums.shape and kind in ("replicates", "embedded")):
        return _phase_error_compiled(sums, sums_err, kind, convergence)
    mag = np.abs(sums)
    with np.errstate(divide="ignore", invalid="ignore"):
        if kind == "replicates":
            c, s = sums.real / mag, sums.imag / mag
            out = np.hypot(sums_err.real * s, sums_err.imag * c) / mag
        else:
            across = np.abs((sums_err * np.conj(sums)).imag) / (mag * mag)
            rel = np.abs(sums_err) / mag
            if convergence is None:
                out = across + EMBEDDED_FLOOR * rel
            else:
                q = np.asarray(convergence, np.float64)
                q = q.reshape(q.shape + (1,) * (sums.ndim - q.ndim))
                fast = q < 1.0
                out = np.where(fast, CONVERGENCE_SAFETY * q * across + EMBEDDED_FLOOR * q * rel,
                               across + EMBEDDED_FLOOR * rel)
        out = np.maximum(out, ROUNDOFF_PHASE)
    return np.where(mag > 0, out, np.nan)


#: Arrays of at least this many sums take the compiled pass (:func:`phase_error`).
_COMPILED_MIN = 65_536


def _phase_error_compiled(sums, sums_err, kind, convergence):
    """:func:`phase_error` of whole-camera complex128 arrays: the kernel over 16 pixel
    blocks on two threads, each block taking NumPy's ``|S|`` (and ``|dS|``) of its own
    pixels (no whole-camera temporaries)."""
    from ..kernels.fringe_finish import phase_error_embedded_rows, phase_error_rows

    out = np.empty(sums.shape)
    if kind == "replicates":
        s = np.ascontiguousarray(sums).reshape(-1)
        e = np.ascontiguousarray(sums_err).reshape(-1)
        flat = out.reshape(-1)

        def block(p0, p1):
            sb = s[p0:p1]
            phase_error_rows(sb, e[p0:p1], np.abs(sb), ROUNDOFF_PHASE, 0, p1 - p0,
                             flat[p0:p1])
    else:  # per fringe (the leading axes, each with its convergence factor) x pixel
        if convergence is None:
            q, lead = np.empty(0), 1
        else:
            q = np.asarray(convergence, np.float64)
            q = np.ascontiguousarray(np.broadcast_to(q, sums.shape[:q.ndim])).reshape(-1)
            lead = q.size
        s = np.ascontiguousarray(sums).reshape(lead, -1)
        e = np.ascontiguousarray(sums_err).reshape(lead, -1)
        flat = out.reshape(lead, -1)

        def block(p0, p1):
            sb, eb = s[:, p0:p1], e[:, p0:p1]
            phase_error_embedded_rows(sb, eb, np.abs(sb), np.abs(eb), q, EMBEDDED_FLOOR,
                                      CONVERGENCE_SAFETY, ROUNDOFF_PHASE, 0, p1 - p0,
                                      flat[:, p0:p1])
    in_blocks(s.shape[-1], block)
    return out


def in_blocks(n: int, fn, workers: int = 2) -> None:
    """``fn(p0, p1)`` over 16 blocks of ``range(n)`` on a pool of ``workers`` threads (for
    compiled kernels that release the GIL and write disjoint blocks)."""
    from concurrent.futures import ThreadPoolExecutor

    step = max(1, -(-n // 16))
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(lambda p0: fn(p0, min(p0 + step, n)), range(0, n, step)))


#: The smallest phase error stated (rad): the kernels' arithmetic (fast exp and sincos with
#: relative errors below 1e-11, sums over up to 10^5 rays) leaves phases uncertain by about
#: 1e-12 rad (Gauss-Hermite 8 x 8 to 32 x 32 on Fig. 3's radiometric fringes all agree with
#: 64 x 64 to 4e-12 rad), where the rules' differences can be smaller still.
ROUNDOFF_PHASE = 1e-9


#: The share of the relative sum difference ``|delta S| / |S|`` added to the embedded
#: rule's phase difference: where the two rules are not yet in their asymptotic regime
#: (a lobe that nearly fills a wide cone) their phase difference alone can fall below the
#: rendered rule's error; with this floor the statement bounded the true error (SciPy
#: cubature) in >= 94 % of (pixel, fringe) on 1 and 2 deg cones, orders 4 x 16 to 16 x 64.
EMBEDDED_FLOOR = 0.1

#: Safety factor on the observed convergence factor (:func:`convergence_factor`): the
#: embedded rule's phase difference times ``SAFETY q`` bounded the rendered rule's error in
#: >= 95 % of pixels on Fig. 3 (1 deg cone, orders 5 x 20 to 12 x 48, tested against SciPy
#: cubature); 3 did not at 10 x 40.
CONVERGENCE_SAFETY = 10.0

#: The rule is taken as asymptotic only where the embedded rule already agrees with it to
#: this relative difference ``|dS1| / |S|`` (median over the pixels of a fringe): on 2 and 4
#: deg cones (pre-asymptotic) the ratio of differences can look fast while the error does
#: not fall (there mostly 2e-3 to 0.3 up to 8 x 32; Fig. 3's 1 deg cone at 8 x 32: 2e-4 to
#: 8e-4). Measured: 1e-3 and 2e-3 kept the embedded statement's coverage but at 4 deg 10 x
#: 40; 1e-2 did not (2 deg, 6 x 24).
ASYMPTOTIC_DIFFERENCE = 2e-3


def convergence_factor(sums: np.ndarray, d1: np.ndarray, d2: np.ndarray,
                       exponent: float | None, pixel_axes: int = 2) -> np.ndarray | None:
    """Per fringe (the leading axes of ``sums``; the last ``pixel_axes`` are pixels): the observed
    factor ``q = median(|dS1| / |dS2|)^k`` by which the rendered rule's error is below the
    embedded rule's, ``dS1 = S - S_embedded``, ``dS2 = S - S_second`` and ``k`` from
    :func:`pmdsim.scene.quadrature.convergence_exponent` (an error falling exponentially in
    the order); 1 (no reduction) where the fringe is not clearly asymptotic: ``SAFETY q >=
    1``, or the median ``|dS1| / |S|`` above :data:`ASYMPTOTIC_DIFFERENCE`, or no valid
    pixel. None without an exponent."""
    if exponent is None:
        return None
    lead = sums.shape[:-pixel_axes]
    with np.errstate(divide="ignore", invalid="ignore"):
        a1 = (np.abs(d1) / np.abs(sums)).reshape(lead + (-1,))
        ratio = (np.abs(d1) / np.abs(d2)).reshape(lead + (-1,))
    return convergence_of_ratios(ratio, a1, exponent)


def convergence_of_ratios(ratio: np.ndarray, a1: np.ndarray, exponent: float) -> np.ndarray:
    """:func:`convergence_factor` from its per-pixel inputs ``ratio = |dS1| / |dS2|`` and
    ``a1 = |dS1| / |S|`` (leading axes: fringes; last axis: pixels; non-finite values are
    left out)."""
    lead = ratio.shape[:-1]
    out = np.ones(lead)
    for idx in np.ndindex(*lead):
        r, a = ratio[idx], a1[idx]
        ok = np.isfinite(r) & np.isfinite(a)
        if not ok.any():
            continue
        q = min(1.0, median(r[ok], overwrite=True) ** exponent)
        if CONVERGENCE_SAFETY * q < 1.0 and median(a[ok], overwrite=True) <= ASYMPTOTIC_DIFFERENCE:
            out[idx] = q
    return out


#: Pixels with more of their lobe's weight off the monitor are left out of a target's P95
#: (the chain never counts them valid: ``diagnostics.max_off_monitor_fraction``' default).
MAX_OFF = 0.05


def worst_phase_error(fr, min_modulation: float = 0.05) -> float | None:
    """The largest over fringes of the P95 over pixels of the stated phase error (rad),
    over the pixels whose fringe keeps a modulation ``|S| / f_hit >= min_modulation``
    (washed-out fringes cannot be decoded at any order) and whose lobe has at most
    :data:`MAX_OFF` of its weight off the monitor; None without an estimate."""
    pe = fr.phase_error()
    if pe is None:
        return None
    if fr.sums is not None and fr.sums.dtype == np.complex128:
        # one compiled pass per fringe (the expression below without its (B, H, W) arrays)
        from ..kernels.fringe_finish import decodable_values

        fh, ft = (np.ascontiguousarray(a, np.float64).reshape(-1) for a in (fr.f_hit, fr.f_total))
        buf = np.empty(fh.size)
        worst = None
        for di in range(pe.shape[0]):
            for wi in range(pe.shape[1]):
                n = decodable_values(np.ascontiguousarray(pe[di, wi], np.float64).reshape(-1),
                                     np.ascontiguousarray(fr.sums[di, wi]).reshape(-1), fh, ft,
                                     float(min_modulation), MAX_OFF, buf)
                if n:
                    p = percentile(buf[:n], 95, overwrite=True)
                    worst = p if worst is None else max(worst, p)
        return worst
    with np.errstate(divide="ignore", invalid="ignore"):
        if fr.sums is not None:
            mod = np.abs(fr.sums) / fr.f_hit
        else:  # a non-linear display: the decoder's modulation B / A of the images
            z = np.abs(np.tensordot(np.exp(-1j * np.asarray(fr.shifts)),
                                    np.moveaxis(fr.images.astype(np.float64), 2, 0), axes=1))
            k = len(fr.shifts)
            mod = 2 * z / k / (np.sum(fr.images.astype(np.float64), axis=2) / k)
    with np.errstate(divide="ignore", invalid="ignore"):  # never valid in the chain
        off = 1.0 - np.abs(fr.f_hit) / np.abs(fr.f_total)
    mod = np.where(off > MAX_OFF, 0.0, mod)
    worst = None
    for di in range(pe.shape[0]):
        for wi in range(pe.shape[1]):
            a = pe[di, wi][np.isfinite(pe[di, wi]) & (mod[di, wi] >= min_modulation)]
            if a.size:
                p = percentile(a, 95, overwrite=True)
                worst = p if worst is None else max(worst, p)
    return worst


def value_error(err, cols: slice, norm: np.ndarray, values: np.ndarray | None = None,
                ftot_col: int | None = None) -> np.ndarray | None:
    """(H, W, Q) numerical error of estimator values ``sum_cols * norm`` from the render's
    error (:meth:`pmdsim.render.Simulation._render`: the rqmc half-widths, or the
    differences to the embedded rules, of which the first, as a magnitude, is taken).
    ``ftot_col``: the value is a ratio ``sum / f_total`` (``weighted_mean``): the error of
    ``f_total`` adds ``|value| e_ftot / f_total`` (first order, half-widths added: a bound).
    None without an error."""
    if err is None:
        return None
    e = np.abs(err[0] if isinstance(err, tuple) else err)
    out = e[..., cols] * np.abs(norm)[..., None]
    if ftot_col is not None and values is not None:
        out = out + np.abs(values) * (e[..., ftot_col] * np.abs(norm))[..., None]
    return out


@dataclass(frozen=True)
class FringeResult:
    """Camera fringe images and the sums they come from.

    Attributes
    ----------
    images : (n_directions, n_widths, K, H, W) float32
        Camera values (estimator units); NaN where the vision ray misses the surface.
    sums : (n_directions, n_widths, H, W) complex128 or None
        Normalised ``sum_p f_p exp(i k c_p)`` (c = u or v, the fringe coordinate): its
        argument is the phase a K >= 3 phase-shift decoder returns (gamma = 1 only).
    f_total, f_hit : (H, W) float64
        Normalised sum of all weights / of the weights of rays that hit the monitor.
    sums_err : (n_directions, n_widths, H, W) complex128 or None
        Numerical error of every sum (same units as ``sums``), real and imaginary parts
        separately: ``S - S_embedded`` (mode ``rule``: the difference to the embedded rule,
        signed) or ``t(0.975, R - 1)`` standard errors of the rqmc mean (each part >= 0);
        None without an estimate (modes ``stratified``/``random``, ``error_estimate =
        false``, a display with gamma != 1).
    sampling : dict
        What was rendered: ``mode`` (the effective one), ``rule``, ``nodes``, ``order``,
        ``error`` (``"embedded"``, ``"replicates"`` or None), ``smooth``.
    convergence : (n_directions, n_widths) float64 or None
        Mode ``rule``: the observed convergence factor of each fringe
        (:func:`convergence_factor`; 1 where the rule is not clearly asymptotic), None
        without the second embedded rule.
    stated_phase_error : (n_directions, n_widths, H, W) float64 or None
        The phase error (rad) where the render states it directly: a non-linear display on
        a nearest-pixel monitor (:mod:`pmdsim.render.control_variate`: the error of the shifted
        images' fringe sum ``sum_k I_k exp(-i delta_k)``), else None.
    signed_phase_error : (n_directions, H, W) float32 or None
        The pilot's estimate of the finest width's signed phase error (rad; the rule minus
        a rule 4 x finer, :meth:`pmdsim.render.pilot.Pilot.signed_field`): the error's
        pattern across the camera, not a bound (the bound is the statement,
        :meth:`phase_error`); None without a pilot.
    """

    directions: tuple[str, ...]
    widths: tuple[float, ...]
    shifts: np.ndarray
    images: np.ndarray
    sums: np.ndarray | None
    f_total: np.ndarray
    f_hit: np.ndarray
    sums_err: np.ndarray | None = None
    sampling: dict | None = None
    convergence: np.ndarray | None = None
    stated_phase_error: np.ndarray | None = None
    signed_phase_error: np.ndarray | None = None

    def image(self, direction: str, width: float, k: int) -> np.ndarray:
        return self.images[self.directions.index(direction), self.widths.index(width), k]

    def phase_error(self) -> np.ndarray | None:
        """(n_directions, n_widths, H, W) rad: the numerical error of the phase
        ``arg S`` each sum decodes to, from the part of the sum's error across ``S``
        (first order; the part along ``S`` changes the modulation, not the phase):
        :func:`phase_error` (the embedded rule's phase difference and a floor, scaled by
        the observed :attr:`convergence` where the rule is asymptotic),
        ``sqrt((e_re sin phi)^2 + (e_im cos phi)^2) / |S|`` for the rqmc errors; None
        without :attr:`sums_err`; :attr:`stated_phase_error` where the render stated the
        phase error itself."""
        if self.stated_phase_error is not None:
            return self.stated_phase_error
        if self.sums_err is None or self.sums is None:
            return None
        return phase_error(self.sums, self.sums_err, (self.sampling or {}).get("error"),
                           self.convergence)


@dataclass(frozen=True)
class Geometry:
    """Per-pixel results of the vision rays alone.

    ``surface_mask``: the vision ray hits the front of the surface. ``monitor_mask``: P hits
    the monitor as well. ``specular_u``/``specular_v``: exact monitor coordinates (monitor
    px) of P (NaN where it misses), ``specular_u_px``/``..._v_px`` the nearest monitor pixel.
    ``points``: the surface points.
    """

    surface_mask: np.ndarray
    monitor_mask: np.ndarray
    specular_u: np.ndarray
    specular_v: np.ndarray
    #: (H, W, 3) surface point of each pixel's vision ray (mm; NaN off the surface)
    points: np.ndarray

    @property
    def specular_u_px(self) -> np.ndarray:
        return np.floor(self.specular_u + 0.5)

    @property
    def specular_v_px(self) -> np.ndarray:
        return np.floor(self.specular_v + 0.5)
