"""All Numba settings in one place.

``fast`` kernels may reassociate floating-point sums (``fastmath``) so that LLVM can
vectorise reductions; every such kernel is checked against a NumPy reference in the tests.
Compiled code is cached on disk (``cache=True``) so a second process does not pay for JIT
compilation. On AVX-512 CPUs that run 512-bit instructions at full speed the kernels are
compiled for 512-bit vectors (:func:`wide_vector_features`), set before Numba loads.
"""

from __future__ import annotations

import os
import sys

#: CPUs (LLVM's names) whose 512-bit vector instructions run the render's ray loops faster
#: than two 256-bit ones: AVX-512 without the clock penalty of the first generation
#: (Skylake-X, Cascade Lake), on which LLVM's default, 256-bit vectors, stays.
WIDE_VECTOR_CPUS = frozenset({
    "icelake-client", "icelake-server", "tigerlake", "rocketlake", "sapphirerapids",
    "emeraldrapids", "graniterapids", "graniterapids-d", "diamondrapids", "znver4",
    "znver5"})


def wide_vector_features() -> str | None:
    """The Numba CPU feature string that lets LLVM vectorise with 512-bit registers (the
    host's features plus ``-prefer-256-bit``), or None to keep Numba's default.

    LLVM vectorises for 256-bit registers even where the CPU has AVX-512 (the
    ``prefer-256-bit`` tuning of its Intel targets: the first AVX-512 CPUs lowered their
    clock for 512-bit instructions). The render's ray loops are bound by arithmetic, and on
    the CPUs of :data:`WIDE_VECTOR_CPUS` 512-bit vectors run them 1.4-1.6 x faster on one
    core, less with every core at once (docs/performance.md, "512-bit vectors"). None where
    the user chose the features (``NUMBA_CPU_FEATURES``, ``NUMBA_CPU_NAME``,
    ``NUMBA_ENABLE_AVX``), where ``PMDSIM_VECTOR_BITS=256`` asks for the default, or where
    the CPU is not one of those. The same features apply to every kernel, so a run's numbers
    depend on the CPU and this setting as they depend on the CPU already (reassociated sums
    round differently with other vector widths; within a process, and in the processes it
    starts, which inherit the setting, the bytes stay the same)."""
    if os.environ.get("PMDSIM_VECTOR_BITS", "").strip() == "256" or any(
            name in os.environ for name in
            ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME", "NUMBA_ENABLE_AVX")):
        return None
    import llvmlite.binding as ll

    try:
        features = ll.get_host_cpu_features()
    except RuntimeError:  # the host's features are unknown: Numba's default
        return None
    if not features.get("avx512f") or ll.get_host_cpu_name() not in WIDE_VECTOR_CPUS:
        return None
    return features.flatten() + ",-prefer-256-bit"


def _use_wide_vectors() -> None:
    """Sets ``NUMBA_CPU_FEATURES`` to :func:`wide_vector_features` before Numba is imported
    (Numba's configuration reads it as Numba loads, and its code generator takes the
    features from there when the first function is decorated; processes started from this
    one inherit it), and in Numba's configuration if Numba was imported already. Where Numba
    made its code generator before pmdsim was imported (a kernel of another package), that
    keeps the features it started with: pmdsim's kernels then compile (and cache) for
    those."""
    features = wide_vector_features()
    if features is not None:
        os.environ["NUMBA_CPU_FEATURES"] = features
        config = sys.modules.get("numba.core.config")
        if config is not None:  # Numba imported already: its config read the variable then
            config.CPU_FEATURES = features


_use_wide_vectors()

import numba  # noqa: E402  (after the CPU features are set)
from numba.core import cgutils, types  # noqa: E402
from numba.core.imputils import impl_ret_borrowed  # noqa: E402
from numba.extending import intrinsic  # noqa: E402

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


@parallel_jit
def _layer_probe(out):
    for i in numba.prange(out.shape[0]):
        out[i] = i


def threading_layer() -> str:
    """Numba's threading layer (``"omp"``, ``"tbb"`` or ``"workqueue"``), chosen now by a
    tiny cached parallel kernel where no parallel kernel has run yet (Numba chooses it at
    the first launch)."""
    try:
        return numba.threading_layer()
    except ValueError:
        import numpy as np

        _layer_probe(np.empty(2))
        return numba.threading_layer()


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
