"""``pmdsim export`` never loses a result nor exports a damaged one (issue 38, items 7-9, 15):
damaged and unfinished runs refused naming the file (a byte changed inside a chunk too: the
run writer checksums every chunk), output-path errors as one message, two processes
exporting into one folder never both report the same file, stale temporaries removed with
a note, a run name with a newline kept inside its comment line."""

from __future__ import annotations

import csv
import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_export import _maps
from typer.testing import CliRunner

from pmdsim.cli import app

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp_path, name="run", title="pmdsim run export-test", scale=1.0, chunked=True,
         created="2026-01-02T03:04:05+00:00", checksums=True):
    """A complete fake run (manifest written), 2 chunks per map along y, its store written
    by the run writer (every chunk with its crc32c checksum) or, without ``checksums``, as
    pmdsim wrote stores before them (xarray's defaults)."""
    import xarray as xr

    from pmdsim.store.writer import write_dataset

    x, y, maps = _maps()
    maps = dict(maps, slope_error_y_urad=maps["slope_error_x_urad"] * 0.5,
                reconstructed_height_mm=maps["height_error_nm"] * 1e-6 + 0.01)
    dims = ("surface_y", "surface_x")
    ds = xr.Dataset({k: (dims, v * scale, {"description": f"test {k}"}) for k, v in maps.items()},
                    coords={"surface_x": ("surface_x", x, {"units": "mm"}),
                            "surface_y": ("surface_y", y, {"units": "mm"})},
                    attrs={"title": title, "created_utc": created})
    if chunked:
        ds = ds.chunk({"surface_y": 4})
    run = tmp_path / name
    run.mkdir()
    if checksums:
        write_dataset(ds, run / "run.zarr")
    else:
        ds.to_zarr(run / "run.zarr", consolidated=True, zarr_format=3)
    (run / "pmdsim-run.json").write_text('{"format": "pmdsim-run/1"}\n')
    return run


def _export(*args):
    res = CliRunner().invoke(app, ["export", *map(str, args)])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    return res


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


# ----------------------------------------------------------------------------- damaged runs
def _truncate_chunk(run):
    f = run / "run.zarr" / "height_error_nm" / "c" / "0" / "0"
    f.write_bytes(f.read_bytes()[:7])
    return "height_error_nm"


