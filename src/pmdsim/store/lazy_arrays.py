"""Lazily read variables of a run dataset, without Dask arrays.

The chain's variables of a run dataset are stacks of views of the chain's own arrays
(:func:`lazy_stack`), and the writer stores every camera-image variable rounded as it
reads it (:func:`converted`): nothing is copied until a figure reads a variable or the
writer stores it (one variable at a time). xarray keeps such a variable lazily indexed
(:class:`xarray.core.indexing.LazilyIndexedArray` over a
:class:`xarray.backends.BackendArray`), as it keeps a variable of a file it opened.

Why not Dask arrays: importing ``dask.array`` costs about a CPU-second (its functions'
docstrings are rewritten at import), and a run needs none of it. xarray itself asks, for
every variable it makes, whether the data are a Dask array, and imports ``dask.array`` to
know: :func:`xarray_without_dask_import` answers from the modules already imported (no
object is a Dask array before ``dask.array`` is imported).
"""

from __future__ import annotations

import sys

import numpy as np
from xarray.backends.common import BackendArray
from xarray.core import indexing


def xarray_without_dask_import() -> None:
    """Let xarray's test "is this a Dask array?" answer without importing ``dask.array``
    (idempotent; nothing when xarray has asked already or has changed its internals)."""
    try:
        from packaging.version import Version
        from xarray.namedarray import pycompat
    except ImportError:  # pragma: no cover - another xarray
        return
    cache = getattr(pycompat, "_cached_duck_array_modules", None)
    base = getattr(pycompat, "DuckArrayModule", None)
    if not isinstance(cache, dict) or base is None or "dask" in cache:
        return

    class _DaskWhenImported(base):
        """xarray's record of the ``dask`` duck-array module whose array type is that of
        ``dask.array`` once something imported it, and none before."""

        def __init__(self):  # noqa: D401 - no import of dask.array here
            try:
                import dask
            except ImportError:  # pragma: no cover
                self.module, self.version, self.available = None, Version("0.0.0"), False
                return
            self.module, self.version, self.available = dask, Version(dask.__version__), True

        @property
        def type(self):
            mod = sys.modules.get("dask.array")
            array = getattr(mod, "Array", None)
            return () if array is None else (array,)

    cache["dask"] = _DaskWhenImported()


class _Lazy(BackendArray):
    """A read-only stack of arrays of one shape (``stacked``; else the one array itself),
    converted to ``dtype``, multiplied by ``scale`` and passed through ``convert`` only for
    the part that is indexed."""

    def __init__(self, parts, stacked: bool, dtype=None, scale: float | None = None,
                 convert=None):
        self.parts, self.stacked = [np.asarray(a) for a in parts], stacked
        self.scale, self.convert = scale, convert
        first = self.parts[0]
        self.shape = ((len(self.parts),) if stacked else ()) + first.shape
        self.base = np.dtype(dtype) if dtype is not None else (
            first.dtype if scale is None else np.result_type(first.dtype, scale))
        # the dtype read: that of ``convert``'s output
        self.dtype = (self.base if convert is None
                      else convert(np.zeros((1,) * first.ndim, self.base)).dtype)

    def __getitem__(self, key):
        return indexing.explicit_indexing_adapter(key, self.shape,
                                                  indexing.IndexingSupport.BASIC, self._get)

    def _one(self, a: np.ndarray, key) -> np.ndarray:
        out = np.asarray(a[key]).astype(self.base, copy=False)
        if self.scale is not None:
            out = out * out.dtype.type(self.scale)
        return out if self.convert is None else self.convert(out)

    def _get(self, key: tuple) -> np.ndarray:
        if not self.stacked:
            return self._one(self.parts[0], key)
        first, rest = key[0], key[1:]
        if isinstance(first, (int, np.integer)):
            return self._one(self.parts[first], rest)
        picked = self.parts[first]
        if not picked:
            return np.empty((0,) + tuple(len(range(*k.indices(n))) if isinstance(k, slice)
                                         else 1 for k, n in zip(rest, self.shape[1:])),
                            self.dtype)
        return np.stack([self._one(a, rest) for a in picked])


def lazy_array(data: np.ndarray, dtype=None, scale: float | None = None, convert=None):
    """``data`` (as ``dtype``, times ``scale``, through ``convert``) as a lazily indexed
    array for an xarray variable, referencing ``data`` without a copy."""
    xarray_without_dask_import()
    return indexing.LazilyIndexedArray(_Lazy([data], False, dtype, scale, convert))


def lazy_stack(arrays, dtype=None, scale: float | None = None):
    """``np.stack(arrays)`` (as ``dtype``, times ``scale``) as a lazily indexed array over
    ``arrays``: nothing is copied until it is read (written or drawn)."""
    xarray_without_dask_import()
    return indexing.LazilyIndexedArray(_Lazy(list(arrays), True, dtype, scale))


def converted(data, convert):
    """The data of an xarray variable passed through ``convert`` when read: a lazy stack
    (:func:`lazy_stack`) or an in-memory array without a copy; a Dask array (of a loaded
    run) block by block; anything else converted now."""
    if isinstance(data, indexing.LazilyIndexedArray) and isinstance(data.array, _Lazy) and all(
            isinstance(k, slice) and k == slice(None) for k in data.key.tuple):
        inner = data.array
        first = inner.convert
        both = convert if first is None else (lambda a: convert(first(a)))
        return indexing.LazilyIndexedArray(_Lazy(inner.parts, inner.stacked, inner.base,
                                                 inner.scale, both))
    if isinstance(data, np.ndarray):
        return lazy_array(data, convert=convert)
    da = sys.modules.get("dask.array")
    if da is not None and isinstance(data, da.Array):
        chunks = (1,) * (data.ndim - 2) + tuple(data.shape[-2:])
        dtype = convert(np.zeros((1,) * data.ndim, data.dtype)).dtype
        return data.rechunk(chunks).map_blocks(convert, dtype=dtype)
    return convert(np.asarray(data))


__all__ = ["lazy_array", "lazy_stack", "converted", "xarray_without_dask_import"]
