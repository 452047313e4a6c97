"""Optically smooth surfaces: a specular peak plus a Rayleigh-Rice halo.

A surface whose RMS height is well below the wavelength reflects a share
``exp(-(4 pi sigma cos(theta_i) / lambda)^2)`` of its specular reflectance as a sharp peak
(the coherent reflection; Davies/Beckmann) and scatters the rest into a halo given, to first
order in the heights, by the Rayleigh-Rice (first-order vector perturbation) BRDF

    f(i, o) = (16 pi^2 / lambda^4) cos(theta_i) cos(theta_s) Q S(fx, fy),
    (fx, fy) = (o_xy + i_xy) / lambda        (the grating equation; i towards the camera),

``S`` the two-sided 2-D PSD of the heights (per unit spatial-frequency area, ``int S =
sigma^2``) and ``Q`` the polarisation factor of a substrate of permittivity ``eps``: the
unpolarised mean ``(Q_ss + Q_sp + Q_ps + Q_pp) / 2`` of (Elson and Bennett; Stover,
*Optical Scattering*, eq. 5.15-5.18)

    Q_ss = |(eps - 1) cos(phi_s) / ((cos_i + a_i)(cos_s + a_s))|^2
    Q_sp = |(eps - 1) a_s sin(phi_s) / ((cos_i + a_i)(eps cos_s + a_s))|^2
    Q_ps = |(eps - 1) a_i sin(phi_s) / ((eps cos_i + a_i)(cos_s + a_s))|^2
    Q_pp = |(eps - 1)(a_s a_i cos(phi_s) - eps sin_i sin_s) / ((eps cos_i + a_i)(eps cos_s + a_s))|^2

with ``a = sqrt(eps - sin^2)`` and ``phi_s`` the scattering azimuth from the plane of
incidence (0 = forward). At the specular direction Q is the Fresnel reflectance. Without a
permittivity (``eps`` None) ``Q`` is the constant ``rho_s`` (the small-angle scalar form).
Its total integrated scatter for a PSD narrow against ``1 / lambda`` is the closed form
``R (4 pi sigma cos(theta_i) / lambda)^2``.

**Rendering** (:class:`SpecularHaloBRDF`). The specular share is rendered as the mirror
(the principal ray, no rays spent on a delta: :mod:`pmdsim.render.specular`), the halo by
the lobe rules as a tabulated micro-facet slope density (``MODEL_SLOPE_TABLE`` of the bundle
kernels): with the half-vector slopes ``s``, ``(i + o)_xy = -(cos_i + cos_o) s``, so the
halo is the micro-facet BRDF ``F p(s) / (4 cos_i cos_o cos^4(theta_h))`` with

    p(s) = kappa^2 S(kappa s) / sigma_t^2,   kappa = 2 cos(theta_0) / lambda,
    F = Q(theta_0) (4 pi sigma_t cos(theta_0) / lambda)^2 x (the table's share of p),

``theta_0`` the set-up's incidence and ``sigma_t`` the RMS height of the tabulated band.
This equals the Rayleigh-Rice BRDF exactly at the specular direction for incidence
``theta_0`` and departs from it, to second order in the scattering angle, through
``(cos_i + cos_o) / (2 cos(theta_0))`` (the halo's width scales with ``cos(theta_0) /
cos(theta_i)`` at other incidences), ``cos_i cos_o`` versus ``cos^4(theta_0) / cos^4(theta_h)``
and ``Q``'s angular dependence: ``tests/brdf/test_rayleigh_rice.py`` bounds the difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import RayleighRiceConfig
from .slope_density import SlopeDensityBRDF, TabulatedSlopes


# =========================================================================== physics
def fresnel_unpolarised(eps: complex, cos_i) -> np.ndarray:
    """(|r_s|^2 + |r_p|^2) / 2 of a substrate of relative permittivity ``eps``."""
    ci = np.asarray(cos_i, np.complex128)
    a = np.sqrt(eps - (1 - ci * ci))
    rs = (ci - a) / (ci + a)
    rp = (eps * ci - a) / (eps * ci + a)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def q_factors(eps: complex, cos_i, cos_s, cos_phi, sin_phi):
    """(Q_ss, Q_sp, Q_ps, Q_pp) of the first-order vector perturbation theory."""
    ci = np.asarray(cos_i, np.complex128)
    cs = np.asarray(cos_s, np.complex128)
    si = np.sqrt(np.maximum(1 - np.real(ci) ** 2, 0.0))
    ss = np.sqrt(np.maximum(1 - np.real(cs) ** 2, 0.0))
    ai = np.sqrt(eps - si * si + 0j)
    as_ = np.sqrt(eps - ss * ss + 0j)
    e1 = eps - 1
    q_ss = np.abs(e1 * cos_phi / ((ci + ai) * (cs + as_))) ** 2
    q_sp = np.abs(e1 * as_ * sin_phi / ((ci + ai) * (eps * cs + as_))) ** 2
    q_ps = np.abs(e1 * ai * sin_phi / ((eps * ci + ai) * (cs + as_))) ** 2
    q_pp = np.abs(e1 * (as_ * ai * cos_phi - eps * si * ss) / ((eps * ci + ai) * (eps * cs + as_))) ** 2
    return q_ss, q_sp, q_ps, q_pp


def specular_share(sigma: float, wavelength: float, cos_i) -> np.ndarray:
    """exp(-(4 pi sigma cos(theta_i) / lambda)^2): the coherent share of the reflectance."""
    return np.exp(-(4 * math.pi * sigma * np.asarray(cos_i, np.float64) / wavelength) ** 2)


@dataclass(frozen=True, eq=False)
class RayleighRice:
    """The Rayleigh-Rice BRDF of the halo (module doc). ``psd(fx, fy)`` in mm^4 of
    frequencies in 1/mm along local x (tangential) and y (radial), ``sigma`` its RMS height
    (mm, for the specular share), ``wavelength`` mm, ``eps`` the substrate's relative
    permittivity (``(n + i k)^2``) or None for ``Q = rho_s``."""

    psd: object
    sigma: float
    wavelength: float
    eps: complex | None = None
    rho_s: float = 1.0

    def reflectance(self, cos_i) -> np.ndarray:
        """Specular reflectance R(theta_i): Fresnel of ``eps``, or ``rho_s``."""
        if self.eps is None:
            return np.full(np.shape(cos_i), float(self.rho_s))
        return fresnel_unpolarised(self.eps, cos_i)

    def specular(self, cos_i) -> np.ndarray:
        """Reflectance of the specular peak: R exp(-(4 pi sigma cos / lambda)^2)."""
        return self.reflectance(cos_i) * specular_share(self.sigma, self.wavelength, cos_i)

    def q(self, i_local, o_local) -> np.ndarray:
        """Unpolarised Q (...,)."""
        i = np.asarray(i_local, np.float64)
        o = np.asarray(o_local, np.float64)
        if self.eps is None:
            return np.full(np.broadcast_shapes(i.shape, o.shape)[:-1], float(self.rho_s))
        fwd = -i[..., :2]
        nf = np.linalg.norm(fwd, axis=-1)
        fwd = np.where(nf[..., None] > 1e-12, fwd / np.where(nf > 1e-12, nf, 1.0)[..., None],
                       np.array([1.0, 0.0]))
        oxy = o[..., :2]
        no = np.linalg.norm(oxy, axis=-1)
        cphi = np.where(no > 1e-15, np.sum(oxy * fwd, -1) / np.where(no > 1e-15, no, 1.0), 1.0)
        sphi = np.where(no > 1e-15, (fwd[..., 0] * oxy[..., 1] - fwd[..., 1] * oxy[..., 0])
                        / np.where(no > 1e-15, no, 1.0), 0.0)
        q = q_factors(self.eps, i[..., 2], o[..., 2], cphi, sphi)
        return 0.5 * (q[0] + q[1] + q[2] + q[3])

    def evaluate(self, i_local, o_local) -> np.ndarray:
        i = np.asarray(i_local, np.float64)
        o = np.asarray(o_local, np.float64)
        ci, co = i[..., 2], o[..., 2]
        ok = (ci > 0) & (co > 0)
        f = (i[..., :2] + o[..., :2]) / self.wavelength
        s = self.psd(f[..., 0], f[..., 1])
        val = 16 * math.pi**2 / self.wavelength**4 * ci * co * self.q(i, o) * s
        return np.where(ok, val, 0.0)


# =========================================================================== rendering
def halo_table(psd, sigma_band: float, wavelength: float, theta0: float, half_width: tuple,
               bins: int = 256, sub: int = 3) -> TabulatedSlopes:
    """The halo's slope density ``kappa^2 S(kappa s)`` (``kappa = 2 cos(theta0) /
    lambda``) on a ``bins`` x ``bins`` joint table over ``+-half_width`` (slopes x, y),
    each cell's mass the mean of ``sub`` x ``sub`` samples inside it (normalised over the
    table; the share of the band's variance it holds is :func:`table_share`)."""
    kappa = 2 * math.cos(theta0) / wavelength
    hx, hy = half_width
    ex = np.linspace(-hx, hx, bins + 1)
    ey = np.linspace(-hy, hy, bins + 1)
    t = (np.arange(sub) + 0.5) / sub
    sx = (ex[:-1, None] + np.diff(ex)[:, None] * t).ravel()
    sy = (ey[:-1, None] + np.diff(ey)[:, None] * t).ravel()
    dens = psd(kappa * sx[:, None], kappa * sy[None, :]) * kappa**2
    mass = dens.reshape(bins, sub, bins, sub).mean(axis=(1, 3)) * (ex[1] - ex[0]) * (ey[1] - ey[0])
    table = TabulatedSlopes(-hx, ex[1] - ex[0], -hy, ey[1] - ey[0], mass=np.maximum(mass, 0.0),
                            kind="rayleigh_rice")
    object.__setattr__(table, "_share", float(mass.sum()) / sigma_band**2)
    return table


