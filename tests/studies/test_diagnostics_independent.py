"""Diagnostics against independent values (issue 9).

The warnings of ``check`` are tested on hand-made :class:`Diagnostics` (every number known),
the per-pixel quantities against slow loops (``tests/naive_stats.py``), quadrature, or a
direct recomputation through another code path of the renderer (fringe sums instead of the
ray transport). Each docstring names the bug it guards against.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import naive_stats as ns
from conftest import make_config
from pmdsim.studies import diagnostic_warnings as dw
from pmdsim.studies import diagnostics as dg
from pmdsim.render import Simulation
from pmdsim.scene.sampling import ConeSampling


# =========================================================================== hand-made inputs
def _grid(gr=3, gc=7):
    return dg.PixelGrid(np.arange(gr) * 5, np.arange(gc) * 4, (gr * 5, gc * 4))


def _diag(phase_se, *, estimator="paper", n_rays=100, ess=None, modulation=None,
          directions=("x", "y"), widths=(40.0, 400.0), energy=None, theta_max_deg=1.0):
    grid = _grid()
    shape = grid.grid_shape
    nd, nw = len(directions), len(widths)
    ess = np.full(shape, 0.5 * n_rays) if ess is None else ess
    modulation = np.full((nd, nw) + shape, 0.8) if modulation is None else modulation
    rays = dg.RayStatistics(n_rays, ess, phase_se, modulation, directions, widths, grid)
    return dg.Diagnostics(estimator, n_rays, theta_max_deg, directions, widths, grid,
                          np.ones(grid.shape, bool), energy, rays, "seeds", phase_se)


def _ramp(top_p95, n=21):
    """n values 0..x whose P95 (linear interpolation, rank 19 of 0..20) is ``top_p95``."""
    return np.linspace(0.0, top_p95 * (n - 1) / (0.95 * (n - 1)), n)


def test_suggested_n_rays_follows_n_times_ratio_squared():
    """N (se / target)^2 rounded up to two significant digits, se the P95 over pixels of the
    worst measurable fringe: N = 100, P95 3.3 mrad, target 1 mrad -> 1089 -> 1100; target
    0.5 mrad with P95 1.1 mrad -> 484 -> 490. Guards against N se / target (no square), the
    median or the maximum instead of the P95, rounding down, choosing the fringe by its
    median."""
    for n_rays, p95, target, expected in ((100, 3.3e-3, 1.0, 1100), (100, 1.1e-3, 0.5, 490),
                                          (64, 1.7e-3, 1.0, 190)):
        se = np.zeros((2, 2, 3, 7))
        se[0, 0] = _ramp(p95).reshape(3, 7)            # x / 40: the largest P95 ...
        se[1, 0] = 0.8 * p95                             # y / 40: ... but the larger median
        se[1, 1] = 0.1 * p95
        se[0, 1] = 0.2 * p95
        assert np.percentile(se[0, 0], 95) == pytest.approx(p95, rel=1e-12)
        warns = dw.check(_diag(se, n_rays=n_rays), max_phase_error_mrad=target,
                         min_energy_fraction=0.0)
        w = {x.code: x for x in warns}["phase_error"]
        assert w.setting == "sampling.n_rays" and w.suggested == expected, (n_rays, p95, target)
        assert "x fringes of 40 px" in w.message
        assert f"{p95 * 1e3:.2g} mrad" in w.message


def test_phase_error_below_target_gives_no_warning_and_washed_out_fringes_are_skipped():
    """P95 at 0.9 x the target: no warning; a fringe with median modulation 0.04 (< 0.05)
    and a noise floor below it (ESS 4000: 2 / sqrt(ESS) = 0.03) is washed out, a wider width
    is suggested, and its (huge) error is not what sets N. Guards against a '<' / '>' swap,
    the washed-out fringe entering the worst-fringe choice."""
    se = np.full((2, 2, 3, 7), 0.9e-3)
    se[0, 0] = 5.0                                   # washed out: its phase is noise
    mod = np.full((2, 2, 3, 7), 0.8)
    mod[0, 0] = 0.04
    kw = dict(modulation=mod, n_rays=5000, ess=np.full((3, 7), 4000.0))
    warns = dw.check(_diag(se, **kw), max_phase_error_mrad=1.0)
    assert [w.code for w in warns] == ["washed_out"]
    assert "x fringes of 40 px" in warns[0].message
    assert warns[0].setting == "patterns.fringes.widths_px" and 40.0 not in warns[0].suggested
    se[1, 1] = 1.2e-3
    warns = dw.check(_diag(se, **kw), max_phase_error_mrad=1.0)
    w = {x.code: x for x in warns}["phase_error"]
    assert w.suggested == 7200 and "y fringes of 400 px" in w.message   # 5000 x 1.44


def test_modulation_within_the_noise_floor_is_undetermined():
    """Modulation 0.3 is measurable with ESS 100 (floor 2 / sqrt(100) = 0.2) but not with
    ESS 25 (floor 0.4 > 0.05): 'modulation_undetermined', raise N to bring the floor below
    the 5 % bound: 100 x 1.5 x (0.4 / 0.05)^2 = 9600. Guards against a floor of
    1 / sqrt(ESS) or 2 / ESS, the square missing in the suggestion."""
    se = np.full((1, 1, 3, 7), 1e-4)
    mod = np.full((1, 1, 3, 7), 0.3)
    kw = dict(directions=("x",), widths=(40.0,), modulation=mod, n_rays=100)
    assert dw.check(_diag(se, ess=np.full((3, 7), 100.0), **kw)) == []
    warns = dw.check(_diag(se, ess=np.full((3, 7), 25.0), **kw))
    assert [w.code for w in warns] == ["modulation_undetermined"]
    assert warns[0].setting == "sampling.n_rays" and warns[0].suggested == 9600


def test_ess_warning_fires_below_the_fraction_only_for_cone_estimators():
    """Median ESS 9.9 of 100 rays < 10 %: warning naming sampling.estimator = radiometric;
    10.0 (exactly 10 %) and 10.1: none; the radiometric estimator is never told to switch to
    itself. Guards against the warning never firing (as before issue 9 nothing asserted it
    did), a threshold of min_ess_fraction / N, the mean instead of the median."""
    se = np.full((2, 2, 3, 7), 1e-5)
    ess = np.full((3, 7), 9.9)
    ess[0, :3] = 1000.0                   # a few large values: mean 150, median 9.9
    warns = dw.check(_diag(se, ess=ess))
    w = {x.code: x for x in warns}["effective_sample_size"]
    assert (w.setting, w.suggested) == ("sampling.estimator", "radiometric")
    assert "effective sample size 9.9 of 100 rays" in w.message
    for value in (10.0, 10.1):
        assert dw.check(_diag(se, ess=np.full((3, 7), value))) == []
    assert dw.check(_diag(se, ess=ess, estimator="radiometric")) == []
    assert [x.code for x in dw.check(_diag(se, ess=np.full((3, 7), 20.0)),
                                     min_ess_fraction=0.25)] == ["effective_sample_size"]


def test_energy_warning_names_the_cone_that_keeps_the_target():
    """Median fraction 0.375 < 0.95: 'holds 38 %', min, and theta_max >= ceil(10 x 3.91) / 10
    = 4 deg (the worst pixel); with a target other than the bound, no number is suggested.
    Guards against the median replaced by the min or mean, rounding the angle down, the
    suggestion taken from the median pixel."""
    grid = _grid()
    frac = np.full(grid.grid_shape, 0.375)
    frac[0, 0] = 0.30
    frac[0, 1:4] = 0.9
    need = np.full(grid.grid_shape, 3.2)
    need[2, 6] = 3.91
    e = dg.EnergyFraction(1.0, 0.95, frac, need, np.ones(grid.grid_shape), grid)
    se = np.full((2, 2, 3, 7), 1e-5)
    w = {x.code: x for x in dw.check(_diag(se, energy=e))}["energy_fraction"]
    assert w.setting == "sampling.theta_max_deg" and w.suggested == 4.0
    assert "holds 38 %" in w.message and "min 30 %" in w.message and ">= 4 deg" in w.message
    e90 = dg.EnergyFraction(1.0, 0.90, frac, need, np.ones(grid.grid_shape), grid)
    w = {x.code: x for x in dw.check(_diag(se, energy=e90))}["energy_fraction"]
    assert w.suggested is None
    assert not [x for x in dw.check(_diag(se, energy=e, estimator="radiometric"))
                if x.code == "energy_fraction"]
    assert dw.check(_diag(se, energy=e), min_energy_fraction=0.37) == []


def test_nice_up_rounds_up_to_two_digits():
    """1089 -> 1100, 190 -> 190, 184.96 -> 190, 7.2 -> 8, 12345 -> 13000."""
    assert [dw._nice_up(x) for x in (1089, 190, 184.96, 7.2, 12345)] == [1100, 190, 190, 8, 13000]


def test_pixel_grid_spread_and_order():
    """Rows and columns spread with the corners, pixel_rows/cols in row-major order
    (guards against swapped repeat/tile, which transposes every diagnostics map)."""
    g = dg.PixelGrid.spread((30, 40), 5, 3)
    np.testing.assert_array_equal(g.rows, [0, 14, 29])   # linspace(0, 29, 3) = 0, 14.5, 29
    np.testing.assert_array_equal(g.cols, [0, 10, 20, 29, 39])
    np.testing.assert_array_equal(g.pixel_rows, [0] * 5 + [14] * 5 + [29] * 5)
    np.testing.assert_array_equal(g.pixel_cols, [0, 10, 20, 29, 39] * 3)
    assert g.grid_shape == (3, 5)


# =========================================================================== per-pixel numbers
def test_delta_method_equals_the_slow_formula_with_nearest_ties():
    """se = std_{ddof=1}(Im(z_p e^{-i arg Z})) / (sqrt(N) |mean z|) and the modulation
    |sum w e^{ikc}| / sum w, by loops; nearest pixel centres floor(c + 0.5) with ties at
    x.5 (NumPy's round would go to even). Guards against ddof = 0, sqrt(N) missing, the
    modulation normalised by N, round() instead of floor(c + 0.5), misses counted as c = NaN."""
    rng = np.random.default_rng(11)
    k, n = 5, 37
    u = np.round(rng.normal(50.0, 4.0, (k, n)) * 2) / 2       # many exact x.5 values
    v = rng.normal(20.0, 3.0, (k, n))
    w = rng.uniform(0.2, 1.0, (k, n))
    u[0, :5] = np.nan
    w[0, :5] = 0.0                                              # misses: weight 0
    se, mod = dg.phase_error_from_rays(u, v, w, (13.0,), ("x", "y"), nearest=True)
    for di, coords in enumerate((u, v)):
        for p in range(k):
            c = [math.floor(x + 0.5) if math.isfinite(x) else 0.0 for x in coords[p]]
            z = [wt * complex(math.cos(2 * math.pi * cc / 13), math.sin(2 * math.pi * cc / 13))
                 for wt, cc in zip(w[p], c)]
            zbar = sum(z) / n
            rot = complex(math.cos(-math.atan2(zbar.imag, zbar.real)),
                          math.sin(-math.atan2(zbar.imag, zbar.real)))
            q = [(zz * rot).imag for zz in z]
            qm = sum(q) / n
            sd = math.sqrt(sum((x - qm) ** 2 for x in q) / (n - 1))
            assert se[di, 0, p] == pytest.approx(sd / (math.sqrt(n) * abs(zbar)), rel=1e-10)
            assert mod[di, 0, p] == pytest.approx(abs(sum(z)) / sum(w[p]), rel=1e-12)
    ph = dg.ray_phases(u, v, w, (13.0,), ("x",), nearest=True)
    c0 = np.floor(np.where(np.isfinite(u), u, 0.0) + 0.5)
    np.testing.assert_allclose(ph[0, 0], np.angle((w * np.exp(2j * np.pi * c0 / 13)).sum(-1)),
                               atol=1e-12)


def _near_pi_setup():
    """Base scene, mode random, 12 rays of a Ward lobe; one pixel whose fringe phase sits on
    the +-pi branch cut: width = 2 x the bundle's weighted-mean u (wide fringes: the phase is
    k times the centroid, so it is pi up to the centroid's sampling noise)."""
    cfg = make_config(brdf={"alpha_x": 0.03, "alpha_y": 0.02},
                      monitor={"pixel_model": "continuous"},
                      sampling={"mode": "random", "n_rays": 12, "theta_max_deg": 4.0,
                                "seed": 1000})
    sim = Simulation.from_config(cfg)
    r, c = 16, 20
    u, _, w, _, _ = sim.transport([r], [c])
    hit = np.isfinite(u[0])
    centroid = float(np.sum(w[0][hit] * u[0][hit]) / np.sum(w[0][hit]))
    width = 2.0 * centroid
    return cfg, sim, r, c, width


def test_seeds_phase_error_equals_a_direct_recomputation_across_the_branch_cut():
    """phase_error_seeds against the fringe *renderer* run once per seed (another code path
    than the ray transport the diagnostics use): per-seed phases arg(sums), the circular
    standard deviation about their mean with n - 1 degrees of freedom, by loops. The phases
    straddle +-pi, so a missing wrap gives ~pi instead of ~0.01 rad. Agreement 1e-9
    (relative). Guards against: n instead of n - 1, the arithmetic instead of the circular
    mean, no wrap of the deviations, seeds not first_seed + k, mode stratified."""
    cfg, sim, r, c, width = _near_pi_setup()
    grid = dg.PixelGrid(np.array([r]), np.array([c]), sim.shape)
    n_seeds = 8
    se = dg.phase_error_seeds(sim, grid, (width,), ("x",), n_seeds=n_seeds, first_seed=500)
    phases = []
    sc = sim.scene
    for k in range(n_seeds):
        s = sc.sampling
        samp = ConeSampling(s.n_rays, s.theta_max, s.scheme, "random", 500 + k)
        run = Simulation(sc.replace(sampling=samp), sim.tile_rows, sim.scheduler, sim.num_workers)
        sums = run.render_fringes((width,), ("x",), 4).sums
        phases.append(float(np.angle(sums[0, 0, r, c])))
    assert max(phases) > 3.0 and min(phases) < -3.0, phases     # really across the cut
    expected = ns.circular_std_about_mean(phases, ddof=1)
    assert 1e-3 < expected < 0.3
    assert se.shape == (1, 1, 1, 1)
    assert se[0, 0, 0, 0] == pytest.approx(expected, rel=1e-9)


def test_seeds_error_agrees_with_many_seeds_brute_force():
    """The 8-seed estimate is an estimate of the spread over *all* seeds: its RMS over the
    pixels agrees with the brute-force spread over 64 seeds (two independent 64-seed sets
    agree to 0.2 %; 8-seed sets scatter by 0.87-1.12 over six first seeds, measured, so
    the window is 0.75-1.33; the seeds are fixed, the test is deterministic). Guards
    against an error that does not estimate the run-to-run spread (a standard error of the
    mean: x 0.35; a variance instead of a deviation)."""
    cfg = make_config(brdf={"alpha_x": 0.02, "alpha_y": 0.01},
                      sampling={"mode": "random", "n_rays": 24, "theta_max_deg": 3.0})
    sim = Simulation.from_config(cfg)
    grid = dg.PixelGrid(np.arange(6, 27, 4), np.arange(8, 33, 4), sim.shape)
    valid, _ = dg.incidence(sim.scene, grid.pixel_rows, grid.pixel_cols)
    se8 = dg.phase_error_seeds(sim, grid, (40.0,), ("x", "y"), n_seeds=8, first_seed=0)
    se64 = dg.phase_error_seeds(sim, grid, (40.0,), ("x", "y"), n_seeds=64, first_seed=100)
    ok = np.isfinite(se8) & np.isfinite(se64) & (se64 > 0)
    assert ok.sum() >= 30
    ratio = math.sqrt(np.mean(se8[ok] ** 2) / np.mean(se64[ok] ** 2))
    assert 0.75 < ratio < 1.33, ratio
    assert np.all(np.isnan(se8.reshape(2, 1, -1)[..., ~valid]))


def test_ess_of_a_narrow_lobe_in_a_wide_cone_matches_quadrature_and_warns():
    """Paper estimator, polar cone of 5 deg, isotropic Ward lobe alpha 0.003 at near-normal
    incidence (3 deg): the rays sample the cone uniformly in (theta, phi), so
    ESS / N -> (E f)^2 / E f^2 over that density, computed here by Gauss-Legendre quadrature
    of the BRDF; about 0.086 N here (alpha sqrt(2 pi) / theta_max) (measured within 3 %). ``diagnose`` + ``check`` warn.
    Guards against an ESS of sum w^2 / (sum w)^2, over all rays instead of the hits, the
    warning never firing on a real run."""
    from pmdsim.brdf import Ward

    t = math.radians(3.0)
    cfg = make_config(
        camera={"position_mm": [0.0, -300.0 * math.sin(t), 300.0 * math.cos(t)],
                "look_at_mm": [0.0, 0.0, 0.0]},
        monitor={"centre_mm": [0.0, 200.0 * math.sin(t), 200.0 * math.cos(t)],
                 "look_at_mm": [0.0, 0.0, 0.0]},
        brdf={"alpha_x": 0.003, "alpha_y": 0.003},
        sampling={"n_rays": 401, "theta_max_deg": 5.0})
    sim = Simulation.from_config(cfg)
    rows, cols = np.array([12, 16, 20]), np.array([14, 20, 26])
    u, _, w, _, _ = sim.transport(rows, cols)
    assert np.all(np.isfinite(u))                      # whole cones on the monitor
    ess = dg.ess_from_weights(w)
    valid, i_local = dg.incidence(sim.scene, rows, cols)
    brdf = Ward(0.003, 0.003, 0.4)
    th_max = math.radians(5.0)
    x, wx = np.polynomial.legendre.leggauss(400)
    theta = 0.5 * th_max * (x + 1)
    wth = 0.5 * th_max * wx
    phi = np.arange(256) * 2 * np.pi / 256
    T, P = np.meshgrid(theta, phi, indexing="ij")
    for p in range(3):
        i = i_local[p]
        pdir = i * np.array([-1.0, -1.0, 1.0])
        e1 = np.cross([0.0, 1.0, 0.0], pdir)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(pdir, e1)
        o = ((np.sin(T) * np.cos(P))[..., None] * e1 + (np.sin(T) * np.sin(P))[..., None] * e2
             + np.cos(T)[..., None] * pdir)
        f = brdf.evaluate(np.broadcast_to(i, o.shape), o)
        ef = np.sum(f * wth[:, None]) / (th_max * 256)
        ef2 = np.sum(f * f * wth[:, None]) / (th_max * 256)
        expected = 401 * ef * ef / ef2
        assert 0.07 * 401 < expected < 0.1 * 401
        print(p, ess[p], expected)
        assert ess[p] == pytest.approx(expected, rel=0.05), (p, ess[p], expected)
    diag = dg.diagnose(sim, widths=(400.0,), directions=("x",), grid=(4, 3),
                       phase_method="delta", n_samples=1024)
    warns = {x.code: x for x in dw.check(diag, max_phase_error_mrad=1e3)}
    assert "effective_sample_size" in warns
    assert diag.summary["ess_median"] < 0.1 * 401


# =========================================================================== derived numbers
def test_fig3_energy_numbers_are_derived_by_quadrature():
    """The Fig. 3 lobe (Ward 0.025 / 0.002, 25 deg) in the pipeline tests' tiny scene: the
    energy fraction inside 1 deg and the cone holding 95 % from ``lobe_energy`` (importance
    sampling, 16384 points) equal a deterministic quadrature (``tests/naive_lobe.py``) at the
    pixels of smallest, median and largest incidence (fraction 1e-3, angle 0.01 deg), and the
    numbers the docs quote (37.5 %, 3.97 deg) are what the quadrature gives, not a run's
    output. Guards against an energy fraction without cos(theta_o), the angle to the
    camera's mirror direction taken about i instead of P, the quantile off by one sample."""
    import naive_lobe
    from test_pipeline import tiny_config_dict
    from pmdsim.config import parse_config

    cfg = parse_config(tiny_config_dict())
    sim = Simulation.from_config(cfg)
    grid = dg.PixelGrid.spread(sim.shape, 24, 20)
    frac, theta, per_pixel = naive_lobe.fig3_numbers(cfg, grid.pixel_rows, grid.pixel_cols)
    rows = np.array([p[0] for p in per_pixel])
    cols = np.array([p[1] for p in per_pixel])
    valid, i_local = dg.incidence(sim.scene, rows, cols)
    assert valid.all()
    f, need, _ = dg.lobe_energy(sim.scene.brdf, i_local, math.radians(1.0))
    for k, (_, _, fq, thq) in enumerate(per_pixel):
        assert f[k, 0] == pytest.approx(fq, abs=1e-3)
        assert math.degrees(need[k]) == pytest.approx(thq, abs=0.01)
    assert round(100 * frac, 1) == 37.5          # docs/physics.md: "holds 37.5 %"
    assert round(theta, 2) == 3.97               # docs/physics.md: "95 % needs 3.97 deg"


# =========================================================================== edges and wiring
def test_check_boundaries_are_strict():
    """Exactly at a bound nothing is reported: P95 phase error = 1 mrad (target 1 mrad),
    median energy fraction = the minimum, median modulation = 2 / sqrt(ESS). Guards against
    '>' / '<' turned into '>=' / '<=' (a warning for a run that meets its bound)."""
    se = np.full((1, 1, 3, 7), 1e-3)
    kw = dict(directions=("x",), widths=(40.0,), n_rays=100)
    assert dw.check(_diag(se, **kw), max_phase_error_mrad=1.0) == []
    grid = _grid()
    e = dg.EnergyFraction(1.0, 0.95, np.full(grid.grid_shape, 0.375),
                          np.full(grid.grid_shape, 3.9), np.ones(grid.grid_shape), grid)
    assert dw.check(_diag(se, energy=e, **kw), min_energy_fraction=0.375) == []
    mod = np.full((1, 1, 3, 7), 0.2)          # ESS 100: floor 2 / 10 = 0.2 exactly
    assert dw.check(_diag(se * 0.1, ess=np.full((3, 7), 100.0), modulation=mod, **kw)) == []
    # the default smallest measurable modulation is 5 %: 6 % with a low noise floor is fine
    mod = np.full((1, 1, 3, 7), 0.06)
    assert dw.check(_diag(se * 0.1, ess=np.full((3, 7), 1e4), modulation=mod, **kw)) == []
    assert [w.code for w in dw.check(_diag(se * 0.1, ess=np.full((3, 7), 1e4), modulation=mod,
                                           **kw), min_modulation=0.07)] == ["washed_out"]


def test_ess_over_the_last_axis_of_any_shape():
    """(sum w)^2 / sum w^2 over the last axis for a (2, 3, 4) array, by loops."""
    w = np.random.default_rng(3).uniform(0.0, 1.0, (2, 3, 4))
    ess = dg.ess_from_weights(w)
    for a in range(2):
        for b in range(3):
            assert ess[a, b] == pytest.approx(sum(w[a, b]) ** 2 / sum(w[a, b] ** 2), rel=1e-12)


def test_energy_summary_statistics():
    """EnergyFraction.summary: median and min of the fraction, max and median of the angle,
    over the pixels that see the surface (NaN elsewhere). Guards against min/max or
    median/mean swaps, NaN pixels included."""
    grid = _grid()
    frac = np.linspace(0.2, 0.9, 21).reshape(3, 7) ** 2
    need = np.linspace(1.0, 5.0, 21).reshape(3, 7) ** 2
    frac[0, 0] = need[0, 0] = np.nan
    e = dg.EnergyFraction(1.0, 0.95, frac, need, np.ones(grid.grid_shape), grid)
    s = e.summary()
    ok = np.isfinite(frac)
    assert s["fraction_median"] == pytest.approx(ns.percentile_linear(frac[ok], 50), rel=1e-12)
    assert s["fraction_min"] == pytest.approx(min(frac[ok]), rel=1e-12)
    assert s["theta_needed_deg_max"] == pytest.approx(max(need[ok]), rel=1e-12)
    assert s["theta_needed_deg_median"] == pytest.approx(ns.percentile_linear(need[ok], 50),
                                                         rel=1e-12)
    empty = dg.EnergyFraction(1.0, 0.95, np.full((3, 7), np.nan), need, need, grid)
    assert set(empty.summary()) == {"theta_max_deg", "target"}


def test_full_map_on_a_line_and_beyond_the_nodes():
    """A grid of one row: every camera pixel takes the value of the nearest grid column (no
    interpolation along a line); a grid whose nodes do not reach the image corners
    extrapolates a linear field exactly. Guards against the degenerate branch taken for
    2-D grids or the other axis, |.| dropped from the distances, bounds errors."""
    g = dg.PixelGrid(np.array([5]), np.array([0, 10, 20]), (12, 21))
    full = dg.full_map(np.array([[1.0, 2.0, 3.0]]), g)
    cols = np.arange(21)
    expected = np.array([1.0, 2.0, 3.0])[np.abs(cols[:, None] - [0, 10, 20]).argmin(1)]
    np.testing.assert_array_equal(full, np.broadcast_to(expected, (12, 21)))
    g = dg.PixelGrid(np.array([0, 4, 9, 11]), np.array([7]), (12, 21))
    full = dg.full_map(np.array([[1.0], [2.0], [3.0], [4.0]]), g)
    np.testing.assert_array_equal(full[:, 0], [1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4])  # ties: first
    stacked = dg.full_map(np.stack([np.array([[1.0, 2.0, 3.0]]), np.array([[4.0, 5.0, 6.0]])]),
                          dg.PixelGrid(np.array([5]), np.array([0, 10, 20]), (12, 21)))
    assert stacked.shape == (2, 12, 21)                       # leading axes kept
    np.testing.assert_array_equal(stacked[1] - stacked[0], 3.0)
    g = dg.PixelGrid(np.array([5, 10]), np.array([5, 15]), (20, 20))
    rr, cc = np.meshgrid(g.rows, g.cols, indexing="ij")
    full = dg.full_map(3.0 * rr - 2.0 * cc + 1.0, g)
    r, c = np.mgrid[0:20, 0:20]
    np.testing.assert_allclose(full, 3.0 * r - 2.0 * c + 1.0, atol=1e-12)


def test_nice_up_of_nothing_is_zero():
    """0, negative and non-finite ray counts give 0 (no suggestion), not an error."""
    assert [dw._nice_up(x) for x in (0.0, -5.0, float("inf"), float("nan"))] == [0, 0, 0, 0]


def test_phase_error_of_empty_and_single_ray_bundles():
    """No ray on the monitor: NaN error and modulation (not inf, not 0); one ray: the error is
    unknown, reported as inf. Guards against '> 0' turned into '>= 0', n > 1 into n >= 1."""
    u = np.array([[np.nan, np.nan, np.nan], [10.0, 11.0, 12.0]])
    w = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    se, mod = dg.phase_error_from_rays(u, u, w, (20.0,), ("x",), nearest=False)
    assert np.isnan(se[0, 0, 0]) and np.isnan(mod[0, 0, 0])
    assert np.isfinite(se[0, 0, 1]) and mod[0, 0, 1] == pytest.approx(
        abs(np.exp(2j * np.pi * u[1] / 20).mean()), rel=1e-12)
    assert np.isnan(dg.ray_phases(u, u, w, (20.0,), ("x",), nearest=False)[0, 0, 0])
    se1, _ = dg.phase_error_from_rays(u[1:, :1], u[1:, :1], w[1:, :1], (20.0,), ("x",), False)
    assert se1[0, 0, 0] == np.inf


def test_lobe_energy_skips_rows_without_incidence():
    """Rows of i_local that are NaN or grazing (i_z = 0) give NaN, the others their values
    (guards against '> 0' turned into '>= 0' and a chunk loop that drops rows)."""
    from pmdsim.brdf import Ward

    t = math.radians(20.0)
    good = [-math.sin(t), 0.0, math.cos(t)]
    i = np.array([good, [np.nan] * 3, [1.0, 0.0, 0.0]] + [good] * 18)
    frac, need, albedo = dg.lobe_energy(Ward(0.05, 0.05), i, math.radians(4.0), n_samples=512,
                                        chunk=4)
    bad = np.array([False, True, True] + [False] * 18)
    assert np.all(np.isnan(frac[bad])) and np.all(np.isnan(albedo[bad]))
    assert np.all(np.isfinite(frac[~bad])) and np.all(np.isfinite(need[~bad]))
    np.testing.assert_allclose(frac[~bad], frac[0, 0], rtol=1e-12)


def test_diagnose_wiring_summary_and_masks():
    """diagnose on a grid that includes pixels off the plate: default width 50 px, the
    delta method's error is ray_statistics' (the same arrays), ESS / error / modulation are
    those of the transported rays at the grid pixels (nearest monitor: floor(c + 0.5)) and
    NaN off the plate, and the summary holds their median, minimum and P95. Guards against
    the summary's percentiles swapped, the nearest flag inverted, masks not applied."""
    sim = Simulation.from_config(make_config(sampling={"n_rays": 24, "theta_max_deg": 2.0}))
    diag = dg.diagnose(sim, grid=(5, 4), phase_method="delta", n_samples=512)
    assert diag.widths == (50.0,) and diag.directions == ("x", "y")
    g = diag.grid
    assert np.array_equal(diag.phase_se, diag.rays.phase_se, equal_nan=True)
    valid, _ = dg.incidence(sim.scene, g.pixel_rows, g.pixel_cols)
    assert valid.any() and not valid.all()
    u, v, w, _, _ = sim.transport(g.pixel_rows, g.pixel_cols)
    se, mod = dg.phase_error_from_rays(u, v, w, (50.0,), ("x", "y"), nearest=True)
    ess = dg.ess_from_weights(w)
    shape = g.grid_shape
    np.testing.assert_allclose(diag.rays.ess[valid.reshape(shape)], ess[valid], rtol=1e-12)
    assert np.all(np.isnan(diag.rays.ess[~valid.reshape(shape)]))
    np.testing.assert_allclose(diag.rays.phase_se.reshape(2, 1, -1)[..., valid],
                               se[..., valid], rtol=1e-12)
    np.testing.assert_allclose(diag.rays.modulation.reshape(2, 1, -1)[..., valid],
                               mod[..., valid], rtol=1e-12)
    assert np.all(np.isnan(diag.rays.modulation.reshape(2, 1, -1)[..., ~valid]))
    s = diag.summary
    e_ok = ess[valid]
    assert s["ess_median"] == pytest.approx(ns.percentile_linear(e_ok, 50), rel=1e-12)
    assert s["ess_min"] == pytest.approx(min(e_ok), rel=1e-12)
    sx = se[0, 0][valid]
    assert s["phase_se_rad"]["x/50"]["median"] == pytest.approx(ns.percentile_linear(sx, 50))
    assert s["phase_se_rad"]["x/50"]["p95"] == pytest.approx(ns.percentile_linear(sx, 95))
    assert s["modulation_median"]["y/50"] == pytest.approx(
        ns.percentile_linear(mod[1, 0][valid], 50))
    assert s["n_rays"] == 24 and s["theta_max_deg"] == pytest.approx(2.0)


def test_incidence_by_hand_and_two_seeds_are_enough():
    """incidence: i in the BRDF frame equals the hand-traced direction to the camera
    (``naive.primary``), NaN off the plate; phase_error_seeds accepts 2 seeds and refuses 1.
    Guards against i = +dir, masks inverted, an off-by-one on the seed count."""
    import naive

    cfg = make_config()
    sim = Simulation.from_config(cfg)
    prim = naive.primary(cfg)
    rows, cols = np.array([0, 16, 20, 31]), np.array([0, 20, 25, 39])
    valid, i_local = dg.incidence(sim.scene, rows, cols)
    np.testing.assert_array_equal(valid, prim["valid"][rows, cols])
    for k in np.flatnonzero(valid):
        r, c = rows[k], cols[k]
        frame = (prim["x_axis"][r, c], prim["y_axis"][r, c], prim["normal"][r, c])
        np.testing.assert_allclose(i_local[k], [prim["to_camera"][r, c] @ b for b in frame],
                                   atol=1e-12)
    assert np.all(np.isnan(i_local[~valid]))
    grid = dg.PixelGrid(np.array([16]), np.array([20]), sim.shape)
    assert np.isfinite(dg.phase_error_seeds(sim, grid, n_seeds=2)).all()
    with pytest.raises(ValueError, match="n_seeds"):
        dg.phase_error_seeds(sim, grid, n_seeds=1)


def test_library_defaults_match_the_configuration_defaults():
    """check()'s bounds and diagnose()'s grid, phase method and energy target default to
    DiagnosticsConfig's, so a library call warns like a configured run (and the energy
    warning can name the cone: it needs diagnose's target = check's bound). Guards against
    a default changed in one place only."""
    import inspect

    from pmdsim.config import DiagnosticsConfig

    c = DiagnosticsConfig()
    p = inspect.signature(dw.check).parameters
    assert p["min_energy_fraction"].default == c.min_energy_fraction
    assert p["max_phase_error_mrad"].default == c.max_phase_error_mrad
    assert p["min_ess_fraction"].default == c.min_ess_fraction
    p = inspect.signature(dg.diagnose).parameters
    assert tuple(p["grid"].default) == tuple(c.grid)
    assert p["phase_method"].default == c.phase_method
    assert p["target_fraction"].default == c.min_energy_fraction
    assert inspect.signature(dg.energy_fraction).parameters["target"].default == c.min_energy_fraction
    assert inspect.signature(dg.lobe_energy).parameters["target"].default == c.min_energy_fraction


def test_fewer_than_four_effective_rays_are_not_judged():
    """Median ESS 4 is judged (modulation 1 is above any noise floor: no warning); 3.99 is
    not: the cone estimators are told to sample the lobe, the radiometric one to raise N
    (~ N 1.5 x 4 / ESS). Guards against the bound moved to 5 or to '<='."""
    se = np.full((1, 1, 3, 7), 1e-5)
    kw = dict(directions=("x",), widths=(400.0,), modulation=np.full((1, 1, 3, 7), 1.0),
              n_rays=10)
    assert dw.check(_diag(se, ess=np.full((3, 7), 4.0), **kw)) == []
    warns = dw.check(_diag(se, ess=np.full((3, 7), 3.99), **kw))
    assert [w.code for w in warns] == ["effective_sample_size"] and "< 4" in warns[0].message
    warns = dw.check(_diag(se, ess=np.full((3, 7), 3.99), estimator="radiometric", **kw))
    assert [w.code for w in warns] == ["too_few_rays"] and warns[0].suggested == 16
