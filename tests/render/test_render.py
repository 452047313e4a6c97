"""End-to-end physics of ``pmdsim.render.Simulation`` on small scenes.

Specular limit, the complex-sum identity of the fringe renderer, the estimators, contrast
loss and phase bias of scattering lobes, reproducibility (seeds, tiles, Dask schedulers),
and rays that miss the plate or the monitor. References come from ``tests/naive.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

import naive
from conftest import base_dict, make_config, merge
from pmdsim.config import parse_config
from pmdsim.patterns import Dot, fringe_image, fringe_value, phase_shifts
from pmdsim.render import Simulation

MIRROR = {"__replace__": {"model": "mirror"}}
TINY_WARD = {"__replace__": {"model": "ward", "alpha_x": 1e-5, "alpha_y": 1e-5}}


def sim_of(cfg):
    return Simulation.from_config(cfg)


def assert_images_close(got, ref, what="", rtol=1e-5):
    """float32 images vs float64 references: same NaN pattern, |err| <= rtol * max |ref|."""
    got = np.asarray(got, np.float64)
    assert np.array_equal(np.isnan(got), np.isnan(ref)), f"{what}: NaN patterns differ"
    scale = np.nanmax(np.abs(ref))
    err = np.nanmax(np.abs(got - ref))
    assert err <= rtol * scale, f"{what}: max |err| {err:.3g} > {rtol} x {scale:.3g}"


def fringe_level(coord, width, delta):
    return 0.5 + 0.5 * np.cos(2 * np.pi * coord / width + delta)


# --------------------------------------------------------------------------- specular limit


def specular_expectations(cfg):
    """Naive P per pixel: (prim, nearest (iu, iv), exact (u, v)); asserts no P lies within
    1e-7 px of a monitor pixel boundary (where 'nearest' is decided by the last bit)."""
    prim = naive.primary(cfg)
    u, v = prim["u"], prim["v"]
    on = prim["on_monitor"]
    for c in (u[on], v[on]):
        assert np.all(np.abs((c - 0.5) - np.round(c - 0.5)) > 1e-7)
    assert on.sum() > 200 and (prim["valid"] & ~on).any()
    iu = naive.nearest(np.where(on, u, 0))
    iv = naive.nearest(np.where(on, v, 0))
    return prim, iu, iv


@pytest.mark.parametrize("brdf, estimator", [(MIRROR, "paper"), (MIRROR, "weighted_mean"),
                                             (TINY_WARD, "weighted_mean")])
def test_specular_limit_images_equal_the_monitor_at_the_mirror_point(brdf, estimator):
    """Each valid pixel shows the monitor pixel that the exact mirror reflection of its vision
    ray lands in; black (0) where that reflection misses the monitor; NaN off the plate."""
    cfg = make_config(brdf=brdf, sampling={"estimator": estimator},
                      monitor={"black_level": 0.05, "white_level": 0.8, "gamma": 2.2})
    prim, iu, iv = specular_expectations(cfg)
    levels = np.random.default_rng(3).random((2,) + (120, 200))
    got = sim_of(cfg).render_images(levels)
    for q in range(2):
        lum = naive.luminance(cfg.monitor, levels[q][iv, iu])
        ref = np.where(prim["on_monitor"], lum, 0.0)
        ref = np.where(prim["valid"], ref, np.nan)
        assert_images_close(got[q], ref, f"image {q}")


@pytest.mark.parametrize("pixel_model", ["nearest", "continuous"])
@pytest.mark.parametrize("brdf, estimator", [(MIRROR, "paper"), (TINY_WARD, "weighted_mean")])
def test_specular_limit_fringes(pixel_model, brdf, estimator):
    """Mirror fringes: the pattern at the nearest monitor pixel of P (nearest model) or at the
    exact hit (continuous model), for X and Y, several widths, every shift."""
    cfg = make_config(brdf=brdf, sampling={"estimator": estimator},
                      monitor={"pixel_model": pixel_model, "black_level": 0.1, "white_level": 0.9})
    prim, iu, iv = specular_expectations(cfg)
    widths, k = (16.0, 37.5, 250.0), 5
    res = sim_of(cfg).render_fringes(widths=widths, directions=("x", "y"), shifts=k)
    deltas = phase_shifts(k)
    coord = {"x": iu, "y": iv} if pixel_model == "nearest" else {"x": prim["u"], "y": prim["v"]}
    for d in ("x", "y"):
        for w in widths:
            for q, delta in enumerate(deltas):
                lum = naive.luminance(cfg.monitor, fringe_level(coord[d], w, delta))
                ref = np.where(prim["valid"], np.where(prim["on_monitor"], lum, 0.0), np.nan)
                assert_images_close(res.image(d, w, q), ref, f"{d} w={w} k={q}")


def test_geometry_masks_and_specular_coordinates(base_config):
    prim = naive.primary(base_config)
    g = sim_of(base_config).geometry()
    assert np.array_equal(g.surface_mask, prim["valid"])
    assert np.array_equal(g.monitor_mask, prim["on_monitor"])
    np.testing.assert_allclose(g.specular_u, prim["u"], atol=1e-10)
    np.testing.assert_allclose(g.specular_v, prim["v"], atol=1e-10)
    on = prim["on_monitor"]
    assert np.array_equal(g.specular_u_px[on], naive.nearest(prim["u"][on]))


# --------------------------------------------------------------------------- whole pipeline vs naive


@pytest.mark.parametrize("scheme, mode, estimator", [
    ("polar", "stratified", "paper"),
    ("solid_angle", "random", "paper"),
    ("polar", "random", "weighted_mean"),
])
def test_render_images_and_dots_equal_the_naive_estimator(scheme, mode, estimator):
    cfg = make_config(sampling={"scheme": scheme, "mode": mode, "estimator": estimator, "seed": 8},
                      monitor={"black_level": 0.1, "white_level": 0.7, "gamma": 1.8},
                      compute={"tile_rows": 5})
    sim = sim_of(cfg)
    h, w = sim.shape
    rot = sim.scene.sampling.rotations(0, h, w) if mode == "random" else None
    rays = naive.bundle(cfg, naive.primary(cfg), sim.scene.sampling, rot)
    assert not rays["near_edge"].any()
    levels = np.random.default_rng(4).random((2, 120, 200))
    got = sim.render_images(levels)
    for q in range(2):
        lum = naive.gather_image(rays, naive.luminance(cfg.monitor, levels[q]))
        assert_images_close(got[q], naive.estimate(cfg, rays, lum), f"image {q}")
    dots = [Dot(100, 60, 15), Dot(30.5, 90, 6)]
    got = sim.render_dots(dots)
    mon = cfg.monitor
    for q, d in enumerate(dots):
        lum = mon.black_level + (mon.white_level - mon.black_level) * naive.in_dot(rays, d.u, d.v, d.size)
        lum = np.where(rays["hit"], lum, 0.0)
        assert_images_close(got[q], naive.estimate(cfg, rays, lum), f"dot {q}")


@pytest.mark.parametrize("gamma, rtol", [(1.0, 1e-5), (2.2, 1e-5)])
def test_continuous_fringes_equal_the_naive_estimator(gamma, rtol):
    """Continuous monitor: every ray sees the analytic fringe at its exact hit point (with
    gamma != 1 the renderer expands the displayed profile in harmonics)."""
    cfg = make_config(monitor={"pixel_model": "continuous", "gamma": gamma, "black_level": 0.02})
    sim = sim_of(cfg)
    rays = naive.bundle(cfg, naive.primary(cfg), sim.scene.sampling)
    widths, k = (12.0, 50.0), 4
    res = sim.render_fringes(widths=widths, shifts=k)
    for d, c in (("x", "u"), ("y", "v")):
        for w in widths:
            for q, delta in enumerate(phase_shifts(k)):
                lum = naive.luminance(cfg.monitor, fringe_level(rays[c], w, delta))
                ref = naive.estimate(cfg, rays, np.where(rays["hit"], lum, 0.0))
                assert_images_close(res.image(d, w, q), ref, f"{d} w={w} k={q}", rtol)


# --------------------------------------------------------------------------- complex-sum identity


@pytest.mark.parametrize("monitor, sampling", [
    ({}, {}),
    ({"gamma": 2.2}, {"mode": "random", "seed": 2}),
    ({"black_level": 0.12, "white_level": 0.85}, {"scheme": "solid_angle"}),
    ({"gamma": 2.2, "black_level": 0.05, "white_level": 0.95}, {"estimator": "weighted_mean"}),
])
@pytest.mark.parametrize("shifts", [3, 4, 7])
def test_fringes_equal_explicitly_rendered_fringe_images(monitor, sampling, shifts):
    """render_fringes (one pass, shifts from the complex sums or luminance tables) equals
    render_images of the monitor fringe images, for every shift, X and Y, several widths."""
    sim = sim_of(make_config(monitor=monitor, sampling=sampling))
    widths = (9.0, 20.0, 37.5, 400.0)
    res = sim.render_fringes(widths=widths, directions=("y", "x"), shifts=shifts)
    deltas = phase_shifts(shifts)
    levels = np.array([fringe_image((120, 200), w, d, delta)
                       for d in ("y", "x") for w in widths for delta in deltas])
    explicit = sim.render_images(levels).reshape(res.images.shape)
    assert np.nanmax(explicit) > 0.1 and np.isnan(explicit).any()
    assert_images_close(res.images, explicit.astype(np.float64), "fringes vs images")
    # and the patterns are what the conventions say they are
    u = np.arange(200.0)
    np.testing.assert_allclose(fringe_image((120, 200), 20.0, "x", deltas[1])[7], fringe_value(u, 20.0, deltas[1]))
    np.testing.assert_allclose(fringe_value(u, 20.0, 0.3), 0.5 + 0.5 * np.cos(2 * np.pi * u / 20 + 0.3))


# --------------------------------------------------------------------------- estimators


def test_paper_and_weighted_mean_differ_by_the_normalised_total_weight():
    """paper = (1/N) sum f I, weighted_mean = sum f I / sum f: their ratio is f_total of the
    paper run, (1/N) sum f, the same for every pattern."""
    paper = sim_of(make_config(sampling={"estimator": "paper"}))
    wmean = sim_of(make_config(sampling={"estimator": "weighted_mean"}))
    levels = np.random.default_rng(5).random((2, 120, 200))
    a, b = paper.render_images(levels), wmean.render_images(levels)
    fp = paper.render_fringes(widths=(30.0,))
    fw = wmean.render_fringes(widths=(30.0,))
    valid = paper.geometry().surface_mask
    ratio = fp.f_total
    assert np.all(np.isnan(ratio[~valid])) and np.all(ratio[valid] > 0)
    assert np.nanmax(ratio) / np.nanmin(ratio) > 1.01  # it varies over the image
    np.testing.assert_allclose(fw.f_total[valid], 1.0, rtol=1e-12)
    np.testing.assert_allclose(a, b * ratio, rtol=2e-6, atol=1e-6 * np.nanmax(a))
    np.testing.assert_allclose(fp.images, fw.images * ratio, rtol=2e-6, atol=1e-6 * np.nanmax(fp.images))
    # N counts every ray, P included
    cfg = make_config()
    rays = naive.bundle(cfg, naive.primary(cfg), paper.scene.sampling)
    np.testing.assert_allclose(ratio, np.nansum(rays["f"], -1) / 48 * np.where(valid, 1, np.nan),
                               rtol=1e-9)


def test_weighted_mean_of_a_white_monitor_is_the_fraction_of_weight_on_it():
    cfg = make_config(sampling={"estimator": "weighted_mean"})
    sim = sim_of(cfg)
    white = sim.render_images(np.ones((1, 120, 200)))[0]
    rays = naive.bundle(cfg, naive.primary(cfg), sim.scene.sampling)
    valid = np.isfinite(rays["f"][..., 0])
    f = np.nan_to_num(rays["f"])
    fraction = np.where(rays["hit"], f, 0).sum(-1) / np.where(valid, f.sum(-1), 1.0)
    all_in = rays["hit"].all(-1) & valid
    none_in = ~rays["hit"].any(-1) & valid
    partly = valid & ~all_in & ~none_in
    assert all_in.sum() > 100 and partly.sum() > 10
    np.testing.assert_allclose(white[all_in], 1.0, rtol=1e-6)
    np.testing.assert_allclose(white[partly], fraction[partly], rtol=1e-5)
    visibly = partly & (fraction < 0.99)
    assert visibly.sum() > 5 and np.all(white[visibly] < 0.99) and np.all(white[partly] > 0.0)
    assert np.all(white[none_in] == 0.0)
    assert np.all(np.isnan(white[~valid]))


# --------------------------------------------------------------------------- scattering physics


@pytest.mark.parametrize("wide", ["x", "y"])
def test_fringes_across_the_wide_lobe_lose_more_contrast(wide):
    """With the frame's x along world x (across the plane of incidence, i.e. along monitor u)
    a wide alpha_x blurs X fringes (phase along u) more than Y fringes, and vice versa."""
    alphas = {"alpha_x": 0.025, "alpha_y": 0.002} if wide == "x" else {"alpha_x": 0.002, "alpha_y": 0.025}
    sim = sim_of(make_config(brdf=alphas, sampling={"n_rays": 100, "theta_max_deg": 2.0}))
    res = sim.render_fringes(widths=(20.0,), directions=("x", "y"))
    full = res.f_hit / res.f_total > 1 - 1e-12  # whole bundle on the monitor
    assert full.sum() > 100
    mod = {d: np.abs(res.sums[i, 0]) / res.f_hit for i, d in enumerate(res.directions)}
    narrow = "y" if wide == "x" else "x"
    assert np.all(mod[wide][full] < mod[narrow][full])
    # (the paper's polar sampling over-weights rays near P, so the loss is moderate)
    assert np.median(mod[wide][full]) < 0.9 * np.median(mod[narrow][full])
    assert np.all(mod[narrow][full] > 0.8)
    # the modulation of the images (decoded with K shifts) is the same |sum| / f_hit
    imgs = res.images[res.directions.index(wide), 0].astype(np.float64)
    z = np.tensordot(np.exp(-1j * res.shifts), imgs, axes=1)
    amplitude = 2 * np.abs(z) / len(res.shifts)
    np.testing.assert_allclose(amplitude[full], 0.5 * np.abs(res.sums[res.directions.index(wide), 0][full]),
                               rtol=1e-4, atol=1e-5 * np.nanmax(imgs))


def normal_incidence_config(alpha_x, alpha_y, n_rays=20000, theta_max_deg=4.0):
    """Camera straight above the plate (its centre pixel looks along -n), monitor 200 mm
    above the plate facing it: the centre pixel's P hits the monitor centre at right angles."""
    return parse_config(merge(base_dict(), {
        "camera": {"__replace__": {"resolution": [9, 7], "focal_length_px": 20.0,
                                   "position_mm": [0.0, 0.0, 400.0], "look_at_mm": [0.0, 0.0, 0.0]}},
        "monitor": {"__replace__": {"resolution": [201, 121], "pixel_pitch_mm": 1.0,
                                    "centre_mm": [0.0, 0.0, 200.0], "look_at_mm": [0.0, 0.0, 0.0],
                                    "pixel_model": "continuous"}},
        "brdf": {"alpha_x": alpha_x, "alpha_y": alpha_y},
        "sampling": {"n_rays": n_rays, "theta_max_deg": theta_max_deg, "scheme": "solid_angle",
                     "estimator": "weighted_mean"},
    }))


