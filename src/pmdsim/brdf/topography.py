"""From a measured topography to scattering parameters (pure functions).

A height map ``h`` (rows along y, columns along x, spacing ``dx``, ``dy``; all lengths in mm)
gives

- its **slope density** (central-difference slopes; the geometric regime's micro-facet
  model, :class:`~pmdsim.brdf.slope_density.TabulatedSlopes`), the RMS slopes per axis and
  the equivalent Ward/Beckmann alphas (sqrt(2) x RMS slope per axis), Sdq (the RMS
  gradient, ISO 25178-2);
- its **PSD** (the two-sided 2-D power spectral density per unit spatial-frequency area,
  ``sum S dfx dfy = Sq^2``; a Hann-windowed periodogram) and the fit of the anisotropic
  K-correlation (ABC) model

      S(fx, fy) = A / (1 + (Bx fx)^2 + (By fy)^2)^((C + 1) / 2),   A = Sq^2 Bx By (C - 1) / (2 pi)

  (C > 1; C = 2 is the exponential autocorrelation exp(-sqrt((x/lx)^2 + (y/ly)^2)) with
  B = 2 pi l), by Whittle's likelihood (the periodogram's scatter is exponential, so this
  is unbiased where a fit of log S is not); the correlation lengths are ``B / (2 pi)``, and
  the autocorrelation's 1/e lengths along x and y are reported as measured;
- Sq (areal RMS height), Rq (mean RMS height of the profiles along each axis) and the
  **regime** from the Rayleigh parameter ``g = 4 pi Sq cos(theta_i) / lambda`` at the
  set-up's wavelength and incidence: ``smooth`` (g < 0.5: a specular peak of share
  ``exp(-g^2)`` plus a first-order Rayleigh-Rice halo, :mod:`pmdsim.brdf.rayleigh_rice`),
  ``geometric`` (g > 1.5: the slope density) or ``intermediate`` (neither is exact; the
  topography model then uses the halo while g < 1, the slope density above).

:func:`synthesize` makes a Gaussian random surface of a given PSD (periodic, by FFT
filtering of white noise with an explicit seed) for tests and examples.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .slope_density import TabulatedSlopes

#: Rayleigh parameter below which a surface is optically smooth, above which geometric.
SMOOTH_MAX_G = 0.5
GEOMETRIC_MIN_G = 1.5
#: The topography model's switch between the halo and the slope density.
HALO_MAX_G = 1.0
#: Sq (mm) at or below which a levelled map is flat: 0.1 pm, far below any instrument's
#: noise (the rounding residue of levelling a constant or tilted map is ~1e-16 of its heights).
FLAT_SQ_MM = 1e-10
#: A K-correlation fit with C - 1 below this, or a correlation length B / (2 pi) above
#: this many times the map's extent, is not resolved by the map (the ABC model runs off
#: to a power law or a knee beyond the data: a periodic groove, white noise).
KC_MIN_C_MINUS_1 = 1e-3
KC_MAX_EXTENTS = 100.0


class FlatTopography(ValueError):
    """The map has no height variation left (Sq <= :data:`FLAT_SQ_MM` after levelling)."""


class KCorrelationUnresolved(ValueError):
    """The K-correlation (ABC) model does not describe the map's periodogram."""


def check_not_flat(sq_mm: float, what: str = "the map") -> None:
    """:class:`FlatTopography` when ``sq_mm`` (Sq after levelling) is 0 within rounding."""
    if not (math.isfinite(sq_mm) and sq_mm > FLAT_SQ_MM):
        raise FlatTopography(
            f"{what} is flat (Sq = {sq_mm * 1e6:.3g} nm after levelling): it has no texture to "
            "scatter light; check the file's height column and unit, the levelling (a tilted "
            "plane levels to 0), or use [brdf] model = 'mirror' for an ideal mirror")


