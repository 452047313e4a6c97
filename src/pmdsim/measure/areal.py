"""Areal parameters (ISO 25178-2) and power spectral densities of an error map.

Plain arrays in, plain numbers and arrays out: a map ``z`` (H, W) on a regular grid of
steps ``dx`` (columns) and ``dy`` (rows), NaN (or ``mask`` False) where it holds no value
(a circular aperture, a part that fills a corner of its grid, dropped nodes), and
optionally the numerical error ``e`` (H, W, >= 0) of every node. Everything is computed
over the valid nodes only; nothing is filled or interpolated.

Areal parameters (:func:`areal_parameters`), about the mean of the valid nodes (the map's
form was removed before, e.g. ``reconstruct.remove``; ISO 25178-2's reference plane is the
mean here):

- ``sq`` RMS height, ``sa`` mean absolute height, ``sz`` = max - min (Sp + Sv), ``ssk``
  skewness (mean cube / Sq^3), ``sku`` kurtosis (mean fourth power / Sq^4);
- ``sdq`` the RMS gradient, from forward differences on the grid: over every pair of
  neighbouring valid nodes along x, ``(z[r, c+1] - z[r, c]) / dx``, and along y, each
  direction averaged over its own pairs, ``Sdq^2 = mean(gx^2) + mean(gy^2)`` (surfalize's
  discretisation; a sinusoid of period p reads sinc(pi dx / p) of its slope amplitude: 1 %
  low at 13 nodes per period). Units: the map's unit per mm (nm/mm = urad).

Their numerical errors (``*_err``), where the map has node errors ``e``: ``sq`` and ``sa``
by the interval of a statistic that grows with every ``|d_i|`` (``d`` about the map's
mean; :func:`pmdsim.studies.budget_error.stat_error`, the rule of the run's RMS and P95
errors), ``sz`` by the widest and narrowest range the nodes' errors allow, ``sdq`` by the
same interval on the differences (each difference known to ``(e_i + e_j) / step`` for any
signs, or, with the signed error maps below, to the largest change of that difference plus
the ``floor``'s ``f_i + f_j``), ``ssk`` and ``sku`` to first order, ``sum_i |dS/dz_i| e_i``
(the largest change any signs of the node errors give; with error maps ``e_i`` is the
maps' largest change at the node plus the floor).

Power spectral density (:func:`power_spectrum`):

- the map less its window-weighted mean is multiplied by a window ``w`` that is zero off
  the valid nodes and tapers to the measured region's edge: ``d`` is the distance (mm)
  from a node to the nearest node outside the region (holes smaller than
  :data:`SMALL_HOLE` of the region are not edges: dropped nodes), ``d_max`` its largest
  value. ``"tukey"`` (default): ``w = sin^2(pi d / (2 T))`` within ``T`` =
  :data:`TUKEY_TAPER` ``d_max`` of the edge, 1 inside (the tapered cosine window,
  following any outline); ``"hann"``: ``T = d_max``, on a disc the rotationally symmetric
  Hann window of SurfaceTopography, ``(1 + cos(pi r / R)) / 2`` (to the grid's
  discreteness);
  ``"none"``: ``w`` = 1 on the valid nodes (a periodic, fully measured map);
- 2-D PSD ``C(fx, fy) = dx dy |FFT(w (z - m))|^2 / sum(w^2)`` (unit^2 mm^2), spatial
  frequencies f in 1/mm (cycles, not radians), so that ``sum C dfx dfy`` is the
  window-weighted mean square ``sum w^2 (z - m)^2 / sum w^2`` (Parseval): the normalisation
  of SurfaceTopography's ``power_spectrum_from_area`` (whose wavevectors are ``q = 2 pi f``)
  with the window's mean square taken over the valid nodes only;
- radial bins of width ``df = max(1 / (W dx), 1 / (H dy))`` centred at ``k df``, k = 1 ..
  up to the smaller Nyquist frequency: ``psd_iso`` the bin average of C (unit^2 mm^2) and
  ``psd_radial`` the power of the annulus divided by ``df`` (unit^2 mm, the 1-D radial PSD:
  ``sum psd_radial df`` is the power of the bins, about ``2 pi f C_iso``);
- band-limited RMS of the ``form``, ``mid`` (mid-spatial) and ``high`` bands
  (:func:`default_bands`), ``sqrt(sum_band C dfx dfy)``; the bands cover every frequency
  but DC (the high band takes the corners beyond the radial Nyquist frequency), so their
  squares add up to the window-weighted mean square.

Numerical errors of the PSD. Each amplitude (the square root of the power at a frequency,
in a bin or in a band) moves by at most the amplitude ``a`` of the error map's windowed
spectrum there (triangle inequality), so the PSD's error is ``(sqrt(P) + a)^2 - P`` in its
normalisation and the band RMS's is ``a / sqrt(N sum w^2)`` (N grid nodes). With
``error_maps`` (signed maps of how the map moves by its numerical error: the run's
reconstruction repeated with the decoded coordinates moved by the rule's signed error
pattern, and its opposite; the budget passes none: its shifted maps are no signed
pattern, :mod:`pmdsim.studies.budget_areal`) ``a`` is the larger of
their spectra: the bound for any error whose spectrum is no larger, whatever its phase (the
quadrature's errors vary smoothly across pixels); a ``floor`` (node errors of any signs,
e.g. a solver's tolerance) adds the amplitudes any signs of it give. With node errors ``e``
alone (magnitudes, no signs) it is the bound for any signs: with ``e'`` = ``e`` plus the
largest shift of the weighted mean, ``a^2 = min(n T^2, N sum (w e')^2)`` for n
frequencies, ``T = sum w e'``; never more than the window-weighted RMS of ``e'`` for a
band, but a flat floor across the spectrum (an error that alternated sign from node to node would put its power at the
highest frequencies). Where a PSD is below its error the simulation does not resolve the
map's spectrum there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

#: Names of the PSD bands, low to high spatial frequency.
BANDS = ("form", "mid", "high")
#: Holes (unmeasured regions enclosed by the measured one) smaller than this share of the
#: measured region are not tapered around by the windows (dropped nodes); larger
#: ones (an annulus's centre) are edges like the outer one.
SMALL_HOLE = 0.005
#: Default band edges: the form band holds periods longer than the measured region's
#: larger extent / FORM_CYCLES (what a few Zernike orders describe), the high band periods
#: shorter than HIGH_STEPS grid steps (where the grid's sampling and the integrator act).
FORM_CYCLES = 3.0
HIGH_STEPS = 4.0

#: PSD windows (module docstring) and the tapered share of the ``tukey`` window.
WINDOWS = ("tukey", "hann", "none")
TUKEY_TAPER = 0.25

AREAL = ("sq", "sa", "sz", "ssk", "sku", "sdq")


def _valid(z, mask):
    z = np.asarray(z, np.float64)
    if z.ndim != 2:
        raise ValueError(f"an areal map must be 2-D, got shape {z.shape}")
    v = np.isfinite(z)
    if mask is not None:
        v &= np.asarray(mask, bool)
    return z, v


def _node_error(error, valid):
    if error is None:
        return None
    e = np.abs(np.asarray(error, np.float64))
    if e.shape != valid.shape:
        raise ValueError(f"error: shape {e.shape} is not the map's {valid.shape}")
    return np.where(valid & np.isfinite(e), e, 0.0)


def _error_maps(maps, valid):
    """The signed error maps, checked, 0 where the map or they hold no value."""
    if maps is None:
        return None
    out = []
    for m in maps:
        m = np.asarray(m, np.float64)
        if m.shape != valid.shape:
            raise ValueError(f"error_maps: shape {m.shape} is not the map's {valid.shape}")
        out.append(np.where(valid & np.isfinite(m), m, 0.0))
    return out


def _interval(f, d, e):
    """The larger distance of ``f(|d|)`` to ``f(|d| + e)`` and ``f(max(|d| - e, 0))``."""
    a = np.abs(d)
    s = f(a)
    return float(max(f(a + e) - s, s - f(np.maximum(a - e, 0.0))))


def _rms(a):
    return float(np.sqrt(np.mean(a * a)))


def _mean(a):
    return float(np.mean(a))


def _pairs(z, valid, axis):
    """Forward differences along ``axis`` (1: x, 0: y) over pairs of valid nodes, and the
    index arrays of both nodes (to carry errors)."""
    if axis == 1:
        ok = valid[:, 1:] & valid[:, :-1]
        diff = (z[:, 1:] - z[:, :-1])[ok]
    else:
        ok = valid[1:, :] & valid[:-1, :]
        diff = (z[1:, :] - z[:-1, :])[ok]
    return ok, diff


def _sdq(gx, gy):
    parts = [np.mean(g * g) for g in (gx, gy) if g.size]
    return float(np.sqrt(sum(parts))) if parts else float("nan")


def areal_parameters(z, dx: float, dy: float, mask=None, error=None, error_maps=None,
                     floor=None) -> dict:
    """ISO 25178-2 Sq, Sa, Sz, Ssk, Sku and Sdq of ``z`` over its valid nodes (module
    docstring), with ``n`` (valid nodes); with ``error`` each also as ``<name>_err``
    (``error_maps``, the signed changes of the map, see :func:`power_spectrum`: the node
    errors are their largest magnitude unless ``error`` is given; Ssk and Sku change by the
    largest first-order change a map gives, each difference of Sdq by the largest change
    of that difference; ``floor``, node errors of any signs added to the maps' changes).
    NaN (and ``n`` 0) for a map without a valid node; Sdq NaN without a pair of
    neighbouring valid nodes, Ssk/Sku NaN for a constant map."""
    z, v = _valid(z, mask)
    maps = _error_maps(error_maps, v)
    fl = _node_error(floor, v) if maps and floor is not None else None
    # each node's largest change under the maps, plus the floor's: the node errors where
    # ``error`` is not given, and Ssk's and Sku's (any signs) either way
    map_err = (np.fmax.reduce([np.abs(m) for m in maps]) + (0.0 if fl is None else fl)
               if maps else None)
    e = _node_error(map_err if error is None else error, v)
    n = int(np.count_nonzero(v))
    nan = float("nan")
    out = {k: nan for k in AREAL}
    out["n"] = n
    if e is not None:
        out.update({f"{k}_err": nan for k in AREAL})
    if n == 0:
        return out
    vals = z[v]
    d = vals - vals.mean()
    m2 = float(np.mean(d * d))
    sq = math.sqrt(m2)
    out.update(sq=sq, sa=float(np.mean(np.abs(d))), sz=float(np.ptp(vals)))
    if m2 > 0:
        d2 = d * d
        d3 = d2 * d
        m3, m4 = float(np.mean(d3)), float(np.mean(d2 * d2))
        out["ssk"] = m3 / m2**1.5
        out["sku"] = m4 / m2**2
    okx, gx = _pairs(z, v, 1)
    oky, gy = _pairs(z, v, 0)
    gx, gy = gx / dx, gy / dy
    out["sdq"] = _sdq(gx, gy)
    if e is None:
        return out
    ev = e[v]
    out["sq_err"] = min(_interval(_rms, d, ev), _rms(ev))
    out["sa_err"] = _interval(_mean, d, ev)
    hi = float(np.max(vals + ev) - np.min(vals - ev))
    lo = max(float(np.max(vals - ev) - np.min(vals + ev)), 0.0)
    out["sz_err"] = max(hi - out["sz"], out["sz"] - lo)
    if m2 > 0:
        dm2 = 2 * d / n
        dm3 = 3 * (d2 - m2) / n
        dm4 = 4 * (d3 - m3) / n
        g_sk = dm3 / m2**1.5 - 1.5 * m3 / m2**2.5 * dm2
        g_ku = dm4 / m2**2 - 2 * m4 / m2**3 * dm2
        ek = ev if map_err is None else map_err[v]  # any signs of these node errors
        out["ssk_err"] = float(np.sum(np.abs(g_sk) * ek))
        out["sku_err"] = float(np.sum(np.abs(g_ku) * ek))
    if gx.size or gy.size:
        if maps:  # the change of each difference (and the floor's, any signs)
            ex = np.fmax.reduce([np.abs(np.diff(m, axis=1))[okx] for m in maps]) / dx
            ey = np.fmax.reduce([np.abs(np.diff(m, axis=0))[oky] for m in maps]) / dy
            if fl is not None:
                ex = ex + (fl[:, 1:] + fl[:, :-1])[okx] / dx
                ey = ey + (fl[1:, :] + fl[:-1, :])[oky] / dy
        else:  # any signs: the sum of both nodes' errors
            ex = (e[:, 1:] + e[:, :-1])[okx] / dx
            ey = (e[1:, :] + e[:-1, :])[oky] / dy
        s = out["sdq"]
        up = _sdq(np.abs(gx) + ex, np.abs(gy) + ey)
        down = _sdq(np.maximum(np.abs(gx) - ex, 0), np.maximum(np.abs(gy) - ey, 0))
        out["sdq_err"] = float(max(up - s, s - down))
    return out


# ----------------------------------------------------------------------------- windows
def window(valid, dx: float, dy: float, kind: str = "tukey") -> np.ndarray:
    """The PSD window on the grid (module docstring): 0 off ``valid``."""
    valid = np.asarray(valid, bool)
    if kind == "none":
        return valid.astype(np.float64)
    if kind not in WINDOWS:
        raise ValueError(f"window must be one of {WINDOWS}, got {kind!r}")
    if not valid.any():
        return np.zeros(valid.shape)
    region = valid.copy()
    holes = ndimage.binary_fill_holes(valid) & ~valid
    if holes.any():  # dropped nodes: not an edge to taper to
        labels, k = ndimage.label(holes)
        sizes = ndimage.sum_labels(holes, labels, np.arange(1, k + 1))
        small = np.r_[False, sizes < SMALL_HOLE * valid.sum()]
        region |= small[labels]
    d = ndimage.distance_transform_edt(np.pad(region, 1), sampling=(dy, dx))[1:-1, 1:-1]
    taper = d.max() * (TUKEY_TAPER if kind == "tukey" else 1.0)
    w = np.sin(0.5 * np.pi * np.minimum(d / taper, 1.0)) ** 2
    return np.where(valid, w, 0.0)


_LAST_WINDOW: list = []


def _window_of(valid, dx, dy, kind):
    """:func:`window`, kept for the last region (a run's maps share one)."""
    for key, w in _LAST_WINDOW:
        if key[1:] == (dx, dy, kind) and np.array_equal(key[0], valid):
            return w
    w = window(valid, dx, dy, kind)
    _LAST_WINDOW[:] = [((valid.copy(), dx, dy, kind), w)]
    return w


def default_bands(valid, dx: float, dy: float, form_period_mm: float | None = None,
                  high_period_mm: float | None = None) -> dict:
    """``{band: (f_lo, f_hi)}`` in 1/mm: ``form`` below ``1 / form_period_mm`` (default: the
    measured region's larger extent / :data:`FORM_CYCLES`), ``high`` from
    ``1 / high_period_mm`` (default :data:`HIGH_STEPS` grid steps of the coarser axis) up,
    ``mid`` between (empty for a region of a few grid steps, where the defaults cross). The high band's upper edge is inf (it takes the grid's corners)."""
    valid = np.asarray(valid, bool)
    given = form_period_mm is not None and high_period_mm is not None
    if form_period_mm is None:
        rows, cols = np.nonzero(valid)
        ext = max((np.ptp(cols) + 1) * dx if cols.size else dx,
                  (np.ptp(rows) + 1) * dy if rows.size else dy)
        form_period_mm = ext / FORM_CYCLES
    if high_period_mm is None:
        high_period_mm = HIGH_STEPS * max(dx, dy)
    f_form, f_high = 1.0 / float(form_period_mm), 1.0 / float(high_period_mm)
    if not given and f_form > f_high:  # a region of a few grid steps: no mid band
        f_form = f_high
    if not 0 < f_form <= f_high:
        raise ValueError(f"PSD bands: the form band's shortest period {form_period_mm:g} mm "
                         f"must be longer than the high band's longest {high_period_mm:g} mm")
    return {"form": (0.0, f_form), "mid": (f_form, f_high), "high": (f_high, math.inf)}


@dataclass(frozen=True, eq=False)
class PowerSpectrum:
    """Result of :func:`power_spectrum` (module docstring). Frequencies in 1/mm; ``psd_2d``
    (H, W) in the map's unit^2 mm^2, centred (``np.fft.fftshift``) on ``fx`` (W,), ``fy``
    (H,); ``frequency`` (K,) the radial bins' centres, ``edges`` (K + 1,) their edges,
    ``counts`` the 2-D frequencies in each; ``psd_iso`` (unit^2 mm^2), ``psd_radial``
    (unit^2 mm); ``bands`` ``{name: (f_lo, f_hi)}``, ``band_rms`` ``{name: rms}`` (unit);
    ``*_err`` their numerical errors (None without node errors); ``mean_square`` the
    window-weighted mean square (the bands' squares add up to it)."""

    fx: np.ndarray
    fy: np.ndarray
    psd_2d: np.ndarray
    frequency: np.ndarray
    edges: np.ndarray
    counts: np.ndarray
    psd_iso: np.ndarray
    psd_radial: np.ndarray
    bands: dict
    band_rms: dict
    window: str
    mean_square: float
    n_valid: int
    psd_2d_err: np.ndarray | None = None
    psd_iso_err: np.ndarray | None = None
    psd_radial_err: np.ndarray | None = None
    band_rms_err: dict | None = field(default=None)


def power_spectrum(z, dx: float, dy: float, mask=None, error=None, window_kind: str = "tukey",
                   bands: dict | None = None, error_maps=None, floor=None) -> PowerSpectrum:
    """2-D and radial PSD and band-limited RMS of ``z`` (module docstring); ``bands``
    ``{name: (f_lo, f_hi)}`` (1/mm, default :func:`default_bands`); ``error``: the node
    errors, carried to every PSD value and band RMS for any signs; ``error_maps``: signed
    maps (each (H, W)) of how the map moves by its numerical error (e.g. reconstructed with
    the decoded coordinates moved by +e and by -e): their spectra instead (the larger),
    with ``floor`` (node errors of any signs, e.g. a solver's tolerance) added to their
    amplitudes."""
    z, v = _valid(z, mask)
    if not v.any():
        raise ValueError("power spectrum: the map has no valid node")
    e = _node_error(error, v)
    fl = _node_error(floor, v) if error_maps is not None and floor is not None else None
    h, w_ = z.shape
    wgt = _window_of(v, dx, dy, window_kind)
    sw, sw2 = float(wgt.sum()), float(np.sum(wgt * wgt))
    mean = float(np.sum(wgt[v] * z[v]) / sw)
    f = np.fft.fft2(np.where(v, (z - mean) * wgt, 0.0))
    s = f.real**2 + f.imag**2
    n_all = h * w_
    norm = dx * dy / sw2
    fx, fy = np.fft.fftfreq(w_, dx), np.fft.fftfreq(h, dy)
    fr = np.hypot(fx[None, :], fy[:, None])
    df = max(1.0 / (w_ * dx), 1.0 / (h * dy))
    f_nyq = min(0.5 / dx, 0.5 / dy)
    n_bins = max(math.floor(f_nyq / df - 0.5), 1)
    k = np.ceil(fr / df - 0.5).astype(np.int64)  # bin k: ((k - 1/2) df, (k + 1/2) df]
    inbin = (k >= 1) & (k <= n_bins)
    counts = np.bincount(k[inbin], minlength=n_bins + 1)[1:]
    power = np.bincount(k[inbin], weights=s[inbin], minlength=n_bins + 1)[1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        iso = np.where(counts > 0, norm * power / counts, np.nan)
    radial = power / (n_all * sw2 * df)
    edges = (np.arange(n_bins + 1) + 0.5) * df
    freq = np.arange(1, n_bins + 1) * df
    bands = default_bands(v, dx, dy) if bands is None else dict(bands)
    nonzero = fr > 0
    band_rms, band_sel = {}, {}
    for name, (lo, hi) in bands.items():
        sel = nonzero & (fr >= lo) & (fr < hi)
        band_sel[name] = sel
        band_rms[name] = float(math.sqrt(np.sum(s[sel]) / (n_all * sw2)))
    ms = float(np.sum(s[nonzero]) / (n_all * sw2))
    out = {"fx": np.fft.fftshift(fx), "fy": np.fft.fftshift(fy),
           "psd_2d": np.fft.fftshift(norm * s), "frequency": freq, "edges": edges,
           "counts": counts, "psd_iso": iso, "psd_radial": radial, "bands": bands,
           "band_rms": band_rms, "window": window_kind, "mean_square": ms,
           "n_valid": int(np.count_nonzero(v))}
    def any_signs(e):  # the amplitudes any signs of node errors e can give (docstring)
        shift = float(np.sum(wgt * e) / sw)  # the weighted mean moves by at most this
        ep = np.where(v, e + shift, 0.0) * wgt
        t2 = float(ep.sum()) ** 2
        pars = n_all * float(np.sum(ep * ep))
        return (np.full_like(s, t2), np.minimum(counts * t2, pars),
                {name: min(np.count_nonzero(sel) * t2, pars) for name, sel in band_sel.items()})

    if error_maps is not None:  # the spectra of the error maps themselves (the larger)
        a2 = np.zeros_like(s)
        done: list = []
        for dz in _error_maps(error_maps, v):
            # a map that is another's negative (a signed pattern and its opposite) has the
            # same power spectrum to the bit: one FFT for both
            if any(np.array_equal(dz, -prev) for prev in done):
                continue
            done.append(dz)
            fd = np.fft.fft2(np.where(v, (dz - np.sum(wgt * dz) / sw) * wgt, 0.0))
            a2 = np.maximum(a2, fd.real**2 + fd.imag**2)
        a2_bin = np.bincount(k[inbin], weights=a2[inbin], minlength=n_bins + 1)[1:]
        a2_band = {name: float(np.sum(a2[sel])) for name, sel in band_sel.items()}
        if fl is not None:  # amplitudes add (the triangle inequality, per bin and band)
            f2, f2_bin, f2_band = any_signs(fl)
            a2 = (np.sqrt(a2) + np.sqrt(f2)) ** 2
            a2_bin = (np.sqrt(a2_bin) + np.sqrt(f2_bin)) ** 2
            a2_band = {b: (math.sqrt(a2_band[b]) + math.sqrt(f2_band[b])) ** 2 for b in a2_band}
    elif e is not None:  # any signs of the node errors (module docstring)
        a2, a2_bin, a2_band = any_signs(e)
    if error_maps is not None or e is not None:
        def grow(p, a_sq):
            return (np.sqrt(p) + np.sqrt(a_sq)) ** 2 - p

        out["psd_2d_err"] = np.fft.fftshift(norm * grow(s, a2))
        with np.errstate(invalid="ignore", divide="ignore"):
            out["psd_iso_err"] = np.where(counts > 0, norm * grow(power, a2_bin) / counts, np.nan)
        out["psd_radial_err"] = grow(power, a2_bin) / (n_all * sw2 * df)
        out["band_rms_err"] = {name: float(math.sqrt(a / (n_all * sw2)))
                               for name, a in a2_band.items()}
    return PowerSpectrum(**out)


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


def describe(z, dx: float, dy: float, unit: str, mask=None, error=None,
             window_kind: str = "tukey", bands: dict | None = None, error_maps=None,
             floor=None):
    """(JSON-ready areal parameters, band RMS and 1-D radial PSD of a map, with their
    numerical errors where ``error`` (or ``error_maps``, with ``floor``) is given; its
    :class:`PowerSpectrum`). A map without a valid node: ``({"n": 0, ...}, None)``."""
    z, v = _valid(z, mask)
    ap = areal_parameters(z, dx, dy, v, error, error_maps, floor)
    out = {"unit": unit, "sdq_unit": f"{unit}/mm",
           **{k: (_num(x) if isinstance(x, float) else x) for k, x in ap.items()}}
    if not v.any():
        return out, None
    p = power_spectrum(z, dx, dy, v, error, window_kind, bands, error_maps, floor)
    out["psd"] = psd_summary(p, unit)
    return out, p


def summary(z, dx: float, dy: float, unit: str, mask=None, error=None,
            window_kind: str = "tukey", bands: dict | None = None, error_maps=None,
            floor=None) -> dict:
    """The JSON part of :func:`describe`."""
    return describe(z, dx, dy, unit, mask, error, window_kind, bands, error_maps, floor)[0]


def psd_summary(p: PowerSpectrum, unit: str) -> dict:
    """JSON-ready band RMS and 1-D radial PSD of a :class:`PowerSpectrum`."""
    def arr(a):
        return None if a is None else [_num(x) for x in a]

    out = {"window": p.window, "mean_square": _num(p.mean_square),
           "bands_per_mm": {k: [_num(lo), _num(hi)] for k, (lo, hi) in p.bands.items()},
           "band_rms": {k: _num(x) for k, x in p.band_rms.items()},
           "frequency_per_mm": arr(p.frequency),
           "radial": arr(p.psd_radial), "radial_unit": f"{unit}^2 mm",
           "iso": arr(p.psd_iso), "iso_unit": f"{unit}^2 mm^2"}
    if p.band_rms_err is not None:
        out["band_rms_err"] = {k: _num(x) for k, x in p.band_rms_err.items()}
        out["radial_err"] = arr(p.psd_radial_err)
        out["iso_err"] = arr(p.psd_iso_err)
    return out


#: What the statistics state about the areal parameters and PSDs (statistics.json, budget.json).
DEFINITIONS = {
    "sq, sa, sz, ssk, sku": "ISO 25178-2 about the mean of the valid nodes (the map's form "
                            "removal is the reference): RMS, mean |z|, max - min, skewness, "
                            "kurtosis; unit: the map's",
    "sdq": "ISO 25178-2 RMS gradient from forward differences over pairs of valid neighbours, "
           "each axis averaged over its own pairs; unit: the map's per mm (nm/mm = urad)",
    "psd": "2-D PSD dx dy |FFT(w (z - m))|^2 / sum w^2 (unit^2 mm^2) with the tapered window w "
           "of the measured region (tukey: cosine taper over the outer quarter of the distance "
           "to the edge); radial: power of each annulus (bin width df = the grid's coarser "
           "frequency step) / df, unit^2 mm, its integral is the window-weighted mean square; "
           "iso: the annulus' mean of the 2-D PSD; frequencies f in 1/mm (cycles)",
    "band_rms": "sqrt of the 2-D PSD summed over a band of spatial frequency (form: periods "
                "longer than the measured extent / 3; high: shorter than 4 grid steps; mid: "
                "between); their squares add up to the window-weighted mean square",
    "_err": "numerical error: the run's node errors carried to each number (Sq, Sa: exact "
            "interval; Sz: widest and narrowest range); Ssk, Sku, Sdq, PSD and band RMS from "
            "the change of the map for the rule's signed error pattern (x 2) and the "
            "solver's floor (Sdq: interval on the differences; Ssk, Sku: first order, any "
            "signs of each node's change; PSD, band RMS: the spectrum of the change), "
            "pmdsim.measure.areal, pmdsim.run.reconstruction",
}


__all__ = ["AREAL", "BANDS", "DEFINITIONS", "PowerSpectrum", "areal_parameters",
           "default_bands", "describe", "power_spectrum", "psd_summary", "summary", "window"]
