"""The statistics under the image fit (:mod:`pmdsim.studies.fit_stats`), each against an
independent computation: the noise model against the sensor simulated many times, the
phase-shift split and signal test against their closed forms, the parameter covariance
(noise, model error, Birge factor) against the scatter of repeated linear fits, and the
decoded modulation against fringes of known modulation."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.scene.sensor import Sensor
from pmdsim.studies.fit import decoded_modulation, median_modulation
from pmdsim.studies.fit_stats import (NoiseModel, fringe_signal_ratio, harmonic_noise_variance,
                                      harmonic_split, parameter_covariance)


@pytest.mark.parametrize("settings", [
    dict(dark_noise_electrons=6.0),
    dict(dark_noise_electrons=3.0, prnu=0.02, dsnu_electrons=9.0, offset_dn=37.0,
         dark_signal_electrons=40.0, gain_dn_per_electron=0.13),
    dict(dark_noise_electrons=2.0, shot_noise=False, offset_dn=5.0, bit_depth=14),
])
def test_noise_model_matches_the_simulated_sensor(settings):
    """Mean and spread of many captured values (fixed patterns and temporal noise together,
    as the fit sees them) against NoiseModel's dark level and sigma at three levels."""
    s = Sensor(enabled=True, exposure_electrons=8000.0, full_well_electrons=20000.0, seed=3,
               **settings)
    noise = NoiseModel.from_sensor(s)
    levels = np.array([0.08, 0.35, 0.9])  # of the reference value 1.0
    x = np.broadcast_to(levels[:, None, None, None], (3, 8, 120, 100)).copy()
    x[0, 0, 0, 0] = 1.0  # the reference
    dn = s.capture(x, reference=1.0).dn
    for i, lev in enumerate(levels):
        y_true = s.gain * s.exposure * lev  # DN of the signal, without the dark level
        got = noise.signal(dn[i]).ravel()[1:]
        assert np.mean(got) == pytest.approx(y_true, rel=2e-3, abs=0.05)
        assert np.std(got) == pytest.approx(float(noise.sigma(y_true)), rel=0.03)


def test_harmonic_split_keeps_sinusoids_and_measures_noise():
    rng = np.random.default_rng(1)
    k = 7
    d = 2 * np.pi * np.arange(k) / k
    a = rng.uniform(1, 2, (5, 6))
    b = rng.uniform(0, 1, (5, 6))
    phi = rng.uniform(-3, 3, (5, 6))
    fringes = a + b * np.cos(phi + d[:, None, None])  # (K, H, W), dx != dy
    sin_part, rest = harmonic_split(fringes)
    np.testing.assert_allclose(sin_part, fringes, atol=1e-12)
    np.testing.assert_allclose(rest, 0.0, atol=1e-12)
    # a second harmonic is all "rest"; the split is orthogonal
    h2 = 0.3 * np.cos(2 * d + 0.4)[:, None, None] * np.ones((5, 6))
    _, rest2 = harmonic_split(fringes + h2)
    np.testing.assert_allclose(rest2, h2, atol=1e-12)
    # white noise of variance 4: the rest has variance 4 per degree of freedom
    noise = 2.0 * rng.standard_normal((3, k, 80, 90))
    noise[0, 2, 5, 7] = np.nan  # an incomplete pixel is left out
    var, dof = harmonic_noise_variance(noise + 5.0 + 2.0 * np.cos(d + 1.0)[:, None, None])
    assert dof == (3 * 80 * 90 - 1) * (k - 3)
    assert var == pytest.approx(4.0, rel=0.02)
    assert np.isnan(harmonic_noise_variance(noise[:, :3])[0])


def test_fringe_signal_ratio_is_one_for_noise_and_large_for_fringes():
    rng = np.random.default_rng(2)
    k, h, w = 4, 60, 70
    d = 2 * np.pi * np.arange(k) / k
    noise = 3.0 * rng.standard_normal((2, k, h, w)) + 100.0
    r = fringe_signal_ratio(noise, 9.0)
    assert np.all(np.abs(r - 1) < 5 / np.sqrt(h * w)), r
    b = 1.5  # |Z| = b: ratio 1 + b^2 / (4 sigma^2 / K)
    fr = noise + b * np.cos(0.3 + d)[None, :, None, None]
    np.testing.assert_allclose(fringe_signal_ratio(fr, 9.0), 1 + b**2 / (4 * 9.0 / k),
                               rtol=0.06)


