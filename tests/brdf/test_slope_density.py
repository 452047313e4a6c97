"""Tests of the slope-density micro-facet BRDF (``pmdsim.brdf.slope_density``).

- the Gaussian density is the Beckmann model: values, pdf and samples to 1e-12, the same
  kernel vector;
- every new sampler (separable table = kinematic, joint table = height map, grating
  orders) against its pdf by the chi-square test of ``test_radiometric``;
- the compiled kernels (cone estimator weights, radiometric lobe sums) against the NumPy
  reference for the table and the orders;
- physics: the kinematic density of a flat turned plate maps a point-like dot to the
  closed-form top-hat of full width 2 f d / r (normal incidence) within 2 %, and radial
  fringes keep sin(x)/x, x = k d f / r, times the Gaussian factor exp(-(k d alpha)^2) of
  the random roughness, within 1 %.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import make_config
from scipy import stats

from test_radiometric import _facing_config, _decoded_modulation, _lobe_reference
from pmdsim.brdf import Beckmann, brdf_from_config, lobe_weight
from pmdsim.brdf.slope_density import (GaussianSlopes, GratingOrders, SlopeDensityBRDF,
                                       TabulatedSlopes, arc_slope_cdf, kinematic_slopes,
                                       tabulated_from_file)
from pmdsim.config import ConfigError, parse_config
from pmdsim.render import Simulation
from pmdsim.trace import trace_primary


def _i_local(theta_deg, phi):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


def _random_dirs(rng, n, zmin=0.05):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + zmin
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# =========================================================================== Gaussian = Beckmann
@pytest.mark.parametrize("smith", [True, False])
def test_gaussian_density_is_beckmann(smith):
    rng = np.random.default_rng(3)
    ref = Beckmann(0.3, 0.12, 0.7, smith)
    sd = SlopeDensityBRDF(GaussianSlopes(0.3, 0.12), 0.7, smith)
    i = _random_dirs(rng, 2000)
    o = _random_dirs(rng, 2000)
    for name in ("evaluate", "pdf"):
        a, b = getattr(ref, name)(i, o), getattr(sd, name)(i, o)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-300, err_msg=name)  # subnormals
    u1, u2 = 1 - rng.random(2000), rng.random(2000)
    np.testing.assert_allclose(sd.sample(u1, u2, i), ref.sample(u1, u2, i), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(sd.kernel_params(), ref.kernel_params())
    cfg = make_config(brdf={"__replace__": {"model": "slope_density", "density": "gaussian",
                                            "alpha_x": 0.3, "alpha_y": 0.12,
                                            "rho_s": 0.7}})
    np.testing.assert_array_equal(brdf_from_config(cfg.brdf).kernel_params(),
                                  Beckmann(0.3, 0.12, 0.7, True).kernel_params())


# =========================================================================== samplers
def chi2_sample_vs_pdf(sample, pdf, i_local, n_samples=100_000, n_theta=30, n_phi=60, q=16,
                       seed=0, min_expected=5.0):
    """p-value of a chi-square test of ``sample`` against ``pdf`` on a (theta_o, phi_o) grid
    (as ``test_radiometric.chi2_sample_vs_pdf``), the expected counts by a q x q midpoint
    rule per cell: the tables' densities are discontinuous, which few Gauss nodes miss."""
    rng = np.random.default_rng(seed)
    o = sample(1.0 - rng.random(n_samples), rng.random(n_samples), i_local)
    up = o[:, 2] > 0
    th = np.arccos(np.clip(o[up, 2], -1, 1))
    ph = np.mod(np.arctan2(o[up, 1], o[up, 0]), 2 * np.pi)
    observed, _, _ = np.histogram2d(th, ph, bins=[np.linspace(0, np.pi / 2, n_theta + 1),
                                                  np.linspace(0, 2 * np.pi, n_phi + 1)])
    dt, dp = np.pi / 2 / (n_theta * q), 2 * np.pi / (n_phi * q)
    t = (np.arange(n_theta * q) + 0.5) * dt
    p = (np.arange(n_phi * q) + 0.5) * dp
    T, P = np.meshgrid(t, p, indexing="ij")
    oo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    dens = pdf(np.broadcast_to(i_local, oo.shape), oo) * np.sin(T) * dt * dp
    expected = dens.reshape(n_theta, q, n_phi, q).sum((1, 3)) * n_samples
    obs = np.append(observed.ravel(), (~up).sum())
    exp = np.append(expected.ravel(), max(n_samples - expected.sum(), 0.0))
    small = exp < min_expected
    obs = np.append(obs[~small], obs[small].sum())
    exp = np.append(exp[~small], exp[small].sum())
    keep = exp > 0
    if np.any(obs[~keep] > 0):
        return 0.0
    obs, exp = obs[keep], exp[keep]
    return float(stats.chi2.sf(np.sum((obs - exp) ** 2 / exp), obs.size - 1))