@pytest.mark.parametrize("alpha_x, alpha_y", [(0.01, 0.004), (0.006, 0.006)])
def test_gaussian_lobe_modulation_and_unbiased_phase_at_normal_incidence(alpha_x, alpha_y):
    """At normal incidence the Ward lobe is a Gaussian in the deviation from P with angular
    standard deviation sqrt(2) alpha per axis; on a monitor at distance D it spreads
    sigma = sqrt(2) alpha D / pitch px, so fringes of period w keep the modulation
    exp(-(2 pi sigma / w)^2 / 2). The lobe is symmetric about P: the phase equals the
    specular phase."""
    sim = sim_of(normal_incidence_config(alpha_x, alpha_y))
    g = sim.geometry()
    assert (g.specular_u[3, 4], g.specular_v[3, 4]) == (100.0, 60.0)
    w = 20.0
    k = 2 * np.pi / w
    res = sim.render_fringes(widths=(w,), directions=("x", "y"))
    for i, (d, alpha, spec) in enumerate([("x", alpha_x, 100.0), ("y", alpha_y, 60.0)]):
        z = res.sums[i, 0, 3, 4]
        sigma = np.sqrt(2) * alpha * 200.0
        expected = np.exp(-((k * sigma) ** 2) / 2)
        assert abs(abs(z) / res.f_hit[3, 4] / expected - 1) < 3e-3, d
        assert abs(np.angle(z * np.exp(-1j * k * spec))) < 1e-3, d


# --------------------------------------------------------------------------- reproducibility


def test_same_seed_same_bytes_any_tiling_any_scheduler():
    base = {"sampling": {"mode": "random", "seed": 21}}
    ref = sim_of(make_config(**base)).render_fringes(widths=(20.0, 45.0)).images
    again = sim_of(make_config(**base)).render_fringes(widths=(20.0, 45.0)).images
    assert ref.tobytes() == again.tobytes()
    for tile_rows, scheduler in [(1, "threads"), (5, "synchronous"), (32, "threads"), (100, "synchronous")]:
        other = sim_of(make_config(compute={"tile_rows": tile_rows, "scheduler": scheduler},
                                   **base)).render_fringes(widths=(20.0, 45.0)).images
        assert other.tobytes() == ref.tobytes(), (tile_rows, scheduler)
    different = sim_of(make_config(sampling={"mode": "random", "seed": 22})).render_fringes(
        widths=(20.0, 45.0)).images
    valid = np.isfinite(ref)
    assert np.array_equal(valid, np.isfinite(different))
    assert np.mean(different[valid] != ref[valid]) > 0.5
    stratified = sim_of(make_config()).render_fringes(widths=(20.0, 45.0)).images
    assert not np.array_equal(stratified[valid], ref[valid])


def test_threads_and_synchronous_schedulers_agree_for_images_and_dots():
    levels = np.random.default_rng(6).random((2, 120, 200))
    outs = []
    for scheduler in ("threads", "synchronous"):
        sim = sim_of(make_config(compute={"scheduler": scheduler, "tile_rows": 3}))
        outs.append((sim.render_images(levels), sim.render_dots([Dot(90, 50, 21)])))
    assert outs[0][0].tobytes() == outs[1][0].tobytes()
    assert outs[0][1].tobytes() == outs[1][1].tobytes()


