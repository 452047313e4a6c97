"""Geometry against hand computation (issue 9): the surface-to-monitor distance of the
chain, ``Monitor.pixel_to_world`` / ``world_to_pixel``, a principal ray that reaches the
monitor's back, and the radiometric Beckmann kernel where Smith's G1(i) is well below 1.

The hand computations use ``tests/naive.py`` (written from ``docs/conventions.md`` and the
configuration, not from pmdsim's scene objects) or plain vector algebra in the test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import erfc

import naive
from conftest import base_dict, make_config, merge
from pmdsim.measure import chain
from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.scene import Monitor


# =========================================================================== distance d
def test_surface_to_monitor_distance_from_the_mirror_image_of_the_camera():
    """For a flat plate (z = 0) the reflected ray of a surface point S comes from the
    camera's mirror image C' = (cx, cy, -cz): the monitor point is where the line C' -> S
    meets the monitor plane, d = |M - S|. Computed by hand here for every pixel (camera rays
    from ``naive.vision_ray``, plane intersections by hand) and compared with
    ``chain.surface_to_monitor_mm`` to 1e-9 mm. Guards against a distance from the camera,
    to the monitor centre, to the nearest pixel centre instead of the exact point, or a
    wrong pixel_to_world: the slope test of the chain predicted from the run's own d and
    could not see any of these."""
    cfg = make_config()
    sim = Simulation.from_config(cfg)
    geo = sim.geometry()
    dist = chain.surface_to_monitor_mm(sim, geo)
    cam, mon = cfg.camera, cfg.monitor
    pos = np.asarray(cam.position_mm, np.float64)
    mirror_cam = pos * np.array([1.0, 1.0, -1.0])
    centre, e_u, e_v, n = naive.monitor_axes(mon)
    w, h = cam.resolution
    expected = np.full((h, w), np.nan)
    for row in range(h):
        for col in range(w):
            d = naive.vision_ray(cam, row, col)
            s = pos + (-pos[2] / d[2]) * d                      # hit on z = 0
            if abs(s[0]) > 50.0 or abs(s[1]) > 40.0:            # 100 x 80 mm plate
                continue
            ray = naive.unit(s - mirror_cam)
            t = ((centre - s) @ n) / (ray @ n)
            m = s + t * ray
            u = (m - centre) @ e_u / mon.pixel_pitch_mm + (mon.resolution[0] - 1) / 2
            v = (m - centre) @ e_v / mon.pixel_pitch_mm + (mon.resolution[1] - 1) / 2
            if ray @ n < 0 and -0.5 <= u < mon.resolution[0] - 0.5 and -0.5 <= v < mon.resolution[1] - 0.5:
                expected[row, col] = t
    seen = np.isfinite(expected)
    assert seen.sum() > 400 and (~seen).sum() > 50      # hits and misses both present
    np.testing.assert_array_equal(np.isfinite(dist), seen)
    np.testing.assert_allclose(dist[seen], expected[seen], rtol=0, atol=1e-9)
    # about 200 mm (the configured monitor distance), not the camera's 300 mm
    assert 170.0 < np.nanmedian(dist) < 230.0


# =========================================================================== monitor mapping
def _monitor_cfg(**changes):
    d = base_dict()["monitor"]
    d.update(changes)
    return parse_config(dict(base_dict(), monitor=d)).monitor


@pytest.mark.parametrize("look_at, up", [([0.4, -1.1, 0.0], [0.0, 1.0, 0.0]),
                                         ([30.0, 20.0, -5.0], [0.3, 1.0, 0.2])])
def test_pixel_to_world_matches_the_conventions_and_round_trips(look_at, up):
    """pixel_to_world against the conventions (``naive.monitor_axes``: u to the right, v
    downwards for a viewer facing the screen, pixel centres at integers, (W-1)/2, (H-1)/2 at
    the centre); neighbours one pitch apart, points in the plane; world_to_pixel inverts it;
    a ray aimed at a pixel's world point intersects the monitor at that pixel. Guards
    against a missing -1 in (W - 1)/2 (a half-pixel shift), swapped u/v axes or pitch
    factors, a mirrored axis."""
    mcfg = _monitor_cfg(look_at_mm=look_at, up=up, pixel_pitch_mm=0.7, resolution=[31, 17])
    mon = Monitor.from_config(mcfg)
    centre, e_u, e_v, n = naive.monitor_axes(mcfg)
    rng = np.random.default_rng(2)
    u = rng.uniform(-0.5, 30.49, 200)
    v = rng.uniform(-0.5, 16.49, 200)
    world = mon.pixel_to_world(u, v)
    expected = (centre + ((u - 15.0) * 0.7)[:, None] * e_u + ((v - 8.0) * 0.7)[:, None] * e_v)
    np.testing.assert_allclose(world, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose((world - centre) @ n, 0.0, atol=1e-12)
    np.testing.assert_allclose(mon.pixel_to_world(15.0, 8.0), centre, atol=1e-12)
    step_u = mon.pixel_to_world(4.0, 3.0) - mon.pixel_to_world(3.0, 3.0)
    step_v = mon.pixel_to_world(3.0, 4.0) - mon.pixel_to_world(3.0, 3.0)
    assert np.linalg.norm(step_u) == pytest.approx(0.7, rel=1e-12)
    assert np.linalg.norm(step_v) == pytest.approx(0.7, rel=1e-12)
    assert step_u @ step_v == pytest.approx(0.0, abs=1e-12)
    back = mon.world_to_pixel(world)
    np.testing.assert_allclose(back[..., 0], u, atol=1e-10)
    np.testing.assert_allclose(back[..., 1], v, atol=1e-10)
    origin = centre + 150.0 * n + np.array([1.0, -2.0, 0.5])      # in front of the screen
    du, dv, hit = mon.intersect(origin, naive.unit(world[0] - origin)[None])
    assert hit[0] and du[0] == pytest.approx(u[0], abs=1e-9) and dv[0] == pytest.approx(v[0], abs=1e-9)
    nu, nv, nhit = naive.monitor_hit(mcfg, origin, naive.unit(world[0] - origin)[None])
    assert nhit[0] and nu[0] == pytest.approx(u[0], abs=1e-9)


# =========================================================================== monitor's back
def test_principal_ray_reaching_the_monitors_back_is_masked():
    """The base scene with the monitor turned round (same plane, emitting side away from
    the plate): by hand, P of most plate pixels meets the plane inside the pixel grid, but
    from behind. Every such pixel must be masked (no monitor_mask, NaN specular point, no
    distance, black fringe images, zero weight), never decoded with a coordinate. Guards
    against a missing (dn < 0) test in the compiled or the NumPy intersection."""
    d = base_dict()
    c = np.asarray(d["monitor"]["centre_mm"])
    d["monitor"]["look_at_mm"] = list(2 * c - np.asarray(d["monitor"]["look_at_mm"]))
    cfg = parse_config(d)
    prim = naive.primary(cfg)
    centre, e_u, e_v, n = naive.monitor_axes(cfg.monitor)
    w, h = cfg.monitor.resolution
    behind = np.zeros(prim["valid"].shape, bool)
    for r, col in zip(*np.nonzero(prim["valid"])):
        s, p = prim["point"][r, col], prim["principal"][r, col]
        t = ((centre - s) @ n) / (p @ n)
        x = s + t * p
        u = (x - centre) @ e_u + (w - 1) / 2
        v = (x - centre) @ e_v + (h - 1) / 2
        behind[r, col] = t > 0 and p @ n > 0 and -0.5 <= u < w - 0.5 and -0.5 <= v < h - 0.5
    assert behind.sum() > 300          # the test is meaningful: P reaches the back
    assert not prim["on_monitor"].any()
    sim = Simulation.from_config(cfg)
    geo = sim.geometry()
    assert not geo.monitor_mask.any()
    assert np.all(np.isnan(geo.specular_u[behind])) and np.all(np.isnan(geo.specular_v[behind]))
    assert np.all(np.isnan(chain.surface_to_monitor_mm(sim, geo)))
    mirror = Simulation(sim.scene.specular())
    fr = mirror.render_fringes((20.0,), ("x",), 4)
    assert np.all(fr.images[..., behind] == 0.0)      # black, not NaN, not a pattern
    assert np.all(fr.f_hit[behind] == 0.0)
    rows, cols = np.nonzero(behind)
    u, v, wt, _, _ = sim.transport(rows[:10], cols[:10])
    assert np.all(np.isnan(u)) and np.all(wt == 0.0)


# =========================================================================== Beckmann + Smith
def _smith_g1(v, au, av):
    """Smith G1 of the Beckmann distribution, written from Walter et al. 2007, eq. 27:
    a = cos / (alpha(phi) sin), Lambda = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2."""
    v = np.asarray(v, np.float64)
    sin = np.sqrt(np.maximum(0.0, 1 - v[..., 2] ** 2))
    cos_phi, sin_phi = v[..., 0] / sin, v[..., 1] / sin
    alpha = np.sqrt((cos_phi * au) ** 2 + (sin_phi * av) ** 2)
    a = v[..., 2] / (alpha * sin)
    lam = (np.exp(-a * a) / (a * math.sqrt(math.pi)) - erfc(a)) / 2
    return 1 / (1 + lam)


def test_radiometric_beckmann_weights_with_smith_below_one():
    """Grazing incidence (75 deg) on a rough Beckmann surface (alpha 0.35 / 0.6, the larger
    one in the plane of incidence): G1(i) is about 0.8, not 1 as in every other test geometry. The compiled lobe kernel's weights
    equal F G1(i) G1(o) (i.h) / (cos_i cos_h) (Walter 2007's weight of slope sampling, with
    G1 written out here from the erfc formula) for every ray that hits the monitor. Guards
    against G1(i) dropped, G1(o) evaluated at i, G = G1 only, Lambda's sign."""
    t = math.radians(75.0)
    d = base_dict()
    d["camera"]["position_mm"] = [0.0, -300.0 * math.sin(t), 300.0 * math.cos(t)]
    d["camera"]["look_at_mm"] = [0.0, 0.0, 0.0]
    d["monitor"].update(centre_mm=[0.0, 120.0 * math.sin(math.radians(55)),
                                   120.0 * math.cos(math.radians(55))],
                        look_at_mm=[0.0, 0.0, 0.0], resolution=[400, 300], pixel_pitch_mm=1.0)
    d["brdf"] = {"model": "beckmann", "alpha_u": 0.35, "alpha_v": 0.6, "rho_s": 0.7}
    d["sampling"] = {"n_rays": 64, "estimator": "radiometric", "mode": "random", "seed": 3}
    cfg = parse_config(d)
    sim = Simulation.from_config(cfg)
    prim = naive.primary(cfg)
    rows, cols = [14, 16, 18], [12, 20, 28]
    u, v, wt, dirs, origin = sim.transport(rows, cols)
    n_hit, g1i_max = 0, 0.0
    for p, (r, c) in enumerate(zip(rows, cols)):
        assert prim["valid"][r, c]
        frame = (prim["x_axis"][r, c], prim["y_axis"][r, c], prim["normal"][r, c])
        i = np.array([prim["to_camera"][r, c] @ b for b in frame])
        o = np.stack([dirs[p] @ b for b in frame], -1)
        hit = np.isfinite(u[p])
        h = naive.unit(i + o[hit]) if hit.sum() == 1 else (i + o[hit]) / np.linalg.norm(i + o[hit], axis=-1, keepdims=True)
        g1i = float(_smith_g1(i, 0.35, 0.6))
        g1o = _smith_g1(o[hit], 0.35, 0.6)
        expected = 0.7 * g1i * g1o * (h @ i) / (i[2] * h[:, 2])
        np.testing.assert_allclose(wt[p][hit], expected, rtol=1e-9)
        assert np.all(wt[p][~hit] == 0.0)
        n_hit += hit.sum()
        g1i_max = max(g1i_max, g1i)
    assert n_hit > 60
    assert g1i_max < 0.9                                 # Smith really matters for i


