"""Spatially varying BRDF parameters (``[brdf.variation]``) against uniform-BRDF renders.

Each varied render is compared per pixel with renders of the uniform BRDF whose parameters
are computed independently: the pixel's surface point from the NumPy tracer
(:func:`pmdsim.trace.trace_pixels`), its radius or local (x, y) by hand, the table or map
value by hand (linear formulas), never through :mod:`pmdsim.scene.brdf_variation`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import base_dict, merge
from pmdsim.brdf import Beckmann, Ward
from pmdsim.config import ConfigError, parse_config
from pmdsim.render import Simulation
from pmdsim.scene import Scene
from pmdsim.trace import trace_pixels

WIDTHS = (20.0,)
TURN_CENTRE = (-60.0, 0.0, 0.0)  # the turning axis: through here along the plate normal (+z)


def _cfg(model="ward", estimator="paper", variation=None, frame="rotational", mode="stratified"):
    brdf = ({"model": "ward", "alpha_x": 0.02, "alpha_y": 0.004, "rho_s": 0.4}
            if model == "ward" else
            {"model": "beckmann", "alpha_u": 0.02, "alpha_v": 0.004, "rho_s": 0.4})
    if variation is not None:
        brdf["variation"] = variation
    aniso = ({"frame": "rotational", "centre_mm": list(TURN_CENTRE)} if frame == "rotational"
             else {"frame": "fixed", "x_direction": [1.0, 0.0, 0.0]})
    return parse_config(merge(base_dict(), {
        "brdf": {"__replace__": brdf}, "anisotropy": {"__replace__": aniso},
        "sampling": {"n_rays": 48, "theta_max_deg": 2.0, "estimator": estimator, "mode": mode},
    }))


def _sim(scene):
    return Simulation(scene, tile_rows=8, scheduler="threads", num_workers=2)


def _uniform(scene, ax, ay, rho=None):
    """The scene with the uniform BRDF of the given parameters (no variation)."""
    b = scene.brdf
    rho = b.rho_s if rho is None else rho
    brdf = (dataclasses.replace(b, alpha_u=ax, alpha_v=ay, rho_s=rho) if isinstance(b, Beckmann)
            else dataclasses.replace(b, alpha_x=ax, alpha_y=ay, rho_s=rho))
    return scene.replace(brdf=brdf, brdf_variation=None)


def _modulation(res):
    """(H, W) fringe modulation |sum f exp(i k u)| / sum f of the x fringes (float64)."""
    return np.abs(res.sums[0, 0]) / res.f_total


# --- (1) a constant variation is the uniform BRDF -----------------------------------------
@pytest.mark.parametrize("model, estimator, mode", [
    ("ward", "paper", "stratified"),
    ("beckmann", "weighted_mean", "random"),
    ("ward", "radiometric", "stratified"),
    ("beckmann", "radiometric", "random"),
])
def test_constant_variation_is_the_uniform_brdf(model, estimator, mode):
    const = {"radius_mm": [0.0, 200.0], "alpha_tangential": [0.02, 0.02],
             "alpha_radial": [0.004, 0.004], "rho_s_scale": [1.0, 1.0]}
    scene = Scene.from_config(_cfg(model, estimator, const, mode=mode))
    assert scene.brdf_variation is not None
    var = _sim(scene).render_fringes(WIDTHS, shifts=4)
    uni = _sim(scene.replace(brdf_variation=None)).render_fringes(WIDTHS, shifts=4)
    assert np.isfinite(uni.images).sum() > 100
    np.testing.assert_array_equal(var.images, uni.images)
    np.testing.assert_array_equal(var.f_total, uni.f_total)
    np.testing.assert_array_equal(var.sums, uni.sums)


def test_constant_variation_with_camera_subpixels_is_the_uniform_brdf():
    """The camera-optics path (2 x 2 sub-pixel vision rays per pixel, distortion): every
    vision ray's own geometry row gives its surface point."""
    const = {"radius_mm": [0.0, 200.0], "alpha_radial": [0.004, 0.004],
             "rho_s_scale": [1.0, 1.0]}
    cfg = _cfg("beckmann", "paper", const)
    cfg = cfg.model_copy(update={"camera": cfg.camera.model_copy(update={"subpixels": 2,
                                                                         "k1": 0.01})})
    scene = Scene.from_config(cfg)
    assert not scene.camera.is_simple_pinhole and scene.camera.rays_per_pixel == 4
    var = _sim(scene).render_fringes(WIDTHS, shifts=4)
    uni = _sim(scene.replace(brdf_variation=None)).render_fringes(WIDTHS, shifts=4)
    assert np.isfinite(uni.images).sum() > 100
    np.testing.assert_array_equal(var.images, uni.images)


