"""Failures are not results: ``pmdsim report`` on a damaged run folder names the array and
the file that are broken (exit code 2), and ``--variant`` must name a variant of the run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from conftest import make_config
from pmdsim.cli import app


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    from pmdsim.run import run_simulation

    out = tmp_path_factory.mktemp("report") / "run"
    run_simulation(make_config(), out, figures=False, diagnostics=False)
    return out


@pytest.fixture
def damaged(run_folder, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(run_folder, out)
    return out


def _report(folder, *extra):
    return CliRunner().invoke(app, ["report", str(folder), "--figure", "fringes", *extra])


def _chunk(folder: Path, name: str = "fringes") -> Path:
    files = sorted(p for p in (folder / "run.zarr" / name / "c").rglob("*") if p.is_file())
    return files[len(files) // 2]


def _edit_root(folder: Path, change) -> Path:
    path = folder / "run.zarr" / "zarr.json"
    meta = json.loads(path.read_text())
    change(meta["attributes"])
    path.write_text(json.dumps(meta))
    return path


def test_an_intact_run_is_redrawn(damaged):
    result = _report(damaged)
    assert result.exit_code == 0, result.output
    assert (damaged / "figures" / "fringes.png").is_file()


def test_a_truncated_chunk_names_the_array_and_file(damaged):
    chunk = _chunk(damaged)
    chunk.write_bytes(chunk.read_bytes()[: max(1, chunk.stat().st_size // 2)])
    result = _report(damaged)
    assert result.exit_code == 2, result.output
    assert "'fringes'" in result.output and str(chunk) in result.output


def test_a_zeroed_chunk_names_the_array_and_file(damaged):
    chunk = _chunk(damaged, "surface_mask")
    chunk.write_bytes(b"\x00" * chunk.stat().st_size)
    result = _report(damaged)
    assert result.exit_code == 2, result.output
    assert "'surface_mask'" in result.output and str(chunk) in result.output


@pytest.mark.parametrize("how", ["missing", "invalid_json", "invalid_config"])
def test_a_missing_or_invalid_config_json_is_named(damaged, how):
    def change(attrs):
        if how == "missing":
            attrs.pop("config_json")
        elif how == "invalid_json":
            attrs["config_json"] = "{not json"
        else:
            attrs["config_json"] = json.dumps({"camera": {"resolution": [0, 0]}})

    path = _edit_root(damaged, change)
    result = _report(damaged)
    assert result.exit_code == 2, result.output
    assert "config_json" in result.output and str(path) in result.output


@pytest.mark.parametrize("which", ["run.zarr/zarr.json", "run.zarr/fringes/zarr.json"])
def test_a_truncated_zarr_json_is_named(damaged, which):
    path = damaged / which
    path.write_text(path.read_text()[:40])
    result = _report(damaged)
    assert result.exit_code == 2, result.output
    assert str(path) in result.output


def test_a_deleted_variable_is_named(damaged):
    shutil.rmtree(damaged / "run.zarr" / "f_hit")
    result = _report(damaged)
    assert result.exit_code == 2, result.output
    assert "'f_hit'" in result.output and "missing" in result.output


def test_variant_names_are_checked(damaged):
    result = _report(damaged, "--variant", "bogus")
    assert result.exit_code == 2 and "--variant bogus" in result.output
    assert not (damaged / "figures").exists()


def test_report_output_that_is_a_file_is_refused_before_drawing(damaged, tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    result = _report(damaged, "-o", str(f))
    assert result.exit_code == 2 and "is a file" in result.output
    assert f.read_text() == "x"
