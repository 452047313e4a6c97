"""All Numba settings in one place.

``fast`` kernels may reassociate floating-point sums (``fastmath``) so that LLVM can
vectorise reductions; every such kernel is checked against a NumPy reference in the tests.
Compiled code is cached on disk (``cache=True``) so a second process does not pay for JIT
compilation; every function of ``kernels/`` is stamped with the sources of the whole folder
(:func:`_stamp_kernels_together`). :func:`switch` turns a table of cases into one compiled
if-chain (the bundle kernels' models and pattern kinds).
"""

from __future__ import annotations

import functools
import hashlib
import os

import numba
from numba.core import cgutils, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic

_FOLDER = os.path.dirname(os.path.abspath(__file__))


@functools.lru_cache(maxsize=8)
def _folder_digest(files: tuple) -> str:
    """sha256 of the contents of ``files`` ((path, mtime_ns, size), sorted)."""
    h = hashlib.sha256()
    for path, _, _ in files:
        with open(path, "rb") as f:
            h.update(f.read())
    return h.hexdigest()


def _stamp_kernels_together():
    """Numba keys a cached kernel on its own source file only, but the bundle kernels
    inline functions of other modules of this folder (``models``, ``patterns``,
    ``fastmath``, ...): editing only those would load stale machine code (also from a
    ``NUMBA_CACHE_DIR`` kept across upgrades). So every function of this folder is stamped
    with the contents of all its modules as well; other files keep Numba's own stamp. With
    a Numba without this hook the stamp is Numba's."""
    try:
        from numba.core.caching import _SourceFileBackedLocatorMixin as mixin

        own = mixin.get_source_stamp
    except (ImportError, AttributeError):  # pragma: no cover - another Numba
        return
    if getattr(own, "_pmdsim", False):
        return

    def get_source_stamp(self):
        stamp = own(self)
        path = getattr(self, "_py_file", None)
        if path is None or os.path.dirname(os.path.abspath(path)) != _FOLDER:
            return stamp
        files = []
        for entry in sorted(os.scandir(_FOLDER), key=lambda e: e.name):
            if entry.name.endswith(".py"):
                st = entry.stat()
                files.append((entry.path, st.st_mtime_ns, st.st_size))
        return stamp, _folder_digest(tuple(files))

    get_source_stamp._pmdsim = True
    mixin.get_source_stamp = get_source_stamp


_stamp_kernels_together()

JIT_OPTIONS = dict(nogil=True, cache=True, error_model="numpy")
FAST_OPTIONS = dict(JIT_OPTIONS, fastmath=True)


def jit(fn=None, **overrides):
    """``numba.njit`` with the project's options (serial, GIL released, cached)."""
    options = dict(JIT_OPTIONS, **overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)


def fastjit(fn=None, **overrides):
    """Like :func:`jit` with ``fastmath`` for vectorised reductions."""
    options = dict(FAST_OPTIONS, **overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)


def parallel_jit(fn=None, **overrides):
    """``fastjit`` with ``parallel=True`` (for whole-array kernels such as decoding)."""
    options = dict(FAST_OPTIONS, parallel=True, **overrides)
    if fn is None:
        return lambda f: numba.njit(**options)(f)
    return numba.njit(**options)(fn)


@intrinsic
def borrow(typingctx, arr):
    """A view of ``arr`` without a reference count (no meminfo), for per-pixel loops.

    Numba increments and decrements an array's reference count (an atomic operation)
    whenever an array variable is copied, e.g. as the argument of a function inlined into
    a loop body: tens of atomics per pixel, shared between threads when the tiles write into
    one array. On a view without meminfo those operations fold away. The view does not own
    its memory: the caller must keep ``arr`` alive (an argument, or a local array used
    after the loop) for as long as the view is used, and never return it.
    """

    if not isinstance(arr, types.Array):  # anything else passes through unchanged
        return arr(arr), lambda context, builder, sig, args: impl_ret_borrowed(
            context, builder, sig.return_type, args[0])

    def codegen(context, builder, sig, args):
        src = context.make_array(sig.args[0])(context, builder, args[0])
        dst = context.make_array(sig.return_type)(context, builder)
        dst.meminfo = cgutils.get_null_value(dst.meminfo.type)
        dst.parent = cgutils.get_null_value(dst.parent.type)
        dst.nitems = src.nitems
        dst.itemsize = src.itemsize
        dst.data = src.data
        dst.shape = src.shape
        dst.strides = src.strides
        return dst._getvalue()

    return arr(arr), codegen


def switch(cases):
    """A compiled ``pick(key, args)`` that calls ``fn(args)`` for the ``(key, fn)`` of
    ``cases`` whose key equals ``key`` (an if-chain inlined where it is called, with
    every ``fn`` inlined in its branch; ``args`` is one tuple, since inlined closures
    cannot take ``*args``), and raises ValueError for any other key. This is how the
    bundle kernels compile one specialised body per BRDF model and pattern kind from a
    table: a new case is one more row. Inlined, not called: in a function of its own a
    ray loop no longer knows that its buffers (allocated by the caller) do not overlap,
    and LLVM leaves it scalar or guards it (measured: Fig. 3 sequence 1.25-1.5x the CPU
    time)."""

    @fastjit(inline="always")
    def unknown(key, args):
        raise ValueError("unknown kernel case")

    pick = unknown
    for key, fn in reversed(list(cases)):
        pick = _branch(int(key), fn, pick)
    return pick


def _branch(key, fn, otherwise):
    @fastjit(inline="always")
    def pick(sel, args):
        if sel == key:
            return fn(args)
        return otherwise(sel, args)

    return pick