def _height_map_table():
    rng = np.random.default_rng(11)
    n = 256
    k = np.fft.fftfreq(n)
    spec = np.exp(-(k[:, None] ** 2 / 0.002 + k[None, :] ** 2 / 0.0005))
    noise = np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * spec).real
    heights = 0.02 * noise / noise.std() + 0.002 * np.sin(np.arange(n) / 5.0)[None, :]
    return TabulatedSlopes.from_height_map(heights, 0.01, 0.01, bins=48)


SAMPLERS = {
    "kinematic": lambda: kinematic_slopes(0.4, 0.5, 0.05, 0.15),
    "kinematic_pure": lambda: kinematic_slopes(0.6, 0.5, 0.0, 0.2),
    "height_map": _height_map_table,
    "orders": lambda: GratingOrders(np.arange(-4, 5) * 0.15, np.exp(-0.2 * np.arange(-4, 5) ** 2),
                                    0.08, 0.05),
}


@pytest.mark.parametrize("name", sorted(SAMPLERS))
@pytest.mark.parametrize("incidence", [(0.0, 0.0), (35.0, 0.7), (60.0, 1.9)])
def test_sampler_matches_pdf(name, incidence):
    dens = SAMPLERS[name]()
    brdf = SlopeDensityBRDF(dens, 0.5)
    i = _i_local(*incidence)
    p = chi2_sample_vs_pdf(brdf.sample, brdf.pdf, i, n_samples=100_000)
    assert p > 1 - 0.99 ** (1 / 12), f"{name} {incidence}: chi2 p = {p:.2e}"


def test_chi2_rejects_a_wrong_table():
    """Power: the kinematic sampler against the pdf of a slightly wider arc is rejected."""
    brdf = SlopeDensityBRDF(kinematic_slopes(0.4, 0.5, 0.05, 0.15), 0.5)
    wrong = SlopeDensityBRDF(kinematic_slopes(0.44, 0.5, 0.05, 0.15), 0.5)
    i = _i_local(20.0, 0.3)
    assert chi2_sample_vs_pdf(brdf.sample, wrong.pdf, i, n_samples=100_000) < 1e-6


def test_kinematic_table_is_the_arc_distribution():
    """Cell masses of the pure kinematic table are the exact arc-slope cdf differences; the
    equivalent alpha is sqrt(2) x the exact RMS arc slope (~ f / (sqrt(6) r))."""
    f, r = 0.03, 0.5
    t = kinematic_slopes(f, r, 0.0, 1e-3)
    edges = t.y0 + np.arange(t.mass_y.size + 1) * t.dy
    np.testing.assert_allclose(t.mass_y, np.diff(arc_slope_cdf(edges, f, r)), atol=1e-15)
    rms = math.sqrt((2 * r * math.atanh(f / (2 * r)) - f) / f)
    assert abs(t.equivalent_alphas[1] / (math.sqrt(2) * rms) - 1) < 1e-6
    assert abs(t.equivalent_alphas[1] / (f / (math.sqrt(6) * r)) - 1) < 2e-3


def test_tabulated_from_file_roundtrip(tmp_path):
    rng = np.random.default_rng(2)
    counts = rng.random((10, 12))
    ex, ey = np.linspace(-0.1, 0.1, 11), np.linspace(-0.2, 0.3, 13)
    np.savez(tmp_path / "hist.npz", counts=counts, edges_x=ex, edges_y=ey)
    t = tabulated_from_file(tmp_path / "hist.npz")
    np.testing.assert_allclose(t.density(np.array([-0.095]), np.array([-0.19])),
                               counts[0, 0] / counts.sum() / (0.02 * (0.5 / 12)))
    np.save(tmp_path / "h.npy", rng.normal(size=(40, 50)) * 1e-4)
    with pytest.raises(ValueError, match="pitch_mm"):
        tabulated_from_file(tmp_path / "h.npy")
    assert tabulated_from_file(tmp_path / "h.npy", (0.01, 0.01), 16).shape == (16, 16)
    with pytest.raises(ConfigError, match="file"):
        parse_config(make_config().model_dump() | {"brdf": {"model": "slope_density",
                                                             "density": "tabulated"}})


