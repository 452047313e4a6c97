"""What a run folder stores: float32 at a stated precision, chunked and compressed, with
consolidated metadata (a plain ``xarray.open_zarr`` opens it without a warning), and
``load_run`` still returns every variable ``docs/outputs.md`` lists."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import base_dict, merge
from pmdsim.config import parse_config
from pmdsim.store.writer import FULL_PRECISION, KEEP_BITS, keep_bits

DOCS = Path(__file__).parents[2] / "docs" / "outputs.md"


def test_keep_bits_is_numcodecs_bitround():
    numcodecs = pytest.importorskip("numcodecs")
    rng = np.random.default_rng(1)
    a = (rng.standard_normal(20000) * 10.0 ** rng.uniform(-30, 30, 20000)).astype(np.float32)
    ref = np.asarray(numcodecs.BitRound(keepbits=KEEP_BITS).encode(a)).view(np.float32)
    np.testing.assert_array_equal(keep_bits(a).view(np.uint32), ref.view(np.uint32))
    special = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0], np.float32)
    out = keep_bits(special)
    assert np.isnan(out[0]) and list(out[1:]) == list(special[1:])
    ok = np.isfinite(a) & (a != 0)
    assert np.max(np.abs(keep_bits(a)[ok] / a[ok] - 1)) <= 2.0 ** -(KEEP_BITS + 1)


def _documented_variables() -> set[str]:
    table = DOCS.read_text().split("## Dataset variables")[1].split("\n## ")[0]
    names = set()
    for line in table.splitlines():
        if not line.startswith("| `"):
            continue
        first = line.split("|")[1]
        for tok in re.findall(r"`([^`]+)`", first):
            if "/" in tok:  # fringe_sums_real/imag, dot_centroid_col/row
                stem, _, alt = tok.rpartition("_")
                head, _, a = tok.partition("/")
                names |= {head, head.rsplit("_", 1)[0] + "_" + a}
            elif not tok.endswith("*"):
                names.add(tok)
    return names


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """A run with fringes (decoded), dots, a monitor image and diagnostics."""
    from PIL import Image

    from pmdsim.run import run_simulation

    folder = tmp_path_factory.mktemp("storage")
    Image.fromarray(np.full((120, 200), 200, np.uint8)).save(folder / "grey.png")
    cfg = parse_config(merge(base_dict(), {
        # the default sampling (a rule with its embedded error pass): every documented
        # variable, the numerical errors included
        "sampling": {"mode": "rule"},
        "patterns": {"fringes": {"widths_px": [25.0, 200.0]},
                     "dots": {"positions_px": [[100.0, 60.0]], "size_px": 9},
                     "images": {"files": [str(folder / "grey.png")]}}}))
    return run_simulation(cfg, folder / "run", figures=False)


def test_load_run_returns_every_documented_variable(full_run):
    from pmdsim import load_run

    ds = load_run(full_run.outdir)
    documented = _documented_variables()
    assert {"fringes", "fringe_sums_real", "fringe_sums_imag", "dot_centroid_row",
            "dot_sigma_minor", "diag_phase_se"} <= documented  # the parser reads the table
    missing = sorted(documented - set(ds.data_vars) - set(ds.coords))
    # a deterministic rule has no sampling noise: no Monte-Carlo diagnostics (the table
    # says so); its phase error is the stated one
    assert missing == ["diag_effective_sample_size", "diag_phase_se"]
    assert "fringe_phase_error" in ds.data_vars
    assert any(v.startswith("reference_") for v in ds.data_vars)


def test_stored_precision_and_compression(full_run):
    import xarray as xr
    import zarr

    path = full_run.outdir / "run.zarr"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # consolidated: no fallback warning
        ds = xr.open_zarr(path)
    group = zarr.open_group(path, mode="r")
    for name, var in ds.data_vars.items():
        if var.dims[-2:] == ("row", "col"):
            arr = group[name]
            assert arr.chunks[-2:] == var.shape[-2:] and all(c == 1 for c in arr.chunks[:-2])
            assert arr.compressors, name
            if var.dtype.kind == "f":
                assert var.dtype == np.float32, name
                if name not in FULL_PRECISION:
                    bits = np.asarray(var.values, np.float32).view(np.uint32)
                    assert not np.any(bits & np.uint32((1 << (23 - KEEP_BITS)) - 1)), name


def test_chain_variables_reference_the_chain_and_are_stored_rounded(tmp_path):
    """The dataset's chain variables are views of the chain's own arrays (no second copy of
    the chain in memory: 1.2 GB at 5 MP), and written one image at a time they store the
    same numbers as rounding the stacked arrays at once."""
    import xarray as xr

    from pmdsim.store.schema import dataset_variables
    from pmdsim.store.writer import write_dataset
    from test_deviation_independent import _chain_case

    res = _chain_case()[-1]
    dims, lazy, _ = dataset_variables(res)["modulation_ratio"]
    src = res.directions["x"].deviation.modulation_ratio
    expected = keep_bits(np.stack([src]))
    src[0, 0, 0] = 12345.0  # a view sees the change; a copy would not
    assert np.asarray(lazy)[0, 0, 0, 0] == np.float32(12345.0)
    expected[0, 0, 0, 0] = keep_bits(np.float32([12345.0]))[0]
    ds = xr.Dataset({"modulation_ratio": (dims, lazy)})
    write_dataset(ds, tmp_path / "s.zarr")
    stored = xr.open_zarr(tmp_path / "s.zarr")["modulation_ratio"].values
    assert stored.dtype == np.float32
    np.testing.assert_array_equal(stored, expected)


def test_camera_image_chunks_are_the_bytes_zarr_writes(tmp_path, monkeypatch):
    """The writer encodes the camera-image chunks itself (``write_chunks``: bytes, Blosc,
    CRC-32C); the store is byte for byte the one Zarr writes them into, for every kind of
    camera-image variable: rounded and full-precision floats with NaNs, 3-D and 4-D, bool
    and uint8 maps, on a camera with rows != columns."""
    import filecmp

    import xarray as xr

    from pmdsim.store import writer

    rng = np.random.default_rng(5)
    h, w = 24, 37
    phase = rng.normal(size=(2, h, w))
    phase[0, 3, 4] = np.nan
    ds = xr.Dataset({
        "modulation": (("direction", "width", "row", "col"), rng.random((2, 3, h, w))),
        "absolute_phase": (("direction", "row", "col"), phase, {"units": "rad"}),
        "fringe_sums_real": (("direction", "width", "row", "col"),
                             rng.normal(size=(2, 3, h, w)).astype(np.float32)),
        "empty": (("direction", "row", "col"), np.full((2, h, w), np.nan)),  # fill only
        "valid": (("direction", "row", "col"), rng.random((2, h, w)) > 0.3),
        "decode_flags": (("direction", "row", "col"), rng.integers(0, 5, (2, h, w), np.uint8)),
        "stats": (("statistic",), rng.random(5)),
    }, coords={"direction": ["x", "y"], "row": np.arange(h), "col": np.arange(w)},
        attrs={"name": "chunks"})
    assert "absolute_phase" in writer.FULL_PRECISION
    writer.write_dataset(ds, tmp_path / "direct.zarr")
    calls = []
    monkeypatch.setattr(writer, "write_chunks",
                        lambda array, var: calls.append(array.name)
                        or writer.write_through_zarr(array, var))
    writer.write_dataset(ds, tmp_path / "zarr.zarr")
    assert sorted(calls) == sorted(n for n in ds.data_vars if n != "stats")

    def files(root):
        return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())

    a, b = tmp_path / "direct.zarr", tmp_path / "zarr.zarr"
    assert files(a) == files(b)
    assert any("/c/1/2/0/0" in f for f in files(a))  # every chunk of the 4-D variables
    for f in files(a):
        assert filecmp.cmp(a / f, b / f, shallow=False), f
    back = xr.open_zarr(a, consolidated=True).load()
    np.testing.assert_array_equal(back["decode_flags"].values, ds["decode_flags"].values)
    np.testing.assert_array_equal(back["absolute_phase"].values,
                                  phase.astype(np.float32))
