"""Issue 21's cases through the command line, in-process (typer's CliRunner): each bad
user file, impossible setting and signal-free sensor or display is exit code 2 with a
message naming the field (and the file), nothing written and no traceback. The readers'
own tests (test_user_files.py, test_physics_sanity.py) check what each error says; these
check that every case of the issue reaches the user as bad input."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import base_dict, merge
from test_cli_bad_input import _toml
from test_physics_sanity import REFUSED
from test_user_files import LUT_CASES, _write_case

LENS = {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2, "focal_length_px": None}
HEIGHT_MAP = {"type": "height_map", "spacing_mm": [1.0, 1.5]}


def _invoke(*args):
    from pmdsim.cli import app

    return CliRunner().invoke(app, [str(a) for a in args])


def _simulate_refused(tmp_path, changes, *says):
    cfg = tmp_path / "run.toml"
    cfg.write_text(_toml(merge(base_dict(), changes)))
    out = tmp_path / "out"
    result = _invoke("simulate", cfg, "-o", out, "--no-figures")
    text = " ".join(result.output.split())
    assert result.exit_code == 2, result.output
    for s in says:
        assert s in text, (s, text)
    assert "Traceback" not in text and not out.exists()
    return text


# ----------------------------------------------------------------------------- user files
@pytest.mark.parametrize("name", [n for n, (_, p) in LUT_CASES.items() if p is not None])
def test_a_bad_display_lut(tmp_path, name):
    text, problem = LUT_CASES[name]
    (tmp_path / "lut.csv").write_text(text)
    _simulate_refused(tmp_path, {"monitor": {"response_lut": "lut.csv"}},
                      "monitor.response_lut", "lut.csv", problem)


FLATNESS = ["nan.npy", "one.npy", "cube.npy", "truncated.npy", "garbage.npy", "object.npy",
            "text.csv", "ragged.csv", "binary.csv", "truncated.tif"]
HEIGHTS = ["truncated.npy", "object.npy", "structured.npy", "complex.npy", "ragged.csv",
           "binary.csv", "text.csv", "truncated.tif"]


@pytest.mark.parametrize("name", FLATNESS + ["missing.npy"])
def test_a_bad_flatness_map(tmp_path, name):
    problem = "file not found"
    if name != "missing.npy":
        _, problem = _write_case(tmp_path, name)
    _simulate_refused(tmp_path, {"monitor": {"flatness_map": name}}, "monitor.flatness_map",
                      name, problem)


@pytest.mark.parametrize("name", HEIGHTS)
def test_a_bad_height_map(tmp_path, name):
    _, problem = _write_case(tmp_path, name)
    _simulate_refused(tmp_path, {"surface": {"__replace__": dict(HEIGHT_MAP, file=name)}},
                      "surface.file", name, problem)


def test_a_height_map_csv_with_a_header_line_is_read(tmp_path):
    """A CSV whose first line is a header is read (the loader skips one header line): the
    case that crashed is now a valid input; a header-only CSV is refused."""
    from pmdsim.config.files import read_height_map

    z = np.arange(20.0).reshape(4, 5) * 1e-3
    path = tmp_path / "h.csv"
    path.write_text("a,b,c,d,e\n" + "\n".join(",".join(f"{v:g}" for v in r) for r in z) + "\n")
    np.testing.assert_allclose(read_height_map(path, "surface.file"), z)
    (tmp_path / "empty.csv").write_text("a,b,c\n")
    _simulate_refused(tmp_path, {"surface": {"__replace__": dict(HEIGHT_MAP, file="empty.csv")}},
                      "surface.file", "empty.csv")


# ----------------------------------------------------------------------------- settings
SETTINGS = {
    "full_well 1e30": ({"sensor": {"enabled": True, "full_well_electrons": 1e30}},
                       "sensor.full_well_electrons"),
    "exposure 1e30": ({"sensor": {"enabled": True, "exposure_electrons": 1e30}},
                      "sensor.exposure_electrons"),
    "widths 1e-300": ({"patterns": {"fringes": {"widths_px": [50.0, 1e-300, 3200.0]}}},
                      "patterns.fringes.widths_px"),
    "f_number 1e-6": ({"camera": LENS | {"f_number": 1e-6}}, "camera.f_number"),
    "focus 1e-9": ({"camera": LENS | {"f_number": 4.0, "focus_distance_mm": 1e-9}},
                   "focus_distance_mm"),
    "thin lens misses the part": ({"camera": LENS | {"f_number": 4.0,
                                                     "look_at_mm": [400.0, 2.3, 0.0]}},
                                  "camera.focus_distance_mm"),
    "aperture_samples 1e5": ({"camera": {"resolution": [1280, 1024], "focal_length_mm": 16.0,
                                         "pixel_pitch_mm": 0.005, "focal_length_px": None,
                                         "f_number": 8.0, "aperture_samples": 100_000}},
                             "camera.aperture_samples"),
    "sphere R 30, aperture 40": ({"surface": {"__replace__": {
        "type": "sphere", "radius_mm": 30.0, "aperture": {"radius_mm": 40.0}}}}, "aperture"),
    "aperture radius 1e6": ({"surface": {"__replace__": {
        "type": "sphere", "radius_mm": 1e7, "aperture": {"radius_mm": 1e6}}},
        "patterns": {"fringes": {"widths_px": [10.0, 40.0, 200.0]}}}, "reconstruct.spacing_mm"),
    "files = [1]": ({"patterns": {"images": {"files": [1]}}}, "patterns.images.files.0"),
    "n_rays 1e7": ({"sampling": {"n_rays": 10_000_000, "max_rays": 10_000_000}},
                   "sampling.n_rays"),
}
SETTINGS |= {f"physics: {k}": v for k, v in REFUSED.items()}


@pytest.mark.parametrize("name", list(SETTINGS))
def test_an_impossible_setting(tmp_path, name):
    changes, field = SETTINGS[name]
    text = _simulate_refused(tmp_path, changes, field)
    if name == "files = [1]":
        assert "at least 1 item" not in text
    if name.startswith("physics: ") and name != "physics: albedo":
        assert "check the BRDF" not in text  # the old, wrong field


# ----------------------------------------------------------------------------- sweeps
def _sweep(tmp_path, parameters: str, design: str = "grid"):
    from test_sweep import _config

    data = _config({})
    data.pop("sweep")
    cfg = tmp_path / "sweep.toml"
    cfg.write_text(_toml(data) + f'[sweep]\ndecimation = 0\ndesign = "{design}"\n'
                   "[sweep.parameters]\n" + parameters)
    out = tmp_path / "sweep"
    result = _invoke("sweep", cfg, "-o", out, "--no-figures")
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and not (out / "sweep.zarr").exists()
    return " ".join(result.output.split())


def test_a_sweep_point_with_too_many_rays_is_refused_naming_it(tmp_path):
    text = _sweep(tmp_path, '"sampling.n_rays" = [16, 10000000]\n'
                  '"sampling.max_rays" = [10000000, 10000000]\n', "zip")
    assert "sampling.n_rays" in text and "point 1" in text, text
    assert "GB of memory" in text  # the resource estimate refuses it, not the bound


def test_a_sweep_of_a_million_points_is_refused_at_once(tmp_path):
    grid = ", ".join(f"{0.001 + i * 1e-5:.6f}" for i in range(1000))
    text = _sweep(tmp_path, f'"brdf.alpha_x" = [{grid}]\n"brdf.alpha_y" = [{grid}]\n')
    assert "sweep.parameters" in text and "1,000,000" in text.replace(" ", ""), text


# ----------------------------------------------------------------------------- no valid pixel
def test_fit_of_images_without_a_usable_pixel_exits_2(tmp_path):
    """Every value saturated (the sensor's 12 bits): nothing to fit, exit 2 naming the
    images, nothing written (the fit's side of 'nothing exits 0 with 0 % valid pixels')."""
    from test_fit_cli import _dict, _write_frames

    cfg = tmp_path / "fit.toml"
    cfg.write_text(_toml(_dict()))
    paths = _write_frames(tmp_path / "sat", "s", np.full((24, 16, 20), 4095, np.uint16))
    out = tmp_path / "out"
    result = _invoke("fit", cfg, *paths, "-o", out, "--no-figure")
    assert result.exit_code == 2, result.output
    assert "images: the x fringes carry no fringe signal" in " ".join(result.output.split())
    assert not out.exists()
