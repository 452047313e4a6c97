"""The run dataset's Zarr encoding and its writer: whole (:func:`write_dataset`) or in parts
behind a run's chain (:class:`DatasetWriter`), with the same bytes.

Encoding: every camera-image variable (``..., row, col``) is one chunk per image, float32,
Blosc LZ4 with bit shuffling (:data:`CODEC`), rounded to :data:`KEEP_BITS` significant
mantissa bits except the absolute coordinates and phases (:data:`FULL_PRECISION`);
:func:`storage_form` gives a dataset as stored. Every array (coordinates included) ends its
codecs with Zarr v3's ``crc32c`` checksum (a standard codec of the Zarr v3 specification,
in zarr-python 3.0 on, through google-crc32c): a byte changed in a chunk after the run wrote
it fails the chunk's read, and :mod:`pmdsim.store.integrity` names the file.

The camera-image chunks are encoded here (:func:`write_chunks`: ``bytes``, Blosc and
``crc32c`` as the array's ``zarr.json`` prescribes) and written as files, byte for byte
what Zarr writes (``tests/store/test_storage.py`` compares every file): Zarr's asynchronous
codec pipeline copied every chunk and took about twice the CPU of the compression itself
(the Fig. 3 dataset: 1.6-2.0 CPU-s written by Zarr, 1.1-1.2 now, in one ``to_zarr`` call
for the whole part).

Writing in parts: the rendered arrays are final when they are rendered, the chain's when
they are computed: nothing needs to wait for the end of the run to be written. A run hands its dataset to the
writer after every step (:meth:`DatasetWriter.offer`); one background thread writes the
variables the store does not hold yet into ``run.zarr`` (the first time creating it, then
adding to it), while the run decodes, compares, reconstructs and diagnoses. At the end
(:meth:`DatasetWriter.finish`) the run waits for what is left, and the group's attributes
and the consolidated metadata are written last: a store that has them is complete, and the
run's manifest is written only after that.

What is written is byte for byte what :func:`write_dataset` writes for
the whole dataset at once (same variables, encodings, rounding and attributes): the
store is only written in parts. Any variable added to the dataset (by any step) is
written: the writer knows no names.
"""

from __future__ import annotations

import contextlib
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
import functools
import numpy as np


def _write_part(ds, path: Path, create: bool) -> None:
    """Write ``ds`` (a part of a run dataset) into the store ``path``: create it, or add
    the part's variables to it. No consolidated metadata (see :func:`finish_store`).
    xarray and Zarr create the arrays (metadata and attributes), the camera-image ones from
    a placeholder of the fill value whose chunks Zarr leaves out, and :func:`write_chunks`
    writes every camera-image chunk with the bytes Zarr would write, rounding one camera
    image at a time as it reads it (:func:`pmdsim.store.lazy_arrays.converted`): writing
    holds one image, whatever the variable's size. A part holding Dask arrays (a loaded
    run's) is written through Zarr, computed on Dask's threaded scheduler, passed explicitly
    (not through ``dask.config``, which is global: the run's other threads use their own).
    Every chunk is written, also one that holds only the fill value
    (``write_empty_chunks``): Zarr's check for such chunks compared every value of every
    camera image (1 ms a chunk, ~0.25 CPU-s on Fig. 3), and a run's chunks are whole
    images, which hold data."""
    stored = storage_form(ds, lazy=True)
    # Dask arrays, asked of each variable without reading it (``Variable.data`` reads a
    # lazily indexed variable whole)
    if any(v.chunks is not None for v in stored.variables.values()):
        from ..render import local_scheduler

        stored.to_zarr(path, mode="w-" if create else "a", consolidated=False,
                       encoding=_encoding(ds, None if create else path), zarr_format=3,
                       write_empty_chunks=True, compute=False).compute(
            scheduler=local_scheduler("threads"))
        return
    direct = [n for n, v in stored.data_vars.items() if _image_like(v)]
    template = stored.assign({n: stored[n].copy(data=_placeholder(stored[n])) for n in direct})
    encoding = _encoding(template, None if create else path)
    for name, e in encoding.items():
        e["write_empty_chunks"] = name not in direct
    template.to_zarr(path, mode="w-" if create else "a", consolidated=False,
                     encoding=encoding, zarr_format=3)
    for name in direct:
        write_chunks(Path(path) / str(name), stored[name].variable)


