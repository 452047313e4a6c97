"""Sampling settings that cannot give a result (issue 38, items 10 and 11), through the
command line: ``--target-error-mrad`` where the sampling has no error estimate is the same
field-named message (exit 2) as in the file; a cone scheme whose bundle reverses the finest
fringe's contrast (``scheme = "solid_angle"`` on Fig. 3's lobe in its 1 deg cone) says so
and names the widths, instead of blaming "the decoding"."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from conftest import base_dict, merge
from test_budget import _write_toml
from typer.testing import CliRunner

from pmdsim.cli import app

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("command", ["simulate", "budget"])
@pytest.mark.parametrize("sampling, says", [
    ({"mode": "stratified"}, "mode = 'stratified' has none"),
    ({"mode": "rule", "error_estimate": False}, "error_estimate = true"),
])
def test_target_error_without_an_error_estimate_is_one_message(tmp_path, command, sampling, says):
    cfg = tmp_path / "run.toml"
    _write_toml(cfg, merge(base_dict(), {"sampling": sampling}))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, [command, str(cfg), "-o", str(out), "--target-error-mrad", "1"])
    assert res.exit_code == 2, res.output
    assert "--target-error-mrad" in res.output and says in res.output
    assert "Traceback" not in res.output and "pydantic" not in res.output
    assert not out.exists()
    # the same in the file: the same exit code, the field named
    _write_toml(cfg, merge(base_dict(), {"sampling": {**sampling, "target_error_mrad": 1.0}}))
    res = CliRunner().invoke(app, [command, str(cfg), "-o", str(out)])
    assert res.exit_code == 2 and "target_error_mrad" in res.output and says in res.output


def _fig3_small(n_rays: int, scheme: str) -> dict:
    d = tomllib.loads((ROOT / "examples" / "paper_fig3.toml").read_text())
    d["camera"].update(resolution=[32, 26], pixel_pitch_mm=0.192)
    d["sampling"].update(n_rays=n_rays, scheme=scheme)
    d["patterns"]["fringes"]["widths_px"] = [50.0, 400.0, 3200.0]
    d["output"].update(write_images=False, figures=False)
    return d


@pytest.mark.parametrize("n_rays", [16, 64])
def test_solid_angle_rule_on_fig3_says_why_no_pixel_is_valid(tmp_path, n_rays):
    cfg = tmp_path / "f3.toml"
    _write_toml(cfg, _fig3_small(n_rays, "solid_angle"))
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    assert res.exit_code == 2, res.output  # the 50 px fringe's contrast is reversed: no pixel
    assert "patterns.fringes.widths_px" in res.output and "reverses its contrast" in res.output
    assert "sampling.scheme = 'solid_angle'" in res.output
    assert not out.exists() and not list(tmp_path.glob("run.tmp-*"))
