"""Curved and measured surfaces against an independent evaluation.

The reference: the sag written out in NumPy (conic formula, asphere sum, numpy's
polyval2d, measure.integrate.zernike for Zernikes, scipy.ndimage.map_coordinates for
height maps), its gradient by a 4th-order central difference, and the ray's root by a
brute-force scan for a sign change refined with scipy.optimize.brentq.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage, optimize

from pmdsim.config import ConfigError, parse_config
from pmdsim.measure.integrate import zernike
from pmdsim.scene.surfaces import surface_from_config, zernike_monomials

VERTEX = np.array([3.0, -2.0, 1.0])
NORMAL = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
XAXIS = (1.0, 0.3, 0.0)

ZCOEF = [(2, 1e-3), (4, 2e-3), (5, -1e-3), (7, 5e-4), (8, 3e-4), (11, -2e-4), (13, 1e-4)]
XYTERMS = [(2, 0, 1e-3), (0, 2, -5e-4), (1, 1, 3e-4), (3, 0, 2e-4), (1, 2, -1e-4), (2, 2, 1e-4)]
rng_map = np.random.default_rng(7)
MAP = 1e-3 * ndimage.gaussian_filter(rng_map.normal(size=(33, 41)), 3.0) * 30


def cfg_dict(kind, **kw):
    d = dict(type=kind, centre_mm=tuple(VERTEX), normal=tuple(NORMAL), x_axis=XAXIS,
             aperture=dict(shape="circular", radius_mm=18.0))
    d.update(kw)
    return d


def surfaces(tmp_path):
    np.save(tmp_path / "map.npy", MAP)
    return {
        "sphere": cfg_dict("sphere", radius_mm=120.0),
        "sphere_convex": cfg_dict("sphere", radius_mm=-80.0),
        "conic": cfg_dict("conic", radius_mm=150.0, conic=-0.6),
        "hyperboloid": cfg_dict("conic", radius_mm=-90.0, conic=-2.5),
        "plane_annulus": cfg_dict("conic", aperture=dict(shape="annular", radius_mm=18.0, inner_radius_mm=6.0)),
        "asphere": cfg_dict("asphere", radius_mm=200.0, conic=-1.0, coefficients=(1e-7, -2e-10, 3e-13)),
        "off_axis": cfg_dict("conic", radius_mm=300.0, conic=-1.0,
                             aperture=dict(shape="rectangular", size_mm=(20.0, 14.0), centre_mm=(40.0, 10.0))),
        "xy_polynomial": cfg_dict("xy_polynomial", radius_mm=250.0, conic=0.5, norm_radius_mm=18.0, terms=XYTERMS),
        "zernike": cfg_dict("zernike", radius_mm=-400.0, norm_radius_mm=18.0, coefficients=ZCOEF),
        "height_map": cfg_dict("height_map", file=str(tmp_path / "map.npy"), spacing_mm=(1.0, 1.0),
                               radius_mm=500.0, aperture=None),
    }


def ref_sag(d, x, y):
    """Independent sag (mm) at local x, y (arrays)."""
    r = d.get("radius_mm")
    c = 0.0 if r is None else 1.0 / r
    k = d.get("conic", 0.0)
    r2 = x * x + y * y
    z = c * r2 / (1 + np.sqrt(1 - (1 + k) * c * c * r2))
    for i, a in enumerate(d.get("coefficients", ()) if d["type"] == "asphere" else ()):
        z = z + a * r2 ** (i + 2)
    if d["type"] == "xy_polynomial":
        s = d["norm_radius_mm"]
        cm = np.zeros((4, 4))
        for i, j, cc in d["terms"]:
            cm[i, j] = cc
        z = z + np.polynomial.polynomial.polyval2d(x / s, y / s, cm)
    if d["type"] == "zernike":
        s = d["norm_radius_mm"]
        for j, cc in d["coefficients"]:
            z = z + cc * zernike(j, x / s, y / s)[0]
    if d["type"] == "height_map":
        h, w = MAP.shape
        col = x + (w - 1) / 2
        row = y + (h - 1) / 2
        z = z + ndimage.map_coordinates(MAP, [np.atleast_1d(row), np.atleast_1d(col)], order=3, mode="mirror").reshape(np.shape(x))
    return z


def ref_grad(d, x, y, h=1e-3):
    def f(a, b):
        return ref_sag(d, a, b)
    gx = (-f(x + 2 * h, y) + 8 * f(x + h, y) - 8 * f(x - h, y) + f(x - 2 * h, y)) / (12 * h)
    gy = (-f(x, y + 2 * h) + 8 * f(x, y + h) - 8 * f(x, y - h) + f(x, y - 2 * h)) / (12 * h)
    return gx, gy


def frame(surf):
    return np.stack([surf.x_axis, surf.y_axis, surf.normal], axis=1)


def rays(surf, n, rng, spread=1.3):
    """Rays from a camera-like point above the surface to points around the aperture."""
    kind, cx, cy, a, b = surf.aperture
    R = frame(surf)
    origin = surf.centre + R @ np.array([cx + 30.0, cy - 20.0, 400.0])
    tx = cx + spread * a * rng.uniform(-1, 1, n)
    ty = cy + spread * (b if kind == "rectangular" else a) * rng.uniform(-1, 1, n)
    targets = surf.centre + np.stack([tx, ty, np.zeros(n)], -1) @ R.T
    d = targets - origin
    return np.broadcast_to(origin, d.shape).copy(), d / np.linalg.norm(d, axis=-1, keepdims=True)


def ref_intersect(d, surf, o, v):
    """Brute force: scan F(t) for the first sign change, refine with brentq."""
    R = frame(surf)
    lo = (o - surf.centre) @ R
    lv = v @ R

    def F(t):
        t = np.asarray(t, np.float64)
        p = lo + t[..., None] * lv
        with np.errstate(invalid="ignore"):
            return p[..., 2] - ref_sag(d, p[..., 0], p[..., 1])

    t0 = -lo[2] / lv[2]
    ts = np.linspace(0.7 * t0, 1.3 * t0, 4001)
    fs = F(ts)
    ok = np.isfinite(fs)
    change = np.nonzero(ok[:-1] & ok[1:] & (np.sign(fs[:-1]) != np.sign(fs[1:])))[0]
    if len(change):
        q = change[0]
        t = optimize.brentq(lambda s: float(F(s)), ts[q], ts[q + 1], xtol=1e-15, rtol=1e-15, maxiter=200)
        return t, lo + t * lv
    return None, None


@pytest.mark.parametrize("name", ["sphere", "sphere_convex", "conic", "hyperboloid", "plane_annulus",
                                  "asphere", "off_axis", "xy_polynomial", "zernike", "height_map"])
def test_intersection_and_normal_match_reference(name, tmp_path):
    d = surfaces(tmp_path)[name]
    cfg = parse_config(_run(d)).surface
    surf = surface_from_config(cfg)
    rng = np.random.default_rng(3)
    o, v = rays(surf, 60, rng)
    t, p, n, hit = surf.intersect(o, v)
    assert hit.any() and (~hit).any(), "the rays must include hits and misses"
    assert np.isfinite(p[hit]).all() and np.isnan(p[~hit]).all()
    R = frame(surf)
    checked = 0
    for q in range(len(o)):
        tr, lp = ref_intersect(d, surf, o[q], v[q])
        inside = tr is not None and bool(surf.in_aperture(lp[0], lp[1]))
        assert hit[q] == inside, (q, tr, lp)
        if not hit[q]:
            continue
        checked += 1
        assert abs(t[q] - tr) < 1e-9
        np.testing.assert_allclose(p[q], surf.centre + R @ lp, atol=1e-9, rtol=0)
        gx, gy = ref_grad(d, np.array(lp[0]), np.array(lp[1]))
        nl = np.array([-gx, -gy, 1.0]) / math.sqrt(1 + gx * gx + gy * gy)
        ang = np.linalg.norm(np.cross(n[q], R @ nl))
        assert ang < 1e-9 and n[q] @ (R @ nl) > 0, ang
    assert checked >= 10


def _run(surface):
    from conftest import base_dict

    d = base_dict()
    d["surface"] = {k: v for k, v in surface.items() if v is not None}
    return d


def test_grazing_and_behind_rays_are_masked():
    surf = surface_from_config(parse_config(_run(dict(type="sphere", radius_mm=50.0,
                                                      aperture=dict(shape="circular", radius_mm=40.0)))).surface)
    o = np.array([[-100.0, 0.0, 0.0], [-100.0, 0.0, 1e-12], [0.0, 0.0, -10.0], [0.0, 0.0, 10.0], [0.0, 0.0, 10.0]])
    v = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    t, p, n, hit = surf.intersect(o, v)
    # tangent at the vertex / grazing: either a miss or a hit with n.v = 0, which the tracer
    # masks (it needs cos_i > 0); behind the origin and pointing away: misses
    for q in (0, 1):
        assert (not hit[q]) or abs(n[q] @ v[q]) < 1e-6
    assert hit.tolist()[2:] == [False, False, True]
    assert np.isnan(p[2:4]).all() and np.isfinite(p[4]).all()
    # a sphere beyond its hemisphere: the ray meets only the far branch -> miss
    t, p, n, hit = surf.intersect(np.array([[0.0, 0.0, 60.0]]), np.array([[0.0, 1.0, 0.0]]))
    assert not hit[0]


def test_zernike_monomials_match_polar_definition():
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-0.7, 0.7, (2, 40))
    for j in range(1, 37):
        c = zernike_monomials(j)
        np.testing.assert_allclose(np.polynomial.polynomial.polyval2d(u, v, c), zernike(j, u, v)[0], atol=1e-12)


def test_height_map_formats(tmp_path):
    import tifffile

    np.savetxt(tmp_path / "map.csv", MAP, delimiter=",")
    tifffile.imwrite(tmp_path / "map.tif", MAP.astype(np.float32))
    np.save(tmp_path / "map.npy", MAP)
    out = {}
    for f in ("map.npy", "map.csv", "map.tif"):
        d = cfg_dict("height_map", file=str(tmp_path / f), spacing_mm=(1.0, 1.0), height_unit="mm")
        d.pop("aperture")
        out[f] = surface_from_config(parse_config(_run(d)).surface)
    x, y = np.array([0.3, -5.2]), np.array([1.1, 7.7])
    z = {f: s.sag(x, y)[0] for f, s in out.items()}
    np.testing.assert_allclose(z["map.csv"], z["map.npy"], atol=1e-15)
    np.testing.assert_allclose(z["map.tif"], z["map.npy"], atol=1e-9)  # float32 storage
    d = cfg_dict("height_map", file=str(tmp_path / "missing.npy"), spacing_mm=(1.0, 1.0))
    with pytest.raises(ConfigError, match="surface.file"):
        surface_from_config(parse_config(_run(d)).surface)


def test_bad_surface_configs_name_the_field():
    with pytest.raises(ConfigError, match="surface.aperture"):
        parse_config(_run(dict(type="sphere", radius_mm=100.0, aperture=dict(shape="annular", radius_mm=5.0))))
    with pytest.raises(ConfigError, match="surface.radius_mm"):
        parse_config(_run(dict(type="sphere", radius_mm=0.0, aperture=dict(radius_mm=5.0))))
    with pytest.raises(ConfigError, match="surface.norm_radius_mm"):
        parse_config(_run(dict(type="zernike", aperture=dict(radius_mm=5.0))))


@pytest.mark.parametrize("surface", [
    dict(type="sphere", radius_mm=-300.0, aperture=dict(shape="circular", radius_mm=45.0)),
    dict(type="zernike", radius_mm=400.0, norm_radius_mm=40.0, coefficients=ZCOEF,
         aperture=dict(shape="annular", radius_mm=40.0, inner_radius_mm=8.0)),
])
def test_compiled_trace_matches_numpy_trace_on_curved_surfaces(surface):
    """kernels.primary.geometry_tile dispatches to the sag kernel; its rows equal the NumPy
    trace (trace_primary + bundle_geometry) in a turning frame; misses are masked."""
    from conftest import make_config

    from pmdsim import trace
    from pmdsim.kernels import bundle as kb
    from pmdsim.kernels import primary as kprim
    from pmdsim.scene import Scene

    cfg = make_config(surface={"__replace__": surface},
                      anisotropy={"__replace__": {"frame": "rotational", "centre_mm": [0.0, 0.0, 0.0]}})
    scene = Scene.from_config(cfg)
    assert np.allclose(scene.anisotropy.axis, scene.surface.normal)
    h, w = scene.camera.height, scene.camera.width
    geo = np.full((h * w, kb.G_SIZE), -7.0)
    spec = np.full((h * w, 2), -7.0)
    kprim.geometry_tile(scene.camera.kernel_params(), scene.surface.kernel_params(),
                        scene.anisotropy.kernel_params(), scene.monitor.kernel_params(),
                        0, h, w, geo, spec)
    hits = trace.trace_primary(scene)
    assert 0.1 < hits.valid.mean() < 0.95
    np.testing.assert_allclose(geo, trace.bundle_geometry(scene, hits), rtol=0, atol=1e-10)
    u, v, on = trace.specular_monitor_coords(scene, hits)
    np.testing.assert_allclose(spec[:, 0], u.reshape(-1), rtol=0, atol=1e-10)
    assert np.isfinite(geo).all()


def test_bspline_pair_matches_scipy_map_coordinates():
    from pmdsim.kernels.surface import bspline_eval_pair
    from pmdsim.scene.surfaces import bspline_coefficients

    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(2, 23, 31))
    rows = rng.uniform(0, 22, 200)
    cols = rng.uniform(0, 30, 200)
    rows[:2], cols[:2] = (0.0, 22.0), (30.0, 0.0)  # the grid's corners
    ou, ov = np.empty(200), np.empty(200)
    bspline_eval_pair(bspline_coefficients(a), bspline_coefficients(b), rows, cols, ou, ov)
    np.testing.assert_allclose(ou, ndimage.map_coordinates(a, [rows, cols], order=3, mode="mirror"), atol=1e-12)
    np.testing.assert_allclose(ov, ndimage.map_coordinates(b, [rows, cols], order=3, mode="mirror"), atol=1e-12)


@pytest.mark.parametrize("axis", [None, (0.2, 0.1, 1.0)])
def test_turning_frame_on_a_sphere_is_radial_about_the_axis(axis):
    """Rotational BRDF frame on a curved part: the turning grooves are the curves where the
    surface meets cylinders about the turning axis, so x (tangential, along the groove) is
    perpendicular to the normal and to r (the point's offset from the axis); y (radial) is
    tangent to the surface and points away from the axis. Default axis: the vertex normal."""
    from conftest import make_config

    from pmdsim import trace
    from pmdsim.scene import Scene

    frame = {"frame": "rotational", "centre_mm": [0.0, 0.0, 0.0]}
    if axis is not None:
        frame["axis"] = list(axis)
    cfg = make_config(surface={"__replace__": dict(type="sphere", radius_mm=-250.0,
                                                   aperture=dict(shape="circular", radius_mm=45.0))},
                      anisotropy={"__replace__": frame})
    scene = Scene.from_config(cfg)
    hits = trace.trace_primary(scene)
    v = hits.valid
    p, n, x, y = hits.point[v], hits.normal[v], hits.x_axis[v], hits.y_axis[v]
    a = np.array([0.0, 0.0, 1.0]) if axis is None else np.asarray(axis) / np.linalg.norm(axis)
    r = p - (p @ a)[:, None] * a  # from the axis to the point, perpendicular to it
    far = np.linalg.norm(r, axis=1) > 1.0
    assert far.sum() > 100
    rn = r / np.linalg.norm(r, axis=1, keepdims=True)
    np.testing.assert_allclose(np.sum(x * rn, 1)[far], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(x * n, 1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(y * n, 1), 0.0, atol=1e-12)
    assert np.all(np.sum(y * r, 1)[far] > 0)
    np.testing.assert_allclose(np.cross(x, y), n, atol=1e-12)
