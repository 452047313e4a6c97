"""The dot moments carry their numerical error (issue 37): ``moments_error`` against
finite differences written here, and the stated errors of an rqmc render against a render
with 16 times the rays (the dot_scan example on a reduced camera)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pmdsim.measure.deviation import MOMENT_ERRORS, image_moments, moments_error

ROOT = Path(__file__).resolve().parents[2]


def _spot(shape=(17, 21), centre=(9.3, 7.6), sig=(3.1, 1.7), angle=0.6):
    """An elongated, rotated Gaussian spot (col, row centre; major, minor sigma; angle)."""
    r, c = np.indices(shape, dtype=float)
    dx, dy = c - centre[0], r - centre[1]
    ca, sa = np.cos(angle), np.sin(angle)
    u, v = ca * dx + sa * dy, -sa * dx + ca * dy
    return np.exp(-0.5 * ((u / sig[0]) ** 2 + (v / sig[1]) ** 2))


def _values(m):
    return np.array([m.centroid[0], m.centroid[1], m.sigma_major, m.sigma_minor,
                     m.elongation, m.angle])


@pytest.mark.parametrize("threshold", [0.0, 0.05])
def test_bound_is_the_sum_of_finite_difference_derivatives(threshold):
    """Each pixel's derivative by a central difference of image_moments (pixels away from
    the threshold, so the set above it is fixed); the stated error must equal
    sum_i |dm/dI_i| e_i for an uneven error map."""
    img = _spot()
    rng = np.random.default_rng(3)
    err = rng.uniform(0.0, 1e-3, img.shape)
    err[img <= threshold + 1e-4] = 0.0  # (a difference step there would cross the threshold)
    got = moments_error(img, err, threshold)
    h = 1e-6
    expected = np.zeros(6)
    for idx in zip(*np.nonzero(img > threshold + 1e-4)):
        up, dn = img.copy(), img.copy()
        up[idx] += h
        dn[idx] -= h
        d = (_values(image_moments(up, threshold)) - _values(image_moments(dn, threshold))) / (2 * h)
        expected += np.abs(d) * err[idx]
    for k, name in enumerate(MOMENT_ERRORS):
        assert got[name] == pytest.approx(expected[k], rel=1e-5), name


def test_threshold_error_shifts_every_weight():
    img = _spot()
    e_t, h = 2e-3, 1e-7
    d = (_values(image_moments(img, 0.05 + h)) - _values(image_moments(img, 0.05 - h))) / (2 * h)
    got = moments_error(img, np.zeros_like(img), 0.05, e_t)
    for k, name in enumerate(MOMENT_ERRORS):
        assert got[name] == pytest.approx(abs(d[k]) * e_t, rel=1e-5), name


def test_unknown_pixel_error_is_infinite_and_empty_image_nan():
    img = _spot()
    err = np.zeros_like(img)
    err[9, 9] = np.nan
    assert all(np.isinf(v) for v in moments_error(img, err).values())
    assert all(np.isnan(v) for v in moments_error(np.zeros((4, 4)), np.zeros((4, 4))).values())


def test_stated_dot_errors_cover_a_render_with_16_times_the_rays():
    """The dot_scan example's kinematic plate (rqmc, its own reason in the config) on a
    64 x 52 camera, four dots: |m(N) - m(16 N)| <= err(N) + err(16 N) for every moment."""
    from pmdsim.config import load_config, with_sampling
    from pmdsim.measure.chain import dot_table
    from pmdsim.patterns import resolve_dots
    from pmdsim.render import Simulation
    from pmdsim.studies.convergence import reduced_config

    cfg = dict(load_config(ROOT / "examples" / "dot_scan.toml").expand())["kinematic"]
    small = reduced_config(cfg, (64, 52))
    dots = resolve_dots(small.patterns.dots, small.monitor.resolution)[10:14]
    tables = []
    for n, seed in ((400, 1), (6400, 2)):
        sim = Simulation.from_config(with_sampling(small, n_rays=n, seed=seed))
        images, err = sim.render_dots(dots, with_error=True)
        tables.append(dot_table(images, dots, dot_errors=err))
    cols = ("centroid_col", "centroid_row", "sigma_major_px", "sigma_minor_px", "elongation",
            "angle_deg")
    checked = 0
    for a, b in zip(*tables):
        if not np.isfinite(a["centroid_col"]):
            continue
        for c in cols:
            assert np.isfinite(a[c + "_err"]) and a[c + "_err"] > 0, c
            assert abs(a[c] - b[c]) <= a[c + "_err"] + b[c + "_err"], (c, a[c], b[c], a[c + "_err"])
            checked += 1
        assert b["centroid_col_err"] < a["centroid_col_err"]  # more rays, smaller error
    assert checked >= 12
