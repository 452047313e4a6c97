"""Topographies outside what the analysis and the ``topography`` model can describe (issue 38,
items 2 and 3): a groove with a noise floor (no K-correlation knee), flat and tilted maps,
every point an outlier. Through the command line: exit 0 with a complete, finite report, or
exit 2 naming the option or field and the file and saying what to do; never a traceback,
never an output folder from a refused run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import base_dict, merge
from test_budget import _write_toml
from typer.testing import CliRunner

from pmdsim.brdf import topography as tp
from pmdsim.brdf.psd import KCorrelation, fit_k_correlation, periodogram, synthesize
from pmdsim.cli import app


def _maps():
    """name -> (ny, nx) heights in um (the command's default unit), dx = 1 um."""
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:48, 0:64]
    groove = 0.003 * np.sin(2 * np.pi * y * 0.5 / 5)
    return {
        "groove_noise": groove + 0.001 * rng.standard_normal((48, 64)),  # the issue's case
        "groove": groove,
        "groove_x": groove.T.copy(),
        "white": 0.002 * rng.standard_normal((48, 64)),
        "zeros": np.zeros((48, 64)),
        "constant": np.full((48, 64), 0.5),
        "tilt": 1e-3 * x + 2e-3 * y + 7.0,  # a plane: levels to 0
        "tiny_noise": 1e-15 * rng.standard_normal((8, 8)),
        "spike": np.where((x == 10) & (y == 7), 5.0, 0.0),
        "steps": np.where(x < 32, 0.0, 0.01) + 0.0,
        "small": rng.standard_normal((4, 4)) * 1e-3,
    }


@pytest.mark.parametrize("name", list(_maps()))
def test_texture_from_any_map_reports_or_refuses_naming_from(tmp_path, name):
    path = tmp_path / f"{name}.npy"
    np.save(path, _maps()[name])
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["texture", "--from", str(path), "--spacing-um", "1", "1.5",
                                   "-o", str(out), "--no-figure"])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 2:
        assert "--from" in res.output and path.name in res.output, res.output
        assert not out.exists()
        return
    js = json.loads((out / "topography.json").read_text())
    for key in ("sq_um", "sdq", "rayleigh"):
        assert js[key] is not None and js[key] > 0, (key, js[key])
    for key in ("alpha_tangential", "alpha_radial"):  # a perfect groove: 0 along it
        assert js[key] is not None and js[key] >= 0, (key, js[key])
    if js["kc_note"]:  # no K-correlation: said in the table, no numbers in the JSON
        assert js["kc_sigma_um"] is None and "K-correlation" in res.output
        assert "not reported" in (out / "topography.txt").read_text()
    else:
        assert js["kc_sigma_um"] > 0 and js["kc_exponent"] > 1


def test_the_issue_groove_has_no_k_correlation_and_says_why(tmp_path):
    path = tmp_path / "h.npy"
    np.save(path, _maps()["groove_noise"])
    res = CliRunner().invoke(app, ["texture", "--from", str(path), "--spacing-um", "1", "1",
                                   "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert "does not describe this map" in res.output
    assert (tmp_path / "o" / "topography.png").is_file()  # the figure draws without the fit


@pytest.mark.parametrize("name, says", [("zeros", "flat"), ("constant", "flat"),
                                        ("tilt", "flat")])
def test_texture_from_a_flat_map_is_refused(tmp_path, name, says):
    path = tmp_path / f"{name}.npy"
    np.save(path, _maps()[name])
    res = CliRunner().invoke(app, ["texture", "--from", str(path), "--spacing-um", "1", "1"])
    assert res.exit_code == 2, res.output
    assert f"--from {path}" in res.output and says in res.output and "unit" in res.output


def test_k_correlation_fit_of_a_synthetic_surface_still_fits():
    """The log-space sigma and the resolution check leave a resolvable surface alone."""
    kc = KCorrelation(2e-6, 2 * math.pi * 4e-3, 2 * math.pi * 2e-3, 2.0)
    h = synthesize(kc, (128, 160), 0.5e-3, 0.4e-3, seed=3)
    fx, fy, s = periodogram(h, 0.5e-3, 0.4e-3, "none")
    fit = fit_k_correlation(fx, fy, s).model
    assert fit.correlation_lengths[0] == pytest.approx(4e-3, rel=0.2)
    assert fit.correlation_lengths[1] == pytest.approx(2e-3, rel=0.2)
    with pytest.raises(tp.FlatTopography):
        fit_k_correlation(fx, fy, np.zeros_like(s))


def _topo_config(tmp_path, heights, **brdf):
    np.save(tmp_path / "topo.npy", heights)
    d = merge(base_dict(), {
        "brdf": {"__replace__": {"model": "topography", "file": str(tmp_path / "topo.npy"),
                                 "spacing_mm": [0.001, 0.0015], **brdf}},
        "sampling": {"estimator": "radiometric"}})
    path = tmp_path / "run.toml"
    _write_toml(path, d)
    return path


@pytest.mark.parametrize("heights, brdf, says", [
    ("zeros", {}, "flat"),
    ("zeros", {"psd": "k_correlation"}, "flat"),
    ("constant", {"regime": "geometric"}, "flat"),
    ("groove_noise", {"outlier_sigma": 1e-9}, "outlier_sigma"),
    ("groove_noise", {"psd": "k_correlation"}, "brdf.psd"),
])
def test_topography_model_outside_its_data_is_refused_naming_the_field(tmp_path, heights, brdf,
                                                                        says):
    cfg = _topo_config(tmp_path, _maps()[heights], **brdf)
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert res.exit_code == 2, res.output
    assert "brdf." in res.output and says in res.output and "topo.npy" in res.output
    assert not out.exists() and not list(tmp_path.glob("run.tmp-*"))
