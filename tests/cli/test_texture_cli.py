"""The ``pmdsim texture`` and ``pmdsim fit`` commands (files, numbers, errors)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from typer.testing import CliRunner

from conftest import base_dict, merge
from test_budget import _write_toml
from pmdsim.cli import app
from pmdsim.config import parse_config
from pmdsim.render import Simulation


def test_cli_texture_issue_example(tmp_path):
    out = tmp_path / "tex"
    res = CliRunner().invoke(app, ["texture", "--feed-um", "30", "--nose-radius-mm", "0.5",
                                   "--rq-um", "0.005", "--correlation-um", "5", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "0.0245" in res.output and "regime" in res.output and "diffractive" in res.output
    p = json.loads((out / "texture.json").read_text())
    assert round(p["kinematic_alpha_radial_small_slope"], 4) == 0.0245
    assert (out / "texture.png").is_file() and (out / "texture.txt").is_file()
    bad = CliRunner().invoke(app, ["texture", "--feed-um", "2000", "--nose-radius-mm", "0.5"])
    assert bad.exit_code == 2 and "feed" in bad.output


def test_cli_fit_recovers_noise_free_alphas(tmp_path):
    """Noise-free float images of a converged render (4096 rays); the configuration's own
    128 rays are refined by the fit until its alphas stop moving."""
    d = merge(base_dict(), {
        "camera": {"resolution": [20, 16], "focal_length_px": 40.0},
        "monitor": {"pixel_model": "continuous"},
        "brdf": {"__replace__": {"model": "ward", "alpha_x": 0.025, "alpha_y": 0.01}},
        "sampling": {"estimator": "radiometric", "n_rays": 128, "mode": "stratified"},
        "patterns": {"fringes": {"widths_px": [15.0, 25.0, 40.0, 70.0], "shifts": 4}}})
    converged = parse_config(merge(d, {"sampling": {"n_rays": 4096}}))
    imgs = Simulation.from_config(converged).render_fringes(
        (15.0, 25.0, 40.0, 70.0), ("x", "y"), 4).images
    paths = []
    for i, frame in enumerate(imgs.reshape(-1, *imgs.shape[-2:])):
        paths.append(tmp_path / f"f{i:02d}.tif")
        tifffile.imwrite(paths[-1], np.nan_to_num(frame * 1000.0, nan=0.0).astype(np.float32))
    d["brdf"] = {"model": "ward", "alpha_x": 0.02, "alpha_y": 0.02}  # not the truth
    cfg_path = tmp_path / "fit.toml"
    _write_toml(cfg_path, d)
    out = tmp_path / "fit"
    res = CliRunner().invoke(app, ["fit", str(cfg_path), *map(str, paths), "-o", str(out)])
    assert res.exit_code == 0, res.output
    p = json.loads((out / "fit.json").read_text())["parameters"]
    assert abs(p["alpha_x"]["value"] / 0.025 - 1) < 0.02
    assert abs(p["alpha_y"]["value"] / 0.01 - 1) < 0.02
    assert (out / "fit.png").is_file()
    assert json.loads((out / "fit.json").read_text())["success"] is True
    bad = CliRunner().invoke(app, ["fit", str(cfg_path), *map(str, paths[:-1]), "-o",
                                   str(tmp_path / "fit2")])
    assert bad.exit_code == 2 and "32" in bad.output


@pytest.mark.parametrize("stop", [KeyboardInterrupt, OSError])
def test_an_interrupted_texture_report_leaves_the_folder_as_it_was(tmp_path, monkeypatch, stop):
    """Ctrl-C (or a full disk) while the figure is drawn: the folder keeps the previous
    report's files byte for byte, no new file and no temporary appears (the three files
    are renamed into place together, texture.json last)."""
    from pmdsim.run import texture as run_texture_mod

    out = tmp_path / "tex"
    args = ["texture", "--feed-um", "20", "--nose-radius-mm", "0.5", "-o", str(out)]
    assert CliRunner().invoke(app, args).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"texture.json", "texture.txt", "texture.png"}

    def broken(*a, **k):
        raise stop("stopped while drawing")

    monkeypatch.setattr(run_texture_mod, "plot_texture", broken)
    res = CliRunner().invoke(app, ["texture", "--feed-um", "30", "--nose-radius-mm", "0.8",
                                   "-o", str(out)])
    assert res.exit_code != 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
