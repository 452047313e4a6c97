"""Camera: pose, OpenCV intrinsics and distortion, pixel footprint and a thin lens.

Projection follows OpenCV (``cv2.projectPoints``) exactly: camera coordinates
``X_c = R^T (X - C)`` (``rotation`` columns are the camera x (right), y (down), z (forward)
axes in world coordinates), ``x' = X_c / Z_c``, ``y' = Y_c / Z_c``, ``r^2 = x'^2 + y'^2``,

    x'' = x' (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x' y' + p2 (r^2 + 2 x'^2)
    y'' = y' (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y'^2) + 2 p2 x' y'
    (col, row) = (fx x'' + cx, fy y'' + cy)

with pixel centres at integer (col, row). A pixel's vision rays start from sensor points:
the pixel centre (``subpixels = 1``) or the centres of an n x n grid over the pixel
(stratified footprint); each point is undistorted (Newton iteration) into the chief ray's
direction ``(x', y', 1)``. A pinhole sends the chief ray. A thin lens (aperture diameter
``D = focal_length_mm / f_number``, plane in focus at ``Z_c = s_f``) sends, for every sensor
point, rays from aperture points ``A`` (antithetic pairs ``A, -A``: a Fibonacci lattice of
``aperture_samples / 2`` points with a per-pixel random Cranley-Patterson shift from
``default_rng([aperture_seed, row])``, mapped to the disk by Shirley-Chiu's concentric map,
and their mirror images through the lens centre, so that a blur that is linear in ``A``
has its centroid exactly at the chief ray; an odd count adds the centre) through the
in-focus point
``F = s_f (x', y', 1)``: all rays of a sensor point meet again at ``F``.

An object-side **telecentric** camera (``telecentric = True``) projects orthographically:
``(col, row) = (fx x'' + cx, fy y'' + cy)`` with ``(x', y') = (X_c, Y_c)`` in mm (no division
by ``Z_c``; fx, fy in px per mm on the part = magnification / pixel pitch; the distortion
polynomial acts on mm, so k1 is in mm^-2). A sensor point's chief ray starts on the entrance
plane ``Z_c = 0`` at ``C + R (x', y', 0)`` and runs along the optical axis ``R e_z``. With an
object-side numerical aperture NA, a pixel integrates the cone of directions whose sines
``(l, m)`` fill the disk of radius NA (the same antithetic lattice as the thin lens's
aperture), all through the in-focus point ``F = (x', y', s_f)``. Its homogeneous
:attr:`Camera.viewpoint` is ``(-R e_z, 0)``: the direction to the camera is the same at every
surface point, which is what the slope conversions use.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..config import CameraConfig
from ..geometry import normalize

_GOLDEN = (1.0 + 5.0**0.5) / 2.0


def concentric_disk(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shirley-Chiu concentric map of unit-square points to the unit disk (area preserving)."""
    a = 2.0 * np.asarray(u1, np.float64) - 1.0
    b = 2.0 * np.asarray(u2, np.float64) - 1.0
    big_a = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(big_a, a, b)
        phi = np.where(big_a, (np.pi / 4) * b / a, np.pi / 2 - (np.pi / 4) * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


@dataclass(frozen=True)
class Camera:
    """Camera with OpenCV intrinsics; see the module docstring.

    ``focal_px`` is fx; ``focal_px_y`` fy (None = fx). ``distortion`` is OpenCV's
    (k1, k2, p1, p2, k3). ``aperture_mm`` is the thin lens's aperture diameter (None =
    pinhole), ``focus_distance_mm`` its plane in focus (None until resolved against the
    surface, :meth:`focused_on`).
    """

    width: int
    height: int
    focal_px: float
    principal_point: tuple[float, float]  # (col, row)
    position: np.ndarray  # (3,) mm
    rotation: np.ndarray  # (3, 3)
    focal_px_y: float | None = None
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    subpixels: int = 1
    aperture_mm: float | None = None
    focus_distance_mm: float | None = None
    aperture_samples: int = 16
    aperture_seed: int = 0
    telecentric: bool = False
    numerical_aperture: float | None = None

    @classmethod
    def from_config(cls, cfg: CameraConfig) -> "Camera":
        """The camera of ``cfg``; with a window ``roi`` (a tuple) that window as its sensor
        (:meth:`CameraConfig.cropped`); ``roi = "auto"`` is resolved by the scene
        (:func:`pmdsim.scene.auto_roi`)."""
        cfg = cfg.cropped()
        w, h = cfg.resolution
        if cfg.camera_matrix is not None:
            k = np.asarray(cfg.camera_matrix, np.float64)
            fx, fy, pp = k[0, 0], k[1, 1], (k[0, 2], k[1, 2])
        else:
            fx = fy = cfg.focal_px
            pp = cfg.principal_point_px or ((w - 1) / 2.0, (h - 1) / 2.0)
        pos = np.asarray(cfg.position_mm, dtype=np.float64)
        if cfg.rotation is not None:
            rot = np.asarray(cfg.rotation, dtype=np.float64)
        else:
            z = normalize(np.subtract(cfg.look_at_mm, pos))
            x = normalize(np.cross(z, cfg.up))
            y = np.cross(z, x)
            rot = np.stack([x, y, z], axis=1)
        aperture = None if cfg.f_number is None else float(cfg.focal_length_mm / cfg.f_number)
        if cfg.projection == "telecentric":
            na = cfg.numerical_aperture
            return cls(
                w, h, float(fx), (float(pp[0]), float(pp[1])), pos, rot,
                focal_px_y=None if fy == fx else float(fy), distortion=cfg.distortion,
                subpixels=cfg.subpixels, focus_distance_mm=cfg.focus_distance_mm,
                aperture_samples=cfg.aperture_samples if na is not None else 1,
                aperture_seed=cfg.aperture_seed, telecentric=True,
                numerical_aperture=None if na is None else float(na),
            )
        return cls(
            w, h, float(fx), (float(pp[0]), float(pp[1])), pos, rot,
            focal_px_y=None if fy == fx else float(fy), distortion=cfg.distortion,
            subpixels=cfg.subpixels, aperture_mm=aperture, focus_distance_mm=cfg.focus_distance_mm,
            aperture_samples=cfg.aperture_samples if aperture is not None else 1,
            aperture_seed=cfg.aperture_seed,
        )

    # ------------------------------------------------------------------ properties
    @property
    def fy(self) -> float:
        return self.focal_px if self.focal_px_y is None else self.focal_px_y

    @property
    def camera_matrix(self) -> np.ndarray:
        """OpenCV's K (3, 3)."""
        return np.array([[self.focal_px, 0.0, self.principal_point[0]],
                         [0.0, self.fy, self.principal_point[1]], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return any(c != 0.0 for c in self.distortion)

    @property
    def is_simple_pinhole(self) -> bool:
        """One undistorted pinhole ray through each pixel centre, fx = fy (the compiled
        per-pixel tracer :func:`pmdsim.kernels.primary.geometry_tile`)."""
        return (self.subpixels == 1 and self.aperture_mm is None and not self.has_distortion
                and self.fy == self.focal_px and not self.telecentric)

    @property
    def has_aperture(self) -> bool:
        """A pixel integrates over an aperture: a thin lens, or a telecentric lens with a
        numerical aperture."""
        return self.aperture_mm is not None or self.numerical_aperture is not None

    @property
    def rays_per_pixel(self) -> int:
        """Vision rays (sub-pixel x aperture samples) per pixel."""
        return self.subpixels**2 * (self.aperture_samples if self.has_aperture else 1)

    @property
    def axis(self) -> np.ndarray:
        """Unit optical axis (viewing direction) in world coordinates."""
        return self.rotation[:, 2].copy()

    @property
    def viewpoint(self) -> np.ndarray:
        """Homogeneous (4,) camera point: ``(C, 1)`` for a projection centre C, ``(-axis, 0)``
        for a telecentric camera (the point at infinity up its axis). The unit direction
        from a surface point S to the camera is ``normalize(v[:3] - v[3] S)``."""
        if self.telecentric:
            return np.concatenate([-self.rotation[:, 2], [0.0]])
        return np.concatenate([np.asarray(self.position, np.float64), [1.0]])

    def directions_to_camera(self, points) -> np.ndarray:
        """Unit directions (..., 3) from world points (..., 3) to the camera."""
        v = self.viewpoint
        return normalize(v[:3] - v[3] * np.asarray(points, np.float64))

    @property
    def depth_of_field_mm(self) -> float:
        """Half depth of field (mm) about the plane in focus: the defocus at which the blur
        of a point (its cone of rays) spans one pixel's footprint on the part. Infinite for a
        pinhole and for an ideal (NA-free) telecentric camera; a thin lens: the pixel at the
        focus distance, ``s_f^2 / (f_px D)`` (the footprint over the aperture's angle)."""
        if self.telecentric:
            if self.numerical_aperture is None:
                return float("inf")
            na = self.numerical_aperture
            footprint = 1.0 / min(self.focal_px, self.fy)
            return footprint / (2.0 * na / np.sqrt(1.0 - na * na))
        if self.aperture_mm is None or self.focus_distance_mm is None:
            return float("inf")
        footprint = self.focus_distance_mm / min(self.focal_px, self.fy)
        return footprint * self.focus_distance_mm / self.aperture_mm

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``CAM_*``; pinhole)."""
        from ..kernels import primary as kp

        p = np.zeros(kp.CAM_SIZE)
        p[kp.CAM_POS : kp.CAM_POS + 3] = self.position
        p[kp.CAM_ROT : kp.CAM_ROT + 9] = self.rotation.reshape(-1)
        p[kp.CAM_F] = self.focal_px
        p[kp.CAM_CX], p[kp.CAM_CY] = self.principal_point
        return p

    # ------------------------------------------------------------------ distortion
    def distort(self, x, y):
        """Normalised undistorted (x', y') -> distorted (x'', y'') (OpenCV)."""
        k1, k2, p1, p2, k3 = self.distortion
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return xd, yd

    def undistort(self, xd, yd, iterations: int = 50, tol: float = 1e-15):
        """Inverse of :meth:`distort` by Newton's method (numerical Jacobian-free: the
        analytic 2 x 2 Jacobian); converges to ~1e-15 for calibrations of real lenses."""
        xd = np.asarray(xd, np.float64)
        yd = np.asarray(yd, np.float64)
        if not self.has_distortion:
            return xd.copy(), yd.copy()
        k1, k2, p1, p2, k3 = self.distortion
        x, y = xd.copy(), yd.copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
            fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
            fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
            a = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
            b = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            c = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            d = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
            det = a * d - b * c
            dx = (d * fx - b * fy) / det
            dy = (a * fy - c * fx) / det
            x -= dx
            y -= dy
            if np.all(np.abs(dx) + np.abs(dy) < tol):
                break
        return x, y

    # ------------------------------------------------------------------ rays
    def chief_directions_camera(self, rows, cols) -> np.ndarray:
        """Undistorted normalised sensor points as (x', y', 1) (..., 3) in camera coordinates
        (fractional pixels allowed): the unnormalised chief-ray directions of a perspective
        camera; (mm, mm, 1) of a telecentric one."""
        xd = (np.asarray(cols, np.float64) - self.principal_point[0]) / self.focal_px
        yd = (np.asarray(rows, np.float64) - self.principal_point[1]) / self.fy
        x, y = self.undistort(xd, yd)
        return np.stack([x, y, np.ones_like(x)], axis=-1)

    def ray_directions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Unit world directions (..., 3) of the chief rays through sensor points (rows, cols)."""
        if self.telecentric:
            shape = np.broadcast_shapes(np.shape(rows), np.shape(cols)) + (3,)
            return np.broadcast_to(self.rotation[:, 2], shape).copy()
        return normalize(self.chief_directions_camera(rows, cols) @ self.rotation.T)

    def chief_rays(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions (..., 3) of the chief rays through sensor points
        (rows, cols): from the projection centre (perspective) or from the entrance plane
        along the axis (telecentric)."""
        if self.telecentric:
            xy = self.chief_directions_camera(rows, cols)
            xy[..., 2] = 0.0
            o = self.position + xy @ self.rotation.T
            return o, np.broadcast_to(self.rotation[:, 2], o.shape).copy()
        d = self.ray_directions(rows, cols)
        return np.broadcast_to(self.position, d.shape), d

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) = (col, row) of world points (mm), OpenCV's model."""
        # einsum, not matmul: OpenBLAS takes ~10x longer for an (N, 3) @ (3, 3) product
        pc = np.einsum("...j,jk->...k", np.asarray(points, np.float64) - self.position, self.rotation)
        if self.telecentric:  # orthographic: behind the entrance plane nothing is seen
            behind = np.where(pc[..., 2] > 0, 1.0, np.nan)
            x, y = pc[..., 0] * behind, pc[..., 1] * behind
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                x = pc[..., 0] / pc[..., 2]
                y = pc[..., 1] / pc[..., 2]
        xd, yd = self.distort(x, y) if self.has_distortion else (x, y)  # distort is the identity then
        out = np.empty(x.shape + (2,))
        out[..., 0] = self.focal_px * xd + self.principal_point[0]
        out[..., 1] = self.fy * yd + self.principal_point[1]
        return out

    def subpixel_offsets(self) -> np.ndarray:
        """(n^2, 2) (d_col, d_row) offsets of the n x n sub-pixel centres from the pixel centre."""
        n = self.subpixels
        o = (np.arange(n) + 0.5) / n - 0.5
        dr, dc = np.meshgrid(o, o, indexing="ij")
        return np.stack([dc.ravel(), dr.ravel()], axis=-1)

    def aperture_points(self, row: int, width: int) -> np.ndarray:
        """(width, m, 2) aperture points of the pixels of camera row ``row``: mm, camera x
        and y (thin lens); direction sines (l, m) in the disk of radius NA (telecentric);
        (width, 1, 2) zeros without an aperture."""
        if not self.has_aperture:
            return np.zeros((width, 1, 2))
        m = self.aperture_samples
        half = m // 2
        j = np.arange(max(half, 1), dtype=np.float64)
        u1 = (j + 0.5) / max(half, 1)
        u2 = np.mod(j / _GOLDEN, 1.0)
        off = np.random.default_rng([self.aperture_seed, int(row)]).random((width, 2))
        s1 = np.mod(u1[None] + off[:, :1], 1.0)
        s2 = np.mod(u2[None] + off[:, 1:], 1.0)
        x, y = concentric_disk(s1, s2)
        pts = np.stack([x, y], axis=-1)[:, :half]
        parts = [pts, -pts] + ([np.zeros((width, 1, 2))] if m % 2 else [])
        scale = self.numerical_aperture if self.telecentric else 0.5 * self.aperture_mm
        return scale * np.concatenate(parts, axis=1)

    def pixel_aperture_points(self, rows, cols) -> np.ndarray:
        """(P, m, 2) :meth:`aperture_points` of the pixels (rows[k], cols[k]) (int arrays),
        each from its own camera row's samples."""
        out = np.empty((rows.size, self.aperture_samples, 2))
        for r in np.unique(rows):
            sel = rows == r
            out[sel] = self.aperture_points(int(r), self.width)[cols[sel]]
        return out

    def vision_rays(self, rows, cols):
        """Origins and unit directions (P, S, 3) of every pixel's S vision rays (sub-pixels
        x aperture samples, sub-pixel major) for pixels (rows[k], cols[k]); rows from the
        pixel's own camera row seed the aperture samples."""
        rows = np.asarray(rows, np.int64).ravel()
        cols = np.asarray(cols, np.int64).ravel()
        sub = self.subpixel_offsets()  # (n2, 2)
        if self.telecentric:
            return self._telecentric_rays(rows, cols, sub)
        chief = self.chief_directions_camera(rows[:, None] + sub[None, :, 1],
                                             cols[:, None] + sub[None, :, 0])  # (P, n2, 3)
        if self.aperture_mm is None:
            d = normalize(chief @ self.rotation.T)
            o = np.broadcast_to(self.position, d.shape).copy()
            return o, d
        if self.focus_distance_mm is None:
            raise ValueError("camera.focus_distance_mm: not resolved; build the camera through "
                             "Scene.from_config or Camera.focused_on(surface)")
        ap = self.pixel_aperture_points(rows, cols)
        focus = chief * self.focus_distance_mm  # (P, n2, 3), Z_c = s_f
        a3 = np.concatenate([ap, np.zeros(ap.shape[:-1] + (1,))], axis=-1)  # (P, m, 3)
        dcam = focus[:, :, None, :] - a3[:, None, :, :]  # (P, n2, m, 3)
        d = normalize(dcam @ self.rotation.T).reshape(rows.size, -1, 3)
        o = (self.position + a3 @ self.rotation.T)  # (P, m, 3)
        o = np.broadcast_to(o[:, None], (rows.size, sub.shape[0], self.aperture_samples, 3))
        return o.reshape(rows.size, -1, 3).copy(), d

    def _telecentric_rays(self, rows, cols, sub):
        """:meth:`vision_rays` of a telecentric camera: per sensor point its chief ray (no
        aperture) or its m aperture rays through the in-focus point."""
        pts = self.chief_directions_camera(rows[:, None] + sub[None, :, 1],
                                           cols[:, None] + sub[None, :, 0])  # (P, n2, 3)
        pts[..., 2] = 0.0
        if self.numerical_aperture is None:
            o = self.position + pts @ self.rotation.T
            return o.reshape(rows.size, -1, 3), np.broadcast_to(
                self.rotation[:, 2], (rows.size, sub.shape[0], 3)).reshape(rows.size, -1, 3).copy()
        if self.focus_distance_mm is None:
            raise ValueError("camera.focus_distance_mm: not resolved; build the camera through "
                             "Scene.from_config or Camera.focused_on(surface)")
        sines = self.pixel_aperture_points(rows, cols)
        lz = np.sqrt(1.0 - np.sum(sines * sines, axis=-1, keepdims=True))
        dcam = np.concatenate([sines, lz], axis=-1)  # (P, m, 3) unit
        sf = self.focus_distance_mm
        focus = pts + np.array([0.0, 0.0, sf])  # (P, n2, 3)
        ocam = focus[:, :, None, :] - (sf / dcam[:, None, :, 2:3]) * dcam[:, None, :, :]
        o = (self.position + ocam @ self.rotation.T).reshape(rows.size, -1, 3)
        d = np.broadcast_to((dcam @ self.rotation.T)[:, None], ocam.shape).reshape(rows.size, -1, 3)
        return o, d.copy()

    def lens_inputs(self, rows, cols):
        """Inputs of :func:`pmdsim.kernels.primary.geometry_lens` for pixels (rows[k], cols[k]):
        chief directions (P, n2, 3) in camera coordinates, aperture points (P, m, 2) and the
        focus depth (0 for a pinhole). The same rays as :meth:`vision_rays`."""
        rows = np.asarray(rows, np.int64).ravel()
        cols = np.asarray(cols, np.int64).ravel()
        sub = self.subpixel_offsets()
        chief = self.chief_directions_camera(rows[:, None] + sub[None, :, 1],
                                             cols[:, None] + sub[None, :, 0])
        if self.aperture_mm is None:
            return chief, np.zeros((rows.size, 1, 2)), 0.0
        if self.focus_distance_mm is None:
            raise ValueError("camera.focus_distance_mm: not resolved; build the camera through "
                             "Scene.from_config or Camera.focused_on(surface)")
        ap = self.pixel_aperture_points(rows, cols)
        return chief, ap, float(self.focus_distance_mm)

    def focused_on(self, surface) -> "Camera":
        """This camera with ``focus_distance_mm`` resolved: unchanged when given or pinhole;
        otherwise the depth (Z_c) of the surface point the image centre's chief ray sees."""
        if not self.has_aperture or self.focus_distance_mm is not None:
            return self
        r, c = (self.height - 1) / 2.0, (self.width - 1) / 2.0
        o, d = self.chief_rays(np.array([r]), np.array([c]))
        _, p, _, hit = surface.intersect(np.ascontiguousarray(o), d)
        if not bool(hit[0]):
            from ..config import ConfigError

            raise ConfigError(
                "invalid set-up:\n  camera.focus_distance_mm: the image centre does not see "
                "the surface, so the default focus is undefined; aim the camera at the part "
                "(camera.look_at_mm, position_mm) or give camera.focus_distance_mm"
            )
        z = float((p[0] - self.position) @ self.rotation[:, 2])
        return replace(self, focus_distance_mm=z)