def _placeholder(var) -> np.ndarray:
    """A read-only array of ``var``'s shape and dtype holding only the fill value Zarr
    gives such an array (NaN for floats, 0 and False otherwise), without memory."""
    fill = np.nan if var.dtype.kind == "f" else 0
    return np.broadcast_to(np.array(fill, dtype=var.dtype), var.shape)


def write_through_zarr(array: Path, var) -> None:
    """Write every chunk of ``var`` into the Zarr array folder ``array`` by Zarr itself
    (every chunk, also one of fill values only, as :func:`write_chunks` does)."""
    import zarr

    target = zarr.open_array(str(array), mode="r+").with_config({"write_empty_chunks": True})
    for index in np.ndindex(*var.shape[:-2]):
        target[index] = var[index].values


def crc32c_checksum(data) -> bytes:
    """The 4 bytes Zarr v3's ``crc32c`` codec appends to the encoded ``data``: its CRC-32C,
    little endian."""
    import google_crc32c

    return int(google_crc32c.value(data)).to_bytes(4, "little")


#: ``blosc`` codec configuration -> :class:`numcodecs.Blosc` shuffle
_SHUFFLE = {"noshuffle": 0, "shuffle": 1, "bitshuffle": 2}


def write_chunks(array: Path, var) -> None:
    """Write every chunk of the camera-image variable ``var`` (an xarray Variable, read
    one image at a time) into the Zarr v3 array folder ``array`` as its ``zarr.json``
    prescribes: one chunk per camera image, codecs ``bytes`` (little endian), ``blosc``
    and ``crc32c`` (the 4-byte little-endian CRC-32C of the compressed bytes appended), keys
    of the ``default`` encoding. The same bytes as Zarr writes (tests/store/test_storage.py
    compares every file), without Zarr's asynchronous pipeline and its copies of every
    chunk (about a CPU-second on the Fig. 3 run). An array described otherwise is written
    through Zarr."""
    import json

    from numcodecs import Blosc

    meta = json.loads((array / "zarr.json").read_text())
    codecs = [c["name"] for c in meta["codecs"]]
    chunk = meta["chunk_grid"]["configuration"]["chunk_shape"]
    shape = tuple(meta["shape"])
    keys = meta["chunk_key_encoding"]
    one_image = list(chunk) == [1] * (len(shape) - 2) + list(shape[-2:])
    endian = (meta["codecs"][0].get("configuration") or {}).get("endian", "little")
    if (codecs != ["bytes", "blosc", "crc32c"] or not one_image or endian != "little"
            or keys.get("name") != "default" or tuple(var.shape) != shape):
        write_through_zarr(array, var)
        return
    conf = meta["codecs"][1]["configuration"]
    blosc = Blosc(cname=conf["cname"], clevel=conf["clevel"], shuffle=_SHUFFLE[conf["shuffle"]],
                  blocksize=conf["blocksize"], typesize=conf["typesize"])
    sep = (keys.get("configuration") or {}).get("separator", "/")
    dtype = np.dtype(meta["data_type"]).newbyteorder("<")
    for index in np.ndindex(*shape[:-2]):
        block = np.ascontiguousarray(var[index].values, dtype)
        data = blosc.encode(block)
        crc = crc32c_checksum(data)
        key = sep.join(["c", *map(str, index), "0", "0"])
        target = array / key
        target.parent.mkdir(parents=True, exist_ok=True)
        with open(target, "wb") as fh:
            fh.write(data)
            fh.write(crc)


def finish_store(path: Path, attrs: dict) -> None:
    """Write the group attributes ``attrs`` and the consolidated metadata of the store
    ``path`` (so that a plain ``xarray.open_zarr(path)`` opens it without a warning)."""
    import warnings

    import xarray as xr
    import zarr

    with warnings.catch_warnings():
        # zarr-python notes that consolidated metadata is not (yet) in the v3 spec; xarray
        # and zarr-python read it, other readers ignore it and list the store instead
        warnings.filterwarnings("ignore", message="Consolidated metadata", category=UserWarning)
        xr.Dataset(attrs=attrs).to_zarr(path, mode="a", consolidated=False, zarr_format=3)
        zarr.consolidate_metadata(str(path), zarr_format=3)


