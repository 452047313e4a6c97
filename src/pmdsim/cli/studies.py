"""The studies' commands: ``pmdsim converge`` (sampling against a reference of stated error),
``pmdsim budget`` (the error budget) and ``pmdsim sweep`` (a parameter study)."""

from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from .common import _guard, _console, _fail, _numbers, _output_folder


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
    (paper, weighted_mean, radiometric) against a reference (radiometric, largest N) that
    states its own numerical error: a row whose difference is within it says "not
    resolved", a fringe where the reference is not converged is named; writes
    OUT/convergence.csv, convergence.png, convergence.json and warns about the configured
    settings (lobe energy outside theta_max, phase standard error, effective sample size)."""
    import math

    from ..config import load_config
    from ..run.convergence import run_convergence
    from ..studies.convergence import DEFAULT_N, DEFAULT_THETA_DEG

    from ..config import InputError

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
        if not (0 < cw <= 65536 and 0 < ch <= 65536):
            raise InputError(f"--camera must be WxH with 1 to 65536 px per axis, e.g. 160x128, "
                             f"got {camera!r}")
        from ..config.resources import check_study, convergence_configs

        # the study's renders, one after the other: the largest must fit, all the CPU limit
        check_study(convergence_configs(cfg, ns, thetas, ests, (cw, ch)), "converge")
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
                "vs reference ± its error (mrad)", "modulation"):
        table.add_column(col, justify="right" if col not in ("estimator", "fringe") else "left")
    picks = [r for r in rows
             if (r["estimator"] == "paper" and r["n_rays"] == cfg.sampling.n_rays
                 and math.isclose(r["theta_max_deg"], cfg.sampling.theta_max_deg))
             or (r["estimator"] == "radiometric" and r["n_rays"] in (cfg.sampling.n_rays, n_max))]
    for r in picks:
        th = "" if math.isnan(r["theta_max_deg"]) else f"{r['theta_max_deg']:g} deg"
        is_ref = r["estimator"] == "radiometric" and r["n_rays"] == n_max
        table.add_row(r["estimator"], th, str(r["n_rays"]) + (" (ref.)" if is_ref else ""),
                      f"{r['direction']} {r['width_px']:g} px",
                      _with_error(r["phase_rms_rad"], r["phase_error_rms_rad"]),
                      ("reference ± " + _mrad(r["reference_error_rms_rad"])) if is_ref
                      else _vs_reference(r),
                      f"{r['modulation_median']:.3f}")
    if not console.is_terminal:  # a pipe or a file: Rich's 80 columns would wrap every cell
        from rich.console import Console

        console = Console(width=max(console.width, 132), soft_wrap=True, highlight=False)
    console.print(table)
    ref = result.reference or {}
    stale = [f"{f['direction']} {f['width_px']:g} px ({_mrad(f['error_rms_rad'])} mrad)"
             for f in ref.get("fringes", []) if not f["converged"]]
    console.print(f"reference: {ref.get('run')}, every row states its numerical error (the "
                  "rule's own statement, RMS over the pixels); 'not resolved': the difference "
                  "is within the reference's error", markup=False)
    if stale:
        _console(stderr=True).print(
            "warning: the reference is NOT converged for " + ", ".join(stale) + ": its stated "
            "numerical error exceeds "
            f"{1e3 * ref.get('converged_below_rad', float('nan')):g} mrad, so differences "
            "from it are not the sampling error of the other rows there; raise --n-values",
            style="yellow", markup=False)
    console.print(f"table  {result.table}")
    if result.figure is not None:
        console.print(f"figure {result.figure}")
    for w in result.warnings:
        _console(stderr=True).print(f"warning: {w.message}", style="yellow", markup=False)
    for note in result.notes:
        _console(stderr=True).print(f"note: {note}", style="yellow", markup=False)


def _mrad(rad) -> str:
    """A phase in mrad (3 significant digits); "unknown" without a value."""
    if rad is None or rad != rad:
        return "unknown"
    return "> pi" if rad == float("inf") else f"{1e3 * rad:.3g}"


def _with_error(value: float, err: float) -> str:
    return f"{1e3 * value:.3g}" + ("" if err != err else f" ± {_mrad(err)}")


def _vs_reference(r: dict) -> str:
    """The row's difference from the reference, or why it is not a number."""
    ref = _mrad(r["reference_error_rms_rad"])
    if not r["resolved"]:
        return f"not resolved (± {ref})"
    return f"{1e3 * r['phase_rms_vs_reference_rad']:.3g} ± {ref}"


