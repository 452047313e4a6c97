"""All Numba settings in one place.

``fast`` kernels may reassociate floating-point sums (``fastmath``) so that LLVM can
vectorise reductions; every such kernel is checked against a NumPy reference in the tests.
Compiled code is cached on disk (``cache=True``) so a second process does not pay for JIT
compilation.
"""

from __future__ import annotations

import numba
from numba.core import cgutils, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic

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
