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

The PSD models, the periodogram and its fit are in :mod:`pmdsim.brdf.psd`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..config import TopographyConfig
from .slope_density import TabulatedSlopes
from .psd import FLAT_SQ_MM, FlatTopography, KCorrelationUnresolved, TabulatedPSD, fit_k_correlation, periodogram, window_fraction

#: Rayleigh parameter below which a surface is optically smooth, above which geometric.
SMOOTH_MAX_G = 0.5
GEOMETRIC_MIN_G = 1.5
#: The topography model's switch between the halo and the slope density.
HALO_MAX_G = 1.0
def check_not_flat(sq_mm: float, what: str = "the map") -> None:
    """:class:`FlatTopography` when ``sq_mm`` (Sq after levelling) is 0 within rounding."""
    if not (math.isfinite(sq_mm) and sq_mm > FLAT_SQ_MM):
        raise FlatTopography(
            f"{what} is flat (Sq = {sq_mm * 1e6:.3g} nm after levelling): it has no texture to "
            "scatter light; check the file's height column and unit, the levelling (a tilted "
            "plane levels to 0), or use [brdf] model = 'mirror' for an ideal mirror")


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
def read_local(cfg: TopographyConfig):
    """The configured topography file in the local frame: (heights mm, dx, dy, Topography)."""
    from ..topofile import read_topography

    t = read_topography(cfg.file, "brdf.file", spacing_mm=cfg.spacing_mm,
                        height_unit=cfg.height_unit, level=cfg.level, fill=cfg.fill,
                        outlier_sigma=cfg.outlier_sigma)
    h, dx, dy = to_local(t.heights, t.dx, t.dy, cfg.radial_axis)
    return h, dx, dy, t


def from_config(cfg: TopographyConfig, incidence_deg: float = 0.0):
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