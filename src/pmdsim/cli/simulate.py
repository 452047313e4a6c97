"""``pmdsim simulate``: a run folder from a configuration, and its summary tables."""

from __future__ import annotations

import contextlib
import gc
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

from .common import _guard, _console, _fail, _si


@contextlib.contextmanager
def _cluster(address: str | None):
    """A ``dask.distributed`` client of the scheduler at ``address`` (None: no client);
    a bad address or a missing package is bad input (exit 2)."""
    if address is None:
        yield None
        return
    from ..config import InputError

    if "://" not in address and not address.rsplit(":", 1)[-1].isdigit():
        raise InputError(f"--scheduler: {address!r} is not a Dask scheduler address; give "
                         "one such as tcp://host:8786 (the local scheduler is the "
                         "configuration's compute.scheduler)")
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: pip install "
                         "'pmdsim[distributed]'") from None
    try:
        client = Client(address, timeout="20s")
    except (OSError, TimeoutError) as err:
        raise InputError(f"--scheduler: no Dask scheduler answers at {address} ({err}); "
                         "start one (dask scheduler) or check the address") from None
    with client:
        yield client


def simulate(
    config: Path = typer.Argument(..., help="Run configuration (TOML), e.g. "
                                  "examples/paper_fig3.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Run folder to create."),
    overwrite: bool = typer.Option(False, "--overwrite",
                                   help="Replace an existing run folder."),
    no_figures: bool = typer.Option(False, "--no-figures",
                                    help="Do not draw the figures (faster)."),
    decode: bool | None = typer.Option(
        None, "--decode/--no-decode",
        help="Decode the fringes and compare them with the ideal specular reference "
        "(deviation maps, statistics). Default: the configuration's decode.enabled ('auto': "
        "whenever the fringe widths allow it). --decode makes it an error when they do not."),
    no_diagnostics: bool = typer.Option(
        False, "--no-diagnostics",
        help="Do not compute the run diagnostics (lobe energy inside theta_max, effective "
        "sample size, phase standard error) and their warnings."),
    scheduler: str | None = typer.Option(
        None, "--scheduler",
        help="Render the run's tiles on the Dask cluster at this scheduler address "
        "(tcp://host:8786; same results as a local run; needs pmdsim[distributed]). "
        "Default: the configuration's compute.scheduler, on this machine."),
    target_error_mrad: float | None = typer.Option(
        None, "--target-error-mrad",
        help="Raise the quadrature rule's order (n_rays) until the stated numerical phase "
        "error (P95 over pixels, every fringe) is below this (the same as [sampling] target_error_mrad); "
        "the order used is reported, a target not met within sampling.max_rays is a warning."),
) -> None:
    """Render the configured patterns and write a run folder (images, run.zarr, figures);
    by default also decode the fringes and measure their deviation from the ideal specular
    reference (statistics.json, summary.txt, deviation figures), and check the sampling
    (diagnostics: warnings, each naming the setting that fixes it; bounds in the
    configuration's diagnostics section)."""
    from ..store.folder_lock import OutputBusy, check_free

    try:  # a run already writing there: fail before the heavy imports (pydantic, NumPy)
        check_free(output)
    except OutputBusy as err:
        _fail(str(err))
    console = _console()
    with _guard():
        from ..config import load_config, with_target_error

        cfg = with_target_error(load_config(config), target_error_mrad)  # field-named errors
        from ..report.text import warning_text
        from ..run import run_simulation
        from ..store.folder import check_output_dir

        check_output_dir(output, overwrite)
    # the objects of the imports so far (modules, classes, the configuration) live as long
    # as this process: out of the garbage collector's way, which otherwise scans them
    # again in every full collection of the run (~3 % of its CPU time); and a young
    # generation of 20 000 objects instead of 700: the run's Python objects are few and
    # large (arrays), its cycles die young, and the matplotlib import in a thread
    # otherwise fills the old generation for four full collections (0.44 -> 0.15-0.21 s
    # of collection on Fig. 3, peak memory no higher)
    gc.freeze()
    gc.set_threshold(20_000, 20, 20)
    figures = False if no_figures else None
    t0 = time.perf_counter()
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn())
    with _guard():
        with Progress(*columns, console=console, transient=False) as bar:
            task = bar.add_task(f"simulating {cfg.name}", total=None)

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            with _cluster(scheduler) as client:
                result = run_simulation(cfg, output, progress, overwrite=overwrite,
                                        figures=figures, decode=decode,
                                        diagnostics=not no_diagnostics, client=client)
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
    chain_time = ""
    if "reference" in result.timings:
        chain_time = (f"specular reference {result.timings['reference']:.2f} s, decoding and "
                      f"deviation {result.timings.get('decode', 0.0):.2f} s, ")
    diag_time = ""
    if result.timings.get("diagnostics", 0.0) > 0.005:
        diag_time = f"diagnostics {result.timings['diagnostics']:.2f} s, "
    table.add_row("wall time", f"{wall:.2f} s (geometry {result.timings['geometry']:.2f} s, "
                  f"{chain_time}{diag_time}writing {result.timings['write']:.2f} s, "
                  f"figures {result.timings['figures']:.2f} s)")
    table.add_row("run folder", str(result.outdir))
    if result.sizes:
        from ..store.folder import size_text

        table.add_row("size", size_text(result.sizes).removeprefix("run folder: "))
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
    else:
        for p in result.figure_paths:
            table.add_row("figure", str(p))
    for label, text in _diagnostics_rows(result):
        table.add_row(label, text)
    console.print(table)
    _print_statistics(console, result)
    for sub in result.variants or (result,):
        for w in sub.warnings:  # diagnostics, each with the setting that fixes it
            prefix = f"{sub.config.name}: " if result.variants else ""
            text = warning_text(w.message, w.setting, w.suggested)
            _console(stderr=True).print(f"warning: {prefix}{text}", style="yellow",
                                        markup=False)
    for note in result.notes:
        _console(stderr=True).print(f"note: {note}", style="yellow", markup=False)


def _diagnostics_rows(result) -> list[tuple[str, str]]:
    """One summary-table row per run (variant) with diagnostics: lobe energy inside
    theta_max, effective sample size, largest P95 phase standard error."""
    rows = []
    members = result.variants or (result,)
    for sub in members:
        d = sub.statistics.get("diagnostics")
        if not d:
            continue
        parts = []
        e = d.get("energy", {})
        if e.get("fraction_median") is not None:
            parts.append(f"lobe energy inside theta_max {100 * e['fraction_median']:.1f} %")
        if d.get("ess_median") is not None:
            parts.append(f"effective sample size {d['ess_median']:.1f} of {d['n_rays']}")
        p95 = [v["p95"] for v in d.get("phase_se_rad", {}).values() if v["p95"] is not None]
        if p95:
            parts.append(f"phase std. error <= {1e3 * max(p95):.3g} mrad (P95, "
                         f"{d['phase_se_method']} method)")
        label = f"diagnostics {sub.config.name}" if result.variants else "diagnostics"
        rows.append((label, ", ".join(parts) + " (statistics.json)"))
    return rows


def _print_statistics(console: Console, result) -> None:
    """Deviation statistics per variant and direction (RMS and P95 over the valid pixels)."""
    per = result.statistics if result.variants else (
        {result.config.name: result.statistics} if result.statistics else {})
    per = {name: st for name, st in per.items() if "directions" in st}  # decoded ones
    if not per:
        return
    table = Table(title="deviation from the ideal specular reference (decoded mirror; "
                  "'vs exact P': of the monitor coordinate from the exact specular point); "
                  "each cell: RMS (upper) and P95 (lower) over the valid pixels, ± the "
                  "rendering's numerical error of that statistic where stated; all "
                  "statistics in statistics.json, summary.txt", title_justify="left",
                  show_lines=True)
    # fits 80 columns: two short lines per cell; the variant column only with variants
    named = bool(result.variants)
    if named:
        table.add_column("variant", justify="left", overflow="fold", min_width=8)
    for col in ("dir", "phase\nmrad", "monitor\npx", "vs exact\nP, px", "slope\nurad",
                "valid\n%"):
        table.add_column(col, justify="left" if col == "dir" else "right", no_wrap=True)

    def pair(s, e=None):
        if not s or s["rms"] is None:
            return "nan"
        if not e or e.get("rms") is None:
            return f"{s['rms']:.3g}\n{s['p95']:.3g}"
        return f"{s['rms']:.3g} ± {e['rms']:.1g}\n{s['p95']:.3g} ± {e['p95']:.1g}"

    for name, st in per.items():
        for d, s in st["directions"].items():
            ne = s.get("numerical_error") or {}
            cells = (d.upper(), pair(s["phase_mrad"], ne.get("phase_mrad")),
                     pair(s["coord_px"], ne.get("coord_px")),
                     pair(s.get("coord_vs_exact_px")), pair(s["slope_urad"], ne.get("slope_urad")),
                     f"{100 * s['coord_px']['valid_fraction']:.1f}")
            table.add_row(*((name,) + cells if named else cells))
    console.print(table)
    from ..report.text import numerical_warnings

    for name, st in per.items():
        for w in numerical_warnings(st):
            console.print(f"[yellow]warning: {(name + ': ') if named else ''}{w}[/yellow]")
