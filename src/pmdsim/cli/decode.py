"""``pmdsim decode``: camera images (real or simulated) to phase, monitor coordinate and flags."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from .common import _guard, _console


def decode(
    images: list[Path] = typer.Argument(
        ..., help="Fringe images (TIFF/PNG, single-channel; multi-page TIFFs add all their "
        "pages) in the order WIDTH-MAJOR, THEN SHIFT: the K shifts of the first width, then "
        "the K of the second, ...; frame j*K + k (0-based) shows the j-th width with shift 2 pi k / "
        "K, i.e. 0.5 + 0.5 cos(2 pi u / width + 2 pi k / K)."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder to create."),
    widths: str | None = typer.Option(
        None, "--widths", help="Fringe widths (periods) in monitor px, comma-separated, in "
        "frame order, e.g. 50,400,3200."),
    shifts: int | None = typer.Option(None, "--shifts", help="Number K >= 3 of equal phase "
                                      "shifts per width."),
    direction: str = typer.Option("x", "--direction", help="x: phase along monitor columns "
                                  "u (vertical fringe lines); y: along rows v."),
    extent_px: float | None = typer.Option(None, "--extent-px", help="Monitor extent along "
                                           "the direction, monitor px (width for x, height "
                                           "for y)."),
    method: str | None = typer.Option(None, "--method", help="Unwrapping: hierarchical "
                                      "(default), heterodyne or number_theoretic."),
    pitch_mm: float | None = typer.Option(None, "--pitch-mm", help="Monitor pixel pitch, mm "
                                          "(adds monitor coordinates in mm)."),
    from_run: Path | None = typer.Option(
        None, "--from-run", help="A simulation's run folder: widths (ascending, the order of "
        "its file names, so RUN/fringes/x_*.tif in shell order is right), shifts, extent, "
        "pitch and method are read from it; options given here win."),
    variant: str | None = typer.Option(None, "--variant", help="With --from-run on a run "
                                       "with variants: the variant the images belong to (for "
                                       "the comparison; inferred from the image paths)."),
    min_relative_amplitude: float = typer.Option(0.1, "--min-relative-amplitude",
                                                 help="Flag pixels whose fringe amplitude is "
                                                 "below this fraction of the median."),
    max_order_residual: float = typer.Option(0.25, "--max-order-residual",
                                             help="Flag pixels whose fringe-order residual "
                                             "exceeds this (0 < r <= 0.5)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output."),
    no_figures: bool = typer.Option(False, "--no-figures", help="Do not draw the maps."),
) -> None:
    """Decode phase-shifted fringe images (real camera images or a simulation's) to absolute
    phase, monitor coordinate, modulation and reliability flags; writes OUT/decode.zarr,
    statistics.json and PNG maps."""
    import math

    console = _console()
    with _guard():
        from ..config import InputError
        from ..run.decode_run import decode_files, make_setup

        # the options first, before any image is read
        if not (math.isfinite(max_order_residual) and 0 < max_order_residual <= 0.5):
            raise InputError(f"--max-order-residual must lie in (0, 0.5] (0.5 = ambiguous "
                             f"order), got {max_order_residual:g}")
        if not (math.isfinite(min_relative_amplitude) and min_relative_amplitude >= 0):
            raise InputError(f"--min-relative-amplitude must be a finite number >= 0, got "
                             f"{min_relative_amplitude:g}")
        if output.exists() and not output.is_dir():
            raise InputError(f"-o {output}: exists and is a file, not a folder; choose "
                             "another -o")
        width_list = None
        if widths is not None:
            try:
                width_list = [float(x) for x in widths.replace(" ", "").split(",") if x]
            except ValueError:
                raise InputError(f"--widths must be comma-separated numbers (monitor px), "
                                 f"got {widths!r}") from None
        setup = make_setup(widths=width_list, shifts=shifts, direction=direction,
                           extent_px=extent_px, method=method, pitch_mm=pitch_mm,
                           from_run=from_run)
        result = decode_files(images, output, setup,
                              min_relative_amplitude=min_relative_amplitude,
                              max_order_residual=max_order_residual, overwrite=overwrite,
                              figures=not no_figures, from_run=from_run, variant=variant)
    st = result.statistics
    table = Table(title=f"pmdsim decode ({setup.direction.upper()}, {setup.method})",
                  show_header=False, title_justify="left")
    table.add_column("", style="bold", no_wrap=True)
    table.add_column("", overflow="fold")
    table.add_row("frames", f"{len(setup.widths_px)} widths {list(setup.widths_px)} x "
                  f"K = {setup.shifts} ({setup.source})")
    table.add_row("valid pixels", f"{st['valid']:,} of {st['pixels']:,} "
                  f"({100 * st['valid_fraction']:.2f} %)")
    table.add_row("flags", ", ".join(f"{k} {v:,}" for k, v in st["flag_counts"].items()))
    if "compared_with_run" in st:
        c = st["compared_with_run"]
        table.add_row("vs the run's decoding", f"RMS {c['rms']:.3g} px, max {c['max']:.3g} px "
                      f"({c['n_valid']:,} px)")
    table.add_row("decode time", f"{result.seconds['decode']:.3f} s")
    table.add_row("output", str(result.outdir))
    console.print(table)