def test_constant_map_file_is_the_uniform_brdf(tmp_path):
    """The map path (.npz, fixed frame) with constant grids."""
    f = tmp_path / "const.npz"
    np.savez(f, alpha_tangential=np.full((5, 7), 0.02), rho_s_scale=np.ones((5, 7)))
    cfg = _cfg("ward", "paper", {"file": str(f), "spacing_mm": [20.0, 20.0]}, frame="fixed")
    scene = Scene.from_config(cfg)
    var = _sim(scene).render_fringes(WIDTHS, shifts=4)
    uni = _sim(scene.replace(brdf_variation=None)).render_fringes(WIDTHS, shifts=4)
    np.testing.assert_array_equal(var.images, uni.images)


# --- (2) a radius-dependent alpha on a flat turned plate -----------------------------------
def _two_pixels(scene, res):
    """Two pixels, far apart in radius, whose vision rays hit the plate and whose bundles
    light up (finite, non-zero modulation)."""
    mod = _modulation(res)
    ok = np.isfinite(mod) & (mod > 0.05)
    rows, cols = np.nonzero(ok)
    hits = trace_pixels(scene, rows, cols)
    pt = hits.point[0]
    r = np.hypot(pt[:, 0] - TURN_CENTRE[0], pt[:, 1] - TURN_CENTRE[1])
    k1, k2 = int(np.argmin(r)), int(np.argmax(r))
    return [(rows[k], cols[k], r[k]) for k in (k1, k2)]


@pytest.mark.parametrize("model, estimator", [("ward", "paper"), ("beckmann", "radiometric")])
def test_radius_dependent_alpha_matches_uniform_renders(model, estimator):
    r_tab = [0.0, 150.0]
    at = [0.005, 0.04]  # tangential alpha grows eightfold over the table
    ar = [0.002, 0.008]
    var_cfg = {"radius_mm": r_tab, "alpha_tangential": at, "alpha_radial": ar}
    scene = Scene.from_config(_cfg(model, estimator, var_cfg))
    var = _sim(scene).render_fringes(WIDTHS, directions=("x",), shifts=4)
    mod = _modulation(var)
    pix = _two_pixels(scene, var)
    assert pix[1][2] - pix[0][2] > 30.0  # the two pixels lie at clearly different radii
    uniform_mods = []
    for row, col, r in pix:
        ax = at[0] + (at[1] - at[0]) * r / r_tab[1]
        ay = ar[0] + (ar[1] - ar[0]) * r / r_tab[1]
        uni = _sim(_uniform(scene, ax, ay)).render_fringes(WIDTHS, directions=("x",), shifts=4)
        m_uni = _modulation(uni)
        uniform_mods.append(m_uni)
        assert mod[row, col] == pytest.approx(m_uni[row, col], rel=1e-9, abs=1e-12)
    # the check can fail: each pixel's modulation differs from the other radius's alpha
    (r1, c1, _), (r2, c2, _) = pix
    assert abs(uniform_mods[1][r1, c1] / mod[r1, c1] - 1) > 0.02
    assert abs(uniform_mods[0][r2, c2] / mod[r2, c2] - 1) > 0.02


