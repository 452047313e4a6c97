"""All Numba settings in one place.

``fast`` kernels may reassociate floating-point sums (``fastmath``) so that LLVM can
vectorise reductions; every such kernel is checked against a NumPy reference in the tests.
Compiled code is cached on disk (``cache=True``) so a second process does not pay for JIT
compilation.
"""

from __future__ import annotations

import numba

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
