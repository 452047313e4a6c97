"""Monocular reconstruction and the 3-D slope conversion (measure/reconstruct.py).

The "noise-free specular chain": the decoded monitor coordinates of a mirror on a
continuous monitor are the exact monitor hits of the principal rays
(trace.specular_monitor_coords); the reconstruction must return the configured surface.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdsim import trace
from pmdsim.config import parse_config
from pmdsim.measure.reconstruct import reconstruct, slope_deviation_3d
from pmdsim.scene import Scene
from pmdsim.scene.surfaces import surface_from_config

APERTURE = dict(shape="circular", radius_mm=20.0)
FREEFORM = dict(type="xy_polynomial", radius_mm=800.0, norm_radius_mm=20.0, aperture=APERTURE,
                terms=[[2, 0, 2e-3], [0, 2, -1e-3], [1, 1, 1e-3], [3, 0, 5e-4], [1, 2, -4e-4],
                       [4, 0, 2e-4], [2, 2, -3e-4], [0, 4, 1e-4], [5, 1, 1e-4]])


def scene_dict(surface, incidence_deg=20.0, npx=320, focal_px=2600.0):
    t = math.radians(incidence_deg)
    return {
        "camera": {"resolution": [npx, npx], "focal_length_px": focal_px,
                   "position_mm": [0.0, -400 * math.sin(t), 400 * math.cos(t)],
                   "look_at_mm": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]},
        "monitor": {"resolution": [800, 600], "pixel_pitch_mm": 0.5,
                    "centre_mm": [0.0, 250 * math.sin(t), 250 * math.cos(t)],
                    "look_at_mm": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]},
        "surface": surface,
        "brdf": {"model": "mirror"},
    }


def decoded(surface, **kw):
    scene = Scene.from_config(parse_config(scene_dict(surface, **kw)))
    hits = trace.trace_primary(scene)
    u, v, on = trace.specular_monitor_coords(scene, hits)
    return scene, u, v


def prior(surface):
    return surface_from_config(parse_config(scene_dict(surface)).surface)


def errors(rec, truth):
    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    z, gx, gy, _ = truth.sag(x, y)
    m = rec.mask
    e = rec.height_mm[m] - z[m]
    e -= e.mean()
    return (np.sqrt(np.mean(e**2)), np.sqrt(np.mean((rec.slope_x[m] - gx[m]) ** 2)),
            np.sqrt(np.mean((rec.slope_y[m] - gy[m]) ** 2)), m.sum() / np.isfinite(rec.nominal_mm).sum())


CASES = {
    # true surface, nominal prior (deliberately not the truth)
    "sphere": (dict(type="sphere", radius_mm=800.0, aperture=APERTURE),
               dict(type="sphere", radius_mm=790.0, aperture=APERTURE)),
    "conic": (dict(type="conic", radius_mm=-600.0, conic=-2.0, aperture=APERTURE),
              dict(type="sphere", radius_mm=-600.0, aperture=APERTURE)),
    "freeform": (FREEFORM, dict(type="sphere", radius_mm=800.0, aperture=APERTURE)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_noise_free_chain_reconstructs_the_surface(name):
    truth, nominal = CASES[name]
    scene, u, v = decoded(truth)
    rec = reconstruct(u, v, scene.camera, scene.monitor, prior(nominal), spacing_mm=0.5)
    h_rms, sx_rms, sy_rms, covered = errors(rec, scene.surface)
    assert rec.converged and rec.iterations < 10
    assert covered > 0.97
    assert h_rms < 1e-6  # 1 nm
    assert sx_rms < 1e-7 and sy_rms < 1e-7  # 0.1 urad


def test_height_map_of_the_freeform_gives_the_same_answer(tmp_path):
    """The freeform's polynomial part sampled at 0.25 mm into a .npy height map on the same
    base sphere: the reconstruction matches the freeform within the spline's interpolation
    error (measured here against the analytic freeform: < 2 nm over the aperture)."""
    free = prior(FREEFORM)
    step = 0.25
    xs = np.arange(-22.0, 22.0 + step / 2, step)
    x, y = np.meshgrid(xs, xs)
    base = prior(dict(type="sphere", radius_mm=800.0, aperture=APERTURE))
    hmap = free.sag(x, y)[0] - base.sag(x, y)[0]
    np.save(tmp_path / "ff.npy", hmap)
    surf = dict(type="height_map", file=str(tmp_path / "ff.npy"), spacing_mm=(step, step), radius_mm=800.0,
                aperture=APERTURE)
    scene, u, v = decoded(surf)
    # interpolation error of the map itself (bicubic B-spline vs the analytic freeform)
    xg, yg = np.meshgrid(np.arange(-19.5, 19.6, 0.5) + 0.13, np.arange(-19.5, 19.6, 0.5) + 0.07)
    inside = np.hypot(xg, yg) < 19.5
    interp = np.abs(scene.surface.sag(xg, yg)[0] - free.sag(xg, yg)[0])[inside].max()
    assert interp < 2e-6
    rec = reconstruct(u, v, scene.camera, scene.monitor, base, spacing_mm=0.5)
    h_vs_map, sx_map, sy_map, _ = errors(rec, scene.surface)
    h_vs_free, sx_free, sy_free, _ = errors(rec, free)
    assert h_vs_map < 1e-6 and sx_map < 1e-7 and sy_map < 1e-7
    assert h_vs_free < 1e-6 + interp
    assert sx_free < 2e-6 and sy_free < 2e-6  # slope interpolation error of the map


@pytest.mark.parametrize("incidence_deg", [0.0, 25.0, 45.0])
@pytest.mark.parametrize("tilt_axis", ["in_plane", "across_plane"])
def test_tilted_flat_mirror_reports_the_tilt(incidence_deg, tilt_axis):
    """A flat mirror tilted by delta about an axis in the plane of incidence (y-z plane:
    axis y, the ray turns across the plane by 2 delta cos(theta_i)) or across it (axis x,
    in-plane deflection 2 delta): the 3-D conversion and the reconstruction both report
    delta within 1e-3; the old scalar coord / (2 d) is cos(theta_i) short across the plane."""
    delta = 2e-4
    flat = dict(type="conic", aperture=APERTURE)
    if tilt_axis == "in_plane":  # rotation about y
        normal = (math.sin(delta), 0.0, math.cos(delta))
    else:  # rotation about x
        normal = (0.0, -math.sin(delta), math.cos(delta))
    tilted = dict(flat, normal=normal)
    scene0, u0, v0 = decoded(flat, incidence_deg=incidence_deg, npx=160, focal_px=1300.0)
    scene1, u1, v1 = decoded(tilted, incidence_deg=incidence_deg, npx=160, focal_px=1300.0)
    # the pixel that sees the tilt axis (the plate centre) sees the same point in both
    col, row = np.rint(scene0.camera.project(np.zeros(3))).astype(int)
    hits = trace.trace_pixels(scene0, [row], [col])
    s = hits.point[0, 0]
    changed_u = tilt_axis == "in_plane"
    uu = u1[row, col] if changed_u else u0[row, col]
    vv = v0[row, col] if changed_u else v1[row, col]
    got = abs(slope_deviation_3d(s, scene0.camera.position, scene0.monitor, u0[row, col], v0[row, col], uu, vv))
    true_tilt = math.atan(math.tan(delta))  # the normal's tilt angle
    assert abs(got / true_tilt - 1) < 1e-3
    # the old scalar conversion: right in the plane, cos(theta_i) short across it
    m0 = scene0.monitor.pixel_to_world(u0[row, col], v0[row, col])
    m1 = scene0.monitor.pixel_to_world(u1[row, col], v1[row, col])
    scalar = np.linalg.norm(m1 - m0) / (2 * np.linalg.norm(m0 - s))
    expected_ratio = math.cos(math.radians(incidence_deg)) if changed_u else 1.0
    assert abs(scalar / true_tilt - expected_ratio) < 5e-3
    # the reconstruction: the whole plate's slopes in the prior's frame
    rec = reconstruct(u1, v1, scene1.camera, scene1.monitor, prior(flat), spacing_mm=1.0)
    want_x, want_y = -normal[0] / normal[2], -normal[1] / normal[2]
    m = rec.mask
    assert m.sum() > 1000
    got_main = rec.slope_x[m] if changed_u else rec.slope_y[m]
    other = rec.slope_y[m] if changed_u else rec.slope_x[m]
    want = want_x if changed_u else want_y
    np.testing.assert_allclose(got_main, want, rtol=1e-3)
    assert np.abs(other).max() < 1e-3 * delta


def test_run_writes_surface_errors(tmp_path):
    """A run of the turned-sphere example (shrunk): the specular variant, rendered and decoded
    like camera images on a continuous monitor, reconstructs the sphere to < 1 nm; the
    dataset, statistics, summary and figure carry the surface errors."""
    import json
    from pathlib import Path

    from pmdsim.config import load_config
    from pmdsim.run import run_simulation
    from pmdsim.store.schema import load_run

    cfg = load_config(Path(__file__).parents[2] / "examples" / "turned_sphere.toml")
    d = cfg.model_dump()
    d["camera"].update(resolution=(64, 64), pixel_pitch_mm=0.03)
    d["sampling"]["n_rays"] = 8
    d["variants"] = [{"name": "mirror", "brdf": {"model": "mirror"}},
                     {"name": "kinematic", "brdf": d["variants"][1]["brdf"]}]
    d["reconstruct"]["spacing_mm"] = 1.0
    out = tmp_path / "run"
    run_simulation(parse_config(d), out, diagnostics=False)
    stats = json.loads((out / "mirror" / "statistics.json").read_text())["reconstruction"]
    assert stats["converged"] and stats["aperture_fraction"] > 0.9
    assert stats["height_error_nm"]["rms"] < 1.0 and stats["slope_error_x_urad"]["rms_about_zero"] < 0.1
    kin = json.loads((out / "kinematic" / "statistics.json").read_text())["reconstruction"]
    assert kin["height_error_nm"]["rms"] > 10 * stats["height_error_nm"]["rms"]
    ds = load_run(out, variant="kinematic")
    for name in ("height_error_nm", "slope_error_x_urad", "slope_error_y_urad",
                 "reconstructed_height_mm", "reference_height_error_nm"):
        assert ds[name].dims == ("surface_y", "surface_x")
    h = ds["height_error_nm"].values
    assert np.isclose(np.sqrt(np.nanmean((h - np.nanmean(h)) ** 2)), kin["height_error_nm"]["rms"])
    assert (out / "kinematic" / "figures" / "surface_errors.png").is_file()
    assert "height error" in (out / "kinematic" / "summary.txt").read_text()
    # every aperture node is reported or excluded and counted, with the reason, in
    # statistics.json, summary.txt and the dataset (which the figure draws grey)
    ex = kin["excluded_nodes"]
    status = ds["reconstruction_node_status"].values
    assert ex["aperture_nodes"] == int((status >= 0).sum()) == kin["grid_points"] + ex["total"]
    assert ex["total"] == sum(ex[k] for k in kin["excluded_definitions"])
    assert kin["rim_fit_nodes"] == int((status == 1).sum())
    assert np.array_equal(np.isfinite(h), (status == 0) | (status == 1))
    assert f"not reported: {ex['total']} of the aperture's {ex['aperture_nodes']} nodes" in (
        out / "kinematic" / "summary.txt").read_text()


def test_surface_errors_terms_name_a_known_aberration():
    """A reconstruction with a known error (the truth minus 20 nm RMS of Z8 coma and 10 nm of
    Z4 power) reports those Zernike terms and nothing else; RMS/PV/P95 follow the map."""
    from pmdsim.measure.integrate import height_stats, zernike
    from pmdsim.measure.reconstruct import Reconstruction, surface_errors

    truth = prior(dict(type="sphere", radius_mm=800.0, aperture=APERTURE))
    xs = np.arange(-20.0, 20.01, 0.5)
    x, y = np.meshgrid(xs, xs)
    z, gx, gy, _ = truth.sag(x, y)
    m = np.hypot(x, y) <= 20.0
    err = np.zeros_like(x)
    ex = np.zeros_like(x)
    ey = np.zeros_like(x)
    for j, c in ((8, 20e-6), (4, 10e-6)):
        a, b, d = zernike(j, x / 20.0, y / 20.0)
        err += c * a
        ex += c * b / 20.0
        ey += c * d / 20.0
    nan = np.where(m, 1.0, np.nan)
    rec = Reconstruction(xs, xs, m, (z + err) * nan, (gx + ex) * nan, (gy + ey) * nan, z * nan, 1, (0.0,), True)
    e = surface_errors(rec, truth, "piston")
    t = e.stats["terms_nm"]
    assert t["basis"] == "zernike"
    assert abs(t["Z8"] - 20.0) < 1e-6 and abs(t["Z4"] - 10.0) < 1e-6
    assert max(abs(v) for k, v in t.items() if k not in ("basis", "Z8", "Z4")) < 1e-6
    s = height_stats(e.height_nm)
    assert e.stats["height_error_nm"]["rms"] == pytest.approx(s.rms)
    np.testing.assert_allclose(e.slope_x_urad[m], ex[m] * 1e6, atol=1e-9)


def test_reconstruct_prior_config():
    """[reconstruct] prior: a nominal shape other than the configured surface; errors name
    the field."""
    from conftest import base_dict

    from pmdsim.config import ConfigError
    from pmdsim.run.reconstruction import reconstruct_coords

    truth = dict(type="sphere", radius_mm=800.0, aperture=APERTURE)
    d = scene_dict(truth, npx=200, focal_px=1700.0)
    d["reconstruct"] = {"prior": dict(type="sphere", radius_mm=790.0, aperture=APERTURE)}
    cfg = parse_config(d)
    scene = Scene.from_config(cfg)
    hits = trace.trace_primary(scene)
    u, v, _ = trace.specular_monitor_coords(scene, hits)
    rec, err, problem = reconstruct_coords(cfg, scene, u, v, np.isfinite(u))
    assert problem is None and rec.converged
    # the grid's nominal is the prior (R 790), the errors are against the truth (R 800)
    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    np.testing.assert_allclose(rec.nominal_mm[rec.mask], prior(d["reconstruct"]["prior"]).sag(x, y)[0][rec.mask])
    assert err.stats["height_error_nm"]["rms"] < 1.0
    bad = base_dict()
    bad["reconstruct"] = {"prior": {"type": "sphere", "radius_mm": 100.0}}
    with pytest.raises(ConfigError, match=r"reconstruct\.prior\.aperture"):
        parse_config(bad)


def test_bisector_slope_kernels_match_numpy():
    """The compiled per-node slopes (kernels.reconstruct) against the NumPy reference
    slopes_in_frame(bisector_normals(...)), with a generic and with a planar monitor."""
    from pmdsim.kernels.reconstruct import bisector_slopes, bisector_slopes_planar
    from pmdsim.measure.reconstruct import planar_monitor, bisector_normals, slopes_in_frame

    scene, u, v = decoded(CASES["freeform"][0], npx=80, focal_px=650.0)
    rng = np.random.default_rng(3)
    n = 500
    points = rng.uniform(-20, 20, (n, 3)) * [1, 1, 0.05]
    mu = rng.uniform(0, 800, n)
    mv = rng.uniform(0, 600, n)
    q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    rot = np.ascontiguousarray(q * np.sign(np.linalg.det(q)))
    cam = np.asarray(scene.camera.position, np.float64)
    m3 = scene.monitor.pixel_to_world(mu, mv)
    want = slopes_in_frame(bisector_normals(points, cam, m3), rot)
    a, b = np.empty(n), np.empty(n)
    bisector_slopes(points, cam, np.ascontiguousarray(m3), rot, a, b)
    np.testing.assert_allclose(a, want[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b, want[1], rtol=1e-12, atol=1e-15)
    planar = planar_monitor(scene.monitor)
    assert planar is not None and planar_monitor(object()) is None
    bisector_slopes_planar(points, cam, mu, mv, *planar, rot, a, b)
    np.testing.assert_allclose(a, want[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b, want[1], rtol=1e-12, atol=1e-15)


def test_iterative_solves_give_the_exact_solves_answer():
    """The height-normal loop warm-starts an iterative Southwell solver and asks it for
    three digits of each correction; it ends where exact (sparse LU) solves end, well
    within tol_mm, and both stop on the geometric tail estimate, not at max_iter."""
    truth, nominal = CASES["freeform"]
    scene, u, v = decoded(truth)
    got = reconstruct(u, v, scene.camera, scene.monitor, prior(nominal), spacing_mm=0.5, solver="pcg")
    exact = reconstruct(u, v, scene.camera, scene.monitor, prior(nominal), spacing_mm=0.5, solver="direct")
    assert np.array_equal(got.mask, exact.mask) and not got.mask.all()  # circular: a masked solve
    assert np.nanmax(np.abs(got.height_mm - exact.height_mm)) < 1e-9
    assert got.converged and exact.converged and got.iterations < 6


def test_a_start_next_to_the_fixed_point_ends_there_sooner():
    """``start``: from a reconstruction's own height, the coordinates moved by 3e-3 monitor
    px (as the run's numerical-error reconstruction moves them) end within 2 tol_mm of the
    reconstruction started from the nominal shape, in fewer iterations; a start of the
    wrong shape is refused, naming the field."""
    truth, nominal = CASES["freeform"]
    scene, u, v = decoded(truth)
    args = (scene.camera, scene.monitor, prior(nominal))
    first = reconstruct(u, v, *args, spacing_mm=0.5)
    du = 3e-3 * np.cos(0.01 * np.arange(u.size)).reshape(u.shape)  # uneven, x only
    cold = reconstruct(u + du, v, *args, spacing_mm=0.5)
    warm = reconstruct(u + du, v, *args, spacing_mm=0.5, start=first.height_mm)
    assert np.array_equal(warm.mask, cold.mask)
    assert np.nanmax(np.abs(warm.height_mm - cold.height_mm)) < 2e-8
    assert np.nanmax(np.abs(cold.height_mm - first.height_mm)) > 1e-7  # the move shows
    assert warm.converged and warm.iterations < cold.iterations
    with pytest.raises(ValueError, match="start"):
        reconstruct(u, v, *args, spacing_mm=0.5, start=first.height_mm[:-1])
    # a repetition without its own slope tolerance: the same height and slopes, NaN there
    bare = reconstruct(u + du, v, *args, spacing_mm=0.5, start=first.height_mm,
                       slope_tolerance=False)
    for a in ("height_mm", "slope_x", "slope_y"):
        assert np.array_equal(getattr(bare, a), getattr(warm, a), equal_nan=True)
    assert np.isnan(bare.slope_tolerance) and warm.slope_tolerance > 0
    assert bare.tolerance_mm == warm.tolerance_mm


def test_settled_rule():
    """Stop when the last change is below tol, or when the contracting iteration's geometric
    tail (last * q / (1 - q), q the ratio of the last two changes) is."""
    from pmdsim.measure.reconstruct import _settled

    assert _settled([1e-9], 1e-8)
    assert not _settled([1e-3], 1e-8)
    assert _settled([1e-3, 1e-6], 1e-8)  # tail 1e-6 * 1e-3 / (1 - 1e-3) = 1e-9
    assert not _settled([1e-3, 1e-4], 1e-8)  # tail 1.1e-5
    assert not _settled([1e-6, 9e-7], 1e-8)  # q = 0.9: too slow to trust the estimate
    assert not _settled([1e-8, 2e-8], 1e-8)  # growing


def test_nearest_valid_pixel_matches_the_distance_transform():
    """Few invalid pixels (k-d tree of the valid edge) and many (distance transform): the
    nearest valid pixel's distance equals SciPy's exact Euclidean distance transform."""
    from scipy import ndimage

    from pmdsim.measure.interpolate import _nearest_valid

    rng = np.random.default_rng(5)
    for frac in (0.01, 0.3):
        valid = ndimage.binary_opening(rng.random((90, 120)) > frac * 3, iterations=1) | (rng.random((90, 120)) > frac)
        valid[:3, :] = False
        bad = ~valid
        rows, cols = _nearest_valid(valid)
        assert valid[rows, cols].all()
        got = np.hypot(rows - np.nonzero(bad)[0], cols - np.nonzero(bad)[1])
        want = ndimage.distance_transform_edt(bad)[bad]
        np.testing.assert_allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("margin", [0, 2])
def test_node_support_kernel_matches_numpy(margin):
    """kernels.reconstruct.node_support against the plain rule: the spline serves a node
    whose 4 x 4 support grown by ``margin`` (floor - 1 - margin .. floor + 2 + margin) lies
    inside the image and is all valid;
    else the node's own pixel (the nearest, round half up) decides: valid -> the rim fit,
    invalid -> pixel_invalid, outside the image (or NaN, inf) -> outside; edge coordinates
    included (-0.5 is pixel 0, w - 0.5 is outside)."""
    from pmdsim.kernels import reconstruct as kr

    rng = np.random.default_rng(11)
    valid = rng.random((40, 50)) > (0.1 if margin == 0 else 0.01)
    cols = np.concatenate([rng.uniform(-2, 52, 4000),
                           [np.nan, np.inf, -np.inf, 0.0, 48.999, 49.0, -0.5, 49.5, -0.5000001, 1.0]])
    rows = np.concatenate([rng.uniform(-2, 42, 4000), [1.0, 1.0, 1.0, 0.0, 38.5, 3.0, 2.0, 2.0, 2.0, 1.0]])
    want = np.empty(len(cols), np.int8)
    for k, (c, r) in enumerate(zip(cols, rows)):
        if not (np.isfinite(c) and np.isfinite(r) and -0.5 <= c < 49.5 and -0.5 <= r < 39.5):
            want[k] = kr.SUPPORT_OUTSIDE
            continue
        cn, rn = int(np.floor(c + 0.5)), int(np.floor(r + 0.5))
        c0, r0 = int(np.floor(c)) - 1 - margin, int(np.floor(r)) - 1 - margin
        n = 4 + 2 * margin
        if not valid[rn, cn]:
            want[k] = kr.SUPPORT_PIXEL_INVALID
        elif c0 >= 0 and r0 >= 0 and c0 + n <= 50 and r0 + n <= 40 and valid[r0:r0 + n, c0:c0 + n].all():
            want[k] = kr.SUPPORT_SPLINE
        else:
            want[k] = kr.SUPPORT_RIM
    got = np.empty(len(cols), np.int8)
    kr.node_support(valid, cols, rows, margin, got)
    np.testing.assert_array_equal(got, want)
    assert {kr.SUPPORT_SPLINE, kr.SUPPORT_RIM, kr.SUPPORT_PIXEL_INVALID, kr.SUPPORT_OUTSIDE} <= set(got)


def test_run_states_the_reconstructions_numerical_error(tmp_path):
    """A run on the Gauss rule states the numerical error of every surface statistic (the
    reconstruction repeated with the coordinates moved by their numerical error): moving
    them by minus that error instead (a perturbation the statement covers, the
    reconstruction being linear in small changes) changes RMS, P95 and PV of the height
    and slope errors by at most the stated errors; the summary and the figure print them."""
    import json
    from pathlib import Path

    from pmdsim.config import load_config
    from pmdsim.render import Simulation
    from pmdsim.run import run_simulation
    from pmdsim.store.schema import load_run
    from pmdsim.run.reconstruction import reconstruct_coords

    cfg = load_config(Path(__file__).parents[2] / "examples" / "turned_sphere.toml")
    d = cfg.model_dump()
    d["camera"].update(resolution=(64, 48), pixel_pitch_mm=0.03)
    d["sampling"].update(n_rays=16, mode="rule")  # the pilot starts at 16 nodes; the example's target picks the order
    d["variants"] = [{"name": "kinematic", "brdf": d["variants"][1]["brdf"]}]
    d["reconstruct"]["spacing_mm"] = 1.0
    out = tmp_path / "run"
    cfg = parse_config(d)
    run_simulation(cfg, out, diagnostics=False)
    stats = json.loads((out / "kinematic" / "statistics.json").read_text())["reconstruction"]
    ds = load_run(out, variant="kinematic")
    dirs = list(ds["direction"].values)
    coord = {k: np.where(ds["valid"].values[dirs.index(k)],
                         ds["monitor_coord_px"].values[dirs.index(k)], np.nan) for k in "xy"}
    err = {k: np.nan_to_num(ds["coord_deviation_px_error"].values[dirs.index(k)]) for k in "xy"}
    assert max(err["x"].max(), err["y"].max()) > 0
    valid = np.isfinite(coord["x"]) & np.isfinite(coord["y"])
    vcfg = parse_config(json.loads(ds.attrs["config_json"]))
    scene = Simulation.from_config(vcfg).scene
    _, moved, _ = reconstruct_coords(vcfg, scene, coord["x"] - err["x"], coord["y"] - err["y"],
                                     valid)
    # the baseline: the same stored (float32) coordinates unmoved, so that the comparison
    # is of the move alone (the float32 rounding of the stored coordinates, up to 1e-4 px,
    # can exceed a Gauss rule's stated error of a few 1e-5 px)
    _, base, _ = reconstruct_coords(vcfg, scene, coord["x"], coord["y"], valid)
    for key, attr in (("height_error_nm", "height_nm"), ("slope_error_x_urad", "slope_x_urad"),
                      ("slope_error_y_urad", "slope_y_urad")):
        st = stats[key]

        def stats_of(r):
            a = getattr(r, attr)
            a = a[np.isfinite(a)]
            dev = a - a.mean()
            return {"rms": np.sqrt(np.mean(dev * dev)), "p95": np.percentile(np.abs(dev), 95),
                    "pv": np.ptp(a)}, a

        got, a = stats_of(moved)
        ref, _ = stats_of(base)
        for stat, value in got.items():
            assert st[stat + "_err"] >= 0
            assert abs(value - ref[stat]) <= 1.05 * st[stat + "_err"] + 1e-9 * abs(st[stat]), (
                key, stat, value, ref[stat], st[stat + "_err"])
        if key != "height_error_nm":  # the slopes' RMS about zero, as the figure shows
            assert st["rms_about_zero_err"] >= 0
            z = np.sqrt(np.mean(a * a))
            assert abs(z - st["rms_about_zero"]) <= 1.05 * st["rms_about_zero_err"] + 1e-9 * z
    assert "± " in (out / "kinematic" / "summary.txt").read_text().split("height error")[1]
    # the areal parameters: Sq is the RMS with its error; Sq, Sa, Sz from the same node
    # errors cover the same move. Ssk, Sku, Sdq and the PSDs take their errors from the
    # error's own signed pattern (pmdsim.render.pilot.Pilot.signed_field), which the
    # envelope's move is not: tests/render/test_pilot.py checks them against a rule 4 x
    # finer (on Fig. 3); here they are stated, > 0
    ar = stats["areal"]
    for key, attr, var in (("height_error_nm", "height_nm", "height_error"),
                           ("slope_error_x_urad", "slope_x_urad", "slope_error_x"),
                           ("slope_error_y_urad", "slope_y_urad", "slope_error_y")):
        st = ar[key]
        assert st["sq"] == pytest.approx(stats[key]["rms"], rel=1e-9)
        assert st["sq_err"] == pytest.approx(stats[key]["rms_err"], rel=1e-9)
        assert st["n"] == stats[key]["n"]
        a, b0 = (getattr(r, attr) for r in (moved, base))
        a, b0 = a[np.isfinite(a)], b0[np.isfinite(b0)]
        for k, f in (("sa", lambda x: np.mean(np.abs(x - x.mean()))), ("sz", np.ptp)):
            assert abs(f(a) - f(b0)) <= 1.05 * st[k + "_err"] + 1e-9 * abs(st[k]), (key, k)
        assert all(st[k + "_err"] > 0 for k in ("ssk", "sku", "sdq"))
        assert all(e > 0 for e in st["psd"]["band_rms_err"].values())
        assert np.all(ds[f"{var}_psd_err"].values > 0)
        assert ds[f"{var}_psd_2d"].dims == ("psd_fy", "psd_fx")
        assert ds[f"{var}_psd"].attrs["units"].endswith("^2 mm")
    assert "reference_height_error_psd" in ds and "sq" in ar["reference_height_error_nm"]
    assert (out / "kinematic" / "figures" / "surface_psd.png").is_file()