# --- (3) a rho_s scale map multiplies the camera values ------------------------------------
def test_rho_scale_map_multiplies_paper_camera_values(tmp_path):
    """A linear scale map s(x, y) = 0.5 + 0.004 x + 0.002 y (bilinear interpolation of a
    linear function is exact) from a .csv: paper-estimator values are the uniform ones times
    s at each pixel's surface point; weighted_mean values do not change."""
    dx = dy = 5.0
    xs = np.arange(-60.0, 60.0 + dx / 2, dx)
    ys = np.arange(-50.0, 50.0 + dy / 2, dy)
    grid = 0.5 + 0.004 * xs[None, :] + 0.002 * ys[:, None]
    f = tmp_path / "rho.csv"
    np.savetxt(f, grid, delimiter=",")
    var_cfg = {"file": str(f), "quantity": "rho_s_scale", "spacing_mm": [dx, dy],
               "origin_mm": [-60.0, -50.0]}
    scene = Scene.from_config(_cfg("ward", "paper", var_cfg, frame="fixed"))
    var = _sim(scene).render_fringes(WIDTHS, shifts=4)
    uni = _sim(scene.replace(brdf_variation=None)).render_fringes(WIDTHS, shifts=4)
    h, w = var.f_total.shape
    rows, cols = np.mgrid[0:h, 0:w]
    pt = trace_pixels(scene, rows.ravel(), cols.ravel()).point[0].reshape(h, w, 3)
    s = 0.5 + 0.004 * pt[..., 0] + 0.002 * pt[..., 1]  # plate: local (x, y) = world (x, y)
    ok = np.isfinite(uni.f_total)
    assert ok.sum() > 100 and np.ptp(s[ok]) > 0.3
    np.testing.assert_allclose(var.f_total[ok], uni.f_total[ok] * s[ok], rtol=1e-12, atol=0)
    np.testing.assert_allclose(var.sums[:, :, ok], uni.sums[:, :, ok] * s[ok], rtol=1e-12,
                               atol=1e-15)
    np.testing.assert_allclose(var.images[..., ok], uni.images[..., ok] * s[ok], rtol=1e-6,
                               atol=1e-6)
    np.testing.assert_array_equal(np.isfinite(var.images), np.isfinite(uni.images))
    wm = _sim(scene.replace(estimator="weighted_mean"))
    wu = _sim(scene.replace(brdf_variation=None, estimator="weighted_mean"))
    a, b = wm.render_fringes(WIDTHS, shifts=4), wu.render_fringes(WIDTHS, shifts=4)
    np.testing.assert_allclose(a.sums[:, :, ok], b.sums[:, :, ok], rtol=1e-12, atol=1e-14)


# --- (4) bad input names the field ---------------------------------------------------------
@pytest.mark.parametrize("variation, field", [
    ({"radius_mm": [0.0, 20.0, 10.0], "alpha_tangential": [0.01, 0.02, 0.03]}, "radius_mm"),
    ({"radius_mm": [0.0, 20.0], "alpha_radial": [0.01, 0.02, 0.03]}, "alpha_radial"),
    ({"radius_mm": [0.0, 20.0]}, "radius_mm"),
    ({"radius_mm": [0.0, 20.0], "rho_s_scale": [1.0, 1.0], "file": "m.npz",
      "spacing_mm": [1.0, 1.0]}, "radius_mm"),
    ({"file": "m.npy", "spacing_mm": [1.0, 1.0]}, "quantity"),
    ({"file": "m.npz"}, "spacing_mm"),
    ({"radius_mm": [0.0, 20.0], "alpha_tangential": [0.01, 3.0]}, "alpha_tangential"),
])
def test_bad_variation_names_the_field(variation, field):
    with pytest.raises(ConfigError) as err:
        _cfg("ward", "paper", variation)
    assert "brdf.variation" in str(err.value) and field in str(err.value)


@pytest.mark.parametrize("brdf", [
    {"model": "mirror"},
    {"model": "slope_density", "density": "gaussian", "alpha_x": 0.01, "alpha_y": 0.01},
])
def test_variation_of_an_unsupported_model_names_the_field(brdf):
    data = merge(base_dict(), {"brdf": {"__replace__": dict(
        brdf, variation={"radius_mm": [0.0, 1.0], "rho_s_scale": [1.0, 1.0]})}})
    with pytest.raises(ConfigError, match=r"brdf\.variation.*'ward' and 'beckmann'"):
        parse_config(data)