# =========================================================================== slopes
@pytest.mark.parametrize("theta_i", [25.0, 50.0])
def test_slope_conversion_follows_the_plane_of_incidence_closed_form(theta_i):
    """A surface tilt delta turns the reflected ray by 2 delta in the plane of incidence and
    by 2 delta cos(theta_i) across it; on a monitor at distance d facing the ray a
    coordinate deviation c (mm) is therefore a slope c / (2 d) in the plane and
    c / (2 d cos(theta_i)) across (PHYSICS.md). chain.slope_deviation_urad (3-D) against
    that, for 0.2 monitor px of 0.1 mm at d = 500 mm (within 1e-3), and the small-angle path
    (no slope geometry) against c / (2 d) exactly. Guards against the across-plane cos
    missing, u/v swapped, a wrong sign or unit (urad)."""
    t = math.radians(theta_i)
    d = 500.0
    cfg = parse_config({
        "camera": {"resolution": [1, 1], "focal_length_px": 1000.0,
                   "position_mm": [0.0, -2000 * math.sin(t), 2000 * math.cos(t)],
                   "look_at_mm": [0, 0, 0], "up": [0, 1, 0]},
        "monitor": {"resolution": [801, 801], "pixel_pitch_mm": 0.1,
                    "centre_mm": [0.0, d * math.sin(t), d * math.cos(t)],
                    "look_at_mm": [0, 0, 0], "up": [0, 1, 0], "pixel_model": "continuous"},
        "surface": {"type": "flat", "size_mm": [100.0, 100.0]},
        "brdf": {"model": "mirror"},
    })
    sim = Simulation.from_config(cfg)
    geo = sim.geometry()
    assert geo.monitor_mask[0, 0]
    prim = naive.primary(cfg)
    sg = chain.SlopeGeometry(prim["point"], np.asarray(cfg.camera.position_mm, np.float64),
                             sim.scene.monitor)
    dist = np.array([[d]])
    c_px = np.array([[0.2]])
    c_mm = 0.2 * 0.1
    # the monitor's v axis lies in the plane of incidence (y-z), u across it
    along = chain.slope_deviation_urad("y", c_px, geo, sg, dist, 0.1)[0, 0]
    across = chain.slope_deviation_urad("x", c_px, geo, sg, dist, 0.1)[0, 0]
    # same sign as the small-angle path (a positive coordinate deviation, a positive slope)
    assert along == pytest.approx(c_mm / (2 * d) * 1e6, rel=1e-3)
    assert across == pytest.approx(c_mm / (2 * d * math.cos(t)) * 1e6, rel=1e-3)
    small = chain.slope_deviation_urad("x", c_px, geo, None, dist, 0.1)[0, 0]
    assert small == pytest.approx(c_mm / (2 * d) * 1e6, rel=1e-12)
    assert np.isnan(chain.slope_deviation_urad("x", np.array([[np.nan]]), geo, sg, dist, 0.1)[0, 0])


