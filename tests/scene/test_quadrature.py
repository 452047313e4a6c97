"""Quadrature rules of the bundle and their stated numerical error (issue 18).

The rules' weights and nodes are checked against closed-form moments; the rendered fringe
sums against converged integrals by SciPy's adaptive cubature (tests/naive_quadrature.py,
independent of pmdsim's samplers and kernels) on the Fig. 3 scene with a coarse camera
(same field of view, a few pixels of reference); the stated per-pixel error against the
true error; on a nearest-pixel monitor (rqmc) against a converged reference of a different
method (the randomised lattice with 64 x the rays).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import naive_quadrature as nq
from conftest import make_config
from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.scene import quadrature as q
from pmdsim.scene.sampling import ConeSampling

FIG3 = Path(__file__).parents[2] / "examples" / "paper_fig3.toml"
WIDTHS = (50.0, 400.0, 3200.0)


def fig3(**sampling):
    """The Fig. 3 configuration with a 40 x 32 camera over the same field of view and the
    default sampling except ``sampling``."""
    d = tomllib.loads(FIG3.read_text())
    d["camera"]["resolution"] = [40, 32]
    d["camera"]["pixel_pitch_mm"] = 0.0048 * 32
    keep = {k: d["sampling"][k] for k in ("theta_max_deg", "scheme", "estimator")}
    d["sampling"] = {**keep, **sampling}
    return d


def pick(mask, n, seed):
    rr, cc = np.nonzero(mask)
    k = np.random.default_rng(seed).choice(rr.size, n, replace=False)
    return list(zip(rr[k].tolist(), cc[k].tolist()))


# ----------------------------------------------------------------------------- the rules
def test_cone_rule_integrates_polynomials_and_harmonics():
    rule = q.cone_rule((5, 12))
    assert rule.w.sum() == pytest.approx(1.0, abs=1e-14)
    # Gauss-Legendre with 5 nodes: exact to degree 9 in u1; trapezoid: exact for cos(m 2 pi u2), m < 12
    for k in range(10):
        assert np.sum(rule.w * rule.u1**k) == pytest.approx(1.0 / (k + 1), rel=1e-12)
    for m in range(1, 12):
        assert abs(np.sum(rule.w * np.cos(2 * math.pi * m * rule.u2 + 0.3))) < 1e-13
    assert abs(np.sum(rule.w * np.cos(2 * math.pi * 12 * rule.u2))) > 0.5  # aliasing at m = n


@pytest.mark.parametrize("scheme", ["polar", "solid_angle"])
def test_lobe_mapped_cone_rule_follows_a_narrow_lobe(scheme):
    """A narrow lobe (sigma 0.4 deg) in a 4 deg cone: the radial nodes crowd towards P, and
    the weights (the measure over the lobe's density) integrate a lobe-shaped function of
    u1 several times better than the plain rule of the same size (reference: SciPy's quad)."""
    from scipy.integrate import quad

    tm, sig = math.radians(4.0), math.radians(0.4)
    rule = q.cone_rule((8, 4), scheme, tm, lobe_sigma=sig)
    plain = q.cone_rule((8, 4), scheme, tm)
    assert np.median(rule.u1) < 0.5 * np.median(plain.u1)

    def theta(u):
        return tm * u if scheme == "polar" else np.arccos(1 - u * (1 - math.cos(tm)))

    def g(u):
        t = theta(u) / sig
        return np.exp(-0.5 * t * t) * (1.0 + 0.3 * t + 0.1 * np.cos(2 * t))

    exact = quad(g, 0.0, 1.0, epsabs=0, epsrel=1e-13, points=[0.01, 0.05, 0.2], limit=200)[0]
    mapped = abs(np.sum(rule.w * g(rule.u1)) / exact - 1)
    assert mapped < 1e-3
    assert mapped < 0.2 * abs(np.sum(plain.w * g(plain.u1)) / exact - 1)


def test_hermite_rule_moments_of_the_slopes():
    """Mapped as the kernel maps (u1, u2) to slopes, a = sqrt(-ln u1) cos(2 pi u2) (alpha 1):
    the Gaussian moments E[a^2] = 1/2, E[a^4] = 3/4, E[a^2 b^2] = 1/4, odd moments 0."""
    rule = q.hermite_rule((6, 5))
    r = np.sqrt(-np.log(rule.u1))
    a, b = r * np.cos(2 * math.pi * rule.u2), r * np.sin(2 * math.pi * rule.u2)
    E = lambda v: float(np.sum(rule.w * v))  # noqa: E731
    assert E(np.ones_like(a)) == pytest.approx(1.0, abs=1e-14)
    assert E(a * a) == pytest.approx(0.5, rel=1e-9)
    assert E(a**4) == pytest.approx(0.75, rel=1e-9)
    assert E(b * b) == pytest.approx(0.5, rel=1e-9)
    assert E(a * a * b * b) == pytest.approx(0.25, rel=1e-9)
    assert abs(E(a)) < 1e-9 and abs(E(a**3 * b)) < 1e-9


@pytest.mark.parametrize("order", [(512, 384), (300, 520)])
def test_hermite_rule_high_orders_are_finite_and_exact(order):
    """Orders the pilot's finer rules reach (4 x and 16 x the nodes of a 128 x 128 rule):
    every weight finite (NumPy's hermgauss gave NaN at 512), and the closed form
    E[cos(p a) cos(q b)] = exp(-(p^2 + q^2) / 4) of the Gaussian slopes (alpha 1) holds."""
    rule = q.hermite_rule(order)
    assert np.all(np.isfinite(rule.w)) and np.all(rule.w >= 0)
    assert np.all((rule.u1 >= 0) & (rule.u1 < 1))
    live = rule.w > 0  # corner nodes whose weight underflows to 0 (r up to ~45)
    r = np.sqrt(-np.log(rule.u1[live]))
    a, b = r * np.cos(2 * math.pi * rule.u2[live]), r * np.sin(2 * math.pi * rule.u2[live])
    E = lambda v: float(np.sum(rule.w[live] * v))  # noqa: E731
    assert E(np.ones_like(a)) == pytest.approx(1.0, abs=1e-13)
    assert E(np.cos(3.0 * a) * np.cos(1.3 * b)) == pytest.approx(math.exp(-(9.0 + 1.69) / 4), rel=1e-10)
    assert E(a**4) == pytest.approx(0.75, rel=1e-10)


def test_orders_and_embedded_orders():
    assert q.cone_order(256) == (8, 32)
    assert q.cone_order(100) == (5, 20)
    assert q.square_order(1024) == (32, 32)
    assert q.embedded_order((8, 32)) == (6, 24)
    assert q.embedded_order((1, 4)) == (1, 3)
    assert q.second_embedded_order((8, 32)) == (4, 16)
    assert q.second_embedded_order((16, 16)) == (8, 8)
    assert q.second_embedded_order((1, 4)) == (1, 2)
    # linear orders 16, 12, 8: one step of 4 from the embedded to the rule as to the embedded
    assert q.convergence_exponent((8, 32)) == pytest.approx(1.0)
    assert q.convergence_exponent((5, 20)) == pytest.approx((10 - math.sqrt(60)) / (math.sqrt(60) - math.sqrt(30)))
    assert q.convergence_exponent((1, 1)) is None
    s = ConeSampling(256, math.radians(1.0), mode="rule")
    assert s.rule(False).n == 256 and not s.include_principal
    assert s.ray_weights(False).sum() == pytest.approx(256.0)
    assert [p.part for p in s.error_passes()] == [0, 1, 2]
    assert [p.rule(False).order for p in s.error_passes()] == [(8, 32), (6, 24), (4, 16)]


def test_convergence_factor_follows_a_geometric_error():
    """Differences of a geometrically converging sequence: S_L = S + c rho^L (c complex,
    varying over the pixels) at L = 16, 12, 8 give q = rho^4 = E(16) / E(12); fringes whose
    embedded difference is not small, or whose factor is not below 1/10, get 1."""
    from pmdsim.render.results import ASYMPTOTIC_DIFFERENCE, convergence_factor, phase_error

    rng = np.random.default_rng(4)
    exact = np.exp(1j * rng.uniform(0, 6, (3, 5, 7)))
    c = 1e-2 * (rng.normal(size=(3, 5, 7)) + 1j * rng.normal(size=(3, 5, 7)))
    rho = np.array([0.5, 0.55, 0.9])[:, None, None]
    s16, s12, s8 = (exact + c * rho**L for L in (16, 12, 8))
    q = convergence_factor(s16, s16 - s12, s16 - s8, 1.0)
    # |dS1| / |dS2| = (rho^12 - rho^16) / (rho^8 - rho^16) at every pixel
    expect = (rho**12 - rho**16) / (rho**8 - rho**16)
    assert q[0] == pytest.approx(expect[0, 0, 0], rel=1e-12)
    assert q[1] == pytest.approx(expect[1, 0, 0], rel=1e-12)
    assert q[2] == 1.0  # 0.9^4 = 0.66: not clearly asymptotic
    c = 1e4 * c
    big = convergence_factor(exact + c * rho**16, c * (rho**16 - rho**12), c * (rho**16 - rho**8), 1.0)
    assert np.median(np.abs(c * (rho**16 - rho**12))[0]) > 5 * ASYMPTOTIC_DIFFERENCE
    assert big[0] == 1.0  # the same rate, but the differences are not yet small
    # the statement: 10 q x the phase difference + 0.1 q x the relative difference
    d1 = s16 - s12
    pe = phase_error(s16, d1, "embedded", q)
    across = np.abs((d1 * np.conj(s16)).imag) / np.abs(s16) ** 2
    np.testing.assert_allclose(pe[0], q[0] * (10 * across[0] + 0.1 * np.abs(d1[0]) / np.abs(s16[0])))
    np.testing.assert_allclose(pe[2], across[2] + 0.1 * np.abs(d1[2]) / np.abs(s16[2]))


def test_sobol_replicates_differ_and_repeat():
    a, b = q.sobol_points(64, 3, 0), q.sobol_points(64, 3, 1)
    assert not np.allclose(a.u1, b.u1)
    np.testing.assert_array_equal(a.u1, q.sobol_points(64, 3, 0).u1)
    assert abs(a.u1.mean() - 0.5) < 0.01  # a scrambled (0, m, 2)-net is balanced


# ----------------------------------------------------------------------------- Fig. 3
@pytest.fixture(scope="module")
def fig3_paper():
    cfg = parse_config(fig3(n_rays=256))
    fr = Simulation.from_config(cfg).render_fringes(WIDTHS, ["x", "y"])
    pixels = pick(np.isfinite(fr.sums[0, 0]), 10, 1)
    ref = np.array([nq.cone_sums(cfg, nq.pixel(cfg, r, c), WIDTHS)[0] for r, c in pixels])
    return cfg, fr, pixels, ref


def test_fig3_paper_rule_256_within_0p1_mrad_of_cubature(fig3_paper):
    """Acceptance: the default sampling with only n_rays = 256 gives every fringe's phase
    within 0.1 mrad (P95 over pixels) of the converged integral of the paper's estimator."""
    cfg, fr, pixels, ref = fig3_paper
    assert fr.sampling["mode"] == "rule" and fr.sampling["order"] == [8, 32]
    got = np.array([fr.sums[:, :, r, c] for r, c in pixels])
    err = np.abs(np.angle(got / ref))  # (pixels, directions, widths)
    p95 = np.percentile(err, 95, axis=0) * 1e3
    assert (p95 < 0.1).all(), p95
    # the normalisation is the estimator's: the modulus agrees too
    np.testing.assert_allclose(np.abs(got), np.abs(ref), rtol=2e-4)  # the kernels' polynomial exp


def test_fig3_stated_error_bounds_the_true_error_and_is_not_a_blanket(fig3_paper):
    """The stated error (the pilot against a rule 4 x finer) bounds the error against
    cubature in >= 95 % of (pixel, fringe), and is not far above it on the finest fringes,
    which the deviation's error is taken from (the embedded rules' statement was 9 x in X,
    140 x in Y; the pilot's: tests/render/test_pilot.py)."""
    cfg, fr, pixels, ref = fig3_paper
    pe = fr.phase_error()
    got = np.array([fr.sums[:, :, r, c] for r, c in pixels])
    stated = np.array([pe[:, :, r, c] for r, c in pixels])
    true = np.abs(np.angle(got / ref))
    assert np.mean(stated >= true) >= 0.95
    assert np.all(np.isfinite(stated))
    assert fr.sampling["error"] == "pilot"  # issue 36: the pilot's statement
    ratio = np.median(stated[:, :, 0] / true[:, :, 0], axis=0)  # per direction, 50 px
    assert np.all(ratio < 20), ratio
    assert np.all(ratio > 1), ratio


def test_coarse_rule_error_is_bounded_where_it_matters():
    """A rule too small for the 2 deg cone (n_rays 36: 4 x 8, the azimuths following the
    lobe; 64 nodes are already within 0.01 mrad): real errors of tenths of mrad, and the
    stated error still bounds them in >= 95 % of (pixel, fringe)."""
    cfg = parse_config(fig3(n_rays=36, theta_max_deg=2.0))
    fr = Simulation.from_config(cfg).render_fringes(WIDTHS[1:], ["x", "y"])
    pixels = pick(np.isfinite(fr.sums[0, 0]), 6, 2)
    ref = np.array([nq.cone_sums(cfg, nq.pixel(cfg, r, c), WIDTHS[1:])[0] for r, c in pixels])
    got = np.array([fr.sums[:, :, r, c] for r, c in pixels])
    stated = np.array([fr.phase_error()[:, :, r, c] for r, c in pixels])
    true = np.abs(np.angle(got / ref))
    assert true.max() > 1e-5  # not converged: the check means something
    assert np.mean(stated >= true) >= 0.95


@pytest.mark.parametrize("brdf", [
    {"model": "ward", "alpha_x": 0.025, "alpha_y": 0.002, "rho_s": 0.4},
    {"model": "beckmann", "alpha_u": 0.025, "alpha_v": 0.002, "rho_s": 0.4},
])
def test_fig3_radiometric_gauss_hermite_within_0p1_mrad(brdf):
    """Radiometric estimator, Ward and Beckmann, 256 Gauss-Hermite nodes: every decodable
    fringe (all but X at 50 px, washed out to a modulation ~ 1e-12) within 0.1 mrad of the
    rendering integral by cubature over the micro-normal slopes."""
    d = fig3(n_rays=256, estimator="radiometric")
    d["brdf"] = brdf
    cfg = parse_config(d)
    fr = Simulation.from_config(cfg).render_fringes(WIDTHS, ["x", "y"])
    assert fr.sampling["rule"].startswith("Gauss-Hermite")
    inner = np.zeros(fr.sums.shape[-2:], bool)
    inner[6:26, 8:32] = True  # bundles well inside the monitor (the cubature's edges)
    pixels = pick(inner & np.isfinite(fr.sums[0, 0]), 3, 3)
    for r, c in pixels:
        px = nq.pixel(cfg, r, c)
        sx = nq.lobe_sums(cfg, px, WIDTHS[1:], ("x",))[0][0]
        sy = nq.lobe_sums(cfg, px, WIDTHS, ("y",))[0][0]
        err = np.concatenate([np.angle(fr.sums[0, 1:, r, c] / sx), np.angle(fr.sums[1, :, r, c] / sy)])
        assert np.abs(err).max() * 1e3 < 0.1, err
        stated = np.concatenate([fr.phase_error()[0, 1:, r, c], fr.phase_error()[1, :, r, c]])
        # bounded, or below the reference's own tolerance (Gauss-Hermite is all but exact
        # here: 16 x 16 agrees with 64 x 64 to 4e-12 rad; the statement's floor is 1e-9 rad)
        assert np.all(stated >= 1e-9)
        assert np.mean((stated >= np.abs(err)) | (np.abs(err) < 1e-9)) >= 0.95


# ----------------------------------------------------------------------------- nearest monitor
def test_nearest_monitor_rqmc_error_bounds_the_true_one():
    """A nearest-pixel monitor (steps in the integrand) in mode 'rqmc' (8 scrambled Sobol
    replicates): the stated 95 % error must bound the error against a converged reference
    of another method (the Cranley-Patterson-rotated lattice, 64 x the rays) in about 95 %
    of the pixels. (Mode 'rule' renders the control variate: tests/render/test_control_variate.py.)"""
    cfg = make_config(sampling={"n_rays": 256, "mode": "rqmc"}, monitor={"pixel_model": "nearest"})
    sim = Simulation.from_config(cfg)
    fr = sim.render_fringes([20.0], ["x", "y"])
    assert fr.sampling["mode"] == "rqmc" and fr.sampling["error"] == "replicates"
    ref = Simulation.from_config(make_config(
        sampling={"n_rays": 16384, "mode": "random", "seed": 5},
        monitor={"pixel_model": "nearest"})).render_fringes([20.0], ["x", "y"])
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.isfinite(fr.sums) & np.isfinite(ref.sums) & (np.abs(ref.sums) > 0.2 * ref.f_hit)
        true = np.abs(np.angle(fr.sums / ref.sums))[ok]
    stated = fr.phase_error()[ok]
    assert true.size > 500
    assert np.mean(stated >= true) >= 0.95  # measured 0.985-0.99 over seeds 0-2
    assert np.median(stated) < 20 * np.median(true)  # an error statement, not a blanket


def test_dots_and_images_return_their_rqmc_error():
    """Dots and monitor images (step integrands: the default rule renders rqmc) return
    their values' numerical error with ``with_error=True``: 95 % half-widths that bound
    the difference to a converged reference of another method (the randomised lattice,
    64 x the rays) in >= 90 % of the values (measured: dots 100 %, images 97 %), and are
    not a blanket (median stated / true below 20)."""
    from pmdsim import patterns

    sim = Simulation.from_config(make_config(sampling={"n_rays": 256, "mode": "rule"}))
    ref = Simulation.from_config(make_config(sampling={"n_rays": 16384, "mode": "random",
                                                       "seed": 5}))
    dots = patterns.dot_grid(sim.scene.monitor.shape, grid=(2, 2), size=40)
    levels = np.random.default_rng(0).random((2,) + sim.scene.monitor.shape)
    for got, want in ((sim.render_dots(dots, with_error=True), ref.render_dots(dots)),
                      (sim.render_images(levels, with_error=True), ref.render_images(levels))):
        (img, err), ok = got, np.isfinite(got[0]) & np.isfinite(want)
        ok &= want > 0.05 * np.nanmax(want)
        true = np.abs(img - want)[ok]
        assert ok.sum() > 200 and err.shape == img.shape
        assert np.mean(err[ok] >= true) >= 0.9
        assert np.median(err[ok]) < 20 * np.median(true)
    assert sim.render_dots(dots).shape == (4,) + img.shape[1:]  # default: the images alone
    lattice = Simulation.from_config(make_config(sampling={"mode": "stratified"}))
    assert lattice.render_dots(dots, with_error=True)[1] is None


def test_modes_keep_their_earlier_meaning():
    """Mode 'stratified' is the earlier default (P + lattice, equal weights, no error)."""
    cfg = make_config(sampling={"mode": "stratified"})
    fr = Simulation.from_config(cfg).render_fringes([20.0], ["x"])
    assert fr.sums_err is None and fr.phase_error() is None
    assert fr.sampling["mode"] == "stratified"


# ----------------------------------------------------------------------------- error control
def test_target_error_raises_the_order_until_met():
    """The pilot doubles the order from n_rays until its statement meets the target, then
    renders that rule (issue 36: on the pilot's grid, the camera once)."""
    cfg = make_config(sampling={"mode": "rule", "n_rays": 16, "target_error_mrad": 0.01},
                      monitor={"pixel_model": "continuous"})
    sim = Simulation.from_config(cfg)
    fr = sim.render_fringes([40.0], ["x", "y"])
    info = fr.sampling
    assert info["target_met"] and info["n_rays"] > 16
    assert info["achieved_p95_mrad"] <= 0.01
    from pmdsim.render.results import worst_phase_error

    assert worst_phase_error(fr) * 1e3 == pytest.approx(info["achieved_p95_mrad"])
    # the order before the last did not meet it (the doubling stopped at the first that did)
    half = Simulation.from_config(make_config(
        sampling={"mode": "rule", "n_rays": info["n_rays"] // 2},
        monitor={"pixel_model": "continuous"})).render_fringes([40.0], ["x", "y"])
    assert worst_phase_error(half) * 1e3 > 0.01


def test_target_error_out_of_reach_warns_with_the_figure():
    cfg = make_config(sampling={"mode": "rule", "n_rays": 16, "max_rays": 32,
                                "target_error_mrad": 1e-9},
                      monitor={"pixel_model": "continuous"})
    with pytest.warns(UserWarning, match=r"target_error_mrad = 1e-09 not met: the stated phase "
                      r"error is .* mrad .* n_rays = 32.*raise sampling.max_rays"):
        fr = Simulation.from_config(cfg).render_fringes([40.0], ["x"])
    assert not fr.sampling["target_met"] and fr.sampling["n_rays"] == 32


def test_target_error_needs_an_error_estimate():
    from pmdsim.config import ConfigError

    with pytest.raises((ConfigError, ValueError), match="target_error_mrad needs an error estimate"):
        make_config(sampling={"mode": "stratified", "target_error_mrad": 0.1})