def test_missing_or_bad_map_file_names_the_field(tmp_path):
    cfg = _cfg("ward", "paper", {"file": str(tmp_path / "nope.npz"), "spacing_mm": [1.0, 1.0]})
    with pytest.raises(ConfigError, match=r"brdf\.variation\.file: .*not found"):
        Scene.from_config(cfg)
    bad = tmp_path / "bad.npz"
    np.savez(bad, something_else=np.ones((3, 3)))
    cfg = _cfg("ward", "paper", {"file": str(bad), "spacing_mm": [1.0, 1.0]})
    with pytest.raises(ConfigError, match=r"brdf\.variation\.file: .*none of the arrays"):
        Scene.from_config(cfg)
    neg = tmp_path / "neg.npy"
    np.save(neg, -np.ones((3, 3)))
    cfg = _cfg("ward", "paper", {"file": str(neg), "quantity": "alpha_radial",
                                 "spacing_mm": [1.0, 1.0]})
    with pytest.raises(ConfigError, match=r"brdf\.variation\.file: .*alpha_radial"):
        Scene.from_config(cfg)


def test_load_config_resolves_the_map_file_next_to_the_config(tmp_path):
    from pmdsim.config import load_config

    np.save(tmp_path / "alpha.npy", np.full((4, 4), 0.01))
    (tmp_path / "run.toml").write_text(
        '[camera]\nresolution = [8, 6]\nfocal_length_px = 20.0\nposition_mm = [0, -100, 200]\n'
        'look_at_mm = [0, 0, 0]\n[monitor]\nresolution = [64, 48]\npixel_pitch_mm = 1.0\n'
        'centre_mm = [0, 100, 200]\nlook_at_mm = [0, 0, 0]\n[surface]\nsize_mm = [50, 50]\n'
        '[brdf]\nmodel = "beckmann"\nalpha_u = 0.02\nalpha_v = 0.004\n'
        '[brdf.variation]\nfile = "alpha.npy"\nquantity = "alpha_radial"\nspacing_mm = [10, 10]\n')
    cfg = load_config(tmp_path / "run.toml")
    assert cfg.brdf.variation.file == str((tmp_path / "alpha.npy").resolve())
    assert Scene.from_config(cfg).brdf_variation.values["alpha_radial"].shape == (4, 4)


@pytest.mark.parametrize("estimator", ["paper", "radiometric"])
def test_transport_uses_the_pixels_own_parameters(estimator):
    """The rays of one pixel (weights; radiometric: also directions drawn from its own
    lobe) equal those of the uniform BRDF with that pixel's parameters."""
    at, ar, sc = [0.005, 0.04], [0.002, 0.008], [0.5, 1.0]
    scene = Scene.from_config(_cfg("ward", estimator, {
        "radius_mm": [0.0, 150.0], "alpha_tangential": at, "alpha_radial": ar,
        "rho_s_scale": sc}))
    row, col = 20, 30
    r = float(np.hypot(*(trace_pixels(scene, [row], [col]).point[0, 0, :2]
                         - np.array(TURN_CENTRE[:2]))))
    lin = lambda t: t[0] + (t[1] - t[0]) * r / 150.0  # noqa: E731
    uni = _uniform(scene, lin(at), lin(ar), rho=0.4 * lin(sc))
    a = _sim(scene).transport([row], [col])
    b = _sim(uni).transport([row], [col])
    assert np.count_nonzero(b[2]) > 10
    np.testing.assert_allclose(a[2], b[2], rtol=1e-12, atol=0)
    np.testing.assert_allclose(a[3], b[3], rtol=0, atol=1e-12)