def table_share(table: TabulatedSlopes) -> float:
    """Share of the band's height variance the halo table holds (1 - what its edges cut)."""
    return float(getattr(table, "_share", 1.0))


@dataclass(frozen=True, eq=False)
class SpecularHaloBRDF:
    """Specular peak (rendered as the mirror, reflectance ``specular_reflectance``) plus a
    halo (``halo``: a tabulated slope-density BRDF whose F is the halo's share, module
    doc). ``exact`` is the Rayleigh-Rice BRDF the halo approximates, ``theta0`` the
    incidence it was built for. ``evaluate``/``sample``/``pdf``/``kernel_params`` are the
    halo's (what the kernels render); the peak is added by the renderer."""

    exact: RayleighRice
    halo: SlopeDensityBRDF
    specular_reflectance: float
    theta0: float
    table_share: float = 1.0
    name: str = "rayleigh_rice"
    is_delta: bool = False

    @property
    def smith_alphas(self) -> tuple[float, float]:
        return self.halo.smith_alphas

    @property
    def halo_reflectance(self) -> float:
        return float(self.halo.rho_s)

    def evaluate(self, i_local, o_local):
        return self.halo.evaluate(i_local, o_local)

    def sample(self, u1, u2, i_local):
        return self.halo.sample(u1, u2, i_local)

    def pdf(self, i_local, o_local):
        return self.halo.pdf(i_local, o_local)

    def kernel_params(self):
        return self.halo.kernel_params()