def budget(
    config: Path = typer.Argument(..., help="Run configuration (TOML), e.g. "
                                  "examples/realistic_system.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder to create."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
    truth: str = typer.Option("centre", "--truth", help="Ground truth of the system rows: "
                              "'centre' (the chief ray through each pixel centre) or "
                              "'footprint' (averaged over the pixel's vision rays)."),
    target_error_mrad: float | None = typer.Option(
        None, "--target-error-mrad",
        help="Raise the quadrature rule's order (n_rays) until the stated numerical phase "
        "error (P95 over pixels, every fringe) is below this (the same as [sampling] target_error_mrad); "
        "the order used is reported, a target not met within sampling.max_rays is a warning."),
) -> None:
    """Error budget: the chain with each system effect of CONFIG alone and all together on
    the ideal mirror, the surface's scattering minus that mirror, and the calibration
    errors (sensitivity x uncertainty); per effect the reconstructed slope error (urad X/Y)
    and height error (nm RMS/PV/P95 after [budget] removal), per direction the deviation from
    the exact reflection points in mrad, monitor px, mm and urad. Writes OUT/budget.csv,
    heights.csv, zernike.csv, budget.json, budget.png (docs/system.md). Every row is
    "value ± numerical error"; the surface is rendered with the radiometric estimator unless
    CONFIG names one."""
    console = _console()
    with _guard():  # Ctrl-C: one line, exit 130 (the run's temporary folder is removed)
        _budget(console, config, output, no_figure, overwrite, truth, target_error_mrad)


def _budget(console, config, output, no_figure, overwrite, truth, target_error_mrad) -> None:
    from ..config import ConfigError, load_config, physical_estimator, with_target_error
    from ..report.budget import budget_text
    from ..run.budget import run_budget

    try:
        cfg = with_target_error(physical_estimator(load_config(config)), target_error_mrad)
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
    for note in result.notes:
        _console(stderr=True).print(f"note: {note}", style="yellow", markup=False)


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
    target_error_mrad: float | None = typer.Option(
        None, "--target-error-mrad",
        help="Raise the quadrature rule's order (n_rays) until the stated numerical phase "
        "error (P95 over pixels, every fringe) is below this (the same as [sampling] target_error_mrad); "
        "the order used is reported, a target not met within sampling.max_rays is a warning."),
) -> None:
    """Run the measurement chain at every point of the configuration's [sweep] (grid, zip or
    random design over any configuration fields) into one Zarr store with a dimension per
    swept field; resumes an interrupted sweep with only its unfinished points. See
    docs/sweeps.md."""
    from ..store.folder_lock import OutputBusy, check_free

    try:  # a sweep already writing there: fail before the heavy imports and the planning
        check_free(output)
    except OutputBusy as err:
        _fail(str(err))
    _output_folder(output)
    from ..config import ConfigError, load_config, physical_estimator, with_target_error
    from ..run.sweep import run_sweep
    from ..studies.sweep import plan_sweep

    console = _console()
    try:
        cfg = with_target_error(physical_estimator(load_config(config)), target_error_mrad)
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
    for note in result.notes:
        _console(stderr=True).print(f"note: {note}", style="yellow", markup=False)
    console.print(f"computed {len(result.computed)} points, {len(result.skipped)} were already "
                  f"done, in {result.seconds:.1f} s")
    console.print(f"store: {result.store}")
    for f in result.files:
        console.print(f"wrote {f}")
    if result.empty:  # a point without a valid pixel is not a result (unless asked for)
        _console(stderr=True).print(
            "error: " + "; ".join(result.empty) + f" (their statistics are NaN in "
            f"{result.store} and points.csv; run such a point alone with pmdsim simulate to "
            "see which stage removed the pixels, or set diagnostics.allow_no_valid_pixels = "
            "true to accept them)", style="bold red", markup=False)
        raise typer.Exit(1)