def _linear_fits(sigma_true, sigma_assumed, u=None, draws=3000, seed=5):
    """Repeated weighted linear fits y = X beta + noise (+ u xi): the estimates' scatter
    and the mean of the covariance parameter_covariance reports."""
    rng = np.random.default_rng(seed)
    n = 60
    t = np.linspace(-1.0, 2.0, n)
    x = np.stack([np.ones(n), t, t**2 - 0.3], axis=1)
    s_assumed = sigma_assumed * (1 + 0.5 * (t > 0.7))  # unequal weights
    s_true = sigma_true * (1 + 0.5 * (t > 0.7))
    beta = np.array([0.4, -1.2, 0.7])
    jw = x / s_assumed[:, None]
    est, covs, chis = [], [], []
    for _ in range(draws):
        y = x @ beta + s_true * rng.standard_normal(n)
        if u is not None:
            y = y + u * rng.standard_normal()
        b, *_ = np.linalg.lstsq(jw, y / s_assumed, rcond=None)
        r = (x @ b - y) / s_assumed
        cv = parameter_covariance(jw, r, None if u is None else (u / s_assumed)[:, None])
        est.append(b)
        covs.append(cv.cov)
        chis.append(cv.chi2_reduced)
    return np.cov(np.array(est).T), np.mean(covs, axis=0), np.mean(chis), jw, s_assumed


def test_covariance_of_noise_alone_matches_repeated_fits():
    emp, rep, chi2, jw, _ = _linear_fits(0.1, 0.1)
    np.testing.assert_allclose(np.diag(rep), np.diag(emp), rtol=0.15)
    # Birge factor: max(1, chi2) makes the mean slightly larger than (J^T J)^-1 itself
    closed = np.linalg.inv(jw.T @ jw)
    assert np.all(np.diag(rep) >= np.diag(closed)) and chi2 == pytest.approx(1.0, abs=0.05)


def test_underestimated_noise_is_widened_by_the_birge_factor():
    emp, rep, chi2, jw, _ = _linear_fits(0.2, 0.1)
    assert chi2 == pytest.approx(4.0, rel=0.05)
    np.testing.assert_allclose(np.diag(rep), np.diag(emp), rtol=0.15)
    closed = np.linalg.inv(jw.T @ jw)
    assert np.all(np.diag(emp) > 3 * np.diag(closed))  # the unscaled covariance would miss


def test_model_error_enters_as_a_correlated_pattern():
    n = 60
    t = np.linspace(-1.0, 2.0, n)
    u = 0.05 * np.sin(3 * t + 0.2) + 0.02  # the model's error pattern, unit std uncertainty
    emp, rep, chi2, jw, s = _linear_fits(0.1, 0.1, u=u)
    np.testing.assert_allclose(np.diag(rep), np.diag(emp), rtol=0.15)
    noise_only = np.linalg.inv(jw.T @ jw)
    assert np.all(np.diag(emp) > 1.3 * np.diag(noise_only))  # the pattern matters here
    # chi-square against I + U U^T: Woodbury against a direct solve
    rng = np.random.default_rng(0)
    r = rng.standard_normal(n)
    uw = (u / s)[:, None]
    cv = parameter_covariance(jw, r, uw, birge=False)
    direct = r @ np.linalg.solve(np.eye(n) + uw @ uw.T, r) / (n - 3)
    assert cv.chi2_reduced == pytest.approx(direct, rel=1e-10)
    a = np.linalg.inv(jw.T @ jw) @ jw.T
    np.testing.assert_allclose(cv.cov_model, a @ uw @ uw.T @ a.T, rtol=1e-10)


def test_decoded_modulation_of_known_fringes():
    rng = np.random.default_rng(4)
    for k in (3, 4, 9):
        d = 2 * np.pi * np.arange(k) / k
        a = rng.uniform(50, 100, (2, 3, 1, 7, 5))
        m = rng.uniform(0.05, 0.95, (2, 3, 1, 7, 5))
        phi = rng.uniform(-np.pi, np.pi, (2, 3, 1, 7, 5))
        im = a * (1 + m * np.cos(phi + d[:, None, None]))
        np.testing.assert_allclose(decoded_modulation(im), m[:, :, 0], rtol=1e-12)
        im[0, 1, :, 2, 3] = np.nan
        med = median_modulation(im)
        ref = np.array([[np.nanmedian(np.where(np.isnan(im[i, j, 0]), np.nan, m[i, j, 0]))
                         for j in range(3)] for i in range(2)])
        np.testing.assert_allclose(med, ref, rtol=1e-12)
    dark = np.zeros((1, 1, 4, 2, 2))
    assert np.all(np.isnan(decoded_modulation(dark)))