# =========================================================================== PSD models
@dataclass(frozen=True)
class KCorrelation:
    """Anisotropic K-correlation (ABC) PSD with RMS height ``sigma`` (mm), ``bx``, ``by``
    (mm; correlation lengths ``b / (2 pi)``) and exponent ``c`` > 1 (see module doc)."""

    sigma: float
    bx: float
    by: float
    c: float = 2.0

    def __post_init__(self):
        if not (self.sigma >= 0 and self.bx > 0 and self.by > 0 and self.c > 1):
            raise ValueError(f"K-correlation needs sigma >= 0, bx, by > 0 and c > 1, got {self}")

    @property
    def a(self) -> float:
        return self.sigma**2 * self.bx * self.by * (self.c - 1) / (2 * math.pi)

    @property
    def correlation_lengths(self) -> tuple[float, float]:
        return self.bx / (2 * math.pi), self.by / (2 * math.pi)

    def __call__(self, fx, fy):
        q = 1.0 + (self.bx * np.asarray(fx, np.float64)) ** 2 + (self.by * np.asarray(fy, np.float64)) ** 2
        return self.a * q ** (-(self.c + 1) / 2)

    def band_variance(self, fmax: float) -> float:
        """Variance inside the elliptical band (Bx fx)^2 + (By fy)^2 <= (B fmax)^2 with
        B = min(bx, by): sigma^2 (1 - (1 + (B fmax)^2)^((1 - C) / 2))."""
        b = min(self.bx, self.by)
        return self.sigma**2 * (1 - (1 + (b * fmax) ** 2) ** ((1 - self.c) / 2))


@dataclass(frozen=True, eq=False)
class TabulatedPSD:
    """A PSD on the periodogram grid (``fx`` (nx,), ``fy`` (ny,) increasing, ``s`` (ny, nx)),
    bilinear between nodes, 0 outside the measured band."""

    fx: np.ndarray
    fy: np.ndarray
    s: np.ndarray

    def __call__(self, fx, fy):
        from scipy.interpolate import RegularGridInterpolator

        f = RegularGridInterpolator((self.fy, self.fx), self.s, bounds_error=False, fill_value=0.0)
        fx, fy = np.broadcast_arrays(np.asarray(fx, np.float64), np.asarray(fy, np.float64))
        return f(np.stack([fy, fx], -1))

    @property
    def variance(self) -> float:
        return float(self.s.sum() * (self.fx[1] - self.fx[0]) * (self.fy[1] - self.fy[0]))


# =========================================================================== spectra
def periodogram(heights, dx: float, dy: float, window: str = "hann"):
    """Two-sided 2-D PSD of a height map: ``(fx (nx,), fy (ny,), S (ny, nx))``, zero
    frequency in the middle (``fftshift``), normalised so that ``S.sum() dfx dfy`` is the
    mean square height (the window's power is divided out). ``window``: ``"hann"`` (for
    measured, non-periodic maps: little leakage of the levelling residue) or ``"none"``."""
    h = np.asarray(heights, np.float64)
    h = h - h.mean()
    ny, nx = h.shape
    if window == "hann":
        w = np.outer(np.hanning(ny + 2)[1:-1], np.hanning(nx + 2)[1:-1])
    elif window == "none":
        w = np.ones_like(h)
    else:
        raise ValueError(f"window must be 'hann' or 'none', got {window!r}")
    spec = np.fft.fftshift(np.abs(np.fft.fft2(h * w)) ** 2)
    s = spec * dx * dy / (nx * ny * np.mean(w * w))
    fx = np.fft.fftshift(np.fft.fftfreq(nx, dx))
    fy = np.fft.fftshift(np.fft.fftfreq(ny, dy))
    return fx, fy, s


@dataclass(frozen=True)
class KCorrelationFit:
    """A fitted :class:`KCorrelation` and the standard errors of its parameters (relative:
    ``rel_err`` = (sigma, bx, by, c)), from Whittle's Fisher information."""

    model: KCorrelation
    rel_err: tuple[float, float, float, float]


