"""Camera optics and display geometry through the whole renderer, against closed forms:
defocus MTF of a uniform blur disk, the sub-pixel footprint, cover glass and a bent monitor
moving the decoded point, gamma pre-compensation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import j1

from pmdsim.config import DecodeConfig, parse_config
from pmdsim.measure.chain import decode_fringes
from pmdsim.render import Simulation
from pmdsim.trace import trace_primary

from conftest import make_config

MIRROR = {"__replace__": {"model": "mirror"}}


def _defocus_config(f_number: float, s: float = 300.0, d: float = 200.0, theta_deg: float = 20.0):
    """Camera s mm from a flat mirror at theta, monitor d mm along the reflected chief ray,
    facing it; 0.02 mm monitor pixels (continuous); 5 x 5 px camera, centre pixel on axis."""
    th = math.radians(theta_deg)
    cam = [-s * math.sin(th), 0.0, s * math.cos(th)]
    mon = [d * math.sin(th), 0.0, d * math.cos(th)]
    return parse_config({
        "camera": {"resolution": [5, 5], "focal_length_mm": 25.0, "pixel_pitch_mm": 0.005,
                   "position_mm": cam, "look_at_mm": [0, 0, 0], "f_number": f_number,
                   "aperture_samples": 4096},
        "monitor": {"resolution": [2000, 2000], "pixel_pitch_mm": 0.02, "centre_mm": mon,
                    "look_at_mm": [0, 0, 0], "pixel_model": "continuous"},
        "surface": {"size_mm": [100.0, 100.0]},
        "brdf": {"model": "mirror"},
    })


@pytest.mark.parametrize("f_number", [4.0, 8.0])
def test_defocus_modulation_is_the_blur_disk_mtf(f_number):
    cfg = _defocus_config(f_number)
    sim = Simulation.from_config(cfg)
    assert sim.scene.camera.focus_distance_mm == pytest.approx(300.0, rel=1e-9)
    b = (25.0 / f_number) * 200.0 / 300.0  # blur diameter on the monitor, mm
    periods_mm = (6.0, 12.0)
    res = sim.render_fringes([p / 0.02 for p in periods_mm], ("x", "y"), 4)
    for wi, p in enumerate(periods_mm):
        x = math.pi * b / p
        expect = 2 * j1(x) / x
        for di in range(2):
            mod = abs(res.sums[di, wi, 2, 2]) / res.f_hit[2, 2]
            assert mod == pytest.approx(expect, rel=0.01), (f_number, p, di)


def _decode(sim, widths=(24.0, 200.0)):
    res = sim.render_fringes(widths, ("x", "y"), 4)
    dec = decode_fringes(res, (sim.scene.monitor.width, sim.scene.monitor.height), DecodeConfig())
    return {d: (r.monitor_coord_px, r.valid) for d, r in dec.items()}


def test_subpixel_footprint_tends_to_the_footprint_average():
    rms_centre, rms_foot = [], []
    for n in (1, 2, 4, 8):
        sim = Simulation.from_config(make_config(brdf=MIRROR, camera={"subpixels": n}))
        dec = _decode(sim)
        geo = sim.geometry()
        fu, fv = sim.footprint_specular()
        for d, exact, foot in (("x", geo.specular_u, fu), ("y", geo.specular_v, fv)):
            coord, valid = dec[d]
            ok = valid & np.isfinite(foot) & np.isfinite(exact)
            rms_centre.append((n, d, float(np.sqrt(np.mean((coord - exact)[ok] ** 2)))))
            rms_foot.append((n, d, float(np.sqrt(np.mean((coord - foot)[ok] ** 2)))))
    foot = {(n, d): r for n, d, r in rms_foot}
    for d in ("x", "y"):
        seq = [foot[(n, d)] for n in (1, 2, 4, 8)]
        assert all(b < a for a, b in zip(seq, seq[1:])), seq
        assert seq[0] == pytest.approx(1 / math.sqrt(12), rel=0.25)  # one ray: the staircase
        assert seq[-1] < seq[0] / 5


def _exact_monitor_hits(sim):
    """Principal rays of the pixel-centre chief rays in the monitor frame: the nominal-plane
    hit (mm from the centre, along e_u, e_v) and the unit direction (o_u, o_v, o_n)."""
    scene = sim.scene
    mon = scene.monitor
    hits = trace_primary(scene)
    p = hits.principal
    t = ((mon.centre - hits.point) @ mon.normal) / (p @ mon.normal)
    x = hits.point + t[..., None] * p - mon.centre
    return (x @ mon.e_u, x @ mon.e_v), (p @ mon.e_u, p @ mon.e_v, p @ mon.normal)


def test_cover_glass_and_bent_monitor_move_the_decoded_point():
    base = dict(brdf=MIRROR, monitor={"pixel_model": "continuous"})
    ref = Simulation.from_config(make_config(**base))
    (x0, y0), (ou, ov, on) = _exact_monitor_hits(ref)
    c = -on
    dec0 = _decode(ref)
    # cover glass: shift -(t (tan th - tan th_r)) along the ray's azimuth
    t_g, n_g = 2.0, 1.5
    sim = Simulation.from_config(make_config(brdf=MIRROR, monitor={
        "pixel_model": "continuous", "cover_glass_thickness_mm": t_g, "cover_glass_index": n_g}))
    dec = _decode(sim)
    th = np.arccos(c)
    mag = t_g * (np.tan(th) - np.tan(np.arcsin(np.sin(th) / n_g)))
    sin_th = np.sqrt(ou**2 + ov**2)
    expect = {"x": -mag * ou / sin_th, "y": -mag * ov / sin_th}  # mm
    for d in ("x", "y"):
        ok = dec[d][1] & dec0[d][1]
        got = (dec[d][0] - dec0[d][0])[ok]  # monitor px of 1 mm
        assert np.abs(expect[d][ok]).max() > 0.05
        np.testing.assert_allclose(got, expect[d][ok], atol=1e-6)
    # bow along x, h = k x^2 (mm, towards the viewer): the ray p0 + s o meets it where
    # s o_n = k (x0 + s o_u)^2, the root of k o_u^2 s^2 + (2 k x0 o_u - o_n) s + k x0^2 = 0
    # nearest the plane
    k = 4e-4
    sim = Simulation.from_config(make_config(brdf=MIRROR, monitor={
        "pixel_model": "continuous", "flatness_coefficients_mm": [[0, 0, 0], [0, 0, 0], [k, 0, 0]]}))
    dec = _decode(sim)
    a = k * ou**2
    bq = 2 * k * x0 * ou - on
    cq = k * x0**2
    s = (-bq + np.sqrt(bq**2 - 4 * a * cq)) / (2 * a)  # the root with s -> -cq / bq as k -> 0
    s = np.where(np.abs(2 * cq / (-bq - np.sqrt(bq**2 - 4 * a * cq))) < np.abs(s),
                 2 * cq / (-bq - np.sqrt(bq**2 - 4 * a * cq)), s)
    expect = {"x": s * ou, "y": s * ov}
    for d in ("x", "y"):
        ok = dec[d][1] & dec0[d][1]
        got = (dec[d][0] - dec0[d][0])[ok]
        assert np.abs(expect[d][ok]).max() > 0.05
        np.testing.assert_allclose(got, expect[d][ok], atol=1e-6)


def test_precompensated_gamma_renders_like_a_linear_display():
    lin = Simulation.from_config(make_config(brdf=MIRROR))
    pre = Simulation.from_config(make_config(brdf=MIRROR, monitor={"gamma": 2.2, "precompensate_gamma": True}))
    raw = Simulation.from_config(make_config(brdf=MIRROR, monitor={"gamma": 2.2}))
    a, b, c = _decode(lin), _decode(pre), _decode(raw)
    for d in ("x", "y"):
        ok = a[d][1] & b[d][1]
        np.testing.assert_allclose(b[d][0][ok], a[d][0][ok], atol=1e-9)
        assert np.nanmax(np.abs(c[d][0] - a[d][0])[ok]) > 0.01  # gamma 2.2 uncompensated shows


def test_falloff_dims_by_the_emission_angle():
    """An all-white monitor seen in a mirror: each pixel shows cos(theta)^m of its principal
    ray's emission angle, times the tabulated factor."""
    sim = Simulation.from_config(make_config(brdf=MIRROR, monitor={
        "falloff_exponent": 3.0, "falloff_table": [[0.0, 1.0], [40.0, 0.6]]}))
    img = sim.render_images(np.ones((1,) + sim.scene.monitor.shape))[0]
    _, (ou, ov, on) = _exact_monitor_hits(sim)
    theta = np.arccos(-on)
    expect = np.cos(theta) ** 3 * np.interp(np.degrees(theta), [0, 40], [1.0, 0.6])
    geo = sim.geometry()
    ok = geo.monitor_mask
    assert ok.sum() > 500 and np.ptp(expect[ok]) > 0.05
    np.testing.assert_allclose(img[ok], expect[ok], rtol=1e-5)


