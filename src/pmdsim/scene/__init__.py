"""The scene in world millimetres: camera (``camera``: pinhole, lens, distortion, sub-pixels),
monitor and display (``monitor``, ``display``), surfaces (``surfaces``), the BRDF frame
(``anisotropy``), spatially varying BRDF parameters (``brdf_variation``), the bundle's
sample set (``sampling``, ``quadrature``), the sensor model (``sensor``) and the physics
sanity of each section (``sanity``); :class:`Scene` composes them from their sections."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..brdf import BRDF, Mirror, brdf_from_config
from ..config import CameraConfig, SceneSections, SurfaceConfig
from .sampling import ConeSampling, sampling_from_config
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
    def from_config(cls, cfg: SceneSections) -> "Scene":
        """The scene of the sections ``camera``, ``monitor``, ``surface``, ``anisotropy``,
        ``brdf`` and ``sampling`` (a :class:`~pmdsim.config.RunConfig` has them)."""
        s = cfg.sampling
        surface = surface_from_config(cfg.surface)
        anisotropy = AnisotropyFrame.from_config(cfg.anisotropy)
        if isinstance(surface, SagSurface) and anisotropy.kind == "rotational" and anisotropy.axis is None:
            # a curved surface is turned about its vertex normal, not each point's normal
            anisotropy = replace(anisotropy, axis=surface.normal.copy())
        var = getattr(cfg.brdf, "variation", None)
        cam_cfg = cfg.camera
        if cam_cfg.roi == "auto":
            cam_cfg = cam_cfg.cropped(auto_roi(Camera.from_config(cam_cfg), surface))
        camera = Camera.from_config(cam_cfg).focused_on(surface)
        brdf = brdf_from_config(cfg.brdf, set_up_incidence_deg(camera, surface))
        return cls(
            brdf_variation=(None if var is None
                            else BrdfVariation.from_config(var, surface, anisotropy)),
            camera=camera,
            monitor=Monitor.from_config(cfg.monitor),
            surface=surface,
            anisotropy=anisotropy,
            brdf=brdf,
            sampling=sampling_from_config(s, brdf),
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


def _surface_points(surface, n: int = 129) -> np.ndarray:
    """World points (N, 3) on the surface: a grid of n x n over its local bounds (inside the
    aperture) and n^2 / 4 points on the bounds' outline, to find the pixels that see it."""
    rot = np.stack([surface.x_axis, surface.y_axis, surface.normal], axis=1).astype(np.float64)
    if hasattr(surface, "sag"):
        x0, x1, y0, y1 = surface.bounds()
    else:  # flat rectangle
        x0, x1, y0, y1 = -surface.size[0] / 2, surface.size[0] / 2, -surface.size[1] / 2, surface.size[1] / 2
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    t = np.linspace(0.0, 2 * np.pi, n * n // 4, endpoint=False)
    if hasattr(surface, "sag") and surface.aperture[0] in ("circular", "annular"):
        _, cx, cy, a, _ = surface.aperture
        ex, ey = cx + a * (1 - 1e-9) * np.cos(t), cy + a * (1 - 1e-9) * np.sin(t)
    else:
        ex, ey = np.array([]), np.array([])
    x = np.concatenate([gx.ravel(), ex])
    y = np.concatenate([gy.ravel(), ey])
    if hasattr(surface, "sag"):
        keep = np.asarray(surface.in_aperture(x, y), bool)
        x, y = x[keep], y[keep]
        z = np.asarray(surface.sag(x, y)[0], np.float64)
        ok = np.isfinite(z)
        x, y, z = x[ok], y[ok], z[ok]
    else:
        z = np.zeros_like(x)
    return surface.centre + np.stack([x, y, z], axis=1) @ rot.T


def auto_roi(camera: Camera, surface, margin_px: int = 4) -> tuple[int, int, int, int] | None:
    """``camera.roi = "auto"``: the window (col0, row0, width, height) of ``camera``'s
    sensor holding every pixel that sees ``surface`` (its points projected, the bounding box
    widened by ``margin_px``), None when no surface point lands on the sensor."""
    pts = _surface_points(surface)
    pc = (pts - camera.position) @ camera.rotation
    pix = camera.project(pts[pc[:, 2] > 0])
    w, h = camera.width, camera.height
    ok = np.all(np.isfinite(pix), axis=1) & (pix[:, 0] > -0.5) & (pix[:, 0] < w - 0.5) \
        & (pix[:, 1] > -0.5) & (pix[:, 1] < h - 0.5)
    if not ok.any():
        return None
    c0 = max(0, int(np.floor(pix[ok, 0].min())) - margin_px)
    c1 = min(w - 1, int(np.ceil(pix[ok, 0].max())) + margin_px)
    r0 = max(0, int(np.floor(pix[ok, 1].min())) - margin_px)
    r1 = min(h - 1, int(np.ceil(pix[ok, 1].max())) + margin_px)
    return (c0, r0, c1 - c0 + 1, r1 - r0 + 1)


def resolved_camera(camera: CameraConfig, surface: SurfaceConfig) -> CameraConfig:
    """``camera`` with ``roi = "auto"`` replaced by its window on ``surface``
    (:func:`auto_roi`; None when the camera does not see the surface), so that the estimate
    counts the rendered pixels and the stored configuration names them; ``camera`` itself
    when its ``roi`` is not ``"auto"``."""
    if camera.roi != "auto":
        return camera
    win = auto_roi(Camera.from_config(camera), surface_from_config(surface))
    return camera.model_copy(update={"roi": win})


def set_up_incidence_deg(camera, surface) -> float:
    """Angle (deg) between the surface normal at its centre and the direction to the camera."""
    centre = np.asarray(getattr(surface, "centre", np.zeros(3)), np.float64)
    normal = np.asarray(getattr(surface, "normal", np.array([0.0, 0.0, 1.0])), np.float64)
    d = camera.directions_to_camera(centre) if hasattr(camera, "directions_to_camera") else (
        np.asarray(camera.position, np.float64) - centre)
    c = abs(float(d @ normal)) / max(float(np.linalg.norm(d) * np.linalg.norm(normal)), 1e-300)
    return float(np.degrees(np.arccos(min(c, 1.0))))


__all__ = ["Scene", "auto_roi", "resolved_camera", "set_up_incidence_deg", "BrdfVariation", "Camera", "Monitor", "FlatRectangle", "SagSurface", "AnisotropyFrame", "ESTIMATORS"]