def fit_k_correlation(fx, fy, s, c0: float = 2.0, effective_fraction: float = 1.0) -> KCorrelationFit:
    """Whittle fit of :class:`KCorrelation` to a periodogram (zero frequency left out).

    Standard errors from the Fisher information ``(n / 2) mean(g g^T)``, ``g`` the gradient
    of ``log S`` in the parameters, ``n`` the frequencies used x ``effective_fraction``
    (the share of independent periodogram values: 1 without a window; see
    :func:`periodogram`'s ``window``); the half: a real map's spectrum is Hermitian."""
    from scipy.optimize import minimize

    fxx, fyy = np.meshgrid(fx, fy)
    keep = (fxx != 0) | (fyy != 0)
    fxx, fyy, p = fxx[keep], fyy[keep], s[keep]
    dfa = (fx[1] - fx[0]) * (fy[1] - fy[0])
    var = float(s.sum() * dfa)
    if not (math.isfinite(var) and var > FLAT_SQ_MM**2 and np.all(np.isfinite(p))):
        raise FlatTopography(f"the periodogram holds no variance (Sq^2 = {var:.3g} mm^2): "
                             "a flat map has no PSD to fit")
    # start: the knee at a tenth of the band along each axis
    b0 = [10.0 / max(np.abs(fx).max(), 1e-30), 10.0 / max(np.abs(fy).max(), 1e-30)]
    f2x, f2y = fxx * fxx, fyy * fyy

    def grads(x):
        bx2, by2, e = math.exp(2 * x[1]), math.exp(2 * x[2]), (math.exp(x[3]) + 2) / 2
        q = 1 + bx2 * f2x + by2 * f2y
        lq = np.log(q)
        g = (np.ones_like(q), -e * 2 * bx2 * f2x / q, -e * 2 * by2 * f2y / q, -math.exp(x[3]) / 2 * lq)
        return x[0] - e * lq, g

    def nll(x):  # x = log A, log Bx, log By, log(C - 1); value and gradient
        lm, g = grads(np.clip(x, -300, 300))
        with np.errstate(over="ignore", invalid="ignore"):
            r = p * np.exp(-lm)  # p / m
        if not np.all(np.isfinite(r)):
            return 1e300, np.zeros(4)
        w = 1 - r
        return float(np.mean(lm + r)), np.array([np.mean(w * gi) for gi in g])

    extent = max(1.0 / (fx[1] - fx[0]), 1.0 / (fy[1] - fy[0]))  # the map's larger side

    def model(x):
        # sigma^2 = 2 pi A / (Bx By (C - 1)) in logarithms: no product under- or overflows
        bx, by, cm1 = math.exp(min(x[1], 700)), math.exp(min(x[2], 700)), math.exp(min(x[3], 700))
        if not (cm1 >= KC_MIN_C_MINUS_1 and
                max(bx, by) / (2 * math.pi) <= KC_MAX_EXTENTS * extent and min(bx, by) > 0):
            raise KCorrelationUnresolved(
                f"the K-correlation (ABC) model does not describe this map's PSD: the fit runs "
                f"to C - 1 = {cm1:.3g} and correlation lengths {bx / (2 * math.pi) * 1e3:.3g} / "
                f"{by / (2 * math.pi) * 1e3:.3g} um against a map of {extent * 1e3:.3g} um "
                "(a periodic groove, white noise or a power law: no knee inside the map)")
        sigma = math.sqrt(2 * math.pi) * math.exp(0.5 * (x[0] - x[1] - x[2] - x[3]))
        return KCorrelation(sigma, bx, by, 1 + cm1)

    starts = []
    for k in (1.0, 0.1):
        bx, by = b0[0] * k, b0[1] * k
        starts.append([math.log(var * bx * by * (c0 - 1) / (2 * math.pi)), math.log(bx),
                       math.log(by), math.log(c0 - 1)])
    r = min((minimize(nll, x0, jac=True, method="L-BFGS-B",
                      options=dict(maxiter=2000, ftol=1e-15, gtol=1e-12)) for x0 in starts),
            key=lambda r: r.fun)
    m = model(r.x)
    _, g = grads(r.x)
    g = np.stack(g)
    info = (p.size * effective_fraction / 2) * (g @ g.T) / p.size
    cov = np.linalg.pinv(info)
    js = np.array([0.5, -0.5, -0.5, -0.5])
    rel = (math.sqrt(max(js @ cov @ js, 0.0)), math.sqrt(max(cov[1, 1], 0.0)),
           math.sqrt(max(cov[2, 2], 0.0)), (m.c - 1) / m.c * math.sqrt(max(cov[3, 3], 0.0)))
    return KCorrelationFit(m, rel)


def window_fraction(window: str) -> float:
    """Share of independent periodogram values under a 2-D window: (mean w^2)^2 / mean w^4
    per axis (1 without a window; 0.514^2 for Hann)."""
    if window == "none":
        return 1.0
    return ((3 / 8) ** 2 / (35 / 128)) ** 2