def test_config_errors_name_the_fields():
    base = {"model": "turned", "feed_um": 30.0, "nose_radius_mm": 0.5}
    with pytest.raises(ConfigError, match="rq_um"):
        make_config(brdf={"__replace__": base})
    with pytest.raises(ConfigError, match="correlation_length_um"):
        make_config(brdf={"__replace__": base | {"rq_um": 0.01}})
    with pytest.raises(ConfigError, match="feed_um"):
        make_config(brdf={"__replace__": base | {"feed_um": 2000.0, "rq_um": 0.01,
                                                 "correlation_length_um": 5.0}})
    with pytest.raises(ConfigError, match="wavelengths_nm"):
        make_config(brdf={"__replace__": base | {"rq_um": 0.01, "correlation_length_um": 5.0,
                                                 "wavelengths_nm": [500.0]}})


# =========================================================================== kernels vs NumPy
KERNEL_MODELS = [
    {"model": "slope_density", "density": "kinematic", "feed_um": 150.0, "nose_radius_mm": 0.5,
     "rms_slope_tangential": 0.01, "rms_slope_radial": 0.005, "rho_s": 0.6},
    {"model": "turned", "regime": "diffractive", "feed_um": 20.0, "nose_radius_mm": 0.2,
     "rms_slope_tangential": 0.004, "rms_slope_radial": 0.003, "wavelengths_nm": [600.0, 450.0],
     "spectral_weights": [1.0, 0.5], "rho_s": 0.6},
]


