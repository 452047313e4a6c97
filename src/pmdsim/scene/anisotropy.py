"""The local frame of the anisotropic BRDF: z = normal, x and y in the tangent plane."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import AnisotropyConfig
from ..geometry import dot, normalize


@dataclass(frozen=True)
class AnisotropyFrame:
    """``rotational``: x = tangential, y = radial about ``centre``/``axis`` (the paper);
    ``fixed``: x = ``x_direction`` projected onto the tangent plane. y = n x x always."""

    kind: str
    centre: np.ndarray
    axis: np.ndarray | None
    x_direction: np.ndarray

    @classmethod
    def from_config(cls, cfg: AnisotropyConfig) -> "AnisotropyFrame":
        axis = None if cfg.axis is None else normalize(np.asarray(cfg.axis, np.float64))
        return cls(
            cfg.frame, np.asarray(cfg.centre_mm, np.float64), axis,
            normalize(np.asarray(cfg.x_direction, np.float64)),
        )

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``FRAME_*``)."""
        from ..kernels import primary as kp

        p = np.zeros(kp.FRAME_SIZE)
        p[kp.FRAME_TYPE] = kp.FRAME_ROTATIONAL if self.kind == "rotational" else kp.FRAME_FIXED
        p[kp.FRAME_C : kp.FRAME_C + 3] = self.centre
        if self.axis is not None:
            p[kp.FRAME_AXIS : kp.FRAME_AXIS + 3] = self.axis
            p[kp.FRAME_HAS_AXIS] = 1.0
        p[kp.FRAME_DIR : kp.FRAME_DIR + 3] = self.x_direction
        return p

    def frames(self, points: np.ndarray, normals: np.ndarray):
        """Local (x, y) axes (..., 3) at hit points with unit normals."""
        if self.kind == "rotational":
            r = points - self.centre
            axis = normals if self.axis is None else np.broadcast_to(self.axis, r.shape)
            r = r - dot(r, axis)[..., None] * axis
            radial = r - dot(r, normals)[..., None] * normals
            rn = np.linalg.norm(radial, axis=-1, keepdims=True)
            # At the turning centre the radial direction is undefined: fall back to x_direction.
            fallback = self._project(self.x_direction, normals)
            fallback_radial = np.cross(normals, fallback)  # so that tangential = fallback
            radial = np.where(rn > 1e-9, radial / np.where(rn > 0, rn, 1), fallback_radial)
            x = np.cross(radial, normals)  # tangential: x cross y = z
            y = radial
        else:
            x = self._project(self.x_direction, normals)
            y = np.cross(normals, x)
        return x, y

    @staticmethod
    def _project(d, normals):
        x = d - dot(np.broadcast_to(d, normals.shape), normals)[..., None] * normals
        bad = np.linalg.norm(x, axis=-1) < 1e-9
        if np.any(bad):  # x_direction along the normal: any perpendicular will do
            alt = np.cross(normals, [0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.cross(normals, [1.0, 0.0, 0.0])
            x = np.where(bad[..., None], alt, x)
        return normalize(x)
