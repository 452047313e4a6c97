"""Reverse ray tracing: one vision ray per camera pixel to the surface, its frame and P.

:func:`trace_primary` gives per pixel the hit point, normal, BRDF frame, the direction to
the camera ``i`` and the principal reflection direction ``P``. :func:`bundle_geometry`
turns those into the compact rows the compiled bundle kernel consumes. Everything here is
vectorised NumPy in float64; the per-ray work (N rays per pixel) is in
:mod:`pmdsim.kernels.bundle`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import dot, normalize, reflect
from ..kernels import bundle as kb


@dataclass(frozen=True)
class PrimaryHits:
    """Per-pixel results of the vision rays of camera rows ``row_start:row_stop``.

    All arrays are (rows, width[, 3]); vectors are unit, world coordinates. Pixels whose
    vision ray misses the surface or sees its back have ``valid == False`` and NaN vectors.
    """

    row_start: int
    row_stop: int
    valid: np.ndarray
    point: np.ndarray  # mm
    normal: np.ndarray
    x_axis: np.ndarray  # BRDF frame x (tangential in a rotational frame)
    y_axis: np.ndarray  # BRDF frame y (radial)
    to_camera: np.ndarray  # i
    principal: np.ndarray  # P


def trace_primary(scene, row_start: int = 0, row_stop: int | None = None) -> PrimaryHits:
    """Trace the vision rays of camera rows ``row_start:row_stop`` (all rows by default)."""
    cam = scene.camera
    row_stop = cam.height if row_stop is None else row_stop
    rows, cols = np.mgrid[row_start:row_stop, 0 : cam.width]
    return _trace(scene, rows, cols, row_start, row_stop)


def trace_pixels(scene, rows, cols) -> PrimaryHits:
    """Trace the vision rays of the camera pixels (rows[k], cols[k]); arrays are (1, P[, 3])
    (one 'row' of the selected pixels; ``row_start``/``row_stop`` are -1)."""
    rows = np.atleast_1d(np.asarray(rows, np.int64))[None, :]
    cols = np.atleast_1d(np.asarray(cols, np.int64))[None, :]
    return _trace(scene, rows, cols, -1, -1)


def _trace(scene, rows, cols, row_start, row_stop) -> PrimaryHits:
    cam = scene.camera
    origins, dirs = cam.chief_rays(rows, cols)
    _, point, normal, hit = scene.surface.intersect(origins, dirs)
    normal = normalize(normal)
    i = -dirs
    front = dot(i, normal) > 0
    valid = hit & front
    x, y = scene.anisotropy.frames(point, normal)
    p = reflect(i, normal)
    nan = np.where(valid[..., None], 1.0, np.nan)
    return PrimaryHits(
        row_start, row_stop, valid,
        point * nan, normal * nan, x * nan, y * nan, i * nan, p * nan,
    )


def cone_basis(hits: PrimaryHits):
    """Orthonormal (e1, e2, P) per pixel: e2 normal to the plane of incidence, e1 in it.

    At normal incidence (P parallel to n) e2 is the BRDF frame's y axis.
    """
    p = hits.principal
    e2 = np.cross(hits.normal, p)
    small = np.linalg.norm(e2, axis=-1) < 1e-12
    e2 = np.where(small[..., None], hits.y_axis, e2)
    e2 = normalize(e2)
    e1 = np.cross(e2, p)
    return e1, e2, p


def bundle_geometry(scene, hits: PrimaryHits, basis=None) -> np.ndarray:
    """Rows (pixels, G_SIZE) of per-pixel projections for :func:`kernels.bundle.render_tile`.

    ``basis`` is the per-pixel orthonormal frame (b1, b2, b3) the sample directions are
    expressed in; default: the cone frame about P (:func:`cone_basis`).
    """
    mon = scene.monitor
    b = cone_basis(hits) if basis is None else basis
    s = hits.point.reshape(-1, 3)
    bs = [v.reshape(-1, 3) for v in b]
    i = hits.to_camera.reshape(-1, 3)
    x = hits.x_axis.reshape(-1, 3)
    y = hits.y_axis.reshape(-1, 3)
    n = hits.normal.reshape(-1, 3)
    g = np.zeros((s.shape[0], kb.G_SIZE))
    d = s - mon.centre
    g[:, kb.G_T] = -(d @ mon.normal)
    g[:, kb.G_U0] = d @ mon.e_u / mon.pitch + (mon.width - 1) / 2.0
    g[:, kb.G_V0] = d @ mon.e_v / mon.pitch + (mon.height - 1) / 2.0
    for k, bk in enumerate(bs):
        g[:, kb.G_A + k] = bk @ mon.normal
        g[:, kb.G_B + k] = bk @ mon.e_u / mon.pitch
        g[:, kb.G_C + k] = bk @ mon.e_v / mon.pitch
        g[:, kb.G_X + 1 + k] = dot(bk, x)
        g[:, kb.G_Y + 1 + k] = dot(bk, y)
        g[:, kb.G_Z + 1 + k] = dot(bk, n)
    g[:, kb.G_X] = dot(i, x)
    g[:, kb.G_Y] = dot(i, y)
    g[:, kb.G_Z] = dot(i, n)
    valid = hits.valid.reshape(-1)
    g[~valid] = 0.0
    g[:, kb.G_VALID] = valid
    return g


def specular_monitor_coords(scene, hits: PrimaryHits):
    """Exact monitor coordinates (u, v) (rows, width) in monitor px of the principal rays,
    and the mask of pixels whose P hits the monitor (NaN elsewhere)."""
    return scene.monitor.intersect(hits.point, hits.principal)
