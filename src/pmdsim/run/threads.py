"""The run's threads: one BLAS thread while pmdsim works, and whether Numba takes
parallel kernels from several threads at once (:func:`numba_takes_two_threads`).

NumPy and SciPy each bring an OpenBLAS that starts one thread per core, and its threads
busy-wait for the next call after each one. pmdsim's parallel work is its compiled kernels
(Numba threads) and Dask tasks; the BLAS calls of a run are small (3 x 3 rotations of N x 3
arrays, vector dot products of the iterative solvers), so on a 2-core machine the extra
BLAS threads only spin against the kernels: the Fig. 3 run used 1.5-2.4 CPU-seconds less
with one BLAS thread (17.3-18.5 against 19.7-20.0 CPU-s, medians of 4 runs each; wall
0.1-0.8 s less, within the machine's noise).

The entry points of a run (:func:`~pmdsim.run.simulate.run_simulation`, sweeps,
convergence and budget studies, fits) run under :func:`single_blas`, which limits every
loaded BLAS to one thread with threadpoolctl and restores the previous setting afterwards
(a Jupyter session keeps its own). Set ``PMDSIM_BLAS_THREADS`` to another number to
change the limit (0: leave BLAS as it is). The command line also starts OpenBLAS with that
many threads (:func:`blas_pool_at_start`).
"""

from __future__ import annotations

import functools
import os


def blas_limit() -> int | None:
    """Threads BLAS may use during a run: ``PMDSIM_BLAS_THREADS`` (default 1); None for 0
    (no limit)."""
    raw = os.environ.get("PMDSIM_BLAS_THREADS", "1").strip()
    try:
        n = int(raw)
    except ValueError:
        raise ValueError(f"PMDSIM_BLAS_THREADS: expected a whole number of threads (0 = "
                         f"no limit), got {raw!r}") from None
    if n < 0:
        raise ValueError(f"PMDSIM_BLAS_THREADS: must be >= 0 (0 = no limit), got {n}")
    return n or None


def single_blas(fn):
    """Decorator: ``fn`` runs with BLAS limited to :func:`blas_limit` threads."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        limit = blas_limit()
        if limit is None:
            return fn(*args, **kwargs)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=limit, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper


def blas_pool_at_start() -> None:
    """For a process whose work is all under :func:`single_blas` (the command line): start
    OpenBLAS with :func:`blas_limit` threads (``OPENBLAS_NUM_THREADS``, unless set), so
    that it never creates the per-core threads the limit then keeps idle (they spun after
    the import's and the first calls' work: ~2 % of the Fig. 3 run's CPU). Only before
    NumPy is imported (later it changes nothing); an invalid ``PMDSIM_BLAS_THREADS`` is
    left to the run to report."""
    import sys

    if "numpy" in sys.modules:
        return
    try:
        limit = blas_limit()
    except ValueError:
        return
    if limit is not None:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", str(limit))


def numba_takes_two_threads(choose: bool = False) -> bool:
    """True when Numba's threading layer (chosen at the first parallel kernel) accepts
    parallel kernels launched from several threads at once (omp, tbb; not workqueue): the
    run's helper threads (the reference's reconstruction, the diagnostics, the early
    pilot) need it; False while no parallel kernel has run (not known yet), unless
    ``choose``: then a tiny parallel kernel makes Numba choose it now."""
    import numba

    if choose:
        from ..kernels._jit import threading_layer

        return threading_layer() in ("omp", "tbb")

    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:  # no parallel kernel has run: not known
        return False


__all__ = ["single_blas", "blas_limit", "blas_pool_at_start", "numba_takes_two_threads"]
