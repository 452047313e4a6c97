"""Tests of the inverse problem (``pmdsim.studies.fit``): fringe images -> alphas.

The "measured" images come from :mod:`pmdsim.studies.fit_coverage`'s seeded cases: a
20 x 16 px camera, Ward alphas, incidence and noise drawn per case, rendered with a
converged model (4096 rays, a different sample set than the fit's) and captured by the EMVA
sensor. The fit runs with its default settings; its k = 2 intervals must cover the truth
and its reduced chi-square must be about 1; a wrong noise model must make it fail.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_config
from pmdsim.render import Simulation
from pmdsim.scene.sensor import Sensor
from pmdsim.studies import fit_coverage as fc
from pmdsim.studies.fit import (closed_form_start, fit_config, fit_fringe_images,
                                median_modulation)
from pmdsim.studies.fit_stats import NoiseModel

TRUTH = (0.025, 0.010)
WIDTHS = (15.0, 25.0, 40.0, 70.0)


def _config(ax=TRUTH[0], ay=TRUTH[1]):
    return make_config(
        camera={"resolution": [20, 16], "focal_length_px": 40.0},
        monitor={"pixel_model": "continuous"},
        brdf={"__replace__": {"model": "ward", "alpha_x": ax, "alpha_y": ay, "rho_s": 0.4}},
        sampling={"estimator": "radiometric", "n_rays": 256, "mode": "stratified"})


def test_closed_form_start_is_near_the_truth():
    truth_values = Simulation.from_config(_config()).render_fringes(
        WIDTHS, ("x", "y"), 4).images.astype(np.float64)
    sim = Simulation.from_config(_config(0.02, 0.02))
    m = median_modulation(truth_values)
    ax, ay = closed_form_start(sim, WIDTHS, ("x", "y"), m)
    assert abs(ax / TRUTH[0] - 1) < 0.25 and abs(ay / TRUTH[1] - 1) < 0.25, (ax, ay)


def test_fit_defaults_to_the_radiometric_estimator_unless_set():
    d = fc.case_dict(fc.coverage_cases(1)[0])
    from pmdsim.config import parse_config

    cfg = fit_config(parse_config(d))
    assert (cfg.sampling.estimator, cfg.sampling.mode) == ("radiometric", "rule")  # issue 37
    assert cfg.sampling.error_estimate is False  # the fit refines instead
    from pmdsim.config import with_target_error

    tgt = fit_config(with_target_error(parse_config(d), 0.2))  # the target needs the estimate
    assert tgt.sampling.error_estimate is True and tgt.sampling.target_error_mrad == 0.2
    assert tgt.sampling.mode == "rule"  # the target is the rule's
    own = fit_config(parse_config(d | {"sampling": {"estimator": "paper", "mode": "random",
                                                    "error_estimate": True}}))
    assert (own.sampling.estimator, own.sampling.mode) == ("paper", "random")
    assert own.sampling.error_estimate is True


@pytest.mark.slow  # six fits, ~1 min
def test_fit_uncertainties_cover_the_truth_over_seeded_cases():
    """Six of the study's cases (alphas 0.004-0.04 unequal, incidence, exposure and dark
    noise all drawn; three of them noise-free 16-bit images of a 256-node rule): at least
    five covered at k = 2, the normalised errors' mean square
    consistent with 1 (below 2.5: chi-square with 12 degrees of freedom, P ~ 0.3 %), every
    fit successful with a reduced chi-square near 1."""
    results = [fc.run_case(c) for c in fc.coverage_cases(20)[:6]]
    z = np.array([r.normalised_errors for r in results])
    assert sum(r.covered for r in results) >= 5, z
    assert np.mean(z**2) < 2.5, z
    for r in results:
        assert r.success, r.reason
        # sensor noise: chi-square near 1; noise-free 16-bit images (cases 1, 2, 5): the
        # residual's power against the stated numerical errors', at most about 1
        lo = 0.0 if r.case.noise_free else 0.85
        assert lo < r.chi2_reduced < 1.2, r.chi2_reduced
    assert sum(r.case.noise_free for r in results) == 3


def test_noise_free_images_of_a_converged_model_are_fitted_within_the_model_error():
    """No noise: what is left is the model's numerical error, which the refinement of the
    sample set must bound (k = 2) and have shrunk below half the noise uncertainty."""
    from pmdsim.config import parse_config

    case = fc.coverage_cases(20)[4]
    d = fc.case_dict(case)
    cfg = parse_config(d)
    truth = parse_config(d | {"brdf": {"model": "ward", "alpha_x": case.alpha_x,
                                       "alpha_y": case.alpha_y, "rho_s": 0.4},
                              "sampling": {"estimator": "radiometric", "n_rays": fc.TRUTH_RAYS}})
    values = Simulation.from_config(truth).render_fringes(
        fc.WIDTHS, ("x", "y"), fc.SHIFTS).images * 3000.0
    noise = NoiseModel.from_sensor(Sensor.from_config(cfg.sensor))
    res = fit_fringe_images(cfg, values, fc.WIDTHS, ("x", "y"), noise)
    err = res.values[:2] - (case.alpha_x, case.alpha_y)
    assert np.all(np.abs(err) <= 2 * res.std[:2]), (err, res.std, res.model)
    assert res.model["converged"] and len(res.model["ladder"]) >= 2
    assert res.chi2_reduced < 0.2  # no noise in the images, noise in the weights


def test_a_noise_model_too_small_fails_the_fit():
    """Images captured with gain K, fitted with a noise model of a tenth of the gain (the
    shot noise 10x too small): the reduced chi-square exposes it and the fit fails."""
    case = fc.coverage_cases(20)[3]
    images, cfg = fc.truth_images(case)
    s = Sensor.from_config(cfg.sensor)
    wrong = NoiseModel(s.gain / 10, s.dark_noise_electrons / 10)
    res = fit_fringe_images(cfg, images, fc.WIDTHS, ("x", "y"), wrong, max_rays=100)
    assert not res.success and "chi-square" in res.reason and res.chi2_reduced > 5


def test_coverage_folder_json_and_figure(tmp_path, monkeypatch):
    """The study's folder (results stubbed: the fits are tested above): coverage.json
    counts the covered cases, coverage.png is drawn, the marker makes it replaceable."""
    import json

    from pmdsim.run import fit_coverage as run_cov

    cases = fc.coverage_cases(3, seed=4)
    fake = [fc.CoverageResult(c, (c.alpha_x * (1 + e), c.alpha_y, 1.0), (c.alpha_x * 0.01,
                              c.alpha_y * 0.01, 0.1), (0.0, 0.0, 0.0), 1.0, True, "",
                              abs(e) <= 0.02) for c, e in zip(cases, (0.005, -0.03, 0.0))]
    monkeypatch.setattr(run_cov, "fit_coverage", lambda n, seed, progress=None: fake[:n])
    results, out = run_cov.run_fit_coverage(tmp_path / "cov", n=3, seed=4)
    data = json.loads((out / "coverage.json").read_text())
    assert data["covered_k2"] == 2 and len(data["cases"]) == 3
    assert data["cases"][1]["normalised_errors"][0] == pytest.approx(-3.0)
    assert (out / "coverage.png").stat().st_size > 10_000
    run_cov.run_fit_coverage(tmp_path / "cov", n=3, seed=4, overwrite=True)  # replaceable


def test_three_shifts_without_a_sensor_model_fit_but_say_the_test_was_not_made():
    """K = 3 and no noise model: no degree of freedom is left for a noise estimate, so the
    chi-square is not tested (NaN, a note), and the fit is still made."""
    from pmdsim.config import parse_config

    case = fc.coverage_cases(20)[4]
    d = fc.case_dict(case)
    d.pop("sensor")
    truth = parse_config(d | {"brdf": {"model": "ward", "alpha_x": case.alpha_x,
                                       "alpha_y": case.alpha_y, "rho_s": 0.4},
                              "sampling": {"estimator": "radiometric", "n_rays": 1024}})
    values = Simulation.from_config(truth).render_fringes(fc.WIDTHS, ("x", "y"), 3).images
    res = fit_fringe_images(parse_config(d), values * 1000.0, fc.WIDTHS, ("x", "y"),
                            max_rays=400)
    assert res.success and np.isnan(res.chi2_reduced) and "not made" in res.noise["note"]
    assert res.as_dict()["chi2_reduced"] is None
    assert np.all(np.abs(res.values[:2] / (case.alpha_x, case.alpha_y) - 1) < 0.02)


def test_a_fit_that_cannot_fit_the_machine_is_refused_before_the_images_are_read(tmp_path):
    from typer.testing import CliRunner

    from pmdsim.cli import app
    from pmdsim.config import ConfigError, parse_config
    from pmdsim.studies.fit import check_fit_resources, fit_levels
    from test_budget import _write_toml

    d = fc.case_dict(fc.coverage_cases(1)[0])
    assert fit_levels(parse_config(d)) == [100, 400, 1600, 6400]
    assert fit_levels(parse_config(d), 1000) == [100, 400]
    slow = d | {"compute": d["compute"] | {"max_cpu_hours": 1e-5}}
    with pytest.raises(ConfigError, match=r"sampling\.n_rays: the fit .*max_cpu_hours"):
        check_fit_resources(parse_config(slow))
    huge = d | {"camera": d["camera"] | {"resolution": [40000, 30000],  # and a lens to match
                                         "focal_length_px": 40000.0}}
    with pytest.raises(ConfigError, match=r"camera\.resolution: .* memory"):
        check_fit_resources(parse_config(huge))
    _write_toml(tmp_path / "slow.toml", slow)
    res = CliRunner().invoke(app, ["fit", str(tmp_path / "slow.toml"),
                                   str(tmp_path / "missing.tif"), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and "max_cpu_hours" in res.output, res.output
    assert "missing.tif" not in res.output and not (tmp_path / "out").exists()
