"""Which figures a run draws, and drawing them in worker processes from the run folder.

Figures are named (:data:`FIGURES`); a run draws ``output.figure_set`` of them:
``summary`` (default: ``setup`` and ``overview``, or without decoding ``setup``,
``fringes`` and ``modulation``) or ``all``. Every figure is drawn from the run's dataset
alone (the set-up figure rebuilds the simulation from ``attrs["config_json"]``), so
:func:`draw_figures` can draw them in separate processes that each open ``run.zarr``, and
``pmdsim report RUN`` can draw any of them later.

Drawing in processes pays off only with several figures (each process imports matplotlib
and pmdsim, about 1.5 s): by default a run draws its summary in its own process and uses
one process per core for 4 figures or more (``output.figure_workers``).
"""

from __future__ import annotations

import os
from pathlib import Path

from .dataset import DATASET_NAME

#: Every per-run figure: name -> (file, needs) with needs "fringes" (fringe images in the
#: dataset), "chain" (the measurement chain's variables), "reconstruction" (slope and
#: height error maps of ``[reconstruct]``) or None.
FIGURES = {
    "setup": ("setup.png", None),
    "fringes": ("fringes.png", "fringes"),
    "modulation": ("modulation.png", "fringes"),
    "overview": ("overview.png", "chain"),
    "phase": ("phase.png", "chain"),
    "deviation": ("deviation.png", "chain"),
    "histograms": ("histograms.png", "chain"),
    "modulation_ratio": ("modulation_ratio.png", "chain"),
    "masks": ("masks.png", "chain"),
    "surface_errors": ("surface_errors.png", "reconstruction"),
}
SUMMARY_DECODED = ("setup", "overview", "surface_errors")
SUMMARY = ("setup", "fringes", "modulation")


def _has(ds, needs: str | None) -> bool:
    if needs is None:
        return True
    if needs == "fringes":
        return "fringes" in ds
    if needs == "reconstruction":
        return "height_error_nm" in ds
    return "phase_deviation" in ds


def figure_names(ds, which="summary") -> list[str]:
    """The figures of ``which`` (``"summary"``, ``"all"`` or a list of names) that the
    dataset ``ds`` can give."""
    if which == "all":
        names = list(FIGURES)
    elif which == "summary":
        names = list(SUMMARY_DECODED if "phase_deviation" in ds else SUMMARY)
    else:
        names = list(which)
        unknown = [n for n in names if n not in FIGURES]
        if unknown:
            raise ValueError(f"unknown figure(s) {unknown}; choose from {list(FIGURES)}")
    return [n for n in names if _has(ds, FIGURES[n][1])]


def _simulation(ds):
    from ..config import RunConfig
    from ..render import Simulation

    return Simulation.from_config(RunConfig.model_validate_json(ds.attrs["config_json"]))


def draw_one(ds, name: str, folder: Path, run_name: str, description: str = "",
             sim=None) -> Path:
    """Draw figure ``name`` of dataset ``ds`` into ``folder``."""
    from ..report import chain as plot_chain
    from ..report import scene as plot

    path = Path(folder) / FIGURES[name][0]
    if name == "setup":
        return plot.plot_setup(sim if sim is not None else _simulation(ds), path)
    if name == "fringes":
        return plot.plot_fringe_images(ds, path)
    if name == "modulation":
        return plot.plot_modulation(ds, path)
    if name == "overview":
        return plot_chain.plot_overview(ds, path, run_name, description)
    if name == "surface_errors":
        from ..report.reconstruction import plot_surface_errors
        from ..report.scene import _save

        return _save(plot_surface_errors(ds, run_name, description), path)
    fn = {"phase": plot_chain.plot_phase, "deviation": plot_chain.plot_deviation,
          "histograms": plot_chain.plot_histograms,
          "modulation_ratio": plot_chain.plot_modulation_ratio,
          "masks": plot_chain.plot_masks}[name]
    return fn(ds, path, run_name)


def _draw_from_folder(run_folder: str, name: str, folder: str, run_name: str,
                      description: str) -> str:
    """Worker process job: open the run's dataset and draw one figure."""
    return str(draw_one(open_dataset(run_folder), name, Path(folder), run_name, description))


def open_dataset(run_folder):
    """The run's dataset, each variable read once on first use and kept (a figure reads
    only what it draws)."""
    import xarray as xr

    return xr.open_dataset(Path(run_folder) / DATASET_NAME, engine="zarr", chunks=None,
                           cache=True, consolidated=False)


def default_workers(n_figures: int) -> int:
    """Processes for ``n_figures`` figures: 1 (the run's own) below 4 figures, else one per
    core, at most one per figure."""
    return 1 if n_figures < 4 else max(1, min(os.cpu_count() or 1, n_figures))


def draw_figures(run_folder: str | Path, names, run_name: str, description: str = "",
                 ds=None, sim=None, workers: int | None = None,
                 folder: str | Path | None = None, notes: list | None = None) -> list[Path]:
    """Draw the figures ``names`` of the run folder ``run_folder`` into ``folder`` (default
    ``run_folder/figures``).

    With one worker they are drawn here, from ``ds`` (and ``sim``) when given, else from the
    folder's dataset; with more, each is drawn by a separate process that opens the
    dataset (which must have been written). Returns the paths in the order of ``names``.

    With ``notes`` (a list), a figure that cannot be drawn is a note appended to it (the
    run's data are complete without it) and the others are still drawn; without, the
    error propagates.
    """
    def failed(name, err) -> None:
        if notes is None:
            raise err
        notes.append(f"figure {name} could not be drawn ({type(err).__name__}: {err}); the "
                     "data are complete (run.zarr, statistics.json)")

    run_folder = Path(run_folder)
    folder = Path(folder) if folder is not None else run_folder / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    names = list(names)
    workers = default_workers(len(names)) if workers is None else workers
    if workers <= 1 or len(names) <= 1:
        if ds is None:
            ds = open_dataset(run_folder)
        paths = []
        for n in names:
            try:
                paths.append(draw_one(ds, n, folder, run_name, description, sim))
            except Exception as err:  # noqa: BLE001 - reported in notes (or re-raised)
                failed(n, err)
        return paths
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    # The slowest figures first, so that the pool ends together.
    order = sorted(names, key=lambda n: n != "overview" and n != "deviation")
    with ProcessPoolExecutor(min(workers, len(names)), mp_context=mp.get_context("spawn")) as ex:
        futures = {n: ex.submit(_draw_from_folder, str(run_folder), n, str(folder), run_name,
                                description) for n in order}
        paths = []
        for n in names:
            try:
                paths.append(Path(futures[n].result()))
            except Exception as err:  # noqa: BLE001 - reported in notes (or re-raised)
                failed(n, err)
        return paths


__all__ = ["FIGURES", "figure_names", "draw_figures", "draw_one", "default_workers"]
