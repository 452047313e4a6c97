"""BRDF models behind one small interface (:class:`~pmdsim.brdf.base.BRDF`): Ward,
Beckmann, the mirror, slope densities (``slope_density``; turned surfaces, ``turning``),
measured topographies (``topography``), the specular peak plus Rayleigh-Rice halo
(``rayleigh_rice``) and the surface PSD models both use (``psd``); the model of a
``[brdf]`` section (:func:`brdf_from_config`)."""

from __future__ import annotations

import math

from .base import BRDF, lobe_weight
from .beckmann import Beckmann
from .mirror import Mirror
from .slope_density import SlopeDensityBRDF
from .ward import Ward
from ..config import BrdfConfig, SlopeDensityConfig, TurnedConfig


def brdf_from_config(cfg: BrdfConfig, incidence_deg: float = 0.0) -> BRDF:
    """The BRDF of a ``[brdf]`` configuration; ``incidence_deg``: the set-up's incidence at
    the surface centre, for the models built for one (``rayleigh_rice``, ``topography``)
    when the configuration gives none."""
    if cfg.model == "ward":
        ax, ay = cfg.alphas
        return Ward(ax, ay, cfg.rho_s, cfg.normalization)
    if cfg.model == "beckmann":
        au, av = cfg.alphas
        return Beckmann(au, av, cfg.rho_s, cfg.shadowing == "smith")
    if cfg.model == "mirror":
        return Mirror()
    if cfg.model in ("slope_density", "turned"):
        return _slope_brdf(cfg)
    if cfg.model == "rayleigh_rice":
        from . import rayleigh_rice

        return rayleigh_rice.from_config(cfg, incidence_deg)
    if cfg.model == "topography":
        from . import topography

        return topography.from_config(cfg, incidence_deg)
    raise ValueError(f"brdf.model: unknown model {cfg.model!r}")


def equivalent_alphas(cfg: BrdfConfig) -> tuple[float, float]:
    """(alpha along local x, alpha along local y) of a BRDF configuration: its own alphas
    (Ward, Beckmann, Gaussian slopes) or sqrt(2) x the RMS slope per axis of its slope
    density (kinematic, tabulated, turned); (0, 0) for the mirror."""
    if cfg.model == "mirror":
        return 0.0, 0.0
    if cfg.model in ("ward", "beckmann") or getattr(cfg, "density", None) == "gaussian":
        return cfg.alphas
    return brdf_from_config(cfg).smith_alphas


def _slope_brdf(cfg: SlopeDensityConfig | TurnedConfig) -> SlopeDensityBRDF:
    from . import slope_density as sd
    from . import turning

    smith = cfg.shadowing == "smith"
    if cfg.model == "slope_density" and cfg.density == "gaussian":
        return SlopeDensityBRDF(sd.GaussianSlopes(*cfg.alphas), cfg.rho_s, smith)
    if cfg.model == "slope_density" and cfg.density == "tabulated":
        return SlopeDensityBRDF(sd.tabulated_from_file(cfg.file, cfg.pitch_mm, cfg.bins),
                                cfg.rho_s, smith)
    s_tan, s_rad = cfg.random_rms_slopes()
    feed, radius = cfg.feed_um * 1e-3, cfg.nose_radius_mm
    if cfg.model == "turned" and cfg.regime == "diffractive":
        dens = turning.grating_orders(
            feed, radius, (math.sqrt(2) * s_tan, max(math.sqrt(2) * s_rad, 1e-12)),
            cfg.wavelengths_nm, cfg.spectral_weights, math.radians(cfg.incidence_deg))
    else:
        dens = sd.kinematic_slopes(feed, radius, s_rad, s_tan)
    return SlopeDensityBRDF(dens, cfg.rho_s, smith, name=cfg.model)


__all__ = ["BRDF", "Beckmann", "Mirror", "SlopeDensityBRDF", "Ward", "brdf_from_config", "equivalent_alphas",
           "lobe_weight"]
