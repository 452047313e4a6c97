"""A specular peak beside a lobe (``SpecularHaloBRDF``: optically smooth finishes).

A BRDF with a ``specular_reflectance`` a > 0 (:mod:`pmdsim.brdf.rayleigh_rice`) is a Dirac
peak of reflectance a plus a lobe (the halo) of reflectance h (``halo_reflectance``). Its
pixel sums are the lobe pass's plus the mirror pass's (the principal ray only: no rays spent
on the delta), weighted so that every estimator keeps its meaning:

- ``radiometric`` (``(1/N) sum f cos L / pdf``, the rendering integral): the peak adds
  ``a L(P)``: ``out = out_lobe + a N out_mirror``;
- ``weighted_mean`` (``sum f L / sum f``): the value is the reflectance-weighted mean
  ``(a L(P) + h <L>_lobe) / (a + h)``: ``out = out_lobe + (a / h) F out_mirror`` with ``F``
  the lobe's per-pixel sum of weights;
- ``paper`` (``(1/N) sum f L`` over a cone, no radiometric meaning) has no consistent
  weight for a Dirac peak: refused (``sampling.estimator``).

All kernel output columns (``OUT_FTOTAL``, ``OUT_FHIT`` and the pattern sums) are sums of
ray weights, so the combination is one linear step per pixel.
"""

from __future__ import annotations

import numpy as np

from ..config import ConfigError
from ..kernels import bundle as kb


def specular_reflectance(brdf) -> float:
    """The BRDF's Dirac share a (0 for lobes and for the mirror itself)."""
    if getattr(brdf, "is_delta", False):
        return 0.0
    return float(getattr(brdf, "specular_reflectance", 0.0) or 0.0)


def check_estimator(brdf, estimator: str) -> None:
    if specular_reflectance(brdf) > 0 and estimator == "paper":
        raise ConfigError(f"sampling.estimator: the {brdf.name} model has a specular peak beside "
                          "its halo, which the paper estimator cannot weigh; use "
                          "estimator = 'radiometric' (or 'weighted_mean')")


def add_specular(out_lobe: np.ndarray, out_mirror: np.ndarray, brdf, estimator: str,
                 n_rays: int) -> np.ndarray:
    """Pixel sums (H, W, C) of peak + lobe from the two passes' sums (module doc)."""
    check_estimator(brdf, estimator)
    a = specular_reflectance(brdf)
    if estimator == "radiometric":
        return out_lobe + (a * n_rays) * out_mirror
    h = float(brdf.halo_reflectance)
    ft = out_lobe[..., kb.OUT_FTOTAL]
    c = np.where(np.isfinite(ft) & (ft > 0), ft, 0.0) * (a / h)
    return out_lobe + c[..., None] * out_mirror
