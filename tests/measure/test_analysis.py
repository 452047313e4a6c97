"""Deviation statistics and spot moments against hand-computed values."""

import numpy as np
import pytest

from pmdsim.measure.deviation import compare_direction, deviation_stats, image_moments, slope_deviation, wrap


def test_wrap_range_and_identity():
    x = np.linspace(-20, 20, 1001)
    w = wrap(x)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    assert np.allclose(np.exp(1j * w), np.exp(1j * x))
    assert wrap(np.array([np.pi, -np.pi]))[1] == np.pi


def test_deviation_stats_values_and_masked_count():
    d = np.array([[1.0, -3.0], [np.nan, 2.0]])
    valid = np.array([[True, True], [True, False]])
    considered = np.ones((2, 2), bool)
    s = deviation_stats(d, valid, considered)
    assert s.n_valid == 2 and s.n_masked == 2
    assert s.mean == pytest.approx(-1.0)
    assert s.rms == pytest.approx(np.sqrt(5.0))
    assert s.max == 3.0
    assert s.valid_fraction == pytest.approx(0.5)


def test_compare_direction_masks_low_modulation_and_reports_deviation():
    h, w = 4, 5
    ref_phase = np.linspace(0, 10, h * w).reshape(h, w)
    phase = ref_phase + 0.01
    mod_ref = np.ones((2, h, w))
    mod = np.full((2, h, w), 0.5)
    mod[0, 0, 0] = 0.01  # below the 10 % threshold: masked and counted
    valid = np.ones((h, w), bool)
    dev = compare_direction("x", phase, phase * 50 / (2 * np.pi), mod, valid,
                            ref_phase, ref_phase * 50 / (2 * np.pi), mod_ref, valid, pitch_mm=0.25)
    assert dev.low_modulation[0, 0] and dev.low_modulation.sum() == 1
    assert np.isnan(dev.phase[0, 0])
    assert dev.stats_phase.mean == pytest.approx(0.01)
    assert dev.stats_coord_px.mean == pytest.approx(0.01 * 50 / (2 * np.pi))
    assert dev.stats_coord_mm.mean == pytest.approx(0.25 * 0.01 * 50 / (2 * np.pi))
    assert dev.stats_phase.n_masked == 1
    assert np.allclose(dev.modulation_ratio[1], 0.5)


def test_slope_deviation_small_angle():
    # a tilt of 1e-4 rad moves the hit by 2 * 1e-4 * 600 mm
    assert slope_deviation(2e-4 * 600, 600.0) == pytest.approx(1e-4)


def test_image_moments_gaussian_spot():
    rows, cols = np.mgrid[0:101, 0:121]
    sx, sy, ang = 6.0, 2.0, np.deg2rad(30)
    c, s = np.cos(ang), np.sin(ang)
    x, y = cols - 60.0, rows - 50.0
    xr, yr = c * x + s * y, -s * x + c * y
    img = np.exp(-0.5 * ((xr / sx) ** 2 + (yr / sy) ** 2))
    m = image_moments(img)
    assert m.centroid == pytest.approx((60.0, 50.0), abs=1e-6)
    assert m.sigma_major == pytest.approx(sx, rel=1e-3)
    assert m.sigma_minor == pytest.approx(sy, rel=1e-3)
    assert m.elongation == pytest.approx(3.0, rel=1e-3)
    assert m.angle == pytest.approx(ang, abs=1e-6)


def test_image_moments_empty_image_is_nan_not_crash():
    m = image_moments(np.zeros((5, 5)))
    assert np.isnan(m.sigma_major) and m.total == 0.0
