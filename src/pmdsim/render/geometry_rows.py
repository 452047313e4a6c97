"""Per-pixel geometry rows of the vision rays for the bundle kernels (pinhole rays traced
compiled, or any camera's rays with sub-pixels, a lens or distortion), and the reduction of
a pixel's sub-ray sums (:func:`reduce_subrays`)."""

from __future__ import annotations

import numpy as np

from ..kernels import bundle as kb
from ..kernels import primary as kprim
from ..scene import Scene


def scene_geometry_rows(scene: Scene, row0: int, row1: int, buffers=None):
    """Compiled vision-ray trace of camera rows ``row0:row1``, one pinhole ray per pixel
    centre (cameras with sub-pixels, a lens or distortion: :func:`vision_geometry_rows`).

    Returns the bundle geometry rows ((row1-row0)*W, G_SIZE) and the exact monitor
    coordinates of P ((row1-row0)*W, 2), NaN where P misses the monitor. ``buffers``:
    optional (geo, spec) arrays of at least that many rows to write into (the returned
    arrays are their leading rows), so that a tile loop reuses one allocation.
    """
    if not scene.camera.is_simple_pinhole:
        rows, cols = np.mgrid[row0:row1, 0 : scene.camera.width]
        o, d = scene.camera.chief_rays(rows.ravel(), cols.ravel())
        return _rays_geometry(scene, o, d)
    n = (row1 - row0) * scene.camera.width
    if buffers is not None and buffers[0].shape[0] >= n:
        geo, spec = buffers[0][:n], buffers[1][:n]
    else:
        geo = np.empty((n, kb.G_SIZE))
        spec = np.empty((n, 2))
    kprim.geometry_tile(
        scene.camera.kernel_params(), scene.surface.kernel_params(),
        scene.anisotropy.kernel_params(), scene.monitor.kernel_params(),
        row0, row1, scene.camera.width, geo, spec,
    )
    return geo, spec

def _rays_geometry(scene: Scene, origins, dirs):
    n = origins.shape[0]
    geo = np.empty((n, kb.G_SIZE))
    spec = np.empty((n, 2))
    kprim.geometry_rays(
        np.ascontiguousarray(origins, np.float64), np.ascontiguousarray(dirs, np.float64),
        scene.surface.kernel_params(), scene.anisotropy.kernel_params(),
        scene.monitor.kernel_params(), geo, spec,
    )
    return geo, spec


def vision_geometry_rows(scene: Scene, row: int):
    """Geometry rows (W * S, G_SIZE) and exact monitor hits (W * S, 2) of the S vision rays
    (sub-pixels x aperture samples, :meth:`pmdsim.scene.Camera.vision_rays`) of every pixel
    of camera row ``row``, pixel-major."""
    cam = scene.camera
    w = cam.width
    if cam.telecentric:  # parallel rays from the entrance plane: explicit rays
        o, d = cam.vision_rays(np.full(w, row), np.arange(w))
        return _rays_geometry(scene, o.reshape(-1, 3), d.reshape(-1, 3))
    chief, aperture, focus = cam.lens_inputs(np.full(w, row), np.arange(w))
    n = w * cam.rays_per_pixel
    geo = np.empty((n, kb.G_SIZE))
    spec = np.empty((n, 2))
    kprim.geometry_lens(
        cam.position, np.ascontiguousarray(cam.rotation), chief, aperture, focus,
        scene.surface.kernel_params(), scene.anisotropy.kernel_params(),
        scene.monitor.kernel_params(), geo, spec,
    )
    return geo, spec


def reduce_subrays(out: np.ndarray, estimator: str) -> np.ndarray:
    """Pixel sums (P, C) from the kernel sums of their S vision rays (P, S, C).

    A pixel integrates radiance over its footprint and the aperture: its value is the mean
    over its S rays of each ray's estimate. The ``paper`` and ``radiometric`` estimators
    share the factor 1/N, so the raw sums are averaged; ``weighted_mean`` normalises every
    ray by its own sum of weights first (the pixel's ``OUT_FTOTAL`` becomes 1). Rays that
    miss the surface (NaN) see a black background; a pixel none of whose rays hits is NaN.
    """
    s = out.shape[1]
    ft = out[..., kb.OUT_FTOTAL]
    hit = np.isfinite(ft)
    if estimator == "weighted_mean":
        hit &= ft > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            out = out / ft[..., None]
    elif not hit.all():
        out = out.copy()
    out[~hit] = 0.0  # a ray that misses the surface sees black
    summed = out.sum(axis=1) / s
    if estimator == "weighted_mean":
        summed[:, kb.OUT_FTOTAL] = 1.0
    summed[~hit.any(axis=1)] = np.nan
    return summed