"""The convergence study against independent values (issue 9).

``test_converge.py`` checked that the paper and weighted-mean rows are equal (one render
serves both, by construction) and that the converged reference differs from itself by 0.
Here every number of the table is recomputed through another path (the renderer's complex
fringe sums instead of decoded images, slow loops for the statistics), the radiometric
modulation is checked against the small-slope closed form exp(-(k d alpha)^2), the phase
bias of Ward 1992 against its first-order closed form, and the reduced camera against the
original one with an explicit, off-centre principal point.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import naive
import naive_stats as ns
from conftest import base_dict, make_config
from pmdsim.config import parse_config
from pmdsim.studies.convergence import _stats, convergence_study, reduced_config
from pmdsim.render import Simulation
from pmdsim.scene.sampling import ConeSampling
from pmdsim.scene import Scene


def test_row_statistics_are_rms_mean_and_p95_of_the_absolute_value():
    """_stats: d = -k, k = 0..100, over a mask: RMS sqrt(3350), mean -50, P95 |d| = 95.
    Guards against the P95 of the signed deviation, RMS about the mean, unmasked pixels."""
    d = np.concatenate([-np.arange(101.0), [1e6, np.nan]])
    valid = np.concatenate([np.ones(101, bool), [False, False]])
    rms, mean, p95 = _stats(d, valid)
    assert rms == pytest.approx(math.sqrt(3350.0), rel=1e-13)
    assert mean == pytest.approx(-50.0, rel=1e-14)
    assert p95 == pytest.approx(95.0, rel=1e-13)
    assert all(math.isnan(x) for x in _stats(d, np.zeros(103, bool)))


# =========================================================================== reduced camera
@pytest.mark.parametrize("size, scale", [((20, 16), 0.5), ((30, 24), 0.75)])
def test_reduced_camera_with_explicit_principal_point(size, scale):
    """An off-centre principal point (17.3, 12.8) px on the 40 x 32 camera: reduced pixel
    (r, c) covers the original pixels whose centres average to ((c + 0.5) / s - 0.5,
    (r + 0.5) / s - 0.5); its ray must be the original camera's ray there (pinhole
    directions computed by ``naive.vision_ray`` from the original configuration). Guards
    against scaling the principal point without the half-pixel shift, ignoring it (centred
    default), scaling the focal length by the other axis."""
    cfg = make_config(camera={"principal_point_px": [17.3, 12.8]})
    small = reduced_config(cfg, size)
    assert small.camera.resolution == size
    cam = Scene.from_config(small).camera
    rows, cols = np.mgrid[0:size[1], 0:size[0]]
    got = cam.ray_directions(rows, cols)
    for r in range(0, size[1], 3):
        for c in range(0, size[0], 3):
            expected = naive.vision_ray(cfg.camera, (r + 0.5) / scale - 0.5, (c + 0.5) / scale - 0.5)
            np.testing.assert_allclose(got[r, c], expected, rtol=0, atol=1e-13)


# =========================================================================== the table
S3, C3 = math.sin(math.radians(3.0)), math.cos(math.radians(3.0))


def _normal_incidence_config(alpha=0.013, widths=(20.0, 160.0)):
    """Near-normal incidence (3 deg), continuous monitor 200 mm away facing the plate,
    isotropic Ward lobe: the footprint on the monitor is Gaussian, sigma = sqrt(2) alpha d."""
    d = base_dict()
    d["camera"].update(position_mm=[1.1, -300.0 * S3, 300.0 * C3], look_at_mm=[0.7, 0.4, 0.0])
    d["monitor"].update(centre_mm=[-0.6, 200.0 * S3 + 0.3, 200.0 * C3],
                        look_at_mm=[0.2, -0.5, 0.0], pixel_model="continuous")
    d["brdf"] = {"model": "ward", "alpha_x": alpha, "alpha_y": alpha, "rho_s": 0.4}
    d["sampling"] = {"n_rays": 48, "theta_max_deg": 2.0, "mode": "random", "seed": 7}
    d["patterns"] = {"fringes": {"widths_px": list(widths), "shifts": 4}}
    return parse_config(d)


@pytest.fixture(scope="module")
def study():
    cfg = _normal_incidence_config()
    res = convergence_study(cfg, n_values=(16, 256), theta_values=(1.0,), camera_size=(20, 16),
                            diagnostics=False)
    return cfg, res


def _recompute(cfg, estimator, theta_deg, n, widths, directions):
    """Phase (arg of the complex fringe sums) and modulation |sums| / f_hit of one setting on
    the reduced camera, and the mirror's phase: the renderer's other output, no decoding."""
    small = reduced_config(cfg, (20, 16))
    base = Scene.from_config(small)
    s = base.sampling
    th = s.theta_max if theta_deg is None else math.radians(theta_deg)
    scene = base.replace(sampling=ConeSampling(n, th, s.scheme, s.mode, s.seed), estimator=estimator)
    fr = Simulation(scene).render_fringes(widths, directions, 4)
    ref = Simulation(base.specular()).render_fringes(widths, directions, 4)
    geo = Simulation(base).geometry()
    return np.angle(fr.sums), np.abs(fr.sums) / fr.f_hit, np.angle(ref.sums), geo.monitor_mask


def _wrap(x):
    return np.angle(np.exp(1j * x))


def test_every_column_equals_a_recomputation_from_the_fringe_sums(study):
    """For a cone row (paper, theta 2 deg, N 48), a radiometric row (N 16) and the converged
    row: phase RMS / mean / P95 |.| against the mirror, the RMS against the converged
    (radiometric, largest N) answer, the median modulation and n_valid, recomputed from the
    complex fringe sums with slow loops. Phases agree to 2e-5 rad (float32 images). Guards
    against an unwrapped phase difference (pixels near +-pi), the converged answer taken from
    the smallest N or a cone run, statistics over all pixels, the mean modulation."""
    cfg, res = study
    widths, dirs = (20.0, 160.0), ("x", "y")
    conv_ph, _, _, _ = _recompute(cfg, "radiometric", None, 256, widths, dirs)
    for est, th, n in (("paper", 2.0, 48), ("weighted_mean", 1.0, 16), ("radiometric", None, 16),
                       ("radiometric", None, 256)):
        ph, mod, ref, mask = _recompute(cfg, "paper" if est != "radiometric" else est, th, n,
                                        widths, dirs)
        for di, d in enumerate(dirs):
            for wi, wd in enumerate(widths):
                row = [r for r in res.rows if r["estimator"] == est and r["n_rays"] == n
                       and r["direction"] == d and r["width_px"] == wd
                       and (th is None or r["theta_max_deg"] == th)]
                assert len(row) == 1
                row = row[0]
                ok = mask & np.isfinite(ph[di, wi]) & np.isfinite(ref[di, wi])
                dev = _wrap(ph[di, wi] - ref[di, wi])[ok]
                assert row["n_valid"] == ok.sum() > 100
                assert row["phase_rms_rad"] == pytest.approx(ns.rms(dev), abs=2e-5)
                assert row["phase_mean_rad"] == pytest.approx(ns.mean(dev), abs=2e-5)
                assert row["phase_p95_rad"] == pytest.approx(
                    ns.percentile_linear(np.abs(dev), 95), abs=2e-5)
                assert row["modulation_median"] == pytest.approx(
                    float(np.median(mod[di, wi][ok])), rel=2e-5)
                vs = _wrap(ph[di, wi] - conv_ph[di, wi])[ok]
                assert row["phase_rms_vs_reference_rad"] == pytest.approx(ns.rms(vs), abs=2e-5)
    # the 20 px fringes with few rays have phases all round the circle: the unwrapped
    # difference would be off by 2 pi somewhere, so the wrap is exercised
    ph, _, ref, mask = _recompute(cfg, "radiometric", None, 16, widths, dirs)
    raw = np.abs(ph - ref)[:, 0][:, mask]
    assert np.nanmax(raw) > np.pi


def _distance_px(cfg):
    """Per reduced-camera pixel: distance (monitor px) from the surface point to the exact
    monitor point of P, by hand (``naive.primary`` and a plane intersection)."""
    small = reduced_config(cfg, (20, 16))
    prim = naive.primary(small)
    centre, _, _, n = naive.monitor_axes(small.monitor)
    s, p = prim["point"], prim["principal"]
    t = np.einsum("...k,k->...", centre - s, n) / np.einsum("...k,k->...", p, n)
    return np.where(prim["on_monitor"], t / small.monitor.pixel_pitch_mm, np.nan)


def test_radiometric_modulation_follows_the_small_slope_law(study):
    """Radiometric rows: the median modulation of the 20 px fringes is the median over
    pixels of exp(-(k d alpha)^2) (Gaussian slopes of variance alpha^2 / 2 per axis,
    doubled by reflection; d from the geometry by hand), within 3 % at N = 256 (measured
    within 1 %); the wide
    160 px fringes keep exp(-(k d alpha)^2) ~ 0.99. Guards against a modulation taken as
    B instead of B / A, from the mirror run, or the median over the wrong axis."""
    cfg, res = study
    d_px = _distance_px(cfg)
    alpha = 0.013
    for wd in (20.0, 160.0):
        k = 2 * math.pi / wd
        predicted = float(np.nanmedian(np.exp(-(k * d_px * alpha) ** 2)))
        for d in ("x", "y"):
            row = [r for r in res.rows if r["estimator"] == "radiometric" and r["n_rays"] == 256
                   and r["direction"] == d and r["width_px"] == wd][0]
            assert row["modulation_median"] == pytest.approx(predicted, rel=0.03), (wd, d)
    k = 2 * math.pi / 20.0
    assert 0.3 < np.nanmedian(np.exp(-(k * d_px * alpha) ** 2)) < 0.7


def test_ward1992_phase_bias_follows_its_first_order_closed_form():
    """Ward 1992 moves the reflected energy's centroid towards the normal by
    2 tan(theta_i) alpha^2 in the plane of incidence (docs/physics.md); on a monitor at
    distance d facing the ray that is a shift of 2 tan(theta_i) alpha^2 d, so the converged
    radiometric phase of y fringes deviates from the mirror's by k times that, with one sign
    over the image. At 25 deg, alpha 0.03 in the plane (0.003 across; an isotropic lobe adds
    second-order terms of the across-plane slopes, measured -40 %), 40 px fringes, a monitor
    large enough that no lobe is cut: ~ 0.027 rad, measured within 4 %; asserted 10 %.
    Guards against a phase RMS that is not the deviation's (e.g. about its mean: ~0 here),
    a mean of the absolute value, a factor 2 in the bias."""
    t = math.radians(25.0)
    d = base_dict()
    d["camera"].update(position_mm=[0.0, -300.0 * math.sin(t), 300.0 * math.cos(t)],
                       look_at_mm=[0.0, 0.0, 0.0])
    d["monitor"].update(centre_mm=[0.0, 200.0 * math.sin(t), 200.0 * math.cos(t)],
                        look_at_mm=[0.0, 0.0, 0.0], pixel_model="continuous",
                        resolution=[600, 500])
    d["brdf"] = {"model": "ward", "alpha_x": 0.003, "alpha_y": 0.03, "rho_s": 0.4}
    d["sampling"] = {"n_rays": 64, "theta_max_deg": 1.0, "mode": "stratified"}
    d["patterns"] = {"fringes": {"widths_px": [40.0], "shifts": 4, "directions": ["y"]}}
    cfg = parse_config(d)
    res = convergence_study(cfg, n_values=(1024,), estimators=("radiometric",),
                            camera_size=(20, 16), diagnostics=False)
    row = [r for r in res.rows if r["n_rays"] == 1024][0]
    small = reduced_config(cfg, (20, 16))
    prim = naive.primary(small)
    cos_i = prim["to_camera"][..., 2]
    tan_i = np.sqrt(1 - cos_i**2) / cos_i
    dist = _distance_px(cfg)
    k = 2 * math.pi / 40.0
    bias = k * 2 * tan_i * 0.03**2 * dist
    expected = float(np.sqrt(np.nanmean(bias**2)))
    assert 0.02 < expected < 0.035
    assert row["phase_rms_rad"] == pytest.approx(expected, rel=0.10)
    assert abs(row["phase_mean_rad"]) == pytest.approx(expected, rel=0.10)
    assert row["phase_p95_rad"] > row["phase_rms_rad"]


# =========================================================================== settings and wiring
def test_study_settings_meta_and_timings(study):
    """The configured N (48) and theta_max (2 deg) join the sweeps, sorted; the converged
    answer is named by the largest N; every row's time is a duration (0 <= s < 10 min)."""
    cfg, res = study
    m = res.meta
    assert m["n_values"] == [16, 48, 256] and m["theta_values_deg"] == [1.0, 2.0]
    assert m["reference"]["run"] == "radiometric, N = 256" and m["camera_size"] == [20, 16]
    assert m["widths_px"] == [20.0, 160.0] and m["directions"] == ["x", "y"] and m["shifts"] == 4
    # rows: 2 thetas x 3 N x 2 cone estimators + 3 radiometric, x 2 directions x 2 widths
    assert len(res.rows) == (2 * 3 * 2 + 3) * 4
    assert all(0.0 <= r["seconds"] < 600.0 for r in res.rows)


def test_bad_sweeps_are_refused_at_their_bounds():
    """N = 0, theta_max = 0 or 90 deg, no estimator: a clear error before any rendering.
    Guards against '<' / '<=' / '>=' slips on the bounds (N = 1 and 89.9 deg are fine)."""
    cfg = make_config()
    for kw, field in (({"n_values": (0,)}, "n_values"), ({"theta_values": (0.0,)}, "theta_values"),
                      ({"theta_values": (1.0, 90.0)}, "theta_values"),
                      ({"estimators": ()}, "estimators")):
        with pytest.raises(ValueError, match=field):
            convergence_study(cfg, camera_size=(4, 4), diagnostics=False, **kw)
    res = convergence_study(cfg, n_values=(1,), theta_values=(89.9,), estimators=("paper",),
                            camera_size=(4, 4), diagnostics=False)
    assert {r["n_rays"] for r in res.rows} == {1, 48}
    assert {r["theta_max_deg"] for r in res.rows} == {2.0, 89.9}


def test_reduced_camera_keeps_at_least_one_pixel_per_axis():
    """A 400 x 20 px camera reduced to 10 x 10: scale 1/40, so 10 x 1 px (not 10 x 0); the
    tighter axis sets the scale (guards against one axis used for both)."""
    cfg = make_config(camera={"resolution": [400, 20], "focal_length_px": 800.0})
    assert reduced_config(cfg, (10, 10)).camera.resolution == (10, 1)
    cfg = make_config(camera={"resolution": [20, 400], "focal_length_px": 800.0})
    assert reduced_config(cfg, (10, 10)).camera.resolution == (1, 10)
    # the tighter axis sets the scale: 40 x 32 into 30 x 12 is 3/8, i.e. 15 x 12
    assert reduced_config(make_config(), (30, 12)).camera.resolution == (15, 12)
    assert reduced_config(make_config(), (12, 30)).camera.resolution == (12, 10)


def test_study_checks_the_configured_settings_by_default():
    """Without ``diagnostics=False`` the study diagnoses the configured settings on the
    reduced camera with the [diagnostics] grid, phase method and bounds: the same warnings
    as diagnose + check called directly (the base lobe in a 1 deg cone: energy fraction).
    Guards against the configured phase method being ignored (it was, before issue 9)."""
    from pmdsim.studies import diagnostics as dg
    from pmdsim.studies.diagnostic_warnings import check

    cfg = make_config(sampling={"n_rays": 16, "theta_max_deg": 1.0},
                      diagnostics={"grid": [4, 3], "phase_method": "delta"})
    res = convergence_study(cfg, n_values=(16,), estimators=("radiometric",),
                            camera_size=(16, 12))
    small = reduced_config(cfg, (16, 12))
    sim = Simulation(Scene.from_config(small))
    diag = dg.diagnose(sim, (50.0,), ("x", "y"), grid=(4, 3), phase_method="delta")
    expected = check(diag, bounds=small.diagnostics)
    assert [w.code for w in res.warnings] == [w.code for w in expected]
    assert "energy_fraction" in [w.code for w in res.warnings]
    assert res.diagnostics["energy"] == pytest.approx(diag.summary["energy"])
    assert res.diagnostics["phase_se_method"] == "delta"
    for key, val in diag.summary["phase_se_rad"].items():
        assert res.diagnostics["phase_se_rad"][key] == pytest.approx(val)