def test_progress_is_reported_per_tile():
    calls = []
    sim = sim_of(make_config(compute={"tile_rows": 10}))
    sim.render_images(np.zeros((1, 120, 200)), progress=lambda done, total: calls.append((done, total)))
    assert calls and calls[-1] == (4, 4)


# --------------------------------------------------------------------------- missed rays


def test_pixels_off_the_plate_are_nan_and_masked(base_config):
    sim = sim_of(base_config)
    prim = naive.primary(base_config)
    assert 0.2 < prim["valid"].mean() < 0.8
    g = sim.geometry()
    assert np.array_equal(g.surface_mask, prim["valid"])
    res = sim.render_fringes(widths=(20.0,))
    assert np.all(np.isnan(res.images[..., ~prim["valid"]]))
    assert np.all(np.isfinite(res.images[..., prim["valid"]]))
    assert np.all(np.isnan(res.f_total[~prim["valid"]]))
    assert np.all(np.isnan(g.specular_u[~prim["valid"]]))


@pytest.mark.parametrize("camera", [
    {"position_mm": [0.0, -126.8, 271.9], "look_at_mm": [0.0, -253.6, 543.8]},  # looks away
    {"position_mm": [0.0, -126.8, -271.9], "look_at_mm": [0.0, 0.0, 0.0]},  # sees the back
])
def test_camera_that_sees_no_front_of_the_plate_gives_an_empty_mask(camera):
    """Looking away from the plate, or at its back (the plate reflects on its +normal side
    only), raises nothing: every pixel is invalid (mask False) and every value NaN."""
    sim = sim_of(make_config(camera=camera))
    g = sim.geometry()
    assert not g.surface_mask.any() and not g.monitor_mask.any()
    res = sim.render_fringes(widths=(20.0,))
    assert np.all(np.isnan(res.images)) and np.all(np.isnan(res.f_total))
    assert np.all(np.isnan(sim.render_images(np.ones((1, 120, 200)))))
    assert np.all(np.isnan(sim.render_dots([Dot(100, 60, 15)])))


