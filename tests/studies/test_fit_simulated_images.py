"""`pmdsim fit` on a pmdsim run's own 16-bit fringe images (issue 37): the images carry
their quantisation and their rule's numerical error, and the fit's uncertainty must carry
both. The case of the issue: the Fig. 3 example (truth alpha_x = 0.025, alpha_y = 0.002
exactly) on a reduced camera, its run's 24 fringe images fitted with the run's folder
(the fit reads the run's sampling from it). Before, the truth lay 114 u and 170 u away."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pmdsim.config import load_config
from pmdsim.studies.convergence import reduced_config

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # a run and a fit, ~1 min
def test_fit_of_a_runs_own_images_covers_the_truth(tmp_path):
    from pmdsim.run import run_simulation
    from pmdsim.run.fit import images_sampling_of, run_fit

    cfg = reduced_config(load_config(ROOT / "examples" / "paper_fig3.toml"), (64, 51))
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(update={"figures": False})})
    run = tmp_path / "run"
    run_simulation(cfg, run, diagnostics=False)
    # the order the pilot picked for the target (statistics.json)
    rendered = json.loads((run / "statistics.json").read_text())["sampling"]["n_rays"]
    assert rendered >= 16
    files = sorted((run / "fringes").glob("*.tif"))
    assert len(files) == 24
    # the order a file name sorts in is direction, width, shift: what [patterns.fringes] lists
    smp = images_sampling_of(files)
    assert smp is not None and smp["mode"] == "rule" and smp["n_rays"] == rendered
    assert images_sampling_of(files[:1] + [tmp_path / "elsewhere.tif"]) is None
    res = run_fit(cfg, files, tmp_path / "fit", figure=False).result
    assert res.success, res.reason
    truth = np.array([0.025, 0.002])
    z = (res.values[:2] - truth) / res.std[:2]
    assert np.all(np.abs(z) <= 2.0), (z, res.values, res.std)
    # the images' error is what carries it, not the noise: the noise part alone is tiny
    assert np.all(np.abs(res.values[:2] - truth) > 10 * res.std_noise[:2])
    assert res.model["images"]["sampling"]["n_rays"] == rendered
    assert res.model["quantisation_step"] == 1.0


def test_quantisation_floors_the_noise_of_noise_free_images():
    """Noise-free float images fitted to their own model: the noise estimated from the
    residual is the optimiser's precision; a quantisation step floors it at step/sqrt(12)."""
    from pmdsim.studies import fit_coverage as fc
    from pmdsim.studies.fit import fit_fringe_images

    case = fc.coverage_cases(20)[1]  # a noise-free case of the coverage study
    images, cfg = fc.truth_images(case)
    res = fit_fringe_images(cfg, images, fc.WIDTHS, ("x", "y"), None, quantisation_step=1.0,
                            images_sampling={"estimator": "radiometric", "mode": "rule",
                                             "n_rays": case.images_rays}, max_rays=400)
    assert res.noise["sigma"] >= 1.0 / np.sqrt(12.0) * (1 - 1e-12)
    z = (res.values[:2] - (case.alpha_x, case.alpha_y)) / res.std[:2]
    assert np.all(np.abs(z) <= 2.0) and res.success, (z, res.reason)
