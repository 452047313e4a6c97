"""Surfaces: anything that can intersect vision rays and report hit points and normals.

A surface implements :class:`Surface`; adding a shape (sphere, asphere, height map) is one
new class here. The scattered bundle only needs the hit point and the normal, so the
rendering kernels never see the surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..config import FlatSurfaceConfig
from ..geometry import normalize


class Surface(Protocol):
    def intersect(self, origins: np.ndarray, dirs: np.ndarray):
        """Return (t, points, normals, hit) for rays (..., 3); normals are unit vectors on
        the side the ray came from is *not* assumed: callers check ``dot(-dir, n) > 0``."""

    def outline(self) -> np.ndarray:
        """Closed polyline (K, 3) of the surface boundary, for figures."""

    @property
    def default_x_axis(self) -> np.ndarray: ...

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``SURF_*``)."""


@dataclass(frozen=True)
class FlatRectangle:
    centre: np.ndarray
    normal: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    size: tuple[float, float]

    @classmethod
    def from_config(cls, cfg: FlatSurfaceConfig) -> "FlatRectangle":
        n = normalize(np.asarray(cfg.normal, np.float64))
        x = np.asarray(cfg.x_axis, np.float64)
        x = normalize(x - (x @ n) * n)
        y = np.cross(n, x)
        return cls(np.asarray(cfg.centre_mm, np.float64), n, x, y, tuple(cfg.size_mm))

    @property
    def default_x_axis(self) -> np.ndarray:
        return self.x_axis

    def intersect(self, origins, dirs):
        dn = dirs @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.centre - origins) @ self.normal) / dn
        p = origins + t[..., None] * dirs
        d = p - self.centre
        hit = (
            (t > 0)
            & (np.abs(d @ self.x_axis) <= self.size[0] / 2)
            & (np.abs(d @ self.y_axis) <= self.size[1] / 2)
        )
        normals = np.broadcast_to(self.normal, p.shape)
        return t, p, normals, hit

    def kernel_params(self) -> np.ndarray:
        from ..kernels import primary as kp

        p = np.zeros(kp.SURF_SIZE)
        p[kp.SURF_TYPE] = kp.SURF_FLAT
        p[kp.SURF_C : kp.SURF_C + 3] = self.centre
        p[kp.SURF_N : kp.SURF_N + 3] = self.normal
        p[kp.SURF_X : kp.SURF_X + 3] = self.x_axis
        p[kp.SURF_Y : kp.SURF_Y + 3] = self.y_axis
        p[kp.SURF_HALF] = self.size[0] / 2
        p[kp.SURF_HALF + 1] = self.size[1] / 2
        return p

    def outline(self) -> np.ndarray:
        hx, hy = self.size[0] / 2, self.size[1] / 2
        corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)]
        return np.array([self.centre + a * self.x_axis + b * self.y_axis for a, b in corners])


def surface_from_config(cfg) -> Surface:
    if cfg.type == "flat":
        return FlatRectangle.from_config(cfg)
    raise ValueError(f"surface.type: unknown surface {cfg.type!r}")
