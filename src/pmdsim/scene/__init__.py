"""The scene: camera, monitor, surface, anisotropy frame, BRDF and bundle sampling."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..brdf import BRDF, Mirror, brdf_from_config
from ..config import RunConfig
from .sampling import ConeSampling
from .anisotropy import AnisotropyFrame
from .brdf_variation import BrdfVariation
from .camera import Camera
from .monitor import Monitor
from .surfaces import FlatRectangle, SagSurface, Surface, surface_from_config

ESTIMATORS = ("paper", "weighted_mean", "radiometric")


@dataclass(frozen=True)
class Scene:
    """Everything the tracer needs, in world millimetres.

    ``estimator``: ``paper`` = (1/N) sum f_p I_p (the paper), ``weighted_mean`` =
    sum f_p I_p / sum f_p over the cone, ``radiometric`` = (1/N) sum f_p cos_p I_p / pdf_p
    over N directions sampled from the lobe (see ``docs/physics.md``).
    """

    camera: Camera
    monitor: Monitor
    surface: Surface
    anisotropy: AnisotropyFrame
    brdf: BRDF
    sampling: ConeSampling
    estimator: str = "paper"
    #: spatially varying alpha/rho_s (``[brdf.variation]``); None = the BRDF's constants
    brdf_variation: BrdfVariation | None = None

    def __post_init__(self):
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "Scene":
        s = cfg.sampling
        surface = surface_from_config(cfg.surface)
        anisotropy = AnisotropyFrame.from_config(cfg.anisotropy)
        if isinstance(surface, SagSurface) and anisotropy.kind == "rotational" and anisotropy.axis is None:
            # a curved surface is turned about its vertex normal, not each point's normal
            anisotropy = replace(anisotropy, axis=surface.normal.copy())
        var = getattr(cfg.brdf, "variation", None)
        camera = Camera.from_config(cfg.camera).focused_on(surface)
        return cls(
            brdf_variation=(None if var is None
                            else BrdfVariation.from_config(var, surface, anisotropy)),
            camera=camera,
            monitor=Monitor.from_config(cfg.monitor),
            surface=surface,
            anisotropy=anisotropy,
            brdf=brdf_from_config(cfg.brdf, set_up_incidence_deg(camera, surface)),
            sampling=ConeSampling(
                s.n_rays, float(np.deg2rad(s.theta_max_deg)), s.scheme, s.mode, s.seed
            ),
            estimator=s.estimator,
        )

    def specular(self) -> "Scene":
        """The same scene with the ideal mirror: the reference every deviation is measured from."""
        return replace(self, brdf=Mirror(), brdf_variation=None)

    def replace(self, **changes) -> "Scene":
        return replace(self, **changes)

    @property
    def rays_per_pixel(self) -> int:
        return 1 if self.brdf.is_delta else self.sampling.n_rays


def set_up_incidence_deg(camera, surface) -> float:
    """Angle (deg) between the surface normal at its centre and the direction to the camera."""
    centre = np.asarray(getattr(surface, "centre", np.zeros(3)), np.float64)
    normal = np.asarray(getattr(surface, "normal", np.array([0.0, 0.0, 1.0])), np.float64)
    d = np.asarray(camera.position, np.float64) - centre
    c = abs(float(d @ normal)) / max(float(np.linalg.norm(d) * np.linalg.norm(normal)), 1e-300)
    return float(np.degrees(np.arccos(min(c, 1.0))))


__all__ = ["Scene", "BrdfVariation", "Camera", "Monitor", "FlatRectangle", "SagSurface", "AnisotropyFrame", "ESTIMATORS"]
