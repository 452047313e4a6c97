"""``pmdsim decode``: images written by a simulation decode back (``--from-run`` or explicit
options), PNG input, the output folder, and exit code 2 with a clear message on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pmdsim import run as pipeline

from pmdsim.store import schema
from pmdsim.cli import app
from pmdsim.config import parse_config
from test_pipeline import tiny_config_dict

WIDTHS = [10, 40, 160]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    d = tiny_config_dict(fringes={"widths_px": WIDTHS, "shifts": 4})
    d["output"] = {"figures": False}
    d["variants"] = [{"name": "wide", "brdf": {"model": "ward", "alpha_x": 0.025,
                                                "alpha_y": 0.002}}]
    out = tmp_path_factory.mktemp("decode-cli") / "run"
    pipeline.run_simulation(parse_config(d), out)
    return out


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result, result.output


def frames(run: Path, direction: str = "x") -> list[Path]:
    return sorted((run / "wide" / "fringes").glob(f"{direction}_*.tif"))


def test_help_documents_the_frame_order():
    result, text = invoke("decode", "--help")
    assert result.exit_code == 0
    flat = " ".join(text.split())
    assert "WIDTH-MAJOR, THEN SHIFT" in flat and "--from-run" in flat and "--widths" in flat


@pytest.mark.parametrize("direction", ["x", "y"])
def test_from_run_round_trips_the_simulation(run, tmp_path, direction):
    out = tmp_path / "dec"
    result, text = invoke("decode", *frames(run, direction), "--from-run", run,
                          "--direction", direction, "-o", out)
    assert result.exit_code == 0, text
    stats = json.loads((out / "statistics.json").read_text())
    assert stats["setup"]["widths_px"] == WIDTHS and stats["setup"]["shifts"] == 4
    assert stats["setup"]["extent_px"] == (160 if direction == "x" else 90)
    # The run's own decoding of its float camera values vs. decoding its 16-bit files: the
    # same pixels, equal to far better than 1e-3 monitor px (integer quantisation only).
    cmp = stats["compared_with_run"]
    assert cmp["variant"] == "wide" and cmp["n_valid"] > 1500
    assert cmp["max"] < 1e-3
    ds = schema.load_run(run, variant="wide")
    valid_run = ds["decode_flags"].sel(direction=direction).values == 0
    import xarray as xr

    dec = xr.open_zarr(out / "decode.zarr", consolidated=False)
    np.testing.assert_array_equal(dec["valid"].values, valid_run)
    np.testing.assert_allclose(dec["monitor_coord_mm"].values,
                               dec["monitor_coord_px"].values * 3.0)
    assert sorted(p.name for p in (out / "figures").iterdir()) == [
        "absolute_phase.png", "flags.png", "modulation.png", "monitor_coord.png"]
    assert json.loads((out / "pmdsim-run.json").read_text())["format"] == "pmdsim-decode/1"


def test_explicit_options_equal_from_run_and_png_input(run, tmp_path):
    import xarray as xr

    from pmdsim.store.images import read_image, write_image

    a, b = tmp_path / "a", tmp_path / "b"
    result, text = invoke("decode", *frames(run), "--from-run", run, "-o", a, "--no-figures")
    assert result.exit_code == 0, text
    pngs = []
    for p in frames(run):  # the same frames as 16-bit PNG files, named in frame order
        pngs.append(write_image(tmp_path / "png" / (p.stem + ".png"), read_image(p), "png"))
    result, text = invoke("decode", *pngs, "--widths", "10,40,160", "--shifts", 4,
                          "--extent-px", 160, "--method", "hierarchical", "-o", b,
                          "--no-figures")
    assert result.exit_code == 0, text
    ca = xr.open_zarr(a / "decode.zarr", consolidated=False)["monitor_coord_px"].values
    cb = xr.open_zarr(b / "decode.zarr", consolidated=False)["monitor_coord_px"].values
    np.testing.assert_array_equal(ca, cb)
    assert "monitor_coord_mm" not in xr.open_zarr(b / "decode.zarr", consolidated=False)


@pytest.mark.parametrize("case, message", [
    ("missing file", "does not exist"),
    ("frame count", "12 are needed"),
    ("widths", "add a wider width"),
    ("heterodyne widths", "heterodyne"),
    ("no widths", "--widths"),
    ("order", "reorder the files"),
    ("not a run", "--from-run"),
    ("exists", "--overwrite"),
])
def test_bad_input_exits_2_with_a_clear_message(run, tmp_path, case, message):
    files = frames(run)
    opts = ["--widths", "10,40,160", "--shifts", "4", "--extent-px", "160"]
    out = tmp_path / "out"
    if case == "missing file":
        args = [*files[:-1], tmp_path / "nope.tif", *opts]
    elif case == "frame count":
        args = [*files[:-1], *opts]
    elif case == "widths":
        args = [*files, "--widths", "10,20,40", "--shifts", "4", "--extent-px", "160"]
    elif case == "heterodyne widths":
        args = [*files, *opts, "--method", "heterodyne"]
    elif case == "no widths":
        args = [*files]
    elif case == "order":
        args = [*files[4:8], *files[:4], *files[8:], "--widths", "40,10,160", "--shifts", "4",
                "--extent-px", "160", "--direction", "y"]
    elif case == "not a run":
        args = [*files, "--from-run", tmp_path]
    else:
        out.mkdir()
        (out / "something").write_text("x")
        args = [*files, *opts]
    result, text = invoke("decode", *args, "-o", out)
    assert result.exit_code == 2, text
    assert message in " ".join(text.split()) and "Traceback" not in text
    if case != "exists":
        assert not out.exists()


def test_simulate_decode_flag_errors_and_statistics_table(tmp_path):
    cfg = tmp_path / "c.toml"
    from test_pipeline import TOML

    cfg.write_text(TOML.format(pitch_key="pixel_pitch_mm"))  # widths [8]: cannot unwrap
    result, text = invoke("simulate", cfg, "-o", tmp_path / "a", "--no-figures", "--decode")
    assert result.exit_code == 2
    assert "patterns.fringes.widths_px" in " ".join(text.split())
    assert not (tmp_path / "a").exists()
    result, text = invoke("simulate", cfg, "-o", tmp_path / "b", "--no-figures")
    assert result.exit_code == 0 and "decoding skipped" in " ".join(text.split())
    cfg.write_text(TOML.format(pitch_key="pixel_pitch_mm").replace(
        "widths_px = [8.0]", "widths_px = [10.0, 40.0, 160.0]"))
    result, text = invoke("simulate", cfg, "-o", tmp_path / "c", "--no-figures")
    assert result.exit_code == 0, text
    assert "deviation from the ideal specular reference" in text
    assert (tmp_path / "c" / "statistics.json").is_file()


def test_from_run_with_a_flipped_byte_in_its_coordinates_is_refused(run, tmp_path):
    """--from-run compares with the run's own decoding: a byte changed inside a chunk of
    that run's monitor_coord_px (still decompressing, to other numbers) is refused by its
    checksum, naming the chunk (exit 2, no traceback)."""
    import shutil

    from test_export_safety import _flip_inside

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    files = sorted(p for p in (copy / "wide" / "run.zarr" / "monitor_coord_px" / "c").rglob("*")
                   if p.is_file())
    for chunk in files:  # whichever holds the decoded direction
        _flip_inside(chunk)
    result, text = invoke("decode", *frames(copy), "--from-run", copy, "-o", tmp_path / "out",
                          "--no-figures")
    flat = " ".join(text.split())
    assert result.exit_code == 2, text
    assert any(str(c) in flat for c in files), flat
    assert "checksum" in flat and "'monitor_coord_px'" in flat, flat
    assert "Traceback" not in text
