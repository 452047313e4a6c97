"""The run dataset's lazily read variables (pmdsim.store.lazy_arrays): the same values as the
stacked, converted arrays they stand for, written byte for byte as the arrays themselves,
and a run's dataset code never imports dask.array."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import xarray as xr

from pmdsim.store.writer import _stored, storage_form
from pmdsim.store.lazy_arrays import converted, lazy_array, lazy_stack


def _parts(seed=3):
    rng = np.random.default_rng(seed)
    # unequal rows and columns, a NaN, values of both signs
    a = rng.normal(size=(5, 7)) * 3.0
    b = rng.normal(size=(5, 7)) - 1.5
    a[2, 3] = np.nan
    return a, b


def test_lazy_stack_reads_like_the_stacked_array():
    a, b = _parts()
    ref = (np.stack([a, b]).astype(np.float32) * np.float32(0.25))
    da = xr.DataArray(lazy_stack([a, b], np.float32, 0.25), dims=("direction", "row", "col"))
    np.testing.assert_array_equal(da.values, ref)
    np.testing.assert_array_equal(da.isel(direction=1).values, ref[1])
    np.testing.assert_array_equal(da.isel(row=slice(1, 4), col=3).values, ref[:, 1:4, 3])
    np.testing.assert_array_equal(da.isel(direction=slice(1, None), col=slice(None, None, 2)).values,
                                  ref[1:, :, ::2])
    assert da.dtype == np.float32


def test_lazy_array_and_conversion_match_the_stored_form():
    a, _ = _parts()
    conv = lambda x: _stored("modulation", x)  # noqa: E731 - rounded to KEEP_BITS
    got = xr.DataArray(lazy_array(a, convert=conv), dims=("row", "col")).values
    np.testing.assert_array_equal(got, _stored("modulation", a))
    # a conversion after a lazy stack's own: applied to what the stack reads
    stack = lazy_stack(list(_parts()), np.float32)
    both = xr.DataArray(converted(stack, conv), dims=("d", "row", "col")).values
    np.testing.assert_array_equal(both, _stored("modulation", np.stack(_parts()).astype(np.float32)))


def test_storage_form_lazy_equals_eager(tmp_path):
    a, b = _parts()
    ds = xr.Dataset({
        "phase_deviation": (("direction", "row", "col"), lazy_stack([a, b])),
        "monitor_coord_px": (("direction", "row", "col"), lazy_stack([a * 100, b * 100])),
        "modulation": (("row", "col"), a.astype(np.float32)),
    })
    eager = xr.Dataset({k: (v.dims, np.asarray(v.values)) for k, v in ds.data_vars.items()})
    lazy_vals = storage_form(ds, lazy=True)
    eager_vals = storage_form(eager, lazy=False)
    for k in ds.data_vars:
        x, y = np.asarray(lazy_vals[k].values), np.asarray(eager_vals[k].values)
        assert x.dtype == y.dtype == np.float32
        assert x.tobytes() == y.tobytes(), k


def test_dataset_written_without_dask_array(tmp_path):
    """A dataset of lazy stacks and arrays is built and written (as a run writes it) in a
    fresh interpreter that never imports dask.array; the store reads back the values."""
    code = f"""
import sys, numpy as np, xarray as xr
from pmdsim.store.lazy_arrays import lazy_stack, xarray_without_dask_import
from pmdsim.store.writer import write_dataset
xarray_without_dask_import()
a = np.arange(35.0).reshape(5, 7); b = -a[::-1] / 3
ds = xr.Dataset({{"phase_deviation": (("direction", "row", "col"), lazy_stack([a, b])),
                 "surface_to_monitor_mm": (("row", "col"), a + 0.5)}})
write_dataset(ds, {str(tmp_path / 'run.zarr')!r})
assert "dask.array" not in sys.modules, "dask.array imported"
z = xr.open_zarr({str(tmp_path / 'run.zarr')!r}, consolidated=True)
assert np.array_equal(z["surface_to_monitor_mm"].values, (a + 0.5).astype(np.float32))
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("ok")


def test_written_in_groups_byte_for_byte_as_at_once(tmp_path, monkeypatch):
    """The writer stores a part's variables a group at a time (memory: xarray reads all
    variables of one call first): every file of the store is the same as one call's."""
    from pmdsim.store import writer as writing

    a, b = _parts()
    ds = xr.Dataset({
        "phase_deviation": (("direction", "row", "col"), lazy_stack([a, b])),
        "modulation": (("width", "row", "col"), np.stack([a, b, a * 2]).astype(np.float32)),
        "valid": (("direction", "row", "col"), lazy_stack([a > 0, b > 0])),
        "deviation_stats": (("direction", "statistic"), np.arange(6.0).reshape(2, 3)),
    }, coords={"direction": ["x", "y"], "width": [50.0, 400.0, 3200.0],
               "row": np.arange(5), "col": np.arange(7) * 2})
    monkeypatch.setattr(writing, "GROUP_BYTES", 1)
    assert len(writing._groups(ds)) == 3  # the small variables with the first, then one each
    _assert_same_files(ds, tmp_path, monkeypatch, "GROUP_BYTES", 2**40, 1)


def test_a_large_variable_is_written_chunk_by_chunk_with_the_same_bytes(tmp_path, monkeypatch):
    """A camera-image variable above LARGE_BYTES goes through Dask one image at a time (a
    5 MP run's fringe images): the same files as from one converted copy."""

    a, b = _parts()
    ds = xr.Dataset({
        "phase_deviation": (("direction", "row", "col"), lazy_stack([a, b])),
        "fringes": (("width", "row", "col"), np.stack([a, b, a * 2]).astype(np.float32)),
    }, coords={"direction": ["x", "y"], "row": np.arange(5), "col": np.arange(7) * 2})
    _assert_same_files(ds, tmp_path, monkeypatch, "LARGE_BYTES", 2**40, 1)


def _assert_same_files(ds, tmp_path, monkeypatch, setting: str, *limits) -> None:
    """Write ``ds`` once per value of ``writing.<setting>``: every file byte for byte alike."""
    from pmdsim.store import writer as writing

    stores = []
    for i, limit in enumerate(limits):
        monkeypatch.setattr(writing, setting, limit)
        path = tmp_path / f"{setting}-{i}.zarr"
        writing._write_part(ds, path, create=True)
        writing.finish_store(path, {"name": "t"})
        stores.append({p.relative_to(path): p.read_bytes() for p in sorted(path.rglob("*"))
                       if p.is_file()})
    assert all(s.keys() == stores[0].keys() for s in stores)
    for k in stores[0]:
        assert all(s[k] == stores[0][k] for s in stores), k