def test_lobe_energy_diagnostic_uses_the_pixels_own_lobe():
    """The cone-energy diagnostic of a varied scene equals, pixel by pixel, the one of the
    uniform BRDF with that pixel's alphas (hit point from the NumPy tracer, alpha by hand)."""
    from pmdsim.studies.diagnostics import PixelGrid, energy_fraction, incidence, lobe_energy

    at, ar = [0.005, 0.04], [0.002, 0.008]
    scene = Scene.from_config(_cfg("ward", "paper", {
        "radius_mm": [0.0, 150.0], "alpha_tangential": at, "alpha_radial": ar}))
    grid = PixelGrid.spread((32, 40), 6, 6)
    got = energy_fraction(scene, grid, n_samples=2048)
    rows, cols = grid.pixel_rows, grid.pixel_cols
    pts = trace_pixels(scene, rows, cols).point[0]
    _, i_local = incidence(scene, rows, cols)
    checked = 0
    for k in range(rows.size):
        if not np.isfinite(pts[k]).all():
            continue
        r = np.hypot(pts[k, 0] - TURN_CENTRE[0], pts[k, 1] - TURN_CENTRE[1])
        brdf = Ward(at[0] + (at[1] - at[0]) * r / 150, ar[0] + (ar[1] - ar[0]) * r / 150, 0.4)
        frac, _, albedo = lobe_energy(brdf, i_local[k:k + 1], scene.sampling.theta_max, 2048)
        assert got.fraction.ravel()[k] == pytest.approx(frac[0, 0], rel=1e-12)
        assert got.albedo.ravel()[k] == pytest.approx(albedo[0], rel=1e-12)
        checked += 1
    assert checked >= 4
    uni = energy_fraction(scene.replace(brdf_variation=None), grid, n_samples=2048)
    ok = np.isfinite(uni.fraction)
    assert np.nanmax(np.abs(uni.fraction[ok] - got.fraction[ok])) > 0.05  # it matters


def test_fit_refuses_varying_alphas():
    from pmdsim.studies import fit

    cfg = _cfg("ward", "paper", {"radius_mm": [0.0, 100.0], "alpha_radial": [0.004, 0.008]})
    with pytest.raises(ConfigError, match=r"fit: brdf\.variation"):
        fit._with_alphas(cfg, 0.01, 0.01)
    cfg = _cfg("ward", "paper", {"radius_mm": [0.0, 100.0], "rho_s_scale": [1.0, 0.5]})
    assert fit._with_alphas(cfg, 0.01, 0.02).brdf.alpha_y == 0.02


def test_rho_scale_over_the_radius_on_a_sphere():
    """A concave sphere turned about its vertex axis (rotational frame, default axis = the
    vertex normal): rho_s_scale(r) linear in the radius r = hypot(x, y) of each pixel's hit
    point (NumPy tracer) multiplies the paper values."""
    data = merge(base_dict(), {
        "surface": {"__replace__": {"type": "sphere", "radius_mm": 800.0,
                                    "aperture": {"shape": "circular", "radius_mm": 45.0}}},
        "anisotropy": {"__replace__": {"frame": "rotational"}},
        "brdf": {"__replace__": {"model": "ward", "alpha_x": 0.02, "alpha_y": 0.004,
                                 "variation": {"radius_mm": [0.0, 50.0],
                                               "rho_s_scale": [0.3, 1.0]}}},
    })
    scene = Scene.from_config(parse_config(data))
    var = _sim(scene).render_fringes(WIDTHS, shifts=4)
    uni = _sim(scene.replace(brdf_variation=None)).render_fringes(WIDTHS, shifts=4)
    h, w = var.f_total.shape
    rows, cols = np.mgrid[0:h, 0:w]
    pt = trace_pixels(scene, rows.ravel(), cols.ravel()).point[0].reshape(h, w, 3)
    s = 0.3 + 0.7 * np.minimum(np.hypot(pt[..., 0], pt[..., 1]), 50.0) / 50.0
    ok = np.isfinite(uni.f_total)
    assert ok.sum() > 100 and np.ptp(s[ok]) > 0.3
    np.testing.assert_allclose(var.f_total[ok], uni.f_total[ok] * s[ok], rtol=1e-12, atol=0)