class DatasetWriter:
    """Writes a run dataset into ``path`` in the background, part by part.

    :meth:`offer` (after each step of the run) queues the variables and coordinates of the
    dataset that are not written yet; a single thread writes them in order (offers that
    find nothing new cost nothing). :meth:`finish` waits for every part and writes the
    attributes and the consolidated metadata. :meth:`close` (on an error or an interrupt)
    drops what is queued and waits for the part being written, so that no thread writes
    into a folder being removed."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="pmdsim-dataset")
        self._latest = None
        self._written: set = set()
        self._futures: list[Future] = []
        self._lock = threading.Lock()
        self._busy = threading.Lock()  # held while a part is written

    def offer(self, ds) -> None:
        """Queue the variables of ``ds`` that the store does not hold yet. ``ds`` is
        copied (shallow): the run may go on changing its own."""
        with self._lock:
            self._latest = ds.copy(deep=False)
        self._futures.append(self._pool.submit(self._write_new))

    @contextlib.contextmanager
    def paused(self):
        """No part is being written inside this block (it waits for the current one).

        A run forks its figure processes inside it: a fork copies the locks other threads
        hold, and a part being written holds Dask's (``dask.tokenize``'s lock): a child
        forked then waits for it forever."""
        with self._busy:
            yield

    def _write_new(self) -> None:
        with self._busy:
            self._write_new_part()

    def _write_new_part(self) -> None:
        with self._lock:
            ds = self._latest
        new = [n for n in ds.data_vars if n not in self._written]
        coords = [c for c in ds.coords if c not in self._written]
        if not new and not coords:
            return
        part = ds[new]
        # coordinates that came without a variable of their own (e.g. assigned alone)
        part = part.assign_coords({c: ds.coords[c] for c in coords if c not in part.coords})
        # index coordinates already in the store need not be written again (a variable
        # names its dimensions, not them); other coordinates are written with the
        # variables that list them
        part = part.drop_vars([c for c in part.coords
                               if c in self._written and c in part.indexes])
        _write_part(part, self.path, create=not self._written)
        self._written.update(part.variables)

    def finish(self, ds) -> Path:
        """Write what ``ds`` adds, wait for every part, then write the attributes of ``ds``
        and the consolidated metadata. Raises the first error of a part."""
        self.offer(ds)
        try:
            for f in self._futures:
                f.result()
        finally:
            self._pool.shutdown(wait=True)
        finish_store(self.path, dict(ds.attrs))
        return self.path

    def close(self) -> None:
        """Cancel what is queued and wait for the part being written (after an error)."""
        self._pool.shutdown(wait=True, cancel_futures=True)


__all__ = ["DatasetWriter", "finish_store"]


#: Significant mantissa bits kept (of float32's 23) for the stored camera values, lobe
#: weight sums, deviations, modulations, phases within a period and flags' companions:
#: relative precision 2**-17 = 7.6e-6, finer than a 16-bit camera (1.5e-5 of full scale)
#: and far below any deviation the chain reports; the zeroed low bits make the data
#: compress ~2x.
KEEP_BITS = 16
#: Variables stored with full float32 precision: absolute coordinates and phases (their
#: absolute precision matters, ~1e-4 monitor px at 2000 px), and the fringe sums, whose
#: phase ``fringe_phase_error`` states (16 bits decoded 4-5e-3 mrad off at wide fringes,
#: where a Fig. 3 rule states 1e-4 to 1e-3 mrad; tests/render/test_pilot.py).
FULL_PRECISION = frozenset({
    "absolute_phase", "reference_absolute_phase", "monitor_coord_px", "monitor_coord_mm",
    "reference_monitor_coord_px", "reference_monitor_coord_mm", "specular_u", "specular_v",
    "surface_to_monitor_mm", "fringe_sums_real", "fringe_sums_imag",
})


def keep_bits(values: np.ndarray, bits: int = KEEP_BITS) -> np.ndarray:
    """float32 ``values`` rounded (to nearest, ties to even) to ``bits`` significant
    mantissa bits; NaN and inf unchanged. The relative rounding error is <= 2**-(bits+1).
    Returns a new array (``values`` is never changed)."""
    from ..kernels.bits import round_mantissa

    a = np.array(values, dtype=np.float32, order="C", copy=True)
    drop = 23 - bits
    if drop > 0 and a.size:
        round_mantissa(a.reshape(-1).view(np.uint32), drop)  # in place, one pass
    return a


#: Compressor of the camera-image variables: Blosc LZ4 with bit shuffling. On the Fig. 3
#: run (the fringe sums then at 16 bits) it encoded 512 MB of float32 in 0.5 CPU-s to
#: 72 MB; zstd level 5 (the earlier choice) makes 50 MB but takes 3.7 CPU-s, zstd level 1
#: 70 MB in 1.0 s. Noisy floats hardly compress further: the cheap codec is the right trade
#: for a run folder.
CODEC = dict(cname="lz4", clevel=5, shuffle="bitshuffle")


def _image_like(var) -> bool:
    return var.ndim >= 2 and var.dims[-2:] == ("row", "col")


def _encoding(ds, path: Path | None = None) -> dict:
    """Storage of every variable of ``ds`` (coordinates included) that the store ``path``
    does not hold yet (xarray refuses an encoding for a variable it appends to): its
    compressors end with Zarr v3's standard ``crc32c`` checksum codec (4 bytes a chunk:
    a chunk changed on disk fails its read, :mod:`pmdsim.store.integrity`);
    every (..., row, col) variable is one chunk per camera image, float32, Blosc
    (:data:`CODEC`, Zarr v3's standard ``blosc`` codec), the others Zarr's default
    compressor (zstd)."""
    from zarr.codecs import BloscCodec, Crc32cCodec, ZstdCodec

    enc = {}
    for name, var in ds.variables.items():
        if path is not None and (Path(path) / str(name) / "zarr.json").is_file():
            continue
        if name in ds.data_vars and _image_like(var):
            shape = var.shape
            e = {"chunks": (1,) * (len(shape) - 2) + tuple(shape[-2:]),
                 "compressors": (BloscCodec(**CODEC), Crc32cCodec())}
            if var.dtype == np.float64:
                e["dtype"] = "float32"
        else:
            e = {"compressors": (ZstdCodec(), Crc32cCodec())}
        enc[name] = e
    return enc


def _stored(name: str, block: np.ndarray) -> np.ndarray:
    """One chunk as stored: float32, :data:`KEEP_BITS` significant bits unless ``name`` is
    in :data:`FULL_PRECISION`; other dtypes unchanged."""
    if block.dtype.kind != "f":
        return block
    if name in FULL_PRECISION:
        return block.astype(np.float32, copy=False)
    return keep_bits(block)


def storage_form(ds, lazy: bool = False):
    """``ds`` as the run folder stores it: image-like float variables (camera rows x
    columns) in float32 with :data:`KEEP_BITS` significant bits, except
    :data:`FULL_PRECISION` (float32, all bits); everything else unchanged (a shallow copy).

    With ``lazy`` the image-like variables are converted when read
    (:func:`pmdsim.store.lazy_arrays.converted`): writing them holds a rounded copy of one variable
    at a time instead of one of the whole dataset."""
    from . import lazy_arrays as lazy

    new = {}
    for name, var in ds.data_vars.items():
        if not _image_like(var):
            continue
        if lazy:
            arr = lazy.converted(var.variable._data, functools.partial(_stored, name))
            new[name] = var.copy(data=arr)
        elif var.dtype.kind == "f":
            new[name] = var.copy(data=_stored(name, np.asarray(var.values)))
    return ds.assign(new)  # one merge (a merge per variable costs ~10 ms each)


def write_dataset(ds, path: str | Path) -> Path:
    """Write a run dataset to ``path`` (Zarr v3, chunked and compressed, consolidated
    metadata so that a plain ``xarray.open_zarr(path)`` opens it without a warning);
    see :func:`storage_form` for the precision.

    The camera-image variables are rounded, compressed and written one image at a time
    (:func:`_write_part`; a loaded run's Dask arrays on Dask's threaded scheduler, whatever
    scheduler is active: a ``dask.distributed`` client would ship the run's arrays to its
    workers). A run writes its dataset in parts while it computes (:class:`DatasetWriter`),
    with the same bytes."""
    path = Path(path)
    _write_part(ds, path, create=True)
    finish_store(path, dict(ds.attrs))
    return path
