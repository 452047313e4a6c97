"""Camera model against OpenCV, and the thin lens's ray geometry."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import ConfigError, parse_config
from pmdsim.scene import Scene
from pmdsim.scene.camera import Camera, concentric_disk

from conftest import base_dict

cv2 = pytest.importorskip("cv2")

# A real calibration's size of coefficients (12 MP, 16 mm lens): barrel + tangential.
DIST = (-0.112, 0.087, 4.1e-4, -2.7e-4, -0.021)
KMAT = [[3612.5, 0.0, 2041.3], [0.0, 3608.9, 1497.8], [0.0, 0.0, 1.0]]


def _camera_cfg(**kw):
    d = base_dict()
    d["camera"].pop("focal_length_px", None)
    d["camera"].update(resolution=[4096, 3000], camera_matrix=KMAT, dist_coeffs=list(DIST), **kw)
    return parse_config(d)


def test_projection_matches_opencv():
    cfg = _camera_cfg()
    cam = Camera.from_config(cfg.camera)
    rng = np.random.default_rng(5)
    # points in front of the camera filling the field of view
    dirs = cam.ray_directions(rng.uniform(0, 2999, 400), rng.uniform(0, 4095, 400))
    pts = cam.position + dirs * rng.uniform(100, 900, (400, 1))
    ours = cam.project(pts)
    rvec, _ = cv2.Rodrigues(cam.rotation.T)
    tvec = -cam.rotation.T @ cam.position
    cv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), rvec, tvec, cam.camera_matrix, np.array(DIST))
    np.testing.assert_allclose(ours, cv.reshape(-1, 2), atol=1e-6, rtol=0)


def test_named_coefficients_equal_dist_coeffs():
    a = Camera.from_config(_camera_cfg().camera)
    d = base_dict()
    d["camera"].pop("focal_length_px", None)
    k1, k2, p1, p2, k3 = DIST
    d["camera"].update(resolution=[4096, 3000], camera_matrix=KMAT, k1=k1, k2=k2, k3=k3, p1=p1, p2=p2)
    b = Camera.from_config(parse_config(d).camera)
    assert a.distortion == b.distortion


def test_rays_reproject_to_their_pixels():
    cam = Camera.from_config(_camera_cfg().camera)
    rows = np.array([0.0, 10.3, 1500.0, 2999.0])
    cols = np.array([0.0, 4095.0, 2000.2, 17.5])
    pts = cam.position + 500 * cam.ray_directions(rows, cols)
    np.testing.assert_allclose(cam.project(pts), np.stack([cols, rows], -1), atol=1e-8)


def test_thin_lens_rays_meet_in_focus_and_fill_the_aperture():
    cfg = _camera_cfg(focal_length_mm=16.0, f_number=2.8, aperture_samples=64, subpixels=2)
    scene = Scene.from_config(cfg)
    cam = scene.camera
    assert cam.focus_distance_mm == pytest.approx(
        (np.array([1.7, 2.3, 0.0]) - cam.position) @ cam.rotation[:, 2], rel=0.05)
    o, d = cam.vision_rays(np.array([1500, 7]), np.array([2040, 4000]))
    assert o.shape == (2, 4 * 64, 3)
    # each sub-pixel's rays meet at one point on the plane Z_c = s_f
    for p in range(2):
        for s in range(4):
            sl = slice(s * 64, (s + 1) * 64)
            oc = (o[p, sl] - cam.position) @ cam.rotation
            dc = d[p, sl] @ cam.rotation
            t = (cam.focus_distance_mm - oc[:, 2]) / dc[:, 2]
            f = oc + t[:, None] * dc
            assert np.ptp(f, axis=0).max() < 1e-9
            r = np.hypot(oc[:, 0], oc[:, 1])
            assert r.max() <= 16.0 / 2.8 / 2 + 1e-12 and r.max() > 0.8 * 16.0 / 2.8 / 2


def test_concentric_disk_is_uniform():
    u = np.random.default_rng(0).random((2, 200000))
    x, y = concentric_disk(*u)
    r2 = x * x + y * y
    assert r2.max() <= 1 + 1e-12
    assert np.mean(r2) == pytest.approx(0.5, abs=3e-3)  # uniform disk: E[r^2] = 1/2


def test_camera_config_errors():
    d = base_dict()
    d["camera"]["f_number"] = 4.0
    with pytest.raises(ConfigError, match="f_number"):
        parse_config(d)
    d = base_dict()
    d["camera"]["dist_coeffs"] = [0.1, 0.2, 0.3]
    with pytest.raises(ConfigError, match="dist_coeffs"):
        parse_config(d)


def test_compiled_lens_rays_equal_the_numpy_rays():
    """kernels.primary.geometry_lens builds the same rays as Camera.vision_rays: compare
    the geometry rows of both."""
    from pmdsim.kernels import bundle as kb
    from pmdsim.kernels import primary as kp

    cfg = _camera_cfg(focal_length_mm=16.0, f_number=2.8, aperture_samples=7, subpixels=3)
    scene = Scene.from_config(cfg)
    cam = scene.camera
    rows, cols = np.array([1500, 1500, 1502]), np.array([2040, 2050, 1990])
    o, d = cam.vision_rays(rows, cols)
    args = (scene.surface.kernel_params(), scene.anisotropy.kernel_params(), scene.monitor.kernel_params())
    n = o.shape[0] * o.shape[1]
    g1, s1 = np.empty((n, kb.G_SIZE)), np.empty((n, 2))
    kp.geometry_rays(o.reshape(-1, 3), d.reshape(-1, 3), *args, g1, s1)
    g2, s2 = np.empty((n, kb.G_SIZE)), np.empty((n, 2))
    chief, ap, focus = cam.lens_inputs(rows, cols)
    kp.geometry_lens(cam.position, np.ascontiguousarray(cam.rotation), chief, ap, focus, *args, g2, s2)
    assert g1[:, kb.G_VALID].sum() > n // 2
    np.testing.assert_allclose(g2, g1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s2, s1, rtol=0, atol=1e-9)
