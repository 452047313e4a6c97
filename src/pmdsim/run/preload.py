"""What a run imports after its render, imported while the render runs.

The render's kernels release the GIL, so a thread can import meanwhile what the steps
after it need: xarray and zarr's codecs for the dataset, and, when the run draws,
matplotlib and the figure modules (for the figure processes it forks, which inherit
them). Without it the ``dataset`` step imported xarray on the run's critical path, on one
core (0.7 CPU-s of the Fig. 3 run; docs/performance.md).
"""

from __future__ import annotations

import importlib
import threading

_IMPORTS: threading.Thread | None = None
_DATASET_IMPORTED = threading.Event()


def import_in_background(figures: bool = True) -> None:
    """Import, in one thread while the run renders (its kernels release the GIL), what the
    run imports after the render: xarray and zarr's codecs for the dataset (0.7 CPU-s that
    the dataset step otherwise spent on the run's critical path, on one core, right after
    the render), then, with ``figures``, matplotlib and the figure modules, so that neither
    the run nor the drawing processes wait for them. One thread, so that no module is
    imported by two threads at once; the dataset step waits for its part alone
    (:func:`dataset_imported`). Started once per process: the first run decides whether
    the figure modules are among them (a later run imports them where it draws)."""
    global _IMPORTS
    if _IMPORTS is None:
        def work():
            try:
                for name in ("zarr.codecs", "pmdsim.store.lazy_arrays"):  # (xarray)
                    importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the dataset step imports them and reports it
                pass
            finally:
                _DATASET_IMPORTED.set()
            if figures:
                for name in ("chain_maps", "dots", "overview", "reconstruction", "scene"):
                    importlib.import_module(f"pmdsim.report.{name}")
                importlib.import_module("mpl_toolkits.mplot3d")

        _IMPORTS = threading.Thread(target=work, name="pmdsim-imports", daemon=True)
        _IMPORTS.start()


def dataset_imported() -> None:
    """Wait for the background import of the dataset's modules (:func:`import_in_background`;
    at once where none was started): the dataset step must not import them while that
    thread does."""
    if _IMPORTS is not None:
        _DATASET_IMPORTED.wait()


def imports_done() -> None:
    """Wait for the whole background import (before a fork: never in the middle of one)."""
    if _IMPORTS is not None:
        _IMPORTS.join()


__all__ = ["import_in_background", "dataset_imported", "imports_done"]
