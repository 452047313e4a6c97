"""``pmdsim report``: a run's figures drawn again from its folder."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from .common import _console, _fail, _guard, _output_folder


def report(
    run: Path = typer.Argument(..., help="A run folder written by pmdsim simulate."),
    all_figures: bool = typer.Option(False, "--all", help="Every figure (default: the "
                                     "summary, as a run draws it)."),
    figure: list[str] | None = typer.Option(None, "--figure", help="A figure by name "
                                            "(repeatable): setup, fringes, modulation, "
                                            "overview, phase, deviation, histograms, "
                                            "modulation_ratio, masks, surface_errors."),
    variant: str | None = typer.Option(None, "--variant", help="Only this variant of a run "
                                       "with variants (default: all)."),
    output: Path | None = typer.Option(None, "-o", "--output", help="Folder for the figures "
                                       "(default: RUN/figures, or RUN/VARIANT/figures)."),
    workers: int | None = typer.Option(None, "--workers", min=1, help="Drawing processes "
                                       "(default: one per core for 4 figures or more)."),
) -> None:
    """Draw a run's figures again from its folder's dataset alone (run.zarr with its
    configuration): any of them, all of them, into the run or another folder."""
    from ..report.text import description
    from ..store.schema import DATASET_NAME
    from ..run.figures import draw_figures, figure_names
    from ..store.integrity import open_run_checked

    console = _console()
    run = Path(run)
    _output_folder(output)
    if (run / DATASET_NAME).is_dir():
        if variant is not None:
            _fail(f"--variant {variant}: {run} is a run without variants (drop --variant)")
        members = [run]
    else:
        members = sorted(p.parent for p in run.glob(f"*/{DATASET_NAME}"))
        if variant is not None:
            names = [m.name for m in members]
            members = [m for m in members if m.name == variant]
            if names and not members:
                _fail(f"--variant {variant}: {run} has no such variant; its variants are "
                      + ", ".join(names))
    if not members:
        _fail(f"{run}: no {DATASET_NAME} here" + (f" for variant {variant!r}" if variant else "")
              + " (give a run folder written by pmdsim simulate)")
    which = figure or ("all" if all_figures else "summary")
    t0 = time.perf_counter()
    notes: list[str] = []
    with _guard():  # a damaged folder: the array and file that are broken, exit 2
        opened = [(folder, *open_run_checked(folder, notes=notes)) for folder in members]
    for n in notes:  # a run written before the checksums
        _console(stderr=True).print(f"note: {n}", style="yellow", markup=False)
    for folder, ds, cfg in opened:
        try:
            names = figure_names(ds, which)
        except ValueError as err:
            _fail(str(err))
        dest = output / folder.name if output is not None and len(members) > 1 else output
        for p in draw_figures(folder, names, cfg.name, description(cfg), workers=workers,
                              folder=dest):
            console.print(f"wrote {p}")
    console.print(f"in {time.perf_counter() - t0:.1f} s")
