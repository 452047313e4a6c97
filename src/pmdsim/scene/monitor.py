"""Flat monitor: a grid of square emitters with gamma and black/white levels."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..config import MonitorConfig
from ..geometry import normalize
from .display import DisplayGeometry, DisplayResponse, display_from_config


@dataclass(frozen=True)
class Monitor:
    """Pixel (v, u) centre = ``centre + (u - (W-1)/2) pitch e_u + (v - (H-1)/2) pitch e_v``;
    ``normal`` is the emitting side (towards the scene)."""

    width: int
    height: int
    pitch: float  # mm
    centre: np.ndarray
    e_u: np.ndarray
    e_v: np.ndarray
    normal: np.ndarray
    gamma: float = 1.0
    black_level: float = 0.0
    white_level: float = 1.0
    pixel_model: str = "nearest"
    response: DisplayResponse | None = field(default=None, compare=False)
    display: DisplayGeometry = field(default_factory=DisplayGeometry, compare=False)

    def __post_init__(self):
        # The response carries gamma and the levels: keep it in step with the fields (also
        # after dataclasses.replace(monitor, gamma=...)).
        r = self.response or DisplayResponse()
        if (r.gamma, r.black_level, r.white_level) != (self.gamma, self.black_level, self.white_level):
            r = replace(r, gamma=self.gamma, black_level=self.black_level, white_level=self.white_level)
        object.__setattr__(self, "response", r)

    @classmethod
    def from_config(cls, cfg: MonitorConfig) -> "Monitor":
        c = np.asarray(cfg.centre_mm, dtype=np.float64)
        n = normalize(np.subtract(cfg.look_at_mm, c))
        e_u = normalize(np.cross(cfg.up, n))
        e_v = np.cross(e_u, n)
        w, h = cfg.resolution
        return cls(
            w, h, float(cfg.pixel_pitch_mm), c, e_u, e_v, n, float(cfg.gamma),
            float(cfg.black_level), float(cfg.white_level), cfg.pixel_model,
            *display_from_config(cfg),
        )

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in monitor pixels."""
        return (self.height, self.width)

    @property
    def size_mm(self) -> tuple[float, float]:
        return (self.width * self.pitch, self.height * self.pitch)

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``MON_*``)."""
        from ..kernels import primary as kp

        p = np.zeros(kp.MON_SIZE)
        p[kp.MON_C : kp.MON_C + 3] = self.centre
        p[kp.MON_EU : kp.MON_EU + 3] = self.e_u
        p[kp.MON_EV : kp.MON_EV + 3] = self.e_v
        p[kp.MON_N : kp.MON_N + 3] = self.normal
        p[kp.MON_PITCH] = self.pitch
        p[kp.MON_W] = self.width
        p[kp.MON_H] = self.height
        return p

    def pixel_to_world(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """World points (..., 3) of monitor coordinates (u, v) in monitor px."""
        du = (np.asarray(u, np.float64) - (self.width - 1) / 2.0) * self.pitch
        dv = (np.asarray(v, np.float64) - (self.height - 1) / 2.0) * self.pitch
        return self.centre + du[..., None] * self.e_u + dv[..., None] * self.e_v

    def world_to_pixel(self, points: np.ndarray) -> np.ndarray:
        """Monitor coordinates (..., 2) = (u, v) of world points on the monitor plane."""
        d = np.asarray(points, np.float64) - self.centre
        u = d @ self.e_u / self.pitch + (self.width - 1) / 2.0
        v = d @ self.e_v / self.pitch + (self.height - 1) / 2.0
        return np.stack([u, v], axis=-1)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray):
        """Monitor coordinates (u, v) of rays and a mask of rays that hit the emitting side
        inside the pixel grid. Misses get NaN coordinates."""
        dn = dirs @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.centre - origins) @ self.normal) / dn
        p = origins + t[..., None] * dirs
        uv = self.world_to_pixel(p)
        u, v = uv[..., 0], uv[..., 1]
        hit = (
            (dn < 0) & (t > 0)
            & (u >= -0.5) & (u < self.width - 0.5)
            & (v >= -0.5) & (v < self.height - 0.5)
        )
        u = np.where(hit, u, np.nan)
        v = np.where(hit, v, np.nan)
        return u, v, hit

    @property
    def is_linear(self) -> bool:
        """The luminance is exactly affine in the pattern level (gamma 1, no LUT, no
        quantisation)."""
        return self.response.is_linear

    def correction_params(self) -> np.ndarray | None:
        """``mon_corr`` of the render kernels (flatness, cover glass, falloff); None when the
        display is the nominal flat, bare, Lambertian plane."""
        return self.display.kernel_params(self.pitch, self.width, self.height)

    def luminance(self, value: np.ndarray) -> np.ndarray:
        """Displayed luminance of pattern values in [0, 1] (:mod:`pmdsim.scene.display`:
        pre-compensation, drive quantisation, gamma or LUT, black and white levels)."""
        return self.response.luminance(value)