@pytest.mark.parametrize("monitor", [
    {"resolution": [24, 16]},  # a small monitor: most bundles miss it
    {"look_at_mm": [0.0, 500.0, 600.0]},  # facing away: rays reach only its back
])
def test_rays_that_miss_the_monitor_are_black_and_never_nan(monitor):
    cfg = make_config(monitor=monitor, sampling={"mode": "random"})
    sim = sim_of(cfg)
    valid = sim.geometry().surface_mask
    assert valid.sum() > 100
    shape = sim.scene.monitor.shape
    res = sim.render_fringes(widths=(10.0,))
    img = sim.render_images(np.ones((1,) + shape))[0]
    assert np.all(np.isfinite(res.images[..., valid])) and np.all(np.isfinite(img[valid]))
    rays = naive.bundle(cfg, naive.primary(cfg), sim.scene.sampling,
                        sim.scene.sampling.rotations(0, *sim.shape))
    none = ~rays["hit"].any(-1) & valid
    assert none.sum() > 0.5 * valid.sum()
    assert np.all(img[none] == 0.0) and np.all(res.images[..., none] == 0.0)
    assert np.all(res.f_hit[none] == 0.0) and np.all(res.f_total[valid] > 0)
    # weighted mean: a pixel whose rays all miss has nothing to average but stays finite
    wm = sim_of(make_config(monitor=monitor, sampling={"estimator": "weighted_mean"}))
    out = wm.render_images(np.ones((1,) + shape))[0]
    assert np.all(np.isfinite(out[valid]))


