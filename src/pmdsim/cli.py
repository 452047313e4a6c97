"""The ``pmdsim`` command line (Typer + Rich).

    pmdsim simulate CONFIG -o OUTDIR [--overwrite] [--no-figures] [--decode/--no-decode]
                                     [--no-diagnostics]
    pmdsim decode IMAGES... -o OUT (--widths W1,W2,.. --shifts K --extent-px E | --from-run RUN)
    pmdsim converge CONFIG -o OUTDIR [--n-values 25,50,..] [--theta 0.5,1,..] [--camera 160x128]
    pmdsim sweep CONFIG -o OUTDIR [--scheduler threads|processes|synchronous|tcp://..]
                                  [--workers N] [--overwrite] [--no-figures]
    pmdsim report RUN [--all | --figure NAME ...] [--variant NAME] [-o FOLDER]
    pmdsim texture --feed-um F --nose-radius-mm R [--rq-um Q --correlation-um L] [-o OUT]
    pmdsim fit CONFIG IMAGES... -o OUT
    pmdsim warmup
    pmdsim version
    pmdsim --help

Bad input (an invalid configuration or set-up, a missing or unreadable input file, an
existing or busy output folder) prints one red message and exits with code 2, without a
traceback. Anything else is a bug: Python's traceback and exit code 1. Ctrl-C (SIGINT) and
SIGTERM stop a run, remove its temporary folder and exit with 130 / 143.
"""

from __future__ import annotations

import contextlib
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
    rich_markup_mode="markdown",  # docstring lines join into paragraphs
)

#: Exit code for bad input (configuration, files, output folder).
EXIT_BAD_INPUT = 2
#: Exit codes of a run stopped by SIGINT (Ctrl-C) / SIGTERM (128 + signal number).
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


def _bad_input() -> tuple[type[BaseException], ...]:
    """The exceptions that mean bad input (exit code 2): everything else is a bug."""
    from .config import ConfigError, InputError

    return (ConfigError, InputError, FileExistsError, PermissionError, NotADirectoryError,
            IsADirectoryError)


@contextlib.contextmanager
def _guard():
    """Bad input -> one red line, exit 2; SIGINT/SIGTERM -> a note, exit 130/143 (the run's
    temporary folder is already removed); anything else propagates (traceback, exit 1)."""
    from .run.claim import Terminated

    try:
        yield
    except _bad_input() as err:
        _fail(str(err))
    except KeyboardInterrupt as err:
        term = isinstance(err, Terminated)
        _console(stderr=True).print(
            f"{'terminated' if term else 'interrupted'}: stopped; nothing was written "
            "(the temporary folder was removed)", style="bold red", markup=False)
        raise typer.Exit(EXIT_TERMINATED if term else EXIT_INTERRUPTED) from None