def test_lut_and_sensor_photons_from_a_config_file(tmp_path):
    from pmdsim.config import load_config

    (tmp_path / "lut.csv").write_text("drive,cd_m2\n0,0.5\n128,60\n255,300\n")
    (tmp_path / "c.toml").write_text('''
[camera]
resolution = [8, 6]
focal_length_px = 20.0
position_mm = [0.0, -120.0, 260.0]
look_at_mm = [0.0, 0.0, 0.0]
[monitor]
resolution = [100, 80]
pixel_pitch_mm = 1.0
centre_mm = [0.0, 90.0, 180.0]
look_at_mm = [0.0, 0.0, 0.0]
response_lut = "lut.csv"
[surface]
size_mm = [50.0, 50.0]
[brdf]
model = "mirror"
[sensor]
enabled = true
quantum_efficiency = 0.5
exposure_photons = 8000.0
''')
    cfg = load_config(tmp_path / "c.toml")
    sim = Simulation.from_config(cfg)
    mon = sim.scene.monitor
    assert not mon.is_linear
    np.testing.assert_allclose(mon.luminance([0.0, 128 / 255, 1.0]), [0.0, (60 - 0.5) / 299.5, 1.0])
    from pmdsim.scene.sensor import Sensor

    assert Sensor.from_config(cfg.sensor).exposure == pytest.approx(4000.0)


