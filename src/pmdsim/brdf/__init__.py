"""BRDF models behind one small interface (:class:`~pmdsim.brdf.base.BRDF`)."""

from .base import BRDF, lobe_weight
from .beckmann import Beckmann
from .mirror import Mirror
from .ward import Ward


def brdf_from_config(cfg) -> BRDF:
    if cfg.model == "ward":
        ax, ay = cfg.alphas
        return Ward(ax, ay, cfg.rho_s, cfg.normalization)
    if cfg.model == "beckmann":
        au, av = cfg.alphas
        return Beckmann(au, av, cfg.rho_s, cfg.shadowing == "smith")
    if cfg.model == "mirror":
        return Mirror()
    raise ValueError(f"brdf.model: unknown model {cfg.model!r}")


__all__ = ["BRDF", "Beckmann", "Mirror", "Ward", "brdf_from_config", "lobe_weight"]
