"""The object-side telecentric camera against closed forms and direct calculations.

Orthographic projection with a scale (magnification / pixel pitch px per mm), the same
distortion polynomial and pixel footprint as the pinhole, an object-side numerical aperture
(depth of field), and the slope conversions with the camera's viewpoint at infinity.
"""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import ConfigError, parse_config
from pmdsim.kernels import reconstruct as kr
from pmdsim.measure.reconstruct import bisector_normals
from pmdsim.render import Simulation
from pmdsim.scene import Scene
from pmdsim.scene.camera import Camera

from conftest import base_dict, merge

PITCH = 0.0055
MAG = 0.0022  # 0.4 px per mm on the part: the 40 x 32 px camera sees ~100 mm x 80 mm


def _telecentric(**camera) -> dict:
    d = base_dict()
    cam = d["camera"]
    cam.pop("focal_length_px")
    cam.update(projection="telecentric", pixel_pitch_mm=PITCH, magnification=MAG,
               principal_point_px=[19.2, 15.9])
    cam.update(camera)
    return d


def _cam(d) -> Camera:
    return Scene.from_config(parse_config(d)).camera


def _angle(a, b):
    """Angle (rad) between unit vectors, accurate at 1e-16 (atan2 of |a x b| and a . b)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


@pytest.mark.parametrize("extra", [{}, {"subpixels": 3, "k1": 2e-5, "p2": 3e-5}])
def test_vision_rays_are_parallel_to_the_axis(extra):
    cam = _cam(_telecentric(**extra))
    rows, cols = np.mgrid[0:cam.height, 0:cam.width]
    o, d = cam.vision_rays(rows.ravel(), cols.ravel())
    assert d.shape[1] == cam.rays_per_pixel == cam.subpixels ** 2
    assert np.max(_angle(d, cam.rotation[:, 2])) < 1e-12
    # every origin on the entrance plane through position_mm, normal to the axis
    assert np.max(np.abs((o - cam.position) @ cam.rotation[:, 2])) < 1e-12
    # the traced rows see the camera along -axis (to_camera in the compiled geometry rows)
    _, d1 = cam.chief_rays(rows, cols)
    assert np.max(_angle(d1, cam.rotation[:, 2])) < 1e-12


def test_image_scale_is_the_magnification_at_every_depth():
    d = _telecentric()
    cam = _cam(d)
    ex, ey, ez = cam.rotation.T
    rng = np.random.default_rng(3)
    base = cam.position + rng.uniform(-30, 30, (50, 1)) * ex + rng.uniform(-30, 30, (50, 1)) * ey
    for depth in (10.0, 300.0, 5000.0):
        p0 = base + depth * ez
        step = rng.uniform(0.5, 20.0, (50, 1))
        dc = (cam.project(p0 + step * ex) - cam.project(p0))[:, 0]
        dr = (cam.project(p0 + step * ey) - cam.project(p0))[:, 1]
        # px * pitch / mm on the part = the magnification (closed form), whatever the depth
        np.testing.assert_allclose(dc * PITCH / step[:, 0], MAG, rtol=1e-12, atol=0)
        np.testing.assert_allclose(dr * PITCH / step[:, 0], MAG, rtol=1e-12, atol=0)
    # a point on the axis lands on the principal point; behind the entrance plane: NaN
    np.testing.assert_allclose(cam.project(cam.position + 77.0 * ez), [19.2, 15.9], atol=1e-12)
    assert np.all(np.isnan(cam.project(cam.position - 5.0 * ez)))


def test_distortion_matches_the_polynomial_written_here():
    k1, k2, p1, p2, k3 = 3e-4, -2e-7, 4e-5, -6e-5, 1e-10
    cam = _cam(_telecentric(k1=k1, k2=k2, k3=k3, p1=p1, p2=p2))
    ex, ey, ez = cam.rotation.T
    rng = np.random.default_rng(7)
    x, y = rng.uniform(-40, 40, 200), rng.uniform(-35, 35, 200)
    pts = cam.position + x[:, None] * ex + y[:, None] * ey + rng.uniform(1, 900, (200, 1)) * ez
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    f = MAG / PITCH
    np.testing.assert_allclose(cam.project(pts), np.stack([f * xd + 19.2, f * yd + 15.9], -1),
                               rtol=0, atol=1e-9)
    # and the chief rays of pixels reproject onto them (the undistortion is its inverse)
    rows = np.array([0.0, 3.3, 31.0, 17.5])
    cols = np.array([0.0, 39.0, 7.25, 20.0])
    o, dd = cam.chief_rays(rows, cols)
    np.testing.assert_allclose(cam.project(o + 123.0 * dd), np.stack([cols, rows], -1), atol=1e-9)


def test_numerical_aperture_rays_meet_in_focus_and_fill_the_cone():
    na = 0.05
    cam = _cam(_telecentric(numerical_aperture=na, focus_distance_mm=310.0, aperture_samples=33))
    assert cam.rays_per_pixel == 33
    o, d = cam.vision_rays(np.array([3, 20]), np.array([5, 31]))
    ez = cam.rotation[:, 2]
    for p in range(2):
        # every ray passes through the in-focus point of its pixel's chief ray
        oc, dc = cam.chief_rays(np.array([[3, 20][p]]), np.array([[5, 31][p]]))
        focus = oc[0] + 310.0 * dc[0]
        t = (focus - o[p]) @ ez / (d[p] @ ez)
        np.testing.assert_allclose(o[p] + t[:, None] * d[p], np.broadcast_to(focus, (33, 3)),
                                   atol=1e-10)
        # direction sines fill the disk of radius NA, centred on the axis (antithetic pairs)
        sines = np.linalg.norm(np.cross(d[p], ez), axis=-1)
        assert sines.max() <= na + 1e-15 and sines.max() > 0.8 * na
        np.testing.assert_allclose(d[p].mean(axis=0) / np.linalg.norm(d[p].mean(axis=0)), ez,
                                   atol=1e-15)
    # half depth of field: a blur of one pixel footprint, 1 / f_px mm / (2 tan asin NA)
    assert cam.depth_of_field_mm == pytest.approx((PITCH / MAG) / (2 * na / np.sqrt(1 - na * na)),
                                                  rel=1e-12)


def _direct_specular(cam, fx, fy, mon, surface_hit):
    """Monitor coordinates (u, v) of every pixel's reflected chief ray, computed here: the
    ray from the entrance plane along the axis (fx, fy px per mm), the surface hit and
    normal from ``surface_hit(o, d)``, the mirror direction and the monitor plane."""
    rows, cols = np.mgrid[0:cam.height, 0:cam.width]
    ex, ey, ez = cam.rotation.T
    cx, cy = cam.principal_point
    o = cam.position + ((cols - cx) / fx)[..., None] * ex + ((rows - cy) / fy)[..., None] * ey
    d = np.broadcast_to(ez, o.shape)
    p, n, ok = surface_hit(o, d)
    r = d - 2 * np.sum(d * n, -1, keepdims=True) * n
    t = np.sum((mon.centre - p) * mon.normal, -1) / np.sum(r * mon.normal, -1)
    m = p + t[..., None] * r
    u = (m - mon.centre) @ mon.e_u / mon.pitch + (mon.width - 1) / 2
    v = (m - mon.centre) @ mon.e_v / mon.pitch + (mon.height - 1) / 2
    inside = ok & (t > 0) & (u >= -0.5) & (u < mon.width - 0.5) & (v >= -0.5) & (v < mon.height - 0.5)
    return np.where(inside, u, np.nan), np.where(inside, v, np.nan)


def _flat_hit(o, d):
    t = -o[..., 2] / d[..., 2]
    p = o + t[..., None] * d
    ok = (np.abs(p[..., 0]) <= 50.0) & (np.abs(p[..., 1]) <= 40.0)
    return p, np.broadcast_to([0.0, 0.0, 1.0], p.shape), ok


R_SPHERE = 700.0


def _sphere_hit(o, d):
    # concave towards +z: centre of curvature at (0, 0, R), vertex at the origin
    c = np.array([0.0, 0.0, R_SPHERE])
    oc = o - c
    b = np.sum(oc * d, -1)
    disc = b * b - (np.sum(oc * oc, -1) - R_SPHERE ** 2)
    t = -b + np.sqrt(disc)  # the far intersection: the lower cap, near the vertex
    p = o + t[..., None] * d
    n = (c - p) / R_SPHERE
    ok = np.hypot(p[..., 0], p[..., 1]) <= 40.0
    return p, n, ok


@pytest.mark.parametrize("surface,hit", [
    ({"type": "flat", "size_mm": [100.0, 80.0]}, _flat_hit),
    ({"__replace__": {"type": "sphere", "radius_mm": R_SPHERE, "aperture": {"shape": "circular",
                                                                           "radius_mm": 40.0}}},
     _sphere_hit),
])
def test_specular_reference_matches_a_direct_calculation(surface, hit):
    d = merge(_telecentric(camera_matrix=[[0.41, 0.0, 19.2], [0.0, 0.39, 15.9], [0.0, 0.0, 1.0]]),
              {"surface": surface})
    d["camera"].pop("magnification")
    d["camera"].pop("principal_point_px")
    sim = Simulation.from_config(parse_config(d))
    cam = sim.scene.camera
    # fx != fy: a swapped axis moves the hits
    assert cam.focal_px == 0.41 and cam.fy == 0.39
    geo = sim.geometry()
    u, v = _direct_specular(cam, 0.41, 0.39, sim.scene.monitor, hit)
    ok = np.isfinite(u)
    assert ok.sum() > 0.4 * ok.size
    np.testing.assert_array_equal(np.isfinite(geo.specular_u), ok)
    np.testing.assert_allclose(geo.specular_u[ok], u[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(geo.specular_v[ok], v[ok], rtol=0, atol=1e-9)


def test_bisector_with_the_viewpoint_at_infinity():
    """The slope conversions take the homogeneous viewpoint (axis, 0): the direction to the
    camera is the same at every point (NumPy and compiled), and (C, 1) is the centre."""
    rng = np.random.default_rng(11)
    pts = rng.uniform(-20, 20, (30, 3))
    mon = rng.uniform(-200, 200, (30, 3)) + [0, 0, 400]
    axis = np.array([0.3, -0.2, 0.93])
    axis /= np.linalg.norm(axis)
    b = (mon - pts) / np.linalg.norm(mon - pts, axis=1, keepdims=True)
    want = (axis + b) / np.linalg.norm(axis + b, axis=1, keepdims=True)
    np.testing.assert_allclose(bisector_normals(pts, np.r_[axis, 0.0], mon), want, atol=1e-15)
    rot = np.eye(3)
    sx, sy = np.empty(30), np.empty(30)
    kr.bisector_slopes(pts, np.r_[axis, 0.0], mon, rot, sx, sy)
    np.testing.assert_allclose(sx, -want[:, 0] / want[:, 2], rtol=1e-13)
    np.testing.assert_allclose(sy, -want[:, 1] / want[:, 2], rtol=1e-13)
    c = np.array([5.0, -3.0, 600.0])
    sx3, sy3, sx4, sy4 = (np.empty(30) for _ in range(4))
    kr.bisector_slopes(pts, c, mon, rot, sx3, sy3)
    kr.bisector_slopes(pts, np.r_[c, 1.0], mon, rot, sx4, sy4)
    np.testing.assert_array_equal(sx3, sx4)
    np.testing.assert_array_equal(sy3, sy4)


@pytest.mark.parametrize("change,field", [
    ({"focal_length_mm": 50.0}, "focal_length_mm"),
    ({"f_number": 4.0}, "f_number"),
    ({"magnification": None}, "magnification"),
    ({"focus_distance_mm": 300.0}, "numerical_aperture"),
])
def test_telecentric_settings_are_checked(change, field):
    d = _telecentric()
    for k, v in change.items():
        if v is None:
            d["camera"].pop(k)
        else:
            d["camera"][k] = v
    with pytest.raises(ConfigError, match=field):
        parse_config(d)


def test_magnification_needs_projection_telecentric():
    d = base_dict()
    d["camera"]["magnification"] = 0.5
    with pytest.raises(ConfigError, match="projection"):
        parse_config(d)


def test_reconstruction_through_a_telecentric_camera_returns_the_sphere():
    """The noise-free specular chain (exact monitor hits of the principal rays) through a
    telecentric camera: the monocular reconstruction, with the viewpoint at infinity,
    returns the configured sphere from a wrong nominal radius (800 mm for 700 mm)."""
    from pmdsim import trace
    from pmdsim.measure.reconstruct import reconstruct
    from pmdsim.scene.surfaces import surface_from_config

    ap = {"shape": "circular", "radius_mm": 30.0}
    # 3.5 px per mm on the part; a pinhole of the same footprint reaches 3.8 nm / 10 urad RMS
    d = _telecentric(resolution=[240, 200], magnification=PITCH * 3.5,
                     principal_point_px=[119.3, 99.6])
    d["surface"] = {"type": "sphere", "radius_mm": R_SPHERE, "aperture": ap}
    cfg = parse_config(d)
    scene = Scene.from_config(cfg)
    hits = trace.trace_primary(scene)
    u, v, _ = trace.specular_monitor_coords(scene, hits)
    nominal = surface_from_config(parse_config(merge(d, {"surface": {"radius_mm": 800.0}})).surface)
    rec = reconstruct(u, v, scene.camera, scene.monitor, nominal, spacing_mm=1.0)
    truth = scene.surface
    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    z, gx, gy, _ = truth.sag(x, y)
    m = rec.mask
    assert m.sum() > 400
    e = rec.height_mm[m] - z[m]
    e -= e.mean()
    assert rec.converged
    # RMS over the aperture (measured 0.24 nm, 0.008 / 0.66 urad): heights to 1 nm (after
    # piston), slopes to 1 urad; the pinhole of tests/test_reconstruct.py needs 2.3x finer pixels
    assert np.sqrt(np.mean(e ** 2)) < 1e-6
    assert np.sqrt(np.mean((rec.slope_x[m] - gx[m]) ** 2)) < 1e-6
    assert np.sqrt(np.mean((rec.slope_y[m] - gy[m]) ** 2)) < 1e-6


def _small_example():
    """examples/telecentric_micro.toml on a 60 x 48 px camera (the same field on the part)."""
    from pathlib import Path

    from pmdsim import load_config
    from pmdsim.studies.convergence import reduced_config

    cfg = load_config(Path(__file__).parents[2] / "examples" / "telecentric_micro.toml")
    small = reduced_config(cfg, (60, 48))
    assert small.camera.projection == "telecentric"
    assert small.camera.pixel_pitch_mm / small.camera.magnification == pytest.approx(
        cfg.camera.pixel_pitch_mm / cfg.camera.magnification * 500 / 60)
    d = small.model_dump()
    d["sampling"].update(n_rays=16, target_error_mrad=None)
    return type(small).model_validate(d)


def test_example_runs_end_to_end(tmp_path):
    """The telecentric example, simulate and budget, on a reduced camera: a run folder with
    statistics and the reconstruction, and a budget with its rows."""
    import json

    from pmdsim import run_simulation
    from pmdsim.studies.budget import budget

    cfg = _small_example()
    run_simulation(cfg, tmp_path / "run", overwrite=True)
    stats = json.loads((tmp_path / "run" / "statistics.json").read_text())
    rec = stats["reconstruction"]
    assert rec["converged"] and rec["grid_points"] > 100
    # the kinematic lobe's slope error is hundreds of urad, far above the chain's floor
    assert 20.0 < rec["slope_error_x_urad"]["rms"] < 2000.0
    res = budget(cfg)
    effects = {r["effect"] for r in res.rows}
    # the numerical aperture's blur is a row of its own, beside the surface and calibration
    assert {"defocus", "surface", "all_system"} <= effects
    assert {r["effect"] for r in res.height_rows} >= {"camera_position_mm", "calibration_total"}


@pytest.mark.parametrize("na", [0.01, 0.02])
def test_depth_of_field_blur_is_the_disk_mtf(na):
    """Flat mirror, telecentric camera focused on it (the default focus), monitor d = 200 mm
    along the reflected axis: the monitor is seen through a blur disk of diameter
    b = 2 d tan(asin NA) (direction sines uniform in the disk of radius NA; the tangent's
    non-uniformity is O(NA^2)), so the centre pixel's fringe modulation is
    2 J1(pi b / p) / (pi b / p) for period p."""
    from scipy.special import j1

    th = np.radians(20.0)
    d_mon = 200.0
    cfg = parse_config({
        "camera": {"projection": "telecentric", "resolution": [5, 5], "pixel_pitch_mm": 0.005,
                   "magnification": 0.5, "numerical_aperture": na, "aperture_samples": 4096,
                   "position_mm": [-100 * np.sin(th), 0.0, 100 * np.cos(th)],
                   "look_at_mm": [0, 0, 0]},
        "monitor": {"resolution": [2000, 2000], "pixel_pitch_mm": 0.02,
                    "centre_mm": [d_mon * np.sin(th), 0.0, d_mon * np.cos(th)],
                    "look_at_mm": [0, 0, 0], "pixel_model": "continuous"},
        "surface": {"size_mm": [100.0, 100.0]},
        "brdf": {"model": "mirror"},
    })
    sim = Simulation.from_config(cfg)
    assert sim.scene.camera.focus_distance_mm == pytest.approx(100.0, rel=1e-9)
    b = 2 * d_mon * na / np.sqrt(1 - na * na)
    periods_mm = (6.0, 12.0)
    res = sim.render_fringes([p / 0.02 for p in periods_mm], ("x", "y"), 4)
    for wi, p in enumerate(periods_mm):
        x = np.pi * b / p
        expect = abs(2 * j1(x) / x)  # the modulation; past the first zero the phase flips
        for di in range(2):
            mod = abs(res.sums[di, wi, 2, 2]) / res.f_hit[2, 2]
            assert mod == pytest.approx(expect, rel=0.01), (na, p, di)