def test_cli_help_states_the_study_defaults():
    """``pmdsim converge --help`` names the default sweeps and camera; they must be the ones
    the study uses (guards against a default changed without its documentation)."""
    import inspect
    import re

    from pmdsim import cli
    from pmdsim.studies.convergence import DEFAULT_N, DEFAULT_THETA_DEG

    p = inspect.signature(cli.converge).parameters
    n_help = re.search(r"default ([\d,.]+)", p["n_values"].default.help).group(1)
    th_help = re.search(r"default ([\d,.]+)", p["theta"].default.help).group(1)
    assert tuple(int(x) for x in n_help.split(",")) == DEFAULT_N
    assert tuple(float(x) for x in th_help.split(",")) == DEFAULT_THETA_DEG
    w, h = (int(x) for x in p["camera"].default.default.split("x"))
    assert (w, h) == inspect.signature(convergence_study).parameters["camera_size"].default
    assert (w, h) == inspect.signature(reduced_config).parameters["camera_size"].default


def test_study_defaults_without_fringes_and_pixels_off_the_monitor():
    """A configuration that shows only dots: the study uses 50 px fringes, x and y, K = 4.
    The base scene with a 100 x 50 mm monitor has plate pixels whose principal ray misses it
    (found by hand with ``naive.primary``): they are not counted in n_valid even though their decoded
    phases are finite (black images decode to a phase too). Guards against the default K or
    widths changed, and '&' / '|' in the valid mask."""
    cfg = make_config(patterns={"fringes": False, "dots": {"size_px": 9, "grid": [2, 2]}},
                      monitor={"resolution": [100, 50]})
    res = convergence_study(cfg, n_values=(8,), estimators=("radiometric",),
                            camera_size=(20, 16), diagnostics=False)
    m = res.meta
    assert m["shifts"] == 4 and m["widths_px"] == [50.0] and m["directions"] == ["x", "y"]
    prim = naive.primary(reduced_config(cfg, (20, 16)))
    off = prim["valid"] & ~prim["on_monitor"]
    assert off.sum() > 5                          # plate pixels whose P misses the monitor
    for r in res.rows:
        assert r["n_valid"] == int(prim["on_monitor"].sum())
