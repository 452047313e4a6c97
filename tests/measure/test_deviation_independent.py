"""Deviation statistics, the chain's statistics and dot moments against independent values.

Issue 9: these functions were tested against themselves (or not at all), so planted bugs
(sample instead of population std, P95 of the signed deviation, m * r instead of m / r, a
missing background subtraction, a wrong unit factor in ``statistics.json``) passed. Every test
here compares with a closed form or a slow obvious loop (``tests/naive_stats.py``) at a
tolerance that a factor 2, a sign or an off-by-one cannot pass; each docstring names the bug
it guards against. Plain arrays only: fast.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import naive_stats as ns
from pmdsim.measure import chain
from pmdsim.measure import decode as dec
from pmdsim.measure.deviation import compare_direction, deviation_stats, image_moments, wrap


# =========================================================================== deviation_stats
def test_stats_of_an_arithmetic_sequence_match_closed_forms():
    """d = -k, k = 0..100: mean -50, RMS sqrt(3350), population std sqrt(850), P95 of |d|
    = 95 exactly (rank 0.95 x 100), max 100. Guards against: a sample std (ddof = 1 gives
    sqrt(858.5)), the P95 of the signed deviation (-5), P95 vs P96, a sign flip of the mean,
    RMS taken about the mean, the maximum of the signed deviation (0)."""
    d = -np.arange(101.0)
    s = deviation_stats(d, np.ones(101, bool))
    assert s.mean == pytest.approx(-50.0, rel=1e-14)
    assert s.rms == pytest.approx(math.sqrt(3350.0), rel=1e-13)
    assert s.std == pytest.approx(math.sqrt(850.0), rel=1e-13)
    assert s.p95 == pytest.approx(95.0, rel=1e-13)
    assert s.max == 100.0
    assert (s.n_valid, s.n_masked, s.valid_fraction) == (101, 0, 1.0)


def test_stats_match_slow_loops_on_a_masked_map():
    """Random map with NaN holes, invalid pixels and a separate ``considered`` mask: every
    statistic equals the slow loop over the valid finite pixels (rel 1e-12). Guards against
    statistics over the whole map (NaN) or over ``considered``, std of |d|, p95 of d."""
    rng = np.random.default_rng(9)
    d = rng.normal(-0.3, 1.7, (23, 31))
    d[rng.random(d.shape) < 0.1] = np.nan
    valid = rng.random(d.shape) < 0.7
    considered = valid | (rng.random(d.shape) < 0.5)
    s = deviation_stats(d, valid, considered)
    sel = d[valid & np.isfinite(d)]
    assert s.n_valid == sel.size
    assert s.mean == pytest.approx(ns.mean(sel), rel=1e-12)
    assert s.rms == pytest.approx(ns.rms(sel), rel=1e-12)
    assert s.std == pytest.approx(ns.population_std(sel), rel=1e-12)
    assert s.p95 == pytest.approx(ns.percentile_linear(np.abs(sel), 95), rel=1e-12)
    assert s.max == pytest.approx(max(abs(x) for x in sel), rel=1e-15)
    assert s.n_masked == int(considered.sum()) - sel.size
    assert s.valid_fraction == pytest.approx(sel.size / considered.sum(), rel=1e-15)


def test_default_considered_counts_every_finite_or_valid_pixel():
    """``considered`` omitted: the pixels that could be measured are those with a finite
    deviation or marked valid, so a valid pixel whose deviation is NaN counts as masked.
    Guards against the default path collapsing to ``valid`` (n_masked 0) or to the finite
    pixels only, and against a valid_fraction of valid / all pixels."""
    d = np.array([[1.0, np.nan, 3.0, np.nan],
                  [4.0, 5.0, np.nan, 7.0]])
    valid = np.array([[True, True, False, False],
                      [True, False, True, True]])
    # finite: 5 pixels; valid & finite: (0,0), (1,0), (1,3) -> 3; valid but NaN: (0,1), (1,2)
    s = deviation_stats(d, valid)
    considered = 5 + 2
    assert s.n_valid == 3
    assert s.n_masked == considered - 3
    assert s.valid_fraction == pytest.approx(3 / considered, rel=1e-15)
    assert s.mean == pytest.approx((1 + 4 + 7) / 3, rel=1e-15)


def test_empty_statistics_are_nan_and_counted():
    """No valid pixel: NaN statistics, all considered pixels masked (not a crash or 0)."""
    s = deviation_stats(np.ones((3, 4)), np.zeros((3, 4), bool), np.ones((3, 4), bool))
    assert s.n_valid == 0 and s.n_masked == 12 and s.valid_fraction == 0.0
    assert all(math.isnan(getattr(s, k)) for k in ("mean", "rms", "std", "p95", "max"))


def test_wrap_near_plus_minus_pi():
    """Deviations straddling the branch cut: 3.1 - (-3.1) is -0.0832, not 6.2; exactly
    -pi maps to +pi (the half-open interval (-pi, pi]). Guards against a missing or
    shifted wrap (mod 2 pi without the offset, or (-pi, pi) clipping)."""
    a = np.array([3.1, -3.1, math.pi - 1e-9, 7 * math.pi, -math.pi])
    b = np.array([-3.1, 3.1, -math.pi + 1e-9, 0.0, 0.0])
    w = wrap(a - b)
    expected = [6.2 - 2 * math.pi, 2 * math.pi - 6.2, -2e-9, math.pi, math.pi]
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-12)


# =========================================================================== compare_direction
def _direction_case():
    h, w = 3, 4
    ref_phase = np.linspace(-2.0, 9.0, h * w).reshape(h, w)
    phase = ref_phase + np.linspace(-0.02, 0.05, h * w).reshape(h, w)
    width = 24.0
    ref_mod = np.empty((2, h, w))
    ref_mod[0], ref_mod[1] = 0.5, 0.8      # reference modulation != 1 for both widths
    mod = np.empty((2, h, w))
    mod[0], mod[1] = 0.2, 0.4              # ratios 0.4 and 0.5
    mod[0, 0, 0] = 0.04   # ratio 0.08 < 0.1: masked (m * r = 0.02 would be masked too)
    mod[0, 0, 1] = 0.06   # ratio 0.12 >= 0.1: kept   (m * r = 0.03 would be masked)
    mod[1, 1, 2] = 0.07   # coarse width ratio 0.0875 < 0.1: masked by the worst width
    valid = np.ones((h, w), bool)
    valid[2, 3] = False   # decode-flagged surface pixel: masked, not low-modulation
    ref_valid = np.ones((h, w), bool)
    ref_valid[2, 0] = False  # reference not decodable: not considered at all
    return dict(phase=phase, ref_phase=ref_phase, width=width, mod=mod, ref_mod=ref_mod,
                valid=valid, ref_valid=ref_valid)


def test_compare_direction_ratio_and_masks_with_reference_modulation_not_one():
    """Modulation ratio m / r with r = 0.5 and 0.8: guards against m * r and r / m (equal to
    m / r only for r = 1), against thresholding the finest width only (the worst width
    counts), against '>' vs '>=' on the threshold, and against counting pixels the
    reference cannot decode."""
    c = _direction_case()
    pitch = 0.3
    coord = c["phase"] * c["width"] / (2 * math.pi)
    ref_coord = c["ref_phase"] * c["width"] / (2 * math.pi)
    dev = compare_direction("y", c["phase"], coord, c["mod"], c["valid"], c["ref_phase"],
                            ref_coord, c["ref_mod"], c["ref_valid"], pitch, 0.1)
    ratio = c["mod"] / c["ref_mod"]
    ratio[:, ~c["ref_valid"]] = np.nan
    np.testing.assert_allclose(dev.modulation_ratio, ratio, rtol=1e-15, equal_nan=True)
    expected_low = np.zeros((3, 4), bool)
    expected_low[0, 0] = expected_low[1, 2] = True
    np.testing.assert_array_equal(dev.low_modulation, expected_low)
    ok = c["ref_valid"] & c["valid"] & ~expected_low
    np.testing.assert_array_equal(dev.valid, ok)
    # deviation = measured - reference (sign!), mm = px x pitch
    dphi = (c["phase"] - c["ref_phase"])[ok]
    np.testing.assert_allclose(dev.phase[ok], dphi, rtol=1e-15)
    assert np.all(np.isnan(dev.phase[~ok]))
    dpx = (coord - ref_coord)[ok]
    np.testing.assert_allclose(dev.coord_mm[ok], dpx * pitch, rtol=1e-14)
    n_cons = int(c["ref_valid"].sum())
    for st, vals in ((dev.stats_phase, dphi), (dev.stats_coord_px, dpx),
                     (dev.stats_coord_mm, dpx * pitch)):
        assert st.n_valid == ok.sum() and st.n_masked == n_cons - ok.sum()
        assert st.mean == pytest.approx(ns.mean(vals), rel=1e-12)
        assert st.std == pytest.approx(ns.population_std(vals), rel=1e-12)
        assert st.p95 == pytest.approx(ns.percentile_linear(np.abs(vals), 95), rel=1e-12)


def test_modulation_threshold_boundary_is_inclusive():
    """A ratio exactly at min_modulation_ratio is kept (>=); just below it is masked."""
    ref = np.full((1, 1, 2), 0.5)
    mod = np.array([[[0.125, 0.125 - 1e-9]]])       # ratios 0.25 and 0.25 - 2e-9
    z = np.zeros((1, 2))
    ok = np.ones((1, 2), bool)
    dev = compare_direction("x", z, z, mod, ok, z, z, ref, ok, 1.0, 0.25)
    np.testing.assert_array_equal(dev.low_modulation, [[False, True]])


# =========================================================================== chain statistics
def _decode_result(phase, coord, mod, valid, flags=None, widths=(24.0, 192.0)):
    h, w = phase.shape
    if flags is None:
        flags = np.where(valid, 0, int(dec.DecodeFlag.ORDER_RESIDUAL)).astype(np.uint8)
    return dec.DecodeResult(
        absolute_phase=phase, monitor_coord_px=coord, wrapped_phase=np.stack([wrap(phase)] * 2),
        modulation=mod, amplitude=mod * 0.5, offset=np.full(mod.shape, 0.5),
        order_residual=np.zeros((h, w)), flags=flags, valid=valid, widths_px=tuple(widths),
        finest_width_px=min(widths), method="hierarchical")


def _chain_case():
    c = _direction_case()
    w = c["width"]
    coord = c["phase"] * w / (2 * math.pi)
    ref_coord = c["ref_phase"] * w / (2 * math.pi)
    exact = ref_coord + 0.25   # the reference's own quantisation: -0.25 px everywhere
    meas = _decode_result(c["phase"], coord, c["mod"], c["valid"])
    ref = _decode_result(c["ref_phase"], ref_coord, c["ref_mod"], c["ref_valid"])
    geo = SimpleNamespace(specular_u=exact, specular_v=exact + 1.0,
                          surface_mask=np.ones(coord.shape, bool))
    distance = np.linspace(450.0, 650.0, coord.size).reshape(coord.shape)
    cfg = SimpleNamespace(min_modulation_ratio=0.1)
    pitch = 0.3
    res = chain.compare({"x": meas}, {"x": ref}, geo, distance, pitch, cfg, 4)
    return c, coord, ref_coord, exact, distance, pitch, res


def test_chain_statistics_mm_map_mrad_and_urad_values():
    """The millimetre deviation map is px x pitch, the slope map coord_mm / (2 d) in urad,
    and statistics.json holds phase figures in mrad (x 1e3) and slopes in urad: each value is
    recomputed here from the inputs. Guards against a missing or doubled unit factor, d
    instead of 2 d, rad in a mrad field, the RMS field holding the std."""
    c, coord, ref_coord, exact, distance, pitch, res = _chain_case()
    dcx = res.directions["x"]
    ok = dcx.deviation.valid
    dpx = coord - ref_coord
    np.testing.assert_allclose(dcx.deviation.coord_mm[ok], dpx[ok] * pitch, rtol=1e-14)
    slope = dpx * pitch / (2.0 * distance) * 1e6
    np.testing.assert_allclose(dcx.slope_urad[ok], slope[ok], rtol=1e-13)
    stats = chain.statistics(res, "case")
    s = stats["directions"]["x"]
    dphi = (c["phase"] - c["ref_phase"])[ok]
    assert s["phase_mrad"]["mean"] == pytest.approx(1e3 * ns.mean(dphi), rel=1e-12)
    assert s["phase_mrad"]["rms"] == pytest.approx(1e3 * ns.rms(dphi), rel=1e-12)
    assert s["phase_mrad"]["std"] == pytest.approx(1e3 * ns.population_std(dphi), rel=1e-12)
    assert s["phase_mrad"]["p95"] == pytest.approx(
        1e3 * ns.percentile_linear(np.abs(dphi), 95), rel=1e-12)
    assert s["phase_mrad"]["max"] == pytest.approx(1e3 * np.abs(dphi).max(), rel=1e-14)
    assert s["coord_mm"]["rms"] == pytest.approx(pitch * ns.rms(dpx[ok]), rel=1e-12)
    assert s["coord_px"]["mean"] == pytest.approx(ns.mean(dpx[ok]), rel=1e-12)
    assert s["slope_urad"]["mean"] == pytest.approx(ns.mean(slope[ok]), rel=1e-12)
    assert s["slope_urad"]["p95"] == pytest.approx(
        ns.percentile_linear(np.abs(slope[ok]), 95), rel=1e-12)
    # pixel counts: 11 considered, 2 low modulation, 1 decode-flagged, 8 valid
    p = s["pixels"]
    assert (p["considered"], p["valid"], p["low_modulation"], p["decode_flagged"]) == (11, 8, 2, 1)
    assert p["reference_flagged_on_surface"] == 1
    assert s["coord_px"]["n_masked"] == 3 and s["slope_urad"]["n_masked"] == 3
    # reference vs exact: -0.25 px on every considered pixel; surface vs exact on valid ones
    assert s["reference_vs_exact_px"]["mean"] == pytest.approx(-0.25, rel=1e-12)
    assert s["reference_vs_exact_px"]["n_valid"] == 11
    assert s["coord_vs_exact_px"]["mean"] == pytest.approx(ns.mean((coord - exact)[ok]), rel=1e-12)
    # modulation medians by width: surface over its valid pixels, ratio over considered
    assert s["modulation"]["ratio_median_by_width"][0] == pytest.approx(0.4)
    assert s["modulation"]["reference_median_by_width"] == pytest.approx([0.5, 0.8])


def test_chain_dataset_variables_carry_the_same_numbers():
    """The dataset's mm map, slope map and statistics table hold the values recomputed from
    the inputs (guards against a table built from the wrong quantity or statistic order)."""
    c, coord, ref_coord, exact, distance, pitch, res = _chain_case()
    from pmdsim.store.schema import dataset_variables

    # the chain's variables are lazily indexed stacks (store/lazy_arrays.py): read them as arrays
    v = {k: (val[0], np.asarray(val[1])) for k, val in dataset_variables(res).items()}
    ok = res.directions["x"].deviation.valid
    mm = v["coord_deviation_mm"][1][0]
    np.testing.assert_allclose(mm[ok], ((coord - ref_coord) * pitch)[ok], rtol=1e-14)
    assert np.all(np.isnan(mm[~ok]))
    np.testing.assert_allclose(v["monitor_coord_mm"][1][0], coord * pitch, rtol=1e-14)
    table = v["deviation_stats"][1][0]
    qs, sts = list(chain.QUANTITIES), list(chain.STATISTICS)
    dphi = (c["phase"] - c["ref_phase"])[ok]
    assert table[qs.index("phase_mrad"), sts.index("rms")] == pytest.approx(1e3 * ns.rms(dphi))
    assert table[qs.index("coord_mm"), sts.index("p95")] == pytest.approx(
        ns.percentile_linear(np.abs((coord - ref_coord)[ok] * pitch), 95))
    assert table[qs.index("slope_urad"), sts.index("n_valid")] == ok.sum()


# =========================================================================== dot moments
def test_sub_pixel_spot_moments_include_the_pixel_box():
    """A rotated elliptical Gaussian (sigmas 1.6 and 0.7 px) centred between pixels,
    integrated over each pixel (16 x 16 mid-points): its moments are those of the Gaussian
    convolved with the pixel box, covariance C + v I with v = (1 - 1/16^2) / 12 (the box of
    16 mid-points), centroid exactly the sub-pixel centre. Guards against a centroid off by
    half a pixel, a missing centring of the second moments, swapped axes or a wrong angle."""
    centre, smaj, smin, ang = (20.37, 14.81), 1.6, 0.7, math.radians(-35.0)
    img = ns.gaussian_spot((30, 41), centre, smaj, smin, ang, peak=3.0, supersample=16)
    m = image_moments(img)
    c, s = math.cos(ang), math.sin(ang)
    rot = np.array([[c, -s], [s, c]])
    cov = rot @ np.diag([smaj**2, smin**2]) @ rot.T + (1 - 1 / 256) / 12 * np.eye(2)
    evals, evecs = np.linalg.eigh(cov)
    assert m.centroid == pytest.approx(centre, abs=2e-4)
    assert m.sigma_major == pytest.approx(math.sqrt(evals[1]), rel=1e-3)
    assert m.sigma_minor == pytest.approx(math.sqrt(evals[0]), rel=1e-3)
    expected_angle = math.atan2(evecs[1, 1], evecs[0, 1])
    expected_angle = (expected_angle + math.pi / 2) % math.pi - math.pi / 2
    assert m.angle == pytest.approx(expected_angle, abs=2e-3)
    assert m.elongation == pytest.approx(math.sqrt(evals[1] / evals[0]), rel=2e-3)


def test_moments_with_background_and_threshold():
    """Background b plus a Gaussian, threshold b: the background is removed exactly and the
    Gaussian's own sigmas come back; a threshold cutting into the spot (t = 30 % of the peak)
    shrinks the variance per axis by the closed-form factor of max(g - t, 0)
    (``naive_stats.thresholded_gaussian_variance_factor``). Guards against thresholding
    without subtracting (weights img instead of img - t), '>=' vs '>' with NaN, a threshold
    relative instead of absolute."""
    centre, smaj, smin, ang = (40.3, 33.6), 7.0, 4.0, math.radians(20.0)
    g = ns.gaussian_spot((70, 81), centre, smaj, smin, ang, peak=2.0)
    b = 0.3
    img = g + b
    img[0, :5] = np.nan
    m = image_moments(img, threshold=b)
    assert m.sigma_major == pytest.approx(smaj, rel=1e-4)
    assert m.sigma_minor == pytest.approx(smin, rel=1e-4)
    assert m.angle == pytest.approx(ang, abs=1e-4)
    assert m.centroid == pytest.approx(centre, abs=1e-4)
    assert m.total == pytest.approx(np.nansum(g), rel=1e-9)
    t = 0.3
    k = math.sqrt(ns.thresholded_gaussian_variance_factor(t))
    m = image_moments(g, threshold=2.0 * t)
    assert m.sigma_major == pytest.approx(k * smaj, rel=3e-3)
    assert m.sigma_minor == pytest.approx(k * smin, rel=3e-3)
    assert m.elongation == pytest.approx(smaj / smin, rel=5e-3)
    (cx, cy), cov = ns.image_second_moments_loop(g, 2.0 * t)
    assert m.centroid == pytest.approx((cx, cy), abs=1e-9)
    assert m.sigma_major**2 + m.sigma_minor**2 == pytest.approx(np.trace(cov), rel=1e-9)


def test_thresholded_gaussian_factor_matches_quadrature():
    """The closed form used above against SciPy quadrature of max(g - t, 0) r^3 / r."""
    from scipy.integrate import quad

    for t in (0.05, 0.3, 0.7):
        r_cut = math.sqrt(-2 * math.log(t))
        m0 = quad(lambda r: (math.exp(-r * r / 2) - t) * r, 0, r_cut)[0]
        m2 = quad(lambda r: (math.exp(-r * r / 2) - t) * r**3, 0, r_cut)[0]
        assert ns.thresholded_gaussian_variance_factor(t) == pytest.approx(m2 / (2 * m0), rel=1e-10)


def test_dot_table_uses_five_percent_of_the_peak():
    """chain.dot_table thresholds each dot image at 5 % of its maximum: the sigmas shrink by
    sqrt(factor(0.05)) = 0.848, the angle comes in degrees, the centroid is (col, row).
    Guards against a threshold of 5 % of the sum, no threshold, radians in the degree column,
    swapped centroid columns."""
    from pmdsim.patterns import Dot

    centre, smaj, smin, ang = (30.4, 22.7), 6.0, 3.0, math.radians(-25.0)
    img = ns.gaussian_spot((48, 64), centre, smaj, smin, ang, peak=0.8)
    row = chain.dot_table(np.stack([img]), [Dot(100.0, 50.0, 9.0)], "v")[0]
    k = math.sqrt(ns.thresholded_gaussian_variance_factor(0.05))
    assert row["threshold"] == pytest.approx(0.05 * img.max(), rel=1e-12)
    assert row["peak"] == pytest.approx(img.max(), rel=1e-7)
    assert row["sigma_major_px"] == pytest.approx(k * smaj, rel=3e-3)
    assert row["sigma_minor_px"] == pytest.approx(k * smin, rel=3e-3)
    assert row["elongation"] == pytest.approx(2.0, rel=5e-3)
    assert row["angle_deg"] == pytest.approx(-25.0, abs=0.05)
    assert (row["centroid_col"], row["centroid_row"]) == pytest.approx(centre, abs=1e-3)
    assert (row["dot_u_px"], row["dot_v_px"], row["dot_size_px"]) == (100.0, 50.0, 9.0)


def test_rendered_dot_moments_follow_the_lobe():
    """A 30 x 30 monitor-px dot seen through an anisotropic Ward lobe (alpha 0.008 across,
    0.016 in the plane of incidence, 25 deg), radiometric estimator: the camera spot is the
    lobe's monitor footprint, Gaussian with covariance S = diag(2 (alpha_x cos(theta_i) d)^2,
    2 (alpha_y d)^2) / pitch^2 plus the dot's box (30^2 / 12), mapped back to the camera
    through the mirror's Jacobian J = d(u, v) / d(col, row): C = J^-1 S J^-T. J and d come
    from the geometry by hand (``naive.primary``). Sigmas agree within 3 % (measured 0.2 %),
    the major axis lies along the rows, the centroid where P meets the dot's centre. Guards
    against dot moments that only agree with themselves (a swapped axis, a dot rendered at
    (v, u), a box of the wrong size)."""
    import naive
    from conftest import base_dict
    from pmdsim.config import parse_config
    from pmdsim.patterns import Dot
    from pmdsim.render import Simulation

    t = math.radians(25.0)
    d = base_dict()
    d["camera"].update(resolution=[48, 40], focal_length_px=400.0,
                       position_mm=[0.0, -300 * math.sin(t), 300 * math.cos(t)],
                       look_at_mm=[0.0, 0.0, 0.0])
    d["monitor"].update(resolution=[600, 400], pixel_pitch_mm=0.1,
                        centre_mm=[0.0, 200 * math.sin(t), 200 * math.cos(t)],
                        look_at_mm=[0.0, 0.0, 0.0], pixel_model="continuous")
    ax, ay = 0.008, 0.016
    d["brdf"] = {"model": "ward", "alpha_x": ax, "alpha_y": ay, "rho_s": 0.4}
    d["sampling"] = {"n_rays": 4096, "estimator": "radiometric", "mode": "stratified"}
    cfg = parse_config(d)
    u0, v0, size = 300.0, 200.0, 30.0
    img = Simulation.from_config(cfg).render_dots([Dot(u0, v0, size)])[0].astype(np.float64)
    m = image_moments(img)
    prim = naive.primary(cfg)
    u, v = prim["u"], prim["v"]
    r, c = np.unravel_index(np.nanargmin((u - u0) ** 2 + (v - v0) ** 2), u.shape)
    jac = np.array([[(u[r, c + 1] - u[r, c - 1]) / 2, (u[r + 1, c] - u[r - 1, c]) / 2],
                    [(v[r, c + 1] - v[r, c - 1]) / 2, (v[r + 1, c] - v[r - 1, c]) / 2]])
    centre, _, _, n = naive.monitor_axes(cfg.monitor)
    s, p = prim["point"][r, c], prim["principal"][r, c]
    dist = ((centre - s) @ n) / (p @ n)
    cos_i = prim["to_camera"][r, c, 2]
    su = math.sqrt(2) * ax * cos_i * dist / 0.1
    sv = math.sqrt(2) * ay * dist / 0.1
    cov_mon = np.diag([su**2 + size**2 / 12, sv**2 + size**2 / 12])
    ji = np.linalg.inv(jac)
    ev = np.linalg.eigvalsh(ji @ cov_mon @ ji.T)
    assert m.sigma_major == pytest.approx(math.sqrt(ev[1]), rel=0.03)
    assert m.sigma_minor == pytest.approx(math.sqrt(ev[0]), rel=0.03)
    assert 1.5 < m.elongation < 2.5
    assert abs(math.cos(m.angle)) < 0.02                       # major axis along the rows
    expected_centroid = np.array([c, r]) + ji @ np.array([u0 - u[r, c], v0 - v[r, c]])
    assert m.centroid == pytest.approx(tuple(expected_centroid), abs=0.1)


def test_moment_angle_range_over_all_orientations():
    """Spots at orientations every 7.5 deg round the half circle: the angle is reported in
    (-90, 90] deg and equals the true orientation modulo 180 deg (guards against the range
    folding done with the wrong bound or sign; eigenvector signs are arbitrary, so both
    branches are exercised)."""
    for deg in np.arange(-172.5, 180.0, 7.5):
        img = ns.gaussian_spot((41, 41), (20.2, 19.7), 5.0, 2.0, math.radians(deg))
        m = image_moments(img)
        assert -math.pi / 2 < m.angle <= math.pi / 2
        diff = (math.degrees(m.angle) - deg) % 180.0
        assert min(diff, 180.0 - diff) < 0.01, deg


def test_vertical_major_axis_is_plus_ninety_degrees():
    """The angle interval is (-90, 90]: a spot elongated exactly along the rows reports
    +90 deg, never -90 (guards against '>' vs '>=' at the interval's upper end)."""
    for centre in ((20.0, 20.0), (13.0, 20.0)):
        img = ns.gaussian_spot((41, 41), centre, 6.0, 2.0, math.pi / 2)
        assert image_moments(img).angle == math.pi / 2


def test_chain_flag_counts_finest_width_and_coarse_width_rounding():
    """statistics(): decode flags of the considered pixels counted per flag, the finest width
    is the smallest; the error message's suggested width rounds up to two significant digits
    (57 -> 57, 200 -> 200, 1234 -> 1300, 12345 -> 13000). Guards against '&' / '|' on flag
    bits, max instead of min, a step of 10 x digits instead of 10^digits."""
    _, _, _, _, _, _, res = _chain_case()
    s = chain.statistics(res, "case")
    counts = s["directions"]["x"]["pixels"]["decode_flags_of_considered"]
    assert counts["ORDER_RESIDUAL"] == 1 and counts["NAN_INPUT"] == 0
    assert counts["LOW_AMPLITUDE"] == 0 and counts["OUT_OF_RANGE"] == 0
    assert s["finest_width_px"] == 24.0 and s["widths_px"] == [24.0, 192.0]
    assert [chain._coarse_width(x) for x in (57, 200, 1234, 12345)] == [57, 200, 1300, 13000]


def test_dot_table_of_a_dark_image():
    """A dot image with no light (zeros, or NaN where nothing was traced): threshold 0,
    total 0, NaN moments; never a negative threshold."""
    from pmdsim.patterns import Dot

    imgs = np.stack([np.zeros((5, 6)), np.full((5, 6), np.nan), -np.ones((5, 6))])
    rows = chain.dot_table(imgs, [Dot(1.0, 2.0, 3.0)] * 3)
    for r in rows:
        assert r["threshold"] == 0.0 and r["total"] == 0.0 and math.isnan(r["sigma_major_px"])
        assert math.isnan(r["elongation"]) and math.isnan(r["centroid_col"])


def test_moments_do_not_depend_on_the_brightness():
    """A faint spot (total 0.03) has the moments of the same spot 1000 x brighter (guards
    against an emptiness test that is not 'total <= 0')."""
    img = ns.gaussian_spot((30, 30), (14.3, 15.1), 3.0, 1.5, 0.4, peak=1e-3)
    faint, bright = image_moments(img), image_moments(img * 1e3)
    assert faint.total < 0.05
    assert faint.sigma_major == pytest.approx(bright.sigma_major, rel=1e-12)
    assert faint.centroid == pytest.approx(bright.centroid, rel=1e-12)


def test_nothing_considered_means_nothing_valid():
    """No pixel could be measured (``considered`` empty): valid_fraction 0 and no masked
    count, whatever ``valid`` says (guards against dividing by an empty count)."""
    s = deviation_stats(np.ones((2, 2)), np.ones((2, 2), bool), np.zeros((2, 2), bool))
    assert s.valid_fraction == 0.0 and s.n_masked == 0


def test_library_defaults_match_the_configuration_defaults():
    """A library call behaves like a configured run by default: compare_direction's
    min_modulation_ratio is DecodeConfig's. Guards against a default changed in one place."""
    import inspect

    from pmdsim.config import DecodeConfig

    sig = inspect.signature(compare_direction)
    assert sig.parameters["min_modulation_ratio"].default == DecodeConfig().min_modulation_ratio


def test_chain_counts_bundles_off_the_monitor_apart():
    """Pixels whose bundle hangs off the monitor are masked and counted as lobe_off_monitor,
    not as decode-flagged or low-modulation: with off = {(1, 1) valid, (0, 0) low modulation,
    (2, 3) decode-flagged, (2, 0) not considered}, the counts are 2 off, 2 low, 0 flagged,
    7 valid of 11. Guards against the off-monitor set overlapping the other two counts."""
    c = _direction_case()
    w = c["width"]
    coord = c["phase"] * w / (2 * math.pi)
    ref_coord = c["ref_phase"] * w / (2 * math.pi)
    meas = _decode_result(c["phase"], coord, c["mod"], c["valid"])
    ref = _decode_result(c["ref_phase"], ref_coord, c["ref_mod"], c["ref_valid"])
    geo = SimpleNamespace(specular_u=ref_coord, specular_v=ref_coord,
                          surface_mask=np.ones(coord.shape, bool))
    off = np.zeros(coord.shape, bool)
    off[1, 1] = off[0, 0] = off[2, 3] = off[2, 0] = True
    res = chain.compare({"x": meas}, {"x": ref}, geo, np.full(coord.shape, 500.0), 0.3,
                        SimpleNamespace(min_modulation_ratio=0.1), 4, off_monitor=off)
    p = chain.statistics(res, "off")["directions"]["x"]["pixels"]
    assert (p["considered"], p["valid"], p["low_modulation"]) == (11, 7, 2)
    assert p["lobe_off_monitor"] == 2 and p["decode_flagged"] == 0
    assert p["valid"] + p["low_modulation"] + p["decode_flagged"] + p["lobe_off_monitor"] == 11
