"""``pmdsim export``: a run's height and slope error maps as X3P, CSV or xyz."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import _console, _guard


def export(
    run: Path = typer.Argument(..., help="A run folder written by pmdsim simulate (for a run "
                               "with variants: RUN/<variant>)."),
    fmt: str = typer.Option(..., "--format", help="x3p (ISO 25178-72, needs pmdsim[x3p]), csv "
                            "(one table, units in the header) or xyz (x y z per quantity)."),
    output: Path | None = typer.Option(None, "-o", "--output", help="Folder for the files "
                                       "(default: RUN/export)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace existing files."),
) -> None:
    """Export the reconstructed surface's maps (height error, slope errors X/Y and the
    reconstructed height) for surface-metrology software (docs/reconstruction.md); X3P
    holds the heights only (its z axis is a length)."""
    from ..store.export import export_run

    console = _console()
    notes: list[str] = []
    with _guard():
        files = export_run(run, fmt, output, overwrite, notes)
    for n in notes:
        _console(stderr=True).print(f"note: {n}", style="yellow", markup=False)
    for f in files:
        console.print(f"wrote {f}", markup=False)
