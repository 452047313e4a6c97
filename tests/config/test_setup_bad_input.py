"""Set-ups that leave nothing to measure (issue 38, items 13 and 14), through the command
line: a budget whose rim band or camera window leaves no node is refused naming the field
(never exit 0 with every row NaN); a negative window entry is one line naming camera.roi; a
camera with a unit slip in its pixel pitch (a 180 deg field of view) is refused naming the
pitch and the field of view, not the pose."""

from __future__ import annotations

import itertools
import tomllib
from pathlib import Path

import pytest
from conftest import base_dict, merge
from test_budget import _write_toml
from typer.testing import CliRunner

from pmdsim.cli import app
from pmdsim.config import ConfigError, parse_config

ROOT = Path(__file__).resolve().parents[2]
SMALL = {"camera": {"resolution": [20, 16], "focal_length_px": 40.0},
         "patterns": {"fringes": {"widths_px": [50.0, 200.0], "directions": ["x", "y"]}},
         "sampling": {"n_rays": 16}}


def _invoke(tmp_path, command, changes, *extra):
    cfg = tmp_path / "run.toml"
    _write_toml(cfg, merge(merge(base_dict(), SMALL), changes))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, [command, str(cfg), "-o", str(out), *extra])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    return res, out


def test_budget_whose_rim_band_takes_every_node_is_refused(tmp_path, monkeypatch):
    """A band as wide as the 100 x 80 mm plate's inscribed radius (40 mm): refused before
    any rendering (the budget itself is never called)."""
    import pmdsim.run.budget as run_budget

    def never(*a, **k):
        raise AssertionError("the budget ran before the refusal")

    monkeypatch.setattr(run_budget, "budget", never)
    res, out = _invoke(tmp_path, "budget", {"budget": {"rim_exclusion_mm": 40.0}}, "--no-figure")
    assert res.exit_code == 2, res.output
    assert "inscribed radius is 40 mm" in res.output
    assert "budget.rim_exclusion_mm = 40" in res.output and "lower it" in res.output
    assert not out.exists() and not list(tmp_path.glob("out.tmp-*"))


@pytest.mark.parametrize("command", ["budget", "simulate"])
def test_a_window_that_sees_nothing_names_camera_roi(tmp_path, command):
    res, out = _invoke(tmp_path, command, {"camera": {"roi": [0, 0, 1, 1]}})
    assert res.exit_code == 2, res.output
    assert "camera.roi = [0, 0, 1, 1]" in res.output and "'auto'" in res.output
    assert not out.exists()


@pytest.mark.parametrize("roi", [[-1, 0, 10, 10], [0, -3, 5, 5], [0, 0, 0, 5], [1, 2],
                                 "manual", [0.5, 0, 4, 4]])
def test_a_bad_window_is_one_line_naming_camera_roi(tmp_path, roi):
    res, out = _invoke(tmp_path, "budget", {"camera": {"roi": roi}})
    assert res.exit_code == 2, res.output
    assert "camera.roi" in res.output and "col0, row0, width, height" in res.output
    for internal in ("function-after", "functools", "validator", "literal["):
        assert internal not in res.output, res.output
    assert not out.exists()


def test_a_pixel_pitch_in_um_given_as_mm_is_refused_naming_it(tmp_path):
    d = tomllib.loads((ROOT / "examples" / "paper_fig3.toml").read_text())
    d["camera"]["pixel_pitch_mm"] = 38.4  # 38.4 um
    cfg = tmp_path / "f3.toml"
    _write_toml(cfg, d)
    for command in ("simulate", "budget"):
        res = CliRunner().invoke(app, [command, str(cfg), "-o", str(tmp_path / "out")])
        assert res.exit_code == 2, res.output
        assert "pixel_pitch_mm = 38.4" in res.output and "field of view" in res.output
        assert "point the camera" not in res.output and not (tmp_path / "out").exists()


@pytest.mark.parametrize("pitch_mm, focal_mm", list(itertools.product(
    (0.00345, 0.0048, 0.048, 0.48, 4.8, 38.4), (8.0, 50.0, 0.05, 5000.0))))
def test_camera_units_are_accepted_or_refused_by_the_field_of_view(pitch_mm, focal_mm):
    import math

    d = merge(base_dict(), {"camera": {"resolution": [1280, 1024], "focal_length_px": None,
                                       "pixel_pitch_mm": pitch_mm, "focal_length_mm": focal_mm}})
    fov = 2 * math.degrees(math.atan(math.hypot(1280, 1024) * pitch_mm / (2 * focal_mm)))
    from pmdsim.config.camera import MAX_FIELD_OF_VIEW_DEG

    if fov <= MAX_FIELD_OF_VIEW_DEG:
        assert parse_config(d).camera.pixel_pitch_mm == pitch_mm
    else:
        with pytest.raises(ConfigError, match=r"camera: the camera's field of view is .* deg"):
            parse_config(d)


def test_a_180_degree_field_of_view_is_refused(tmp_path):
    res, _ = _invoke(tmp_path, "simulate", {"camera": {"focal_length_px": 0.001}})
    assert res.exit_code == 2 and "field of view is 180 deg" in res.output, res.output
