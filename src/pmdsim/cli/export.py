"""``pmdsim export``: a run's height and slope error maps as X3P, CSV or xyz."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import _console, _fail


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
    reconstructed height) for surface-metrology software (docs/reconstruction.md)."""
    from ..config import InputError
    from ..store.export import export_run

    console = _console()
    try:
        files = export_run(run, fmt, output, overwrite)
    except (InputError, FileNotFoundError) as err:
        _fail(str(err))
    for f in files:
        console.print(f"wrote {f}")
