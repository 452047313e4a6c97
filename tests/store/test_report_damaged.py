"""Failures are not results: ``pmdsim report`` on a damaged run folder names the array and
the file that are broken (exit code 2; a byte changed inside a chunk too: its checksum
fails), and ``--variant`` must name a variant of the run."""

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


@pytest.fixture(scope="module")
def reconstructed_run(tmp_path_factory):
    """A run with a reconstruction (height_error_nm): Fig. 3's geometry at 48 x 40 camera
    px (tests/run/test_pipeline.py's tiny scene)."""
    from test_pipeline import tiny_config_dict

    from pmdsim.config import parse_config
    from pmdsim.run import run_simulation

    out = tmp_path_factory.mktemp("reconstructed") / "run"
    run_simulation(parse_config(tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})),
                   out, figures=False, diagnostics=False)
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


def test_a_byte_flipped_inside_a_chunk_is_refused_by_report_and_export(reconstructed_run,
                                                                          tmp_path):
    """One byte near the middle of a compressed chunk of height_error_nm, changed such that
    the chunk still decompresses (to other heights): only its crc32c sees it. Both commands
    that read run.zarr refuse the run, naming the run, the array and the file."""
    from test_export_safety import _flip_inside

    damaged = tmp_path / "run"
    shutil.copytree(reconstructed_run, damaged)
    chunk = _chunk(damaged, "height_error_nm")
    _flip_inside(chunk)
    for args in (["report", str(damaged), "--figure", "fringes"],
                 ["export", str(damaged), "--format", "csv", "-o", str(tmp_path / "out")]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        text = " ".join(result.output.split())
        assert str(chunk) in text and "'height_error_nm'" in text and "checksum" in text, text
        assert f"the run {damaged} is damaged" in text and "simulate again" in text, text
        assert "Traceback" not in result.output
    assert not (damaged / "figures").exists() and not (tmp_path / "out" / "surface.csv").exists()


@pytest.mark.filterwarnings("ignore:Consolidated metadata:UserWarning")
def test_a_run_written_before_the_checksums_is_redrawn_with_a_note(run_folder, tmp_path):
    """A run.zarr without crc32c (as pmdsim wrote before the checksums) is still read."""
    import xarray as xr

    old = tmp_path / "old"
    shutil.copytree(run_folder, old, ignore=shutil.ignore_patterns("run.zarr"))
    ds = xr.open_zarr(run_folder / "run.zarr").load()
    for v in ds.variables.values():
        v.encoding = {}
    ds.to_zarr(old / "run.zarr", consolidated=True, zarr_format=3)
    assert "crc32c" not in (old / "run.zarr" / "fringes" / "zarr.json").read_text()
    result = _report(old)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "note:" in text and "without checksums" in text, text
    assert (old / "figures" / "fringes.png").is_file()
    assert "without checksums" not in _report(run_folder, "-o", str(tmp_path / "f")).output


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
