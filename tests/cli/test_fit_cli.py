"""``pmdsim fit`` as a user runs it (subprocesses): a good fit exits 0; images the model
cannot describe (noise, shuffled frames, other fringe widths) exit 1 with the reason and
their files written and marked failed; bad input (a camera that sees no monitor, images of
another size, ``-o`` naming an existing file) exits 2 with a clean message before any fit.

Tiny scene: the 20 x 16 px camera of tests/studies/test_fit.py, three widths, four shifts; the
"measured" images are rendered with 512 rays (a different sample set than the fit's
default 100) and captured by a 12-bit EMVA sensor (shot and dark noise)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile

from conftest import base_dict, merge
from test_budget import _write_toml
from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.scene.sensor import Sensor

SRC = str(Path(__file__).parents[2] / "src")
TRUTH = (0.025, 0.010)
WIDTHS = [15.0, 30.0, 70.0]
SENSOR = {"enabled": True, "exposure_electrons": 7000.0, "full_well_electrons": 10000.0,
          "bit_depth": 12, "dark_noise_electrons": 5.0}


def _dict(**changes):
    return merge(base_dict(), merge({
        "camera": {"resolution": [20, 16], "focal_length_px": 40.0},
        "monitor": {"pixel_model": "continuous"},
        "brdf": {"__replace__": {"model": "ward", "alpha_x": 0.02, "alpha_y": 0.02,
                                 "rho_s": 0.4}},
        "sampling": {"n_rays": 100},
        "patterns": {"fringes": {"widths_px": WIDTHS, "shifts": 4}},
        "sensor": SENSOR}, changes))


def _write_frames(folder: Path, stem: str, frames) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, f in enumerate(frames):
        paths.append(folder / f"{stem}{i:02d}.tif")
        tifffile.imwrite(paths[-1], np.nan_to_num(f, nan=0.0).astype(np.uint16))
    return paths


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("fitcli")
    truth = _dict(brdf={"__replace__": {"model": "ward", "alpha_x": TRUTH[0],
                                        "alpha_y": TRUTH[1], "rho_s": 0.4}},
                  sampling={"n_rays": 512, "estimator": "radiometric"})
    values = Simulation.from_config(parse_config(truth)).render_fringes(
        WIDTHS, ("x", "y"), 4).images
    dn = Sensor(**SENSOR, seed=7).capture(values).dn
    frames = dn.reshape(-1, *dn.shape[-2:])
    rng = np.random.default_rng(3)
    other = Simulation.from_config(parse_config(truth)).render_fringes(
        [w * 4 for w in WIDTHS], ("x", "y"), 4).images  # the images of other widths
    cfg = root / "fit.toml"
    _write_toml(cfg, _dict())
    x0, y0, z0 = base_dict()["camera"]["position_mm"]
    off = root / "off.toml"
    _write_toml(off, _dict(camera={"position_mm": [x0 + 300.0, y0, z0]}))
    return {
        "root": root, "cfg": cfg, "off": off,
        "good": _write_frames(root / "good", "f", frames),
        "noise": _write_frames(root / "noise", "n", rng.integers(0, 4000, frames.shape)),
        "shuffled": _write_frames(root / "shuffled", "s", frames[rng.permutation(len(frames))]),
        "widths": _write_frames(root / "widths", "w", Sensor(**SENSOR, seed=8).capture(
            other).dn.reshape(frames.shape)),
        "small": _write_frames(root / "small", "p", frames[:, :, 2:]),
    }


def _fit(cfg, images, out, *extra):
    env = dict(os.environ, PYTHONPATH=SRC)
    return subprocess.run([sys.executable, "-m", "pmdsim.cli", "fit", str(cfg),
                           *map(str, images), "-o", str(out), "--no-figure", *extra],
                          env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.slow  # a fit refined to 1600 rays and a second run: ~20 s
def test_good_images_fit_and_cover_the_truth(case):
    out = case["root"] / "out-good"
    p = _fit(case["cfg"], case["good"], out)
    assert p.returncode == 0, p.stdout + p.stderr
    res = json.loads((out / "fit.json").read_text())
    assert res["success"] is True and res["reason"] == ""
    for name, t in zip(("alpha_x", "alpha_y"), TRUTH):
        q = res["parameters"][name]
        assert abs(q["value"] - t) <= 2 * q["std"], (name, q)
        assert q["std_model"] > 0 and q["std_noise"] > 0
    assert res["model"]["estimator"] == "radiometric"  # the fit's default
    # the sensor's noise model against the images' own phase-shift residual
    assert 0.9 < res["noise"]["observed_to_model"] < 1.1, res["noise"]
    assert (out / "pmdsim-fit.json").is_file()
    again = _fit(case["cfg"], case["good"], out)  # an existing fit folder: refused
    assert again.returncode == 2 and "--overwrite" in again.stderr


@pytest.mark.parametrize("what", ["noise", "shuffled", "widths"])
def test_images_the_model_cannot_describe_exit_1_marked_failed(case, what):
    out = case["root"] / f"out-{what}"
    p = _fit(case["cfg"], case[what], out)
    text = p.stdout + p.stderr
    assert p.returncode == 1, text
    assert "the fit failed" in p.stderr and "Traceback" not in text
    assert "validation error" not in text and "pydantic" not in text
    res = json.loads((out / "fit.json").read_text())
    assert res["success"] is False and res["reason"]
    assert res["reason"] in p.stderr
    assert "FIT FAILED" in (out / "fit.txt").read_text()
    assert json.loads((out / "pmdsim-fit.json").read_text())["success"] is False


def test_bad_input_exits_2_before_the_fit(case):
    root = case["root"]
    off = _fit(case["off"], case["good"], root / "out-off")  # camera 300 mm off
    assert off.returncode == 2 and "monitor.centre_mm" in off.stderr, off.stderr
    assert not (root / "out-off").exists()
    small = _fit(case["cfg"], case["small"], root / "out-small")
    assert small.returncode == 2 and "(16, 18) pixels" in small.stderr, small.stderr
    existing = root / "existing.txt"
    existing.write_text("keep me\n")
    missing = [root / "no-such-image.tif"]  # the output is refused before images are read
    p = _fit(case["cfg"], missing, existing)
    assert p.returncode == 2 and "is a file" in p.stderr and "no-such-image" not in p.stderr
    assert existing.read_text() == "keep me\n"
    for text in (off.stderr, small.stderr, p.stderr):
        assert "Traceback" not in text


def test_target_error_sets_the_fits_order(case):
    """``--target-error-mrad``: the fit starts from the rule's order that meets the target at
    the start values, reports it in fit.json, and still covers the truth."""
    cfg = case["root"] / "rule.toml"
    _write_toml(cfg, _dict(sampling={"mode": "rule", "n_rays": 64}))
    out = case["root"] / "out-target"
    p = _fit(cfg, case["good"], out, "--target-error-mrad", "0.5", "--max-rays", "1024")
    assert p.returncode == 0, p.stdout + p.stderr
    res = json.loads((out / "fit.json").read_text())
    t = res["model"]["target"]
    assert t["target_error_mrad"] == 0.5 and 64 <= t["n_rays"] <= 1024  # capped by --max-rays
    assert (t["achieved_p95_mrad"] <= 0.5) == t["target_met"]
    assert res["model"]["ladder"][0]["n_rays"] == t["n_rays"]  # the fit starts there
    bad = _fit(cfg, case["good"], case["root"] / "out-bad", "--target-error-mrad", "-1")
    assert bad.returncode == 2 and "target-error-mrad" in bad.stderr