def _half_root_json(run):
    f = run / "run.zarr" / "zarr.json"
    f.write_text(f.read_text()[: len(f.read_text()) // 2])
    return "zarr.json"


def _half_var_json(run):
    f = run / "run.zarr" / "slope_error_x_urad" / "zarr.json"
    f.write_text(f.read_text()[:40])
    return "slope_error_x_urad"


def _bad_created(run):
    f = run / "run.zarr" / "zarr.json"
    f.write_text(f.read_text().replace("2026-01-02T03:04:05+00:00", "yesterday at noon"))
    return "created_utc"


def _chunks_deleted(run):
    shutil.rmtree(run / "run.zarr" / "height_error_nm" / "c")
    return "height_error_nm"


def _one_chunk_deleted(run):
    (run / "run.zarr" / "slope_error_y_urad" / "c" / "1" / "0").unlink()
    return "slope_error_y_urad"


def _variable_deleted(run):
    shutil.rmtree(run / "run.zarr" / "height_error_nm")
    return "height_error_nm"


def _no_manifest(run):
    (run / "pmdsim-run.json").unlink()
    return "pmdsim-run.json"


def _temporary_folder(run):
    tmp = run.with_name(f"{run.name}.tmp-{_dead_pid()}")
    (run / "pmdsim-run.json").unlink()
    run.rename(tmp)
    return "temporary"


def _not_a_folder(run):
    shutil.rmtree(run)
    run.write_text("x")
    return "is a file"


DAMAGE = [_truncate_chunk, _half_root_json, _half_var_json, _bad_created, _chunks_deleted,
          _one_chunk_deleted, _variable_deleted, _no_manifest, _temporary_folder, _not_a_folder]


@pytest.mark.parametrize("damage", DAMAGE, ids=lambda f: f.__name__.strip("_"))
@pytest.mark.parametrize("fmt", ["x3p", "csv"])
def test_a_damaged_or_unfinished_run_is_refused_naming_the_file(tmp_path, damage, fmt):
    pytest.importorskip("x3pio")
    run = _run(tmp_path)
    says = damage(run)
    if damage is _temporary_folder:
        run = next(tmp_path.glob("run.tmp-*"))
    out = tmp_path / "out"
    res = _export(run, "--format", fmt, "-o", out)
    assert res.exit_code == 2, res.output
    assert says in res.output and str(run) in res.output, res.output
    assert "Traceback" not in res.output
    assert any(w in res.output for w in ("simulate", "export the finished", "give the folder"))
    assert not out.exists() or not any(out.iterdir())  # nothing written


def test_every_map_nan_is_refused(tmp_path):
    run = _run(tmp_path, scale=float("nan"))
    res = _export(run, "--format", "csv", "-o", tmp_path / "out")
    assert res.exit_code == 2 and "no measured node" in res.output and "height_error_nm" in res.output
    assert not (tmp_path / "out" / "surface.csv").exists()


def test_a_variant_member_is_complete_by_its_parents_manifest(tmp_path):
    parent = tmp_path / "multi"
    parent.mkdir()
    member = _run(parent, name="a")
    (member / "pmdsim-run.json").unlink()
    (parent / "pmdsim-run.json").write_text(json.dumps({"variants": ["a"]}))
    assert _export(member, "--format", "csv").exit_code == 0
    (parent / "pmdsim-run.json").write_text(json.dumps({"variants": ["b"]}))
    res = _export(member, "--format", "xyz")
    assert res.exit_code == 2 and "unfinished" in res.output


def test_a_run_name_with_a_newline_stays_in_its_comment_line(tmp_path):
    run = _run(tmp_path, title="line one\nx_mm,y_mm\r\x00evil")
    for fmt in ("csv", "xyz"):
        assert _export(run, "--format", fmt).exit_code == 0
    lines = (run / "export" / "surface.csv").read_text().splitlines()
    data = [line for line in lines if not line.startswith("#")]
    assert data[0] == "x_mm,y_mm,height_error_nm,slope_error_x_urad,slope_error_y_urad,reconstructed_height_mm"
    rows = list(csv.DictReader(data))
    assert len(rows) == np.isfinite(_maps()[2]["height_error_nm"]).sum()
    assert all(float(r["x_mm"]) > 0 for r in rows)
    xyz = np.loadtxt(run / "export" / "height_error.xyz")
    assert xyz.shape == (len(rows), 3)


# ----------------------------------------------------------------------------- the output path
def test_output_path_errors_are_one_message(tmp_path):
    run = _run(tmp_path)
    afile = tmp_path / "README.md"
    afile.write_text("keep")
    for extra in ([], ["--overwrite"]):  # -o an existing file: the same advice either way
        res = _export(run, "--format", "csv", "-o", afile, *extra)
        assert res.exit_code == 2 and "is a file, not a folder" in res.output, res.output
        assert "choose another -o" in res.output and "--overwrite" not in res.output
    res = _export(run, "--format", "csv", "-o", afile / "sub")
    assert res.exit_code == 2 and "no folder can be made below it" in res.output
    assert afile.read_text() == "keep"
    # the target is a folder: refused even with --overwrite, the folder kept
    out = tmp_path / "out"
    (out / "surface.csv").mkdir(parents=True)
    (out / "surface.csv" / "mine").write_text("keep")
    res = _export(run, "--format", "csv", "-o", out, "--overwrite")
    assert res.exit_code == 2 and "is a folder" in res.output and "remove or rename" in res.output
    assert (out / "surface.csv" / "mine").read_text() == "keep"
    # an existing file: --overwrite named, kept without it
    (out / "height_error.xyz").write_text("keep")
    res = _export(run, "--format", "xyz", "-o", out)
    assert res.exit_code == 2 and "pass --overwrite" in res.output
    assert (out / "height_error.xyz").read_text() == "keep"
    assert not (out / "slope_error_x.xyz").exists()  # checked before any file is written


def test_a_full_disk_is_a_message_and_leaves_nothing(tmp_path, monkeypatch):
    import pmdsim.store.export as ex

    run = _run(tmp_path)
    out = tmp_path / "out"
    calls = []

    def full(tmp, data, **kw):
        calls.append(tmp)
        if len(calls) == 3:  # the third file: the disk fills up
            Path(tmp).write_text("partial")
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp))
        np.savetxt(tmp, data, **kw)

    monkeypatch.setattr(ex.np, "savetxt", full)
    res = _export(run, "--format", "xyz", "-o", out)
    assert res.exit_code == 2, res.output
    assert "No space left on device" in res.output and "nothing of this export was kept" in res.output
    assert list(out.iterdir()) == []  # no temporary, no file of the half-done export


def test_a_stale_temporary_is_removed_with_a_note(tmp_path):
    run = _run(tmp_path)
    out = run / "export"
    out.mkdir()
    pid = _dead_pid()
    stale = out / f".surface.csv.tmp-{pid}"
    stale.write_text("half")
    live = out / f".surface.csv.tmp-{os.getpid()}1"  # not a pid of this machine's processes
    res = _export(run, "--format", "csv")
    assert res.exit_code == 0, res.output
    assert not stale.exists() and "note: removed" in res.output and str(pid) in res.output
    assert "Warning" not in res.output and ".py:" not in res.output
    assert not live.exists() or live.read_text()


def test_two_processes_never_both_write_the_same_file(tmp_path):
    """Three trials of two exports of different runs into one empty folder, started together:
    exactly one wins each file, the other exits 2 naming it (the file, when the winner has
    written it, or the folder's export lock, while the winner still holds it), and the file
    is the winner's."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    runs = [_run(tmp_path, name=f"r{k}", title=f"run-{k}") for k in range(2)]
    for trial in range(3):
        out = tmp_path / f"out{trial}"
        out.mkdir()
        procs = [subprocess.Popen([sys.executable, "-m", "pmdsim.cli", "export", str(r),
                                   "--format", "csv", "-o", str(out)], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                 for r in runs]
        results = [(p.wait(timeout=120), p.stdout.read()) for p in procs]
        codes = sorted(rc for rc, _ in results)
        assert codes == [0, 2], results
        winner = next(k for k, (rc, _) in enumerate(results) if rc == 0)
        loser_text = results[1 - winner][1]
        named = "surface.csv" in loser_text or (
            ".pmdsim-export" in loser_text and "wait for that run to finish" in loser_text)
        assert named and "Traceback" not in loser_text, loser_text
        assert f"run-{winner}" in (out / "surface.csv").read_text()
        assert sorted(p.name for p in out.iterdir()) == ["surface.csv"]


def test_random_damage_of_any_file_never_escapes_as_a_traceback(tmp_path):
    """30 runs, each with one file of run.zarr truncated, overwritten in a few bytes, zeroed
    or deleted (seeded): exit 2 naming a file of the run, or exit 0 with complete files and
    no temporary. A chunk whose bytes changed is always refused naming that file (every
    chunk carries a crc32c checksum: a flipped byte that still decompresses is seen too);
    exit 0 is left to a zarr.json still valid after the change (a digit of an attribute)."""
    good = _run(tmp_path / "good" if (tmp_path / "good").mkdir() is None else None)
    rng = np.random.default_rng(38)
    flipped_chunks = 0
    for k in range(30):
        d = tmp_path / f"c{k}"
        shutil.copytree(good.parent, d)
        run = d / "run"
        files = sorted(p for p in (run / "run.zarr").rglob("*") if p.is_file())
        f = files[rng.integers(len(files))]
        before = f.read_bytes()
        data = bytearray(before)
        op = k % 4
        if op == 0:
            f.write_bytes(bytes(data[: rng.integers(0, max(1, len(data)))]))
        elif op == 1:
            for _ in range(3):
                if data:
                    data[rng.integers(len(data))] = int(rng.integers(256))
            f.write_bytes(bytes(data))
        elif op == 2:
            f.unlink()
        else:
            f.write_bytes(bytes(len(data)))
        fmt = ("csv", "x3p", "xyz")[k % 3]
        if fmt == "x3p":
            pytest.importorskip("x3pio")
        res = _export(run, "--format", fmt, "-o", d / "out")
        assert res.exit_code in (0, 2), (f, res.output)
        changed_chunk = f.name != "zarr.json" and f.exists() and f.read_bytes() != before
        if changed_chunk:
            flipped_chunks += op == 1
            assert res.exit_code == 2 and str(f) in res.output, (f, res.output)
            assert "damaged" in res.output and "simulate again" in res.output, res.output
        if res.exit_code == 2:
            assert str(run) in res.output, res.output
        else:
            assert all(p.stat().st_size > 0 for p in (d / "out").iterdir())
        assert not list((d / "out").glob(".*tmp-*")) if (d / "out").exists() else True
    assert flipped_chunks >= 2  # the seed overwrites bytes inside chunks, not only zarr.json


def _flip_inside(chunk: Path) -> int:
    """Change one byte near the middle of the compressed chunk ``chunk`` (codecs bytes,
    zstd or blosc, then crc32c where the store has it) such that its zstd payload still decompresses,
    to other numbers: a change that only a checksum sees. Returns the byte's offset."""
    import numcodecs

    data = chunk.read_bytes()
    array = next(p for p in chunk.parents if (p / "zarr.json").is_file())
    meta = json.loads((array / "zarr.json").read_text())
    names = [c["name"] for c in meta["codecs"]]
    assert names[0] == "bytes" and names[1] in ("zstd", "blosc"), names
    codec = numcodecs.Zstd() if names[1] == "zstd" else numcodecs.Blosc()
    tail = 4 if names[-1] == "crc32c" else 0
    payload, crc = data[:len(data) - tail], data[len(data) - tail:]
    original = bytes(codec.decode(payload))
    mid = len(payload) // 2
    for pos in sorted(range(len(payload)), key=lambda i: abs(i - mid)):
        bad = bytearray(payload)
        bad[pos] ^= 0x5A
        try:
            decoded = codec.decode(bytes(bad))
        except (RuntimeError, ValueError):
            continue
        if len(decoded) == len(original) and bytes(decoded) != original:
            chunk.write_bytes(bytes(bad) + crc)
            return pos
    raise AssertionError(f"no byte of {chunk} changes its numbers and still decompresses")


