"""Pinhole camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import CameraConfig
from ..geometry import normalize


@dataclass(frozen=True)
class Camera:
    """Pinhole camera; ``rotation`` columns are the camera axes (x right, y down, z forward)
    in world coordinates; pixel (row, col) centres at integer indices."""

    width: int
    height: int
    focal_px: float
    principal_point: tuple[float, float]  # (col, row)
    position: np.ndarray  # (3,) mm
    rotation: np.ndarray  # (3, 3)

    @classmethod
    def from_config(cls, cfg: CameraConfig) -> "Camera":
        w, h = cfg.resolution
        pp = cfg.principal_point_px or ((w - 1) / 2.0, (h - 1) / 2.0)
        pos = np.asarray(cfg.position_mm, dtype=np.float64)
        if cfg.rotation is not None:
            rot = np.asarray(cfg.rotation, dtype=np.float64)
        else:
            z = normalize(np.subtract(cfg.look_at_mm, pos))
            x = normalize(np.cross(z, cfg.up))
            y = np.cross(z, x)
            rot = np.stack([x, y, z], axis=1)
        return cls(w, h, cfg.focal_px, (float(pp[0]), float(pp[1])), pos, rot)

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``CAM_*``)."""
        from ..kernels import primary as kp

        p = np.zeros(kp.CAM_SIZE)
        p[kp.CAM_POS : kp.CAM_POS + 3] = self.position
        p[kp.CAM_ROT : kp.CAM_ROT + 9] = self.rotation.reshape(-1)
        p[kp.CAM_F] = self.focal_px
        p[kp.CAM_CX], p[kp.CAM_CY] = self.principal_point
        return p

    def ray_directions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Unit directions (..., 3) of the vision rays through pixel centres (rows, cols)."""
        x = (np.asarray(cols, np.float64) - self.principal_point[0]) / self.focal_px
        y = (np.asarray(rows, np.float64) - self.principal_point[1]) / self.focal_px
        d = np.stack([x, y, np.ones_like(x)], axis=-1) @ self.rotation.T
        return normalize(d)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) = (col, row) of world points (mm)."""
        pc = (np.asarray(points, np.float64) - self.position) @ self.rotation
        with np.errstate(divide="ignore", invalid="ignore"):
            col = self.focal_px * pc[..., 0] / pc[..., 2] + self.principal_point[0]
            row = self.focal_px * pc[..., 1] / pc[..., 2] + self.principal_point[1]
        return np.stack([col, row], axis=-1)
