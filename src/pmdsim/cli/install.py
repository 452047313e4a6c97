"""After installing: ``pmdsim warmup`` (compile the kernels into the cache) and
``pmdsim version``."""

from __future__ import annotations

import time

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)

from .common import _console, _guard


def warmup() -> None:
    """Compile every kernel once into Numba's on-disk cache (run once after installing, so
    that the first simulation does not pay for compilation); tiny runs that reach every kernel,
    about 90 s on 2 cores (docs/performance.md)."""
    from ..run.warmup import CASES, warmup as run_warmup

    console = _console()
    t0 = time.perf_counter()
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn())
    with _guard(), Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task("compiling kernels", total=len(CASES))
        run_warmup(lambda done, total: bar.update(task, completed=done))
    console.print(f"kernels compiled and cached in {time.perf_counter() - t0:.1f} s")


def version() -> None:
    """Print the pmdsim version."""
    from .._version import __version__

    _console().print(f"pmdsim {__version__}")