def test_a_byte_flipped_inside_a_chunk_is_refused_naming_the_file(tmp_path):
    run = _run(tmp_path)
    chunk = run / "run.zarr" / "height_error_nm" / "c" / "1" / "0"
    _flip_inside(chunk)
    out = tmp_path / "out"
    res = _export(run, "--format", "csv", "-o", out)
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert str(chunk) in text and "'height_error_nm'" in text and "checksum" in text, text
    assert f"the run {run} is damaged" in text and "simulate again" in text, text
    assert "Traceback" not in res.output
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.filterwarnings("ignore:Consolidated metadata:UserWarning")
def test_a_run_written_before_the_checksums_is_exported_with_a_note(tmp_path):
    """A store without crc32c (pmdsim before the checksums) is still read: exported as
    before, with a note that a changed byte cannot be seen; a checked run has no note."""
    import zarr

    old = _run(tmp_path, name="old", checksums=False)
    codecs = [c.to_dict()["name"] for c in zarr.open_array(old / "run.zarr" / "height_error_nm").metadata.codecs]
    assert "crc32c" not in codecs
    res = _export(old, "--format", "csv")
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "note:" in text and "without checksums" in text and str(old / "run.zarr") in text, text
    assert (old / "export" / "surface.csv").is_file()
    new = _run(tmp_path, name="new")
    res = _export(new, "--format", "csv")
    assert res.exit_code == 0 and "without checksums" not in res.output, res.output
