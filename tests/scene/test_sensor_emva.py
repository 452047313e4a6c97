"""Every public method of scene/sensor.py against the EMVA 1288 (release 4.0) linear-model
formulas, the independence of the surface's and the reference's noise, and the default gain
with an ADC offset."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import SensorConfig
from pmdsim.scene.sensor import DEFAULT_FILL, Sensor, capture_dn


def _sensor(**kw):
    base = dict(enabled=True, quantum_efficiency=0.6, full_well_electrons=12000.0,
                dark_noise_electrons=3.0, dark_signal_electrons=20.0, bit_depth=12,
                offset_dn=37.0, seed=11)
    base.update(kw)
    return Sensor.from_config(SensorConfig(**base))


def test_default_gain_with_offset_maps_the_full_well_to_the_adc_top():
    s = _sensor()
    assert s.max_dn == 4095
    # K = (2^b - 1 - offset) / full well: a full pixel reads exactly the top of the ADC
    assert s.gain == pytest.approx((4095 - 37.0) / 12000.0, rel=1e-15)
    assert s.gain * s.full_well_electrons + s.offset_dn == pytest.approx(4095.0, rel=1e-15)
    assert s.saturation_dn == 4095.0
    cap = s.capture(np.full((1, 64, 64), 1.0), reference=0.5)  # twice the exposure: clipped
    assert np.all(cap.dn == 4095.0) and cap.saturated.all()
    # an explicit gain that saturates the ADC before the well: the ADC top
    t = _sensor(gain_dn_per_electron=0.5)
    assert t.saturation_dn == 4095.0
    u = _sensor(gain_dn_per_electron=0.2)  # the well first: K FW + offset
    assert u.saturation_dn == round(0.2 * 12000.0 + 37.0)


def test_exposure_definitions():
    assert _sensor(exposure_electrons=5000.0).exposure == 5000.0
    assert _sensor(exposure_photons=5000.0).exposure == pytest.approx(0.6 * 5000.0)  # mu_e = eta mu_p
    assert _sensor(target_fill=0.4).exposure == pytest.approx(0.4 * 12000.0)
    assert _sensor().exposure == pytest.approx(DEFAULT_FILL * 12000.0)


def test_noise_dn_is_emva_temporal_noise():
    s = _sensor()
    mu_e = np.array([0.0, 100.0, 4000.0])
    k = s.gain
    expect = np.sqrt(k**2 * (3.0**2 + mu_e) + 1 / 12)  # sigma_y^2 = K^2 (sigma_d^2 + mu_e) + sigma_q^2
    np.testing.assert_allclose(s.noise_dn(mu_e), expect, rtol=1e-14)
    np.testing.assert_allclose(_sensor(shot_noise=False).noise_dn(mu_e),
                               np.sqrt(k**2 * 9.0 + 1 / 12) * np.ones(3), rtol=1e-14)


def test_capture_mean_and_variance_with_offset():
    s = _sensor(exposure_electrons=6000.0)
    x = np.full((4, 150, 150), 0.5)
    x[0, 0, 0] = 1.0  # the reference value: 6000 e- at 1.0, 3000 e- at 0.5
    cap = s.capture(x)
    assert cap.electrons_per_value == pytest.approx(6000.0)
    y = cap.dn[:, 1:, 1:]
    mu_e = 3000.0
    # mu_y = K (mu_e + mu_d) + offset; sigma_y^2 = K^2 (sigma_d^2 + mu_e) + 1/12
    assert y.mean() == pytest.approx(s.gain * (mu_e + 20.0) + 37.0, rel=2e-4)
    assert y.var() == pytest.approx(s.noise_dn(mu_e) ** 2, rel=0.02)


def test_fixed_patterns_are_emva_prnu_and_dsnu():
    s = _sensor(prnu=0.01, dsnu_electrons=4.0)
    prnu, dsnu = s.fixed_patterns((300, 300))
    assert prnu.mean() == pytest.approx(1.0, abs=3e-4) and prnu.std() == pytest.approx(0.01, rel=0.02)
    assert abs(dsnu.mean()) < 0.05 and dsnu.std() == pytest.approx(4.0, rel=0.02)
    p2, d2 = s.fixed_patterns((300, 300))
    np.testing.assert_array_equal(prnu, p2)  # fixed by the seed
    # the DSNU in DN, seen as the spatial std of the dark image averaged over frames
    dark = _sensor(dsnu_electrons=4.0, dark_noise_electrons=0.0, shot_noise=False)
    cap = dark.capture(np.zeros((1, 300, 300)), reference=1.0)
    assert cap.dn.std() == pytest.approx(np.sqrt((dark.gain * 4.0) ** 2 + 1 / 12), rel=0.03)


def test_surface_and_reference_captures_have_independent_noise():
    """The surface is stream 0, its specular reference stream 1: temporal noise fields
    uncorrelated, fixed patterns (PRNU, DSNU) shared, as in a real camera."""
    s = _sensor(prnu=0.0, dsnu_electrons=0.0, exposure_electrons=8000.0)
    x = np.full((2, 200, 200), 0.6)
    x[:, 0, 0] = 1.0
    a = capture_dn(s, x, 0).astype(np.float64)[:, 1:, 1:]
    b = capture_dn(s, x, 1).astype(np.float64)[:, 1:, 1:]
    na, nb = a - a.mean(), b - b.mean()
    r = float((na * nb).mean() / (na.std() * nb.std()))
    assert abs(r) < 4 / np.sqrt(na.size)  # 4 sigma of a zero correlation
    again = capture_dn(s, x, 0).astype(np.float64)[:, 1:, 1:]
    np.testing.assert_array_equal(a, again)  # same stream, same seed: the same bytes
    # with fixed patterns the two share the DSNU: positively correlated
    f = _sensor(dsnu_electrons=20.0, prnu=0.02, exposure_electrons=8000.0)
    a = capture_dn(f, x, 0).astype(np.float64)[:, 1:, 1:]
    b = capture_dn(f, x, 1).astype(np.float64)[:, 1:, 1:]
    r = np.corrcoef(a.ravel(), b.ravel())[0, 1]
    fixed = (f.gain * 20.0) ** 2 + (f.gain * 0.02 * 4800.0) ** 2
    assert r == pytest.approx(fixed / (fixed + f.noise_dn(4800.0) ** 2), abs=0.03)


def test_disabled_sensor_and_capture_dn_dtype():
    s = Sensor()
    x = np.random.default_rng(0).random((2, 5, 6))
    np.testing.assert_array_equal(s.capture(x).dn, x)
    d = capture_dn(_sensor(), np.where(x > 0.9, np.nan, x), 0)
    assert d.dtype == np.float32 and np.isnan(d[x > 0.9]).all()
