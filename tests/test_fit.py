"""Tests of the inverse problem (``pmdsim.studies.fit``): fringe images -> alphas.

Images of the small test scene (20 x 16 px camera, radiometric estimator, stratified
sample set, continuous monitor) are simulated with known Ward alphas and captured by the
EMVA sensor model (shot noise, 12-bit ADC, seeded); the fit must recover the alphas within
2 %, and its expanded uncertainties (k = 2) must cover the truth in at least 17 of 20
seeded repeats (the noise is the only difference between repeats).
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_config
from pmdsim.render import Simulation
from pmdsim.scene.sensor import Sensor
from pmdsim.studies.fit import NoiseModel, closed_form_start, fit_fringe_images, median_modulation

TRUTH = (0.025, 0.010)
WIDTHS = (15.0, 25.0, 40.0, 70.0)


def _config(ax=TRUTH[0], ay=TRUTH[1]):
    return make_config(
        camera={"resolution": [20, 16], "focal_length_px": 40.0},
        monitor={"pixel_model": "continuous"},
        brdf={"__replace__": {"model": "ward", "alpha_x": ax, "alpha_y": ay, "rho_s": 0.4}},
        sampling={"estimator": "radiometric", "n_rays": 256, "mode": "stratified"})


@pytest.fixture(scope="module")
def truth_values():
    sim = Simulation.from_config(_config())
    return sim.render_fringes(WIDTHS, ("x", "y"), 4).images.astype(np.float64)


SENSOR = Sensor(enabled=True, exposure_electrons=7000.0, full_well_electrons=10000.0,
                bit_depth=12, dark_noise_electrons=5.0)


def _capture(values, seed):
    s = Sensor(**{**SENSOR.__dict__, "seed": seed})
    return s.capture(values, reference=float(np.nanmax(values))).dn


def test_closed_form_start_is_near_the_truth(truth_values):
    sim = Simulation.from_config(_config(0.02, 0.02))
    m = median_modulation(truth_values)
    ax, ay = closed_form_start(sim, WIDTHS, ("x", "y"), m)
    assert abs(ax / TRUTH[0] - 1) < 0.25 and abs(ay / TRUTH[1] - 1) < 0.25, (ax, ay)


@pytest.mark.slow  # 20 fits, ~28 s CPU alone
def test_fit_recovers_alphas_and_uncertainties_cover(truth_values):
    noise = NoiseModel(SENSOR.gain, SENSOR.dark_noise_electrons)
    cfg = _config(0.02, 0.02)  # the configuration's own alphas are not the truth
    covered = 0
    errors = []
    for seed in range(20):
        res = fit_fringe_images(cfg, _capture(truth_values, seed), WIDTHS, ("x", "y"), noise)
        rel = res.values[:2] / np.array(TRUTH) - 1
        errors.append(np.abs(rel).max())
        if np.all(np.abs(res.values[:2] - TRUTH) <= 2 * res.std[:2]):
            covered += 1
        assert res.success
    assert max(errors) < 0.02, errors
    assert covered >= 17, f"k = 2 intervals covered the truth in {covered} of 20 repeats"
