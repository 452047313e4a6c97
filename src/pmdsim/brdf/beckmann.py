"""Anisotropic Beckmann micro-facet BRDF (Cook-Torrance form), as mainstream renderers use it.

    f(i, o) = F D(h) G(i, o) / (4 cos_i cos_o),
    D(h)    = exp(-tan^2(theta_h) (cos^2 phi_h / alpha_u^2 + sin^2 phi_h / alpha_v^2))
              / (pi alpha_u alpha_v cos^4(theta_h)),

with ``h`` the normalised half vector of ``i`` and ``o``. Parameters:

- ``alpha_u``, ``alpha_v``: roughness along the local x and y axes (tangential and radial
  in a rotational frame), sqrt(2) times the RMS micro-facet slope per axis; for an isotropic
  surface ``alpha`` is the RMS slope. The slope density is the one of Ward's model, so Ward
  with ``alpha_x = alpha_u`` and ``alpha_y = alpha_v`` has the same lobe shape; the models
  differ in the prefactor (Ward 1992: ``rho / (4 pi ax ay sqrt(cos_i cos_o))`` against
  ``F / (4 pi au av cos^4(theta_h) cos_i cos_o) G``). This matches mitsuba's
  ``roughconductor`` with ``distribution = "beckmann"``, ``alpha_u``/``alpha_v`` and a
  constant Fresnel term; mitsuba samples visible normals by default and evaluates Smith's
  G1 with a rational approximation (at most 0.31 % from the exact value), here it is exact.
- ``rho_s``: the Fresnel factor ``F``, a constant (no angular dependence).
- ``smith``: Smith's uncorrelated shadowing-masking ``G = G1(i) G1(o)`` with
  ``G1 = 1 / (1 + Lambda(a))``, ``a = cot(theta) / alpha(phi)``,
  ``Lambda(a) = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2``; ``False``: ``G = 1``.

Sampling: the plain slope distribution ``D(m) cos(theta_m)`` (Walter et al. 2007, identical
to Walter's 2005 Ward sampler, :mod:`pmdsim.brdf.microfacet`), not the distribution of
visible normals; ``pdf(o) = D(h) cos(theta_h) / (4 (i.h))`` and the weight
``f cos_o / pdf = F G (i.h) / (cos_i cos(theta_h))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erfc

from ..kernels import bundle as kb
from . import microfacet


def smith_g1(v_local, alpha_u: float, alpha_v: float) -> np.ndarray:
    """Smith masking G1 (...,) of the Beckmann distribution for local unit directions v."""
    v = np.asarray(v_local, np.float64)
    vz = v[..., 2]
    s = np.sqrt((v[..., 0] * alpha_u) ** 2 + (v[..., 1] * alpha_v) ** 2)
    up = vz > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(up & (s > 0), np.where(up, vz, 1.0) / np.where(s > 0, s, 1.0), np.inf)
        lam = np.where(a < 6.0, 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi)) - erfc(a)), 0.0)
    return np.where(up, 1.0 / (1.0 + lam), 0.0)


@dataclass(frozen=True)
class Beckmann:
    alpha_u: float
    alpha_v: float
    rho_s: float = 1.0
    smith: bool = True
    name: str = "beckmann"
    is_delta: bool = False

    def __post_init__(self):
        if not (self.alpha_u > 0 and self.alpha_v > 0):
            raise ValueError(f"alpha_u, alpha_v must be > 0, got {self.alpha_u}, {self.alpha_v}")
        if not self.rho_s > 0:
            raise ValueError(f"rho_s must be > 0, got {self.rho_s}")

    def distribution(self, h_local) -> np.ndarray:
        """D(h) (...,) for normalised local half vectors; 0 below the surface."""
        h = np.asarray(h_local, np.float64)
        hz = h[..., 2]
        ok = hz > 0
        hz_ = np.where(ok, hz, 1.0)
        e = np.exp(-((h[..., 0] / self.alpha_u) ** 2 + (h[..., 1] / self.alpha_v) ** 2) / hz_**2)
        return np.where(ok, e / (np.pi * self.alpha_u * self.alpha_v * hz_**4), 0.0)

    def evaluate(self, i_local, o_local):
        i_local = np.asarray(i_local, np.float64)
        o_local = np.asarray(o_local, np.float64)
        ci, co = i_local[..., 2], o_local[..., 2]
        ok = (ci > 0) & (co > 0)
        h = microfacet.half_vector(i_local, o_local)
        f = self.rho_s * self.distribution(h) / (4.0 * np.where(ok, ci * co, 1.0))
        if self.smith:
            f = f * smith_g1(i_local, self.alpha_u, self.alpha_v) * smith_g1(
                o_local, self.alpha_u, self.alpha_v)
        return np.where(ok, f, 0.0)

    def sample(self, u1, u2, i_local):
        """Directions (..., 3) reflected about micro-normals drawn from D(m) cos(theta_m)."""
        return microfacet.sample_reflection(u1, u2, i_local, self.alpha_u, self.alpha_v)

    def pdf(self, i_local, o_local):
        """D(h) cos(theta_h) / (4 (i.h)) (...,); 0 below the surface."""
        return microfacet.reflection_pdf(i_local, o_local, self.alpha_u, self.alpha_v)

    def kernel_params(self):
        p = np.zeros(kb.B_SIZE)
        p[kb.B_MODEL] = kb.MODEL_BECKMANN
        p[kb.B_RHO] = self.rho_s
        p[kb.B_AX] = self.alpha_u
        p[kb.B_AY] = self.alpha_v
        p[kb.B_SMITH] = 1.0 if self.smith else 0.0
        return p