def _version_callback(value: bool) -> None:
    if value:
        from ._version import __version__

        _console().print(f"pmdsim {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version_callback,
                                 is_eager=True, help="Print the pmdsim version and exit."),
) -> None:
    """Simulate Phase Measuring Deflectometry (PMD) of scattering surfaces by reverse ray
    tracing with a BRDF-weighted ray bundle per camera pixel."""


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
    decode: bool | None = typer.Option(
        None, "--decode/--no-decode",
        help="Decode the fringes and compare them with the ideal specular reference "
        "(deviation maps, statistics). Default: the configuration's decode.enabled ('auto': "
        "whenever the fringe widths allow it). --decode makes it an error when they do not."),
    no_diagnostics: bool = typer.Option(
        False, "--no-diagnostics",
        help="Do not compute the run diagnostics (lobe energy inside theta_max, effective "
        "sample size, phase standard error) and their warnings."),
) -> None:
    """Render the configured patterns and write a run folder (images, run.zarr, figures);
    by default also decode the fringes and measure their deviation from the ideal specular
    reference (statistics.json, summary.txt, deviation figures), and check the sampling
    (diagnostics: warnings, each naming the setting that fixes it; bounds in the
    configuration's diagnostics section)."""
    from .run.claim import OutputBusy, check_free

    try:  # a run already writing there: fail before the heavy imports (pydantic, NumPy)
        check_free(output)
    except OutputBusy as err:
        _fail(str(err))
    from .config import load_config

    console = _console()
    with _guard():
        cfg = load_config(config)
        from .report.text import warning_text
        from .run import run_simulation
        from .run.files import check_output_dir

        check_output_dir(output, overwrite)
    figures = False if no_figures else None
    t0 = time.perf_counter()
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn())
    with _guard():
        with Progress(*columns, console=console, transient=False) as bar:
            task = bar.add_task(f"simulating {cfg.name}", total=None)

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            result = run_simulation(cfg, output, progress, overwrite=overwrite,
                                    figures=figures, decode=decode,
                                    diagnostics=not no_diagnostics)
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
        from .run.files import size_text

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
                  "each cell: RMS (upper) and P95 (lower) over the valid pixels; all "
                  "statistics in statistics.json, summary.txt", title_justify="left",
                  show_lines=True)
    # fits 80 columns: two short lines per cell; the variant column only with variants
    named = bool(result.variants)
    if named:
        table.add_column("variant", justify="left", overflow="fold", min_width=8)
    for col in ("dir", "phase\nmrad", "monitor\npx", "vs exact\nP, px", "slope\nurad",
                "valid\n%"):
        table.add_column(col, justify="left" if col == "dir" else "right", no_wrap=True)

    def pair(s):
        return "nan" if not s or s["rms"] is None else f"{s['rms']:.3g}\n{s['p95']:.3g}"

    for name, st in per.items():
        for d, s in st["directions"].items():
            cells = (d.upper(), pair(s["phase_mrad"]), pair(s["coord_px"]),
                     pair(s.get("coord_vs_exact_px")), pair(s["slope_urad"]),
                     f"{100 * s['coord_px']['valid_fraction']:.1f}")
            table.add_row(*((name,) + cells if named else cells))
    console.print(table)


@app.command()
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
    from .run.decode_run import decode_files, make_setup

    from .config import InputError

    console = _console()
    with _guard():
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


def _numbers(text: str | None, name: str, kind=float) -> list | None:
    if text is None:
        return None
    try:
        return [kind(x) for x in text.replace(" ", "").split(",") if x]
    except ValueError:
        from .config import InputError

        raise InputError(f"{name} must be comma-separated numbers, got {text!r}") from None