@pytest.mark.parametrize("estimator", ["paper", "weighted_mean", "radiometric"])
def test_subpixel_render_is_the_mean_of_shifted_pinhole_renders(estimator):
    """n x n sub-pixels = the mean of n^2 single-ray renders whose principal point is shifted
    by the sub-pixel offsets (the fast pinhole path, each ray normalised by its own
    estimator); rays that miss the surface count as black."""
    samp = {"estimator": estimator, "n_rays": 16}
    sim = Simulation.from_config(make_config(camera={"subpixels": 2}, sampling=samp))
    got = sim.render_fringes((24.0, 200.0), ("x", "y"), 4).images
    cx, cy = (40 - 1) / 2, (32 - 1) / 2
    parts = []
    for dr in (-0.25, 0.25):
        for dc in (-0.25, 0.25):
            s = Simulation.from_config(make_config(
                camera={"principal_point_px": [cx - dc, cy - dr]}, sampling=samp))
            assert s.scene.camera.is_simple_pinhole
            parts.append(s.render_fringes((24.0, 200.0), ("x", "y"), 4).images.astype(np.float64))
    stack = np.stack(parts)
    hit = np.isfinite(stack)
    expect = np.where(hit, stack, 0.0).sum(0) / 4
    expect[~hit.any(0)] = np.nan
    np.testing.assert_allclose(got, expect, rtol=1e-5, atol=1e-6 * np.nanmax(np.abs(expect)))
    assert np.isnan(got).any() and (hit.sum(0) == 2).any()  # edges: partly on the plate