def test_compiled_slope_deviation_equals_the_numpy_reference():
    """The chain's compiled 3-D slope conversion (kernels.reconstruct.slope_deviation_3d)
    against the NumPy bisector-normal reference (measure.reconstruct.slope_deviation_3d) on random surface
    points and monitor coordinates of the Fig. 3-like geometry, both fringe directions and
    both signs, and NaN where a coordinate or point is missing (1e-12 rad)."""
    from pmdsim.measure.reconstruct import slope_deviation_3d
    from pmdsim.render import Geometry

    cfg = parse_config({
        "camera": {"resolution": [40, 30], "focal_length_px": 60.0,
                   "position_mm": [-845.2, 0.0, 1812.6], "look_at_mm": [0, 0, 0]},
        "monitor": {"resolution": [1920, 1080], "pixel_pitch_mm": 0.25,
                    "centre_mm": [253.6, 0.0, 543.8], "look_at_mm": [0, 0, 0]},
        "surface": {"type": "flat", "size_mm": [300.0, 200.0]},
        "brdf": {"model": "mirror"},
    })
    sim = Simulation.from_config(cfg)
    rng = np.random.default_rng(3)
    shape = (30, 40)
    points = np.concatenate([rng.uniform(-100, 100, shape + (2,)), rng.uniform(-1, 1, shape + (1,))], -1)
    su, sv = rng.uniform(0, 1919, shape), rng.uniform(0, 1079, shape)
    coord = rng.normal(0.0, 0.5, shape)
    coord[0, :5] = np.nan
    points[1, :3] = np.nan
    geo = Geometry(np.ones(shape, bool), np.ones(shape, bool), su, sv, points)
    sg = chain.SlopeGeometry(points, np.asarray(cfg.camera.position_mm, np.float64), sim.scene.monitor)
    for d in ("x", "y"):
        got = chain.slope_deviation_urad(d, coord, geo, sg, None, 0.25)
        u1, v1 = (su + coord, sv) if d == "x" else (su, sv + coord)
        with np.errstate(invalid="ignore"):
            ref = slope_deviation_3d(points, sg.camera_position, sim.scene.monitor, su, sv, u1, v1) * 1e6
        assert np.array_equal(np.isnan(got), np.isnan(ref))
        assert np.isnan(got[0, :5]).all() and np.isnan(got[1, :3]).all()
        ok = ~np.isnan(ref)
        assert np.max(np.abs(got[ok] - ref[ok])) < 1e-6       # urad, i.e. 1e-12 rad
        assert np.abs(ref[ok]).max() > 100                      # not a trivial field