@pytest.mark.parametrize("estimator", ["paper", "weighted_mean"])
def test_fringes_finished_in_the_tiles_equal_the_finish_after_the_render(monkeypatch, estimator):
    """The linear fringes' normalisation, complex sums and shifted images are finished in
    each tile's task (``FringeFinish``), every camera row exactly once; the bytes equal those
    of finishing the whole sums after the render (the path of other schedulers and of the
    rqmc mean)."""
    from pmdsim.render.fringe_finish import FringeFinish

    sim = sim_of(make_config(compute={"tile_rows": 5}, sampling={"estimator": estimator}))
    blocks = []
    call = FringeFinish.rows  # what both paths finish rows with

    def spy(self, r0, r1, raw):
        blocks.append((r0, r1))
        return call(self, r0, r1, raw)

    monkeypatch.setattr(FringeFinish, "rows", spy)
    tiles = sim.render_fringes(widths=(20.0, 45.0), shifts=3)
    assert sorted(blocks) == [(r, min(r + 5, 32)) for r in range(0, 32, 5)]  # the tiles
    blocks.clear()
    monkeypatch.setattr(FringeFinish, "kw", lambda self, mode, ncols: {})  # the tiles do not finish
    after = sim.render_fringes(widths=(20.0, 45.0), shifts=3)
    assert sorted(blocks) == [(r, r + 1) for r in range(32)]  # after the render
    assert np.isfinite(tiles.images).any() and np.isnan(tiles.images).any()
    for name in ("images", "sums", "f_total", "f_hit"):
        assert getattr(tiles, name).tobytes() == getattr(after, name).tobytes(), name
