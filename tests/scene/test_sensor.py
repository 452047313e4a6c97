"""Sensor (EMVA 1288 linear model) against its closed forms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pmdsim.config import ConfigError, SensorConfig, parse_config
from pmdsim.scene.sensor import Sensor

from conftest import base_dict
from pmdsim.store.images import read_image


def _sensor(**kw) -> Sensor:
    return Sensor.from_config(SensorConfig(enabled=True, **kw))


def test_disabled_is_identity():
    x = np.random.default_rng(1).random((3, 8, 9))
    x[0, 2, 3] = np.nan
    cap = Sensor().capture(x)
    np.testing.assert_array_equal(cap.dn, x)
    assert not cap.saturated.any()


@pytest.mark.parametrize("shot", [True, False])
def test_mean_and_variance_match_emva(shot):
    s = _sensor(exposure_electrons=2000.0, full_well_electrons=10000.0, dark_noise_electrons=7.0,
                dark_signal_electrons=30.0, gain_dn_per_electron=0.4, bit_depth=12,
                offset_dn=20.0, shot_noise=shot, seed=3)
    x = np.full((2, 300, 300), 0.5)
    x[:, 0, 0] = 1.0  # the brightest value: 0.5 -> 1000 e-
    cap = s.capture(x)
    y = cap.dn[:, 1:, :].ravel()
    mu_e = 1000.0
    k = 0.4
    mean = k * (mu_e + 30.0) + 20.0
    var = k * k * (7.0**2 + (mu_e if shot else 0.0)) + 1.0 / 12.0
    assert abs(y.mean() - mean) < 4 * np.sqrt(var / y.size) + 1e-9
    assert y.var() == pytest.approx(var, rel=0.02)
    assert np.all(y == np.rint(y))


def test_fixed_patterns_repeat_and_temporal_noise_does_not():
    s = _sensor(exposure_electrons=5000.0, prnu=0.01, dsnu_electrons=5.0, dark_noise_electrons=3.0, seed=7)
    x = np.full((2, 64, 64), 1.0)
    a = s.capture(x).dn
    b = s.capture(x).dn
    np.testing.assert_array_equal(a, b)  # same seed, same bytes
    assert not np.array_equal(a[0], a[1])  # frames differ
    c = s.capture(x, stream=1).dn
    assert not np.array_equal(a, c)
    # PRNU + DSNU: the pixel's time-average follows its fixed gain/offset
    many = np.stack([s.capture(x[:1], stream=k).dn[0] for k in range(40)]).mean(0)
    prnu, dsnu = s.fixed_patterns((64, 64))
    expect = s.gain * (5000.0 * prnu + dsnu)
    assert np.corrcoef(many.ravel(), expect.ravel())[0, 1] > 0.8


def test_saturation_and_nan():
    s = _sensor(exposure_electrons=12000.0, full_well_electrons=10000.0, bit_depth=8)
    x = np.array([[[1.0, 0.5], [np.nan, 0.1]]])
    cap = s.capture(x)
    assert cap.dn[0, 0, 0] == 255 and cap.saturated[0, 0, 0]
    assert not cap.saturated[0, 0, 1]
    assert np.isnan(cap.dn[0, 1, 0]) and not cap.saturated[0, 1, 0]


def test_config_errors():
    d = base_dict()
    d["sensor"] = {"enabled": True, "exposure_electrons": 100.0, "target_fill": 0.5}
    with pytest.raises(ConfigError, match="sensor"):
        parse_config(d)
    d["sensor"] = {"enabled": True, "bit_depth": 8, "offset_dn": 300}
    with pytest.raises(ConfigError, match="offset_dn"):
        parse_config(d)


@pytest.mark.parametrize("k_steps", [4, 8])
def test_decoded_phase_noise(k_steps):
    """std(phi) = sqrt(2 / K) sigma_I / B over many independent captures (pixels x seeds)."""
    s = _sensor(exposure_electrons=4000.0, full_well_electrons=10000.0, dark_noise_electrons=12.0,
                gain_dn_per_electron=0.3, bit_depth=12)
    a_val, b_val = 0.5, 0.3
    phi = np.random.default_rng(0).uniform(-np.pi, np.pi, (64, 64))
    deltas = 2 * np.pi * np.arange(k_steps) / k_steps
    frames = a_val + b_val * np.cos(phi[None] + deltas[:, None, None])
    errs = []
    for seed in range(6):
        cap = Sensor.from_config(SensorConfig(**{**s.__dict__, "seed": seed})).capture(frames, reference=1.0)
        z = np.tensordot(np.exp(-1j * deltas), cap.dn, axes=1)
        errs.append(np.angle(z * np.exp(-1j * phi)))
    err = np.concatenate([e.ravel() for e in errs])
    k = s.gain
    mu_e_mean = 4000.0 * a_val  # the shot-noise variance averages to the offset's
    sigma_i = np.sqrt(k * k * (12.0**2 + mu_e_mean) + 1 / 12)
    b_dn = k * 4000.0 * b_val
    expect = np.sqrt(2.0 / k_steps) * sigma_i / b_dn
    assert err.std() == pytest.approx(expect, rel=0.05)


def test_simulate_writes_what_the_camera_would(tmp_path):
    """With [sensor] on, the run's fringe images are the sensor's digital numbers: integers,
    12-bit range, written unscaled into 16-bit TIFFs; the chain still decodes."""
    from pmdsim import run as pipeline
    from pmdsim.store import schema

    from test_pipeline import tiny_config_dict

    d = tiny_config_dict(fringes={"widths_px": [8, 32, 160], "shifts": 4, "directions": ["x"]})
    d["sensor"] = {"enabled": True, "target_fill": 0.8, "full_well_electrons": 10000.0,
                   "dark_noise_electrons": 3.0, "bit_depth": 12, "seed": 4}
    res = pipeline.run_simulation(parse_config(d), tmp_path / "run", figures=False)
    ds = schema.load_run(res.outdir)
    f = ds["fringes"].values
    finite = f[np.isfinite(f)]
    assert np.all(finite == np.rint(finite)) and finite.max() <= 4095
    assert finite.max() == pytest.approx(0.8 * 4095, rel=0.05)
    assert res.exposure == 1.0
    tif = read_image(res.outdir / "fringes" / "x_w008_k0.tif")
    np.testing.assert_array_equal(tif, np.where(np.isnan(f[0, 0, 0]), 0, f[0, 0, 0]))
    stats = json.loads((res.outdir / "statistics.json").read_text())
    assert stats  # decoded and compared