def specular_halo(exact: RayleighRice, theta0: float, sigma_band: float | None = None,
                  half_width: tuple | None = None, bins: int = 512) -> SpecularHaloBRDF:
    """The rendered model of ``exact`` at incidence ``theta0`` (rad). ``sigma_band``: RMS
    height of the PSD inside the table (default ``exact.sigma``); ``half_width``: the
    table's half widths in slope (default: where the PSD along each axis falls to 1e-4 of
    its largest value, at most the slope of a spatial frequency 1 / lambda)."""
    lam = exact.wavelength
    c0 = math.cos(theta0)
    sigma_band = exact.sigma if sigma_band is None else sigma_band
    if half_width is None:
        half_width = (_extent(exact.psd, lam, c0, 0), _extent(exact.psd, lam, c0, 1))
    table = halo_table(exact.psd, sigma_band, lam, theta0, half_width, bins)
    share = min(table_share(table), 1.0)
    i0 = np.array([math.sin(theta0), 0.0, c0])
    r0 = float(exact.q(i0, i0 * np.array([-1, -1, 1.0])))
    g2 = (4 * math.pi * sigma_band * c0 / lam) ** 2
    # R (1 - exp(-g^2)): first order R g^2, and peak + halo never reflect more than R
    halo = SlopeDensityBRDF(table, r0 * -math.expm1(-g2) * share, smith=False,
                            name="rayleigh_rice")
    return SpecularHaloBRDF(exact, halo, float(exact.specular(c0)), theta0, share)


def _extent(psd, lam, c0, axis):
    """Half width in slope along ``axis`` where psd falls to 1e-4 of S(0), <= 1/(2 c0)."""
    kappa = 2 * c0 / lam
    fmax = 1.0 / lam
    f = np.geomspace(fmax * 1e-6, fmax, 400)
    z = np.zeros_like(f)
    s = psd(f, z) if axis == 0 else psd(z, f)
    peak = int(np.argmax(s))
    below = np.nonzero(s[peak:] < 1e-4 * s[peak])[0]
    fe = f[peak + below[0]] if below.size else fmax
    return float(fe / kappa)


