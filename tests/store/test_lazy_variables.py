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


def test_a_lazy_variable_is_read_one_camera_image_at_a_time(tmp_path, monkeypatch):
    """The writer reads (and rounds) a lazy camera-image variable one camera image at a
    time, whatever the variable's size (a 5 MP run's fringe images), and stores what the
    whole converted stack holds."""
    from pmdsim.store import lazy_arrays
    from pmdsim.store import writer as writing

    a, b = _parts()
    reads = []
    get = lazy_arrays._Lazy._get

    def recording(self, key):
        out = get(self, key)
        reads.append(out.shape)
        return out

    monkeypatch.setattr(lazy_arrays._Lazy, "_get", recording)
    ds = xr.Dataset({"fringes": (("width", "shift", "row", "col"),
                                 lazy_stack([np.stack([a, b]), np.stack([b, a]),
                                             np.stack([a * 2, b])]))},
                    coords={"row": np.arange(5), "col": np.arange(7) * 2})
    writing.write_dataset(ds, tmp_path / "run.zarr")
    assert len(reads) == 6 and all(r == (5, 7) for r in reads)
    back = xr.open_zarr(tmp_path / "run.zarr", consolidated=True)["fringes"].values
    want = np.stack([np.stack([a, b]), np.stack([b, a]), np.stack([a * 2, b])])
    np.testing.assert_array_equal(back, writing.keep_bits(want.astype(np.float32)))