@pytest.mark.parametrize("brdf", KERNEL_MODELS, ids=lambda b: b["model"])
def test_lobe_kernel_matches_numpy_reference(brdf):
    widths, directions = (20.0, 70.0), ("x", "y")
    res = {}
    for model in ("nearest", "continuous"):
        sim = Simulation.from_config(make_config(
            brdf={"__replace__": brdf}, monitor={"pixel_model": model},
            sampling={"estimator": "radiometric", "n_rays": 40, "mode": "random", "seed": 5}))
        res[model] = sim.render_fringes(widths, directions, 4)
    ref = _lobe_reference(sim, widths, directions)
    n = 40
    ok = np.isfinite(ref["ftot"])
    assert ok.sum() > 100
    scale = ref["ftot"][ok].max() / n
    for model, key in (("nearest", "tables"), ("continuous", "harmonic")):
        r = res[model]
        np.testing.assert_allclose(r.f_total[ok], ref["ftot"][ok] / n, rtol=1e-9)
        np.testing.assert_allclose(r.sums[:, :, ok], ref[key][:, :, ok] / n, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("brdf", KERNEL_MODELS, ids=lambda b: b["model"])
def test_cone_kernel_matches_numpy(brdf):
    """The cone estimators' weights are the NumPy ``evaluate`` (a 12 deg cone)."""
    sim = Simulation.from_config(make_config(brdf={"__replace__": brdf},
                                             sampling={"n_rays": 400, "theta_max_deg": 12.0}))
    sc = sim.scene
    rows, cols = [10, 16, 20], [20, 22, 30]
    u, v, f, dirs, origin = sim.transport(rows, cols)
    nonzero = 0
    for p, (r, c) in enumerate(zip(rows, cols)):
        h = trace_primary(sc, r, r + 1)
        frame = (h.x_axis[0, c], h.y_axis[0, c], h.normal[0, c])
        i = np.array([h.to_camera[0, c] @ b for b in frame])
        o = np.stack([dirs[p] @ b for b in frame], -1)
        _, _, hit = sc.monitor.intersect(origin[p], dirs[p])
        ref = np.where(hit, sc.brdf.evaluate(np.broadcast_to(i, o.shape), o), 0.0)
        np.testing.assert_allclose(f[p], ref, rtol=1e-9, atol=1e-12 * ref.max())
        nonzero += np.sum(ref > 0)
    assert nonzero > 100


# =========================================================================== physics
def _kinematic(feed_um, radius_mm, s_tan, s_rad):
    return {"model": "slope_density", "density": "kinematic", "feed_um": feed_um,
            "nose_radius_mm": radius_mm, "rms_slope_tangential": s_tan,
            "rms_slope_radial": s_rad, "rho_s": 0.4}


def test_kinematic_dot_is_the_closed_form_top_hat():
    """Flat turned plate at normal incidence, no radial random roughness: the rays of one
    pixel land on the monitor (distance d) uniformly over a radial band of full width
    2 f d / r (a point-like dot scanned across it gives this top-hat)."""
    f_mm, r_mm, d = 0.03, 0.5, 500.0
    # the stratified lattice: an equal-weight sample of the density (the default rule
    # weights its nodes, so a histogram of rays would not be flat)
    cfg = _facing_config(0.0, _kinematic(30.0, r_mm, 1e-5, 0.0), d, n_rays=8192,
                         monitor_px=2000, mode="stratified")
    sim = Simulation.from_config(cfg)
    u, v, w, _, _ = sim.transport([0], [0])
    hit = np.isfinite(v[0])
    assert hit.all()
    radial_mm = (v[0][hit] - (2000 - 1) / 2) * 0.1  # from the monitor centre = specular point
    width = radial_mm.max() - radial_mm.min()
    closed = 2 * f_mm * d / r_mm
    assert abs(width / closed - 1) < 0.02, f"width {width:.3f} mm vs {closed:.3f} mm"
    # flat: equal weight in 20 equal bins; nothing outside the exact arcs' band
    # d tan(2 atan(s_max)) each side (0.1 % wider than the small-slope f d / r here)
    s_max = (f_mm / 2) / math.sqrt(r_mm**2 - f_mm**2 / 4)
    exact_half = d * math.tan(2 * math.atan(s_max))
    assert np.abs(radial_mm).max() <= exact_half * (1 + 1e-6)  # + the tiny tangential slopes
    hist, _ = np.histogram(radial_mm, bins=20, range=(-exact_half * (1 + 1e-6), exact_half * (1 + 1e-6)), weights=w[0][hit])
    assert hist.min() / hist.max() > 0.95
    assert np.isclose(hist.sum(), w[0][hit].sum(), rtol=1e-12)
    tangential = np.ptp(u[0][hit]) * 0.1
    assert tangential < 0.02 * closed


@pytest.mark.parametrize("x_target", [1.5, 1.9, 2.6])
def test_kinematic_radial_fringes_follow_sinc_times_gauss(x_target):
    """Radial fringes of period p (k = 2 pi / p) on a monitor at d: modulation
    sin(x)/x exp(-(k d alpha)^2), x = k d f / r, alpha = sqrt(2) x the random RMS slope."""
    f_mm, r_mm, d = 0.03, 0.5, 500.0
    s_rand = 5e-3  # Gaussian factor 0.92 ... 0.98: the test sees it
    k = x_target * r_mm / (d * f_mm)
    alpha = math.sqrt(2) * s_rand
    x = k * d * f_mm / r_mm
    closed = math.sin(x) / x * math.exp(-((k * d * alpha) ** 2))
    cfg = _facing_config(0.0, _kinematic(30.0, r_mm, 1e-4, s_rand), d, n_rays=16384,
                         monitor_px=3000)
    sim = Simulation.from_config(cfg)
    mod = _decoded_modulation(sim.render_fringes((2 * math.pi / k / 0.1,), ("y",), 4))
    assert 0.1 < closed < 0.9
    assert abs(mod / closed - 1) < 0.01, f"modulation {mod:.5f} vs closed form {closed:.5f}"
    sinc_only = math.sin(x) / x
    assert abs(mod / sinc_only - 1) > 0.015  # without the random roughness it would fail


def test_lobe_weight_of_table_is_closed_form():
    """f cos_o / pdf = F G (i.h) / (cos_i cos theta_h), independent of the density."""
    brdf = SlopeDensityBRDF(kinematic_slopes(0.4, 0.5, 0.05, 0.15), 0.5, smith=False)
    i = _i_local(30.0, 0.4)
    rng = np.random.default_rng(1)
    o = brdf.sample(1 - rng.random(500), rng.random(500), i)
    o = o[o[:, 2] > 0]
    h = o + i
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    w = lobe_weight(brdf, np.broadcast_to(i, o.shape), o)
    np.testing.assert_allclose(w, 0.5 * (h @ i) / (i[2] * h[:, 2]), rtol=1e-10)