def synthesize(psd, shape, dx: float, dy: float, seed: int) -> np.ndarray:
    """A periodic Gaussian random surface (``shape`` = (ny, nx)) whose expected periodogram
    is ``psd(fx, fy)`` (per unit frequency area): white noise filtered in Fourier space
    (``numpy.random.default_rng(seed)``)."""
    ny, nx = shape
    fx = np.fft.fftfreq(nx, dx)
    fy = np.fft.fftfreq(ny, dy)
    s = psd(fx[None, :], fy[:, None])
    s[0, 0] = 0.0
    rng = np.random.default_rng(seed)
    noise = np.fft.fft2(rng.standard_normal((ny, nx)))
    return np.real(np.fft.ifft2(noise * np.sqrt(s / (dx * dy)))) * 1.0


def autocorrelation_lengths(heights, dx: float, dy: float) -> tuple[float, float]:
    """1/e lengths (x, y) of the (circular, mean-removed) autocorrelation along each axis,
    linear interpolation between samples; the map's extent if it never falls to 1/e."""
    h = np.asarray(heights, np.float64) - np.mean(heights)
    acf = np.real(np.fft.ifft2(np.abs(np.fft.fft2(h)) ** 2))
    acf /= acf[0, 0]
    out = []
    for line, d in ((acf[0, : h.shape[1] // 2], dx), (acf[: h.shape[0] // 2, 0], dy)):
        below = np.nonzero(line < 1 / math.e)[0]
        if below.size == 0:
            out.append(line.size * d)
            continue
        k = below[0]
        a, b = line[k - 1], line[k]
        out.append(d * (k - 1 + (a - 1 / math.e) / (a - b)))
    return out[0], out[1]


# =========================================================================== analysis
def to_local(heights, dx: float, dy: float, radial_axis: str = "y"):
    """The map in the BRDF's local frame (x = tangential, y = radial): transposed when the
    map's radial direction (across the turning grooves) is its x axis."""
    if radial_axis == "y":
        return np.asarray(heights, np.float64), dx, dy
    if radial_axis == "x":
        return np.ascontiguousarray(np.asarray(heights, np.float64).T), dy, dx
    raise ValueError(f"radial_axis must be 'x' or 'y', got {radial_axis!r}")


def slope_table(heights, dx: float, dy: float, bins: int = 128) -> TabulatedSlopes:
    """The slope density of a (local-frame) map: a ``bins`` x ``bins`` joint histogram."""
    return TabulatedSlopes.from_height_map(heights, dx, dy, bins)


@dataclass(frozen=True)
class TopographyAnalysis:
    """What a measured topography means optically (lengths in um unless named)."""

    source: str
    shape: tuple[int, int]  # (ny, nx) in the local frame
    spacing_um: tuple[float, float]  # (dx, dy) local
    sq_um: float
    rq_tangential_um: float  # mean RMS of the profiles along local x
    rq_radial_um: float  # along local y
    sdq: float  # RMS gradient
    rms_slope_tangential: float
    rms_slope_radial: float
    alpha_tangential: float  # sqrt(2) x RMS slope: the equivalent Ward/Beckmann lobe
    alpha_radial: float
    kc_sigma_um: float  # K-correlation fit
    kc_correlation_tangential_um: float  # Bx / (2 pi)
    kc_correlation_radial_um: float
    kc_exponent: float
    kc_rel_err: tuple[float, float, float, float]  # standard errors (sigma, Bx, By, C), relative
    acf_length_tangential_um: float  # 1/e of the autocorrelation
    acf_length_radial_um: float
    wavelength_nm: float
    incidence_deg: float
    rayleigh: float  # 4 pi Sq cos / lambda
    specular_share: float  # exp(-rayleigh^2)
    halo_share_first_order: float  # rayleigh^2 within the propagating band (1st order RR)
    regime: str
    regime_reason: str
    model: str  # what [brdf] model = "topography" renders: rayleigh_rice or slope_density
    kc_note: str = ""  # why the K-correlation fields are NaN (the model does not fit the map)

    def as_dict(self) -> dict:
        return asdict(self)


def regime(g: float) -> tuple[str, str, str]:
    """(regime, reason, model) for the Rayleigh parameter g."""
    if g < SMOOTH_MAX_G:
        r, why = "smooth", (f"Rayleigh parameter 4 pi Sq cos / lambda = {g:.3g} < {SMOOTH_MAX_G}: "
                            f"a specular peak ({math.exp(-g * g):.3g} of the light) plus a "
                            "Rayleigh-Rice halo")
    elif g > GEOMETRIC_MIN_G:
        r, why = "geometric", (f"Rayleigh parameter {g:.3g} > {GEOMETRIC_MIN_G}: no specular "
                               "peak left; geometric optics on the slope density")
    else:
        r, why = "intermediate", (f"Rayleigh parameter {g:.3g} between {SMOOTH_MAX_G} and "
                                  f"{GEOMETRIC_MIN_G}: neither the first-order halo nor the "
                                  "slope density is exact")
    return r, why, "rayleigh_rice" if g < HALO_MAX_G else "slope_density"


def analyse(heights, dx: float, dy: float, wavelength_nm: float = 545.0,
            incidence_deg: float = 0.0, source: str = "", window: str = "hann") -> TopographyAnalysis:
    """Statistics, PSD fit and regime of a local-frame map (mm; x tangential, y radial)."""
    h = np.asarray(heights, np.float64)
    h = h - h.mean()
    gy, gx = np.gradient(h, dy, dx)
    st, sr = float(gx.std()), float(gy.std())
    rq_t = float(np.sqrt(np.mean(np.var(h, axis=1))))  # profiles along x (rows)
    rq_r = float(np.sqrt(np.mean(np.var(h, axis=0))))
    sq = float(h.std())
    check_not_flat(sq, "the map")
    fx, fy, s = periodogram(h, dx, dy, window)
    nan = float("nan")
    try:
        fit = fit_k_correlation(fx, fy, s, effective_fraction=window_fraction(window))
        kc_values, kc_note = (fit.model.sigma, *fit.model.correlation_lengths, fit.model.c,
                              fit.rel_err), ""
    except KCorrelationUnresolved as err:
        kc_values, kc_note = (nan, nan, nan, nan, (nan,) * 4), str(err)
    lt, lr = autocorrelation_lengths(h, dx, dy)
    lam = wavelength_nm * 1e-6
    g = 4 * math.pi * sq * math.cos(math.radians(incidence_deg)) / lam
    name, why, model = regime(g)
    band = 1.0 / lam  # spatial frequencies that scatter into propagating directions (about)
    fxx, fyy = np.meshgrid(fx, fy)
    in_band = (fxx**2 + fyy**2) <= band**2
    var_band = float(s[in_band].sum() * (fx[1] - fx[0]) * (fy[1] - fy[0]))
    g_band = 4 * math.pi * math.sqrt(var_band) * math.cos(math.radians(incidence_deg)) / lam
    return TopographyAnalysis(
        source, h.shape, (dx * 1e3, dy * 1e3), sq * 1e3, rq_t * 1e3, rq_r * 1e3,
        float(np.sqrt(np.mean(gx**2 + gy**2))), st, sr, math.sqrt(2) * st, math.sqrt(2) * sr,
        kc_values[0] * 1e3, kc_values[1] * 1e3, kc_values[2] * 1e3, kc_values[3], kc_values[4],
        lt * 1e3, lr * 1e3, wavelength_nm, incidence_deg, g, math.exp(-g * g), g_band**2,
        name, why, model, kc_note)


def format_analysis(a: TopographyAnalysis) -> str:
    """A plain-text table of :class:`TopographyAnalysis`."""
    kc = ([("K-correlation fit", f"not reported: {a.kc_note}")] if a.kc_note else [
        ("K-correlation sigma / C", (f"{a.kc_sigma_um * 1e3:.4g} nm +- {_pc(a.kc_rel_err[0])} / "
                                     f"{a.kc_exponent:.3g} +- {_pc(a.kc_rel_err[3])}")),
        ("correlation length tang. / rad.", (f"{a.kc_correlation_tangential_um:.4g} +- "
                                             f"{_pc(a.kc_rel_err[1])} / {a.kc_correlation_radial_um:.4g}"
                                             f" +- {_pc(a.kc_rel_err[2])} um (B / 2 pi)"))])
    rows = [
        ("file", a.source or "(array)"),
        ("grid (ny, nx) / spacing dx, dy", f"{a.shape[0]} x {a.shape[1]} / {a.spacing_um[0]:.4g}, "
                                           f"{a.spacing_um[1]:.4g} um (x tangential, y radial)"),
        ("Sq", f"{a.sq_um * 1e3:.4g} nm"),
        ("Rq tangential / radial profiles", f"{a.rq_tangential_um * 1e3:.4g} / "
                                            f"{a.rq_radial_um * 1e3:.4g} nm"),
        ("Sdq (RMS gradient)", f"{a.sdq:.4g}"),
        ("RMS slope tangential / radial", f"{a.rms_slope_tangential:.4g} / {a.rms_slope_radial:.4g}"),
        ("Ward/Beckmann alpha_tangential", f"{a.alpha_tangential:.4g}"),
        ("Ward/Beckmann alpha_radial", f"{a.alpha_radial:.4g}"),
        *kc,
        ("ACF 1/e length tang. / rad.", f"{a.acf_length_tangential_um:.4g} / "
                                        f"{a.acf_length_radial_um:.4g} um"),
        ("wavelength / incidence", f"{a.wavelength_nm:g} nm / {a.incidence_deg:g} deg"),
        ("Rayleigh 4 pi Sq cos/lambda", f"{a.rayleigh:.3g} (specular share {a.specular_share:.4g}; "
                                        f"first-order halo {a.halo_share_first_order:.3g})"),
        ("regime", f"{a.regime}: {a.regime_reason}"),
        ("[brdf] model = 'topography' uses", a.model),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)


def _pc(x: float) -> str:
    return f"{100 * x:.2g} %"


# =========================================================================== configuration
def read_local(cfg):
    """The configured topography file in the local frame: (heights mm, dx, dy, Topography)."""
    from ..topofile import read_topography

    t = read_topography(cfg.file, "brdf.file", spacing_mm=cfg.spacing_mm,
                        height_unit=cfg.height_unit, level=cfg.level, fill=cfg.fill,
                        outlier_sigma=cfg.outlier_sigma)
    h, dx, dy = to_local(t.heights, t.dx, t.dy, cfg.radial_axis)
    return h, dx, dy, t


def from_config(cfg, incidence_deg: float = 0.0):
    """The ``topography`` model: the slope density (geometric) or the specular peak plus the
    Rayleigh-Rice halo of the map's PSD (smooth), by ``cfg.regime`` (``auto``: the
    Rayleigh parameter at the configured or the set-up's incidence, :func:`regime`)."""
    from ..config import ConfigError
    from . import rayleigh_rice as rr
    from .slope_density import SlopeDensityBRDF

    inc = cfg.incidence_deg if cfg.incidence_deg is not None else incidence_deg
    h, dx, dy, _ = read_local(cfg)
    h = h - h.mean()
    lam = cfg.wavelength_nm * 1e-6
    sq = float(h.std())
    try:
        check_not_flat(sq, f"brdf.file: {cfg.file}: the map")
    except FlatTopography as err:
        raise ConfigError(str(err)) from None
    g = 4 * math.pi * sq * math.cos(math.radians(inc)) / lam
    use = cfg.regime if cfg.regime != "auto" else ("smooth" if regime(g)[2] == "rayleigh_rice"
                                                    else "geometric")
    if use == "geometric":
        return SlopeDensityBRDF(slope_table(h, dx, dy, cfg.bins), cfg.rho_s,
                                cfg.shadowing == "smith", name="topography")
    eps = rr.permittivity(cfg.refractive_index)
    rr.check_validity(sq, lam, math.radians(inc), eps, cfg.rho_s,
                      sigma_field=f"brdf.regime = 'smooth' with brdf.file {cfg.file}")
    fx, fy, s = periodogram(h, dx, dy, "hann")
    if cfg.psd == "k_correlation":
        try:
            psd = fit_k_correlation(fx, fy, s, effective_fraction=window_fraction("hann")).model
        except KCorrelationUnresolved as err:
            raise ConfigError(f"brdf.psd = 'k_correlation': {err} ({cfg.file}); use psd = "
                              "'tabulated' (the measured periodogram)") from None
    else:
        psd = TabulatedPSD(fx, fy, s)
    exact = rr.RayleighRice(psd, sq, lam, eps, cfg.rho_s)
    model = rr.specular_halo(exact, math.radians(inc), bins=cfg.halo_bins)
    return rr.SpecularHaloBRDF(model.exact, model.halo, model.specular_reflectance, model.theta0,
                               model.table_share, name="topography")