# =========================================================================== validity
#: The largest Rayleigh parameter g = 4 pi sigma cos(theta_i) / lambda the first-order halo
#: is rendered at (the topography model's switch, :data:`pmdsim.brdf.topography.HALO_MAX_G`):
#: above it the perturbation series does not converge and the surface is geometric.
MAX_RAYLEIGH = 1.0
#: Reflectance at the build incidence below which the substrate reflects nothing useful.
MIN_REFLECTANCE = 1e-6


def rayleigh_parameter(sigma: float, wavelength: float, theta0: float) -> float:
    return 4 * math.pi * sigma * math.cos(theta0) / wavelength


def check_validity(sigma: float, wavelength: float, theta0: float, eps, rho_s: float,
                   sigma_field: str = "brdf.sigma_nm") -> None:
    """ConfigError (naming the fields) when the first-order Rayleigh-Rice halo does not hold:
    a Rayleigh parameter above :data:`MAX_RAYLEIGH`, or a substrate that reflects nothing."""
    from ..config import ConfigError

    g = rayleigh_parameter(sigma, wavelength, theta0)
    if not g <= MAX_RAYLEIGH:
        raise ConfigError(
            f"{sigma_field}: sigma = {sigma * 1e6:.4g} nm at brdf.wavelength_nm = "
            f"{wavelength * 1e6:.4g} nm and {math.degrees(theta0):.3g} deg incidence has the "
            f"Rayleigh parameter 4 pi sigma cos / lambda = {g:.3g}, above the smooth-surface "
            f"limit {MAX_RAYLEIGH:g} of the first-order Rayleigh-Rice halo (the surface is not "
            f"optically smooth: its specular peak is gone and the first-order halo does not "
            f"describe what it scatters); keep sigma below "
            f"{MAX_RAYLEIGH * wavelength / (4 * math.pi * math.cos(theta0)) * 1e6:.3g} nm (or "
            "check the wavelength's unit: nm), or describe the surface by its slopes: model = 'topography' with regime = "
            "'geometric' (a height map), 'slope_density', 'ward' or 'beckmann'")
    r = float(fresnel_unpolarised(eps, math.cos(theta0))) if eps is not None else float(rho_s)
    if not r >= MIN_REFLECTANCE:
        n = cmath_sqrt(eps)
        raise ConfigError(
            f"brdf.refractive_index = ({n.real:g}, {n.imag:g}): the substrate reflects "
            f"{r:.3g} of the light at {math.degrees(theta0):.3g} deg (n = 1, k = 0 is the "
            "surrounding air itself): nothing to measure; give the substrate's (n, k) at "
            "brdf.wavelength_nm (aluminium at 545 nm: (0.96, 6.69); glass: (1.5, 0)), or leave "
            "refractive_index unset (Q = rho_s)")


def cmath_sqrt(z) -> complex:
    import cmath

    return cmath.sqrt(complex(z))


# =========================================================================== configuration
def permittivity(refractive_index) -> complex | None:
    """(n, k) -> eps = (n + i k)^2; None stays None."""
    if refractive_index is None:
        return None
    n, k = refractive_index
    return complex(n, k) ** 2


def from_config(cfg: RayleighRiceConfig, incidence_deg: float = 0.0) -> SpecularHaloBRDF:
    """The ``rayleigh_rice`` model of a configuration (``incidence_deg``: the set-up's, used
    when the configuration gives none)."""
    from .psd import KCorrelation

    theta0 = math.radians(cfg.incidence_deg if cfg.incidence_deg is not None else incidence_deg)
    psd = KCorrelation(cfg.sigma_nm * 1e-6, 2 * math.pi * cfg.correlation_length_tangential_um * 1e-3,
                       2 * math.pi * cfg.correlation_length_radial_um * 1e-3, cfg.exponent_c)
    lam = cfg.wavelength_nm * 1e-6
    eps = permittivity(cfg.refractive_index)
    check_validity(psd.sigma, lam, theta0, eps, cfg.rho_s)
    exact = RayleighRice(psd, psd.sigma, lam, eps, cfg.rho_s)
    return specular_halo(exact, theta0, bins=cfg.halo_bins)