@pytest.mark.parametrize("surface", [
    {"type": "flat", "size_mm": [100.0, 80.0]},
    {"type": "sphere", "radius_mm": 400.0, "aperture": {"shape": "circular", "radius_mm": 45.0}},
])
def test_geometry_points_equal_the_traced_surface_points(surface):
    """``Simulation.geometry().points`` (rebuilt from the compiled geometry rows in the
    monitor's frame) against the vision rays traced in NumPy (``trace.trace_primary``),
    for a flat plate and a concave sphere: the same points to 1e-9 mm, NaN exactly where
    the ray misses the surface."""
    from pmdsim.trace import trace_primary

    d = base_dict()
    d["surface"] = surface
    sim = Simulation.from_config(parse_config(d))
    geo = sim.geometry()
    hits = trace_primary(sim.scene, 0, sim.shape[0])
    ref = np.where(hits.valid[..., None], hits.point, np.nan)
    assert np.array_equal(np.isnan(geo.points[..., 0]), ~hits.valid)
    assert hits.valid.sum() > 100 and (~hits.valid).sum() > 10
    np.testing.assert_allclose(geo.points[hits.valid], ref[hits.valid], rtol=0, atol=1e-9)


def test_transport_directions_are_the_rays_the_kernel_traced():
    """``Simulation.transport``'s world directions, followed from the surface point to the
    monitor plane by hand, land on the monitor coordinates the kernel reports for the same
    rays (1e-6 px), and a ray it reports as a miss crosses the plane outside the monitor.
    With a Gauss rule whose azimuths follow an anisotropic lobe the kernel turns each
    pixel's cone basis about P (``ConeSampling.orient``); the directions once came from the
    unturned basis (the set-up figure drew a bundle 6 px off its own footprint and marked
    rays inside the monitor as misses)."""
    d = merge(base_dict(), {"sampling": {"mode": "rule", "n_rays": 96, "theta_max_deg": 2.0}})
    sim = Simulation.from_config(parse_config(d))
    assert sim.scene.sampling.phi_rho is not None      # the azimuths follow the lobe
    mon = sim.scene.monitor
    rows, cols = [7, 7, 15], [9, 26, 20]  # two at the monitor's edge (some rays miss)
    u, v, wt, dirs, origin = sim.transport(rows, cols)
    n_hit = n_miss = 0
    for p in range(len(rows)):
        dn = dirs[p] @ mon.normal
        t = ((mon.centre - origin[p]) @ mon.normal) / dn
        q = origin[p] + t[:, None] * dirs[p]
        pu = (q - mon.centre) @ mon.e_u / mon.pitch + (mon.width - 1) / 2.0
        pv = (q - mon.centre) @ mon.e_v / mon.pitch + (mon.height - 1) / 2.0
        hit = np.isfinite(u[p])
        np.testing.assert_allclose(pu[hit], u[p][hit], atol=1e-6)
        np.testing.assert_allclose(pv[hit], v[p][hit], atol=1e-6)
        inside = ((dn < 0) & (t > 0) & (pu >= -0.5) & (pu <= mon.width - 0.5)
                  & (pv >= -0.5) & (pv <= mon.height - 0.5))
        assert not inside[~hit].any()
        n_hit += int(hit.sum())
        n_miss += int((~hit).sum())
    assert n_hit > 250 and n_miss >= 4