@app.command()
def converge(
    config: Path = typer.Argument(..., help="Run configuration (TOML), e.g. "
                                  "examples/paper_fig3.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder to create."),
    n_values: str | None = typer.Option(None, "--n-values", help="Rays per pixel to try, "
                                        "comma-separated (default 25,50,100,200,400,800,1600; "
                                        "the config's N is added)."),
    theta: str | None = typer.Option(None, "--theta", help="Cone half angles (deg) for the "
                                     "cone estimators (default 0.5,1,2,4,8; the config's is "
                                     "added)."),
    estimators: str = typer.Option("paper,weighted_mean,radiometric", "--estimators",
                                   help="Estimators to compare, comma-separated."),
    camera: str = typer.Option("160x128", "--camera", help="Reduced camera size WxH, px "
                               "(same field of view)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
    no_diagnostics: bool = typer.Option(False, "--no-diagnostics",
                                        help="Do not check the configured settings."),
) -> None:
    """Study the decoded phase deviation and modulation versus N, theta_max and estimator
    (paper, weighted_mean, radiometric) against the converged answer; writes
    OUT/convergence.csv, convergence.png, convergence.json and warns about the configured
    settings (lobe energy outside theta_max, phase standard error, effective sample size)."""
    import math

    from .config import ConfigError, load_config
    from .run.convergence import run_convergence
    from .studies.convergence import DEFAULT_N, DEFAULT_THETA_DEG

    from .config import InputError

    console = _console()
    with _guard():
        cfg = load_config(config)
        ns = _numbers(n_values, "--n-values", int) or DEFAULT_N
        thetas = _numbers(theta, "--theta") or DEFAULT_THETA_DEG
        ests = tuple(e for e in estimators.replace(" ", "").split(",") if e)
        try:
            cw, ch = (int(x) for x in camera.lower().split("x"))
        except ValueError:
            raise InputError(f"--camera must be WxH in px, e.g. 160x128, got {camera!r}") from None
        t0 = time.perf_counter()
        with console.status(f"convergence study of {cfg.name}") as status:
            result = run_convergence(
                cfg, output, n_values=ns, theta_values=thetas, estimators=ests,
                camera_size=(cw, ch), figure=not no_figure, overwrite=overwrite,
                progress=lambda msg: status.update(f"convergence study of {cfg.name}: {msg}"),
                diagnostics=not no_diagnostics)
    wall = time.perf_counter() - t0

    rows = result.rows
    n_max = max(r["n_rays"] for r in rows)
    table = Table(title=f"pmdsim converge '{cfg.name}' ({wall:.1f} s)", title_justify="left")
    for col in ("estimator", "theta_max", "N", "fringe", "phase RMS vs mirror (mrad)",
                "vs converged (mrad)", "modulation"):
        table.add_column(col, justify="right" if col not in ("estimator", "fringe") else "left")
    picks = [r for r in rows
             if (r["estimator"] == "paper" and r["n_rays"] == cfg.sampling.n_rays
                 and math.isclose(r["theta_max_deg"], cfg.sampling.theta_max_deg))
             or (r["estimator"] == "radiometric" and r["n_rays"] in (cfg.sampling.n_rays, n_max))]
    for r in picks:
        th = "" if math.isnan(r["theta_max_deg"]) else f"{r['theta_max_deg']:g} deg"
        table.add_row(r["estimator"], th, str(r["n_rays"]), f"{r['direction']} {r['width_px']:g} px",
                      f"{1e3 * r['phase_rms_rad']:.3g}",
                      f"{1e3 * r['phase_rms_vs_converged_rad']:.3g}",
                      f"{r['modulation_median']:.3f}")
    console.print(table)
    console.print(f"table  {result.table}")
    if result.figure is not None:
        console.print(f"figure {result.figure}")
    for w in result.warnings:
        _console(stderr=True).print(f"warning: {w.message}", style="yellow", markup=False)


@app.command()
def budget(
    config: Path = typer.Argument(..., help="Run configuration (TOML), e.g. "
                                  "examples/realistic_system.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder to create."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
    truth: str = typer.Option("centre", "--truth", help="Ground truth of the system rows: "
                              "'centre' (the chief ray through each pixel centre) or "
                              "'footprint' (averaged over the pixel's vision rays)."),
) -> None:
    """Error budget: the chain with each system effect of CONFIG alone and all together on
    the ideal mirror, and the surface's scattering minus that mirror; deviation from the
    exact reflection points in mrad, monitor px, mm and urad. Writes OUT/budget.csv,
    budget.json, budget.png (docs/system.md)."""
    from .config import ConfigError, load_config
    from .report.budget import budget_text
    from .run.budget import run_budget

    console = _console()
    try:
        cfg = load_config(config)
        t0 = time.perf_counter()
        with console.status(f"error budget of {cfg.name}") as status:
            result = run_budget(cfg, output, figure=not no_figure, overwrite=overwrite,
                                progress=lambda msg: status.update(f"error budget of {cfg.name}: {msg}"),
                                truth=truth)
    except (ConfigError, FileNotFoundError, FileExistsError, PermissionError,
            NotADirectoryError, ValueError) as err:
        _fail(str(err))
    what = "centre ray" if truth == "centre" else "vision rays (footprint average)"
    console.print(f"pmdsim budget '{cfg.name}' ({time.perf_counter() - t0:.1f} s); deviation from "
                  f"the exact reflection point of each pixel's {what}")
    console.print(budget_text(result.rows, result.height_rows, result.settings), markup=False)
    console.print(f"table  {result.table}")
    if result.figure is not None:
        console.print(f"figure {result.figure}")


@app.command()
def texture(
    feed_um: float = typer.Option(..., "--feed-um", help="Feed per revolution f, um."),
    nose_radius_mm: float = typer.Option(..., "--nose-radius-mm", help="Tool nose radius r, mm."),
    rq_um: float = typer.Option(0.0, "--rq-um", help="Random roughness Rq, um."),
    correlation_um: float = typer.Option(10.0, "--correlation-um",
                                         help="Correlation length of the random roughness, um."),
    wavelength_nm: float = typer.Option(545.0, "--wavelength-nm", help="Wavelength, nm."),
    incidence_deg: float = typer.Option(0.0, "--incidence-deg", help="Angle of incidence, deg."),
    distance_mm: float = typer.Option(600.0, "--distance-mm",
                                      help="Surface-to-monitor distance d, mm."),
    pitch_mm: float = typer.Option(0.25, "--pitch-mm", help="Monitor pixel pitch, mm."),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="Folder for texture.json, texture.txt, texture.png."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
) -> None:
    """Machining to parameters: slope statistics, equivalent Ward/Beckmann alphas, specular
    share, grating order spacing on the monitor and the regime of a diamond-turned surface
    (docs/texture.md)."""
    from .run.texture import run_texture

    try:
        res = run_texture(output, figure=not no_figure, feed_um=feed_um,
                          nose_radius_mm=nose_radius_mm, rq_um=rq_um,
                          correlation_length_um=correlation_um, wavelength_nm=wavelength_nm,
                          incidence_deg=incidence_deg, distance_mm=distance_mm,
                          pixel_pitch_mm=pitch_mm)
    except ValueError as err:
        _fail(str(err))
    console = _console()
    console.print(res.text, markup=False)
    if res.json is not None:
        console.print(f"table  {res.json}")
    if res.figure is not None:
        console.print(f"figure {res.figure}")


@app.command()
def fit(
    config: Path = typer.Argument(..., help="Run configuration (TOML) of the set-up and model; "
                                  "[patterns.fringes] describes the images."),
    images: list[Path] = typer.Argument(..., help="Fringe images, ordered direction, width, "
                                        "shift as [patterns.fringes] lists them."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for fit.json, fit.txt, fit.png."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
) -> None:
    """Images to parameters: fit alpha_x/alpha_y (tangential/radial) and a brightness scale
    of the configured BRDF to fringe images at several widths (closed-form start from the
    modulation, then least squares with the full simulator; docs/texture.md)."""
    from .config import ConfigError, load_config
    from .run.texture import run_fit

    console = _console()
    try:
        cfg = load_config(config)
        t0 = time.perf_counter()
        with console.status(f"fitting {cfg.brdf.model} alphas to {len(images)} images"):
            res = run_fit(cfg, images, output, figure=not no_figure)
    except (ConfigError, FileNotFoundError, ValueError) as err:
        _fail(str(err))
    console.print(f"pmdsim fit '{cfg.name}' ({time.perf_counter() - t0:.1f} s)")
    console.print(res.text, markup=False)
    console.print(f"table  {res.json}")
    if res.figure is not None:
        console.print(f"figure {res.figure}")


@app.command()
def version() -> None:
    """Print the pmdsim version."""
    from ._version import __version__

    _console().print(f"pmdsim {__version__}")


def main() -> None:  # pragma: no cover - console entry for `python -m pmdsim.cli`
    app()


@app.command()
def sweep(
    config: Path = typer.Argument(..., help="Configuration with a [sweep] table, e.g. "
                                  "examples/sweep_roughness.toml."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Sweep folder (sweep.zarr, points.csv, figures/); an "
                                "existing folder of the same sweep is resumed."),
    scheduler: str = typer.Option(
        "threads", "--scheduler",
        help="threads (local thread pool), processes (local dask.distributed cluster), "
        "synchronous, or the address of a running Dask scheduler (tcp://host:8786)."),
    workers: int | None = typer.Option(None, "--workers", min=1,
                                       help="Threads or processes of a local scheduler "
                                       "(default: all cores)."),
    overwrite: bool = typer.Option(False, "--overwrite",
                                   help="Start again when OUTDIR holds a different sweep."),
    no_figures: bool = typer.Option(False, "--no-figures", help="Do not draw the figures."),
) -> None:
    """Run the measurement chain at every point of the configuration's [sweep] (grid, zip or
    random design over any configuration fields) into one Zarr store with a dimension per
    swept field; resumes an interrupted sweep with only its unfinished points. See
    docs/sweeps.md."""
    from .config import ConfigError, load_config
    from .run.sweep import run_sweep
    from .studies.sweep import plan_sweep

    console = _console()
    try:
        cfg = load_config(config)
        plan = plan_sweep(cfg)
    except (ConfigError, FileNotFoundError, ValueError) as err:
        _fail(str(err))
    shape = " x ".join(f"{n} {d}" for n, d in zip(plan.shape, plan.dims))
    console.print(f"sweep '{cfg.name}': {len(plan.points)} points ({plan.sweep.design}: "
                  f"{shape}) on {scheduler}")
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn())
    try:
        with Progress(*columns, console=console, transient=False) as bar:
            task = bar.add_task("points", total=None)

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            result = run_sweep(cfg, output, scheduler=scheduler, num_workers=workers,
                               progress=progress, overwrite=overwrite,
                               figures=not no_figures)
    except (ConfigError, FileNotFoundError, FileExistsError, PermissionError,
            NotADirectoryError, ValueError) as err:
        _fail(str(err))
    console.print(f"computed {len(result.computed)} points, {len(result.skipped)} were already "
                  f"done, in {result.seconds:.1f} s")
    console.print(f"store: {result.store}")
    for f in result.files:
        console.print(f"wrote {f}")


@app.command()
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
                                       "(default: RUN/figures, or RUN/<variant>/figures)."),
    workers: int | None = typer.Option(None, "--workers", min=1, help="Drawing processes "
                                       "(default: one per core for 4 figures or more)."),
) -> None:
    """Draw a run's figures again from its folder's dataset alone (run.zarr with its
    configuration): any of them, all of them, into the run or another folder."""
    from .config import RunConfig
    from .report.text import description
    from .run.dataset import DATASET_NAME
    from .run.figures import draw_figures, figure_names

    console = _console()
    run = Path(run)
    if (run / DATASET_NAME).is_dir():
        members = [run]
    else:
        members = sorted(p.parent for p in run.glob(f"*/{DATASET_NAME}"))
        if variant is not None:
            members = [m for m in members if m.name == variant]
    if not members:
        _fail(f"{run}: no {DATASET_NAME} here" + (f" for variant {variant!r}" if variant else "")
              + " (give a run folder written by pmdsim simulate)")
    from .run.figures import open_dataset

    which = figure or ("all" if all_figures else "summary")
    t0 = time.perf_counter()
    for folder in members:
        ds = open_dataset(folder)
        cfg = RunConfig.model_validate_json(ds.attrs["config_json"])
        try:
            names = figure_names(ds, which)
        except ValueError as err:
            _fail(str(err))
        dest = output / folder.name if output is not None and len(members) > 1 else output
        for p in draw_figures(folder, names, cfg.name, description(cfg), workers=workers,
                              folder=dest):
            console.print(f"wrote {p}")
    console.print(f"in {time.perf_counter() - t0:.1f} s")


@app.command()
def warmup() -> None:
    """Compile every kernel once into Numba's on-disk cache (run once after installing, so
    that the first simulation does not pay for compilation); tiny runs that reach every kernel, about a minute on 2 cores."""
    from .run.warmup import CASES, warmup as run_warmup

    console = _console()
    t0 = time.perf_counter()
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn())
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task("compiling kernels", total=len(CASES))
        run_warmup(lambda done, total: bar.update(task, completed=done))
    console.print(f"kernels compiled and cached in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":  # pragma: no cover
    main()
