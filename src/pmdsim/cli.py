"""The ``pmdsim`` command line (Typer + Rich).

    pmdsim simulate CONFIG -o OUTDIR [--overwrite] [--no-figures]
    pmdsim version
    pmdsim --help

Bad input (an invalid configuration, a missing file, an existing output folder) prints one
red message and exits with code 2, without a traceback.
"""

from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

app = typer.Typer(
    name="pmdsim",
    help="Simulate Phase Measuring Deflectometry (PMD) of scattering surfaces by reverse "
    "ray tracing with a BRDF-weighted ray bundle per camera pixel.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

#: Exit code for bad input (configuration, files, output folder).
EXIT_BAD_INPUT = 2


def _console(stderr: bool = False) -> Console:
    return Console(stderr=stderr, soft_wrap=True, highlight=False)


def _fail(message: str) -> None:
    _console(stderr=True).print(f"error: {message}", style="bold red", markup=False)
    raise typer.Exit(EXIT_BAD_INPUT)


def _si(x: float) -> str:
    for unit, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(x) >= scale:
            return f"{x / scale:.2f} {unit}"
    return f"{x:.0f}"


@app.command()
def simulate(
    config: Path = typer.Argument(..., help="Run configuration (TOML), e.g. "
                                  "examples/paper_fig3.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Run folder to create."),
    overwrite: bool = typer.Option(False, "--overwrite",
                                   help="Replace an existing run folder."),
    no_figures: bool = typer.Option(False, "--no-figures",
                                    help="Do not draw the figures (faster)."),
) -> None:
    """Render the configured patterns and write a run folder (images, run.zarr, figures)."""
    from .config import ConfigError, load_config
    from .io import check_output_dir
    from .pipeline import run_simulation

    console = _console()
    try:
        cfg = load_config(config)
        check_output_dir(output, overwrite)
    except (ConfigError, FileNotFoundError, FileExistsError, PermissionError,
            NotADirectoryError, ValueError) as err:
        _fail(str(err))
    figures = False if no_figures else None
    t0 = time.perf_counter()
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn())
    try:
        with Progress(*columns, console=console, transient=False) as bar:
            task = bar.add_task(f"simulating {cfg.name}", total=None)

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            result = run_simulation(cfg, output, progress, overwrite=overwrite,
                                    figures=figures)
    except (ConfigError, FileNotFoundError, FileExistsError, PermissionError,
            NotADirectoryError, ValueError) as err:
        _fail(str(err))
    wall = time.perf_counter() - t0

    h, w = result.shape
    table = Table(title=f"pmdsim run '{cfg.name}'", show_header=False, title_justify="left")
    table.add_column("", style="bold", no_wrap=True)
    table.add_column("", overflow="fold")  # long paths wrap, never truncated
    table.add_row("camera pixels", f"{w} x {h} = {w * h:,} ({result.surface_pixels:,} on the "
                  "surface)")
    table.add_row("rays per pixel", f"{result.rays_per_pixel}")
    table.add_row("rays traced", f"{result.rays_traced:,}")
    table.add_row("render time", f"{result.timings['render']:.2f} s "
                  f"({_si(result.rays_per_second)}rays/s)")
    table.add_row("wall time", f"{wall:.2f} s (geometry {result.timings['geometry']:.2f} s, "
                  f"writing {result.timings['write']:.2f} s, "
                  f"figures {result.timings['figures']:.2f} s)")
    table.add_row("run folder", str(result.outdir))
    if result.variants:
        for sub in result.variants:
            table.add_row(f"variant {sub.config.name}",
                          f"{sub.dataset_path} (exposure {sub.exposure:.6g})")
    else:
        table.add_row("exposure", f"{result.exposure:.6g} image units per camera value")
        table.add_row("dataset", str(result.dataset_path))
    if result.image_paths:
        folders = sorted({str(p.parent) for p in result.image_paths})
        table.add_row("images", f"{len(result.image_paths)} files in " + ", ".join(folders))
    if result.variants:
        table.add_row("figures", f"{len(result.figure_paths)} files, comparison: "
                      + (str(result.figure_paths[0]) if result.figure_paths else "none"))
        console.print(table)
        return
    for p in result.figure_paths:
        table.add_row("figure", str(p))
    console.print(table)


@app.command()
def version() -> None:
    """Print the pmdsim version."""
    from . import __version__

    _console().print(f"pmdsim {__version__}")


def main() -> None:  # pragma: no cover - console entry for `python -m pmdsim.cli`
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
