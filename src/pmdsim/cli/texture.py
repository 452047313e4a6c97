"""Machining and images to BRDF parameters: ``pmdsim texture`` and ``pmdsim fit``."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from .common import _console, _fail, _guard, _output_folder


def texture(
    feed_um: float | None = typer.Option(None, "--feed-um", help="Feed per revolution f, um."),
    nose_radius_mm: float | None = typer.Option(None, "--nose-radius-mm",
                                                help="Tool nose radius r, mm."),
    from_file: Path | None = typer.Option(
        None, "--from", help="A measured topography (X3P, .sur, .sdf, .al3d, ...; or .npy/.csv/"
        ".tif with --spacing-um): slope density, PSD, Sq, Sdq, correlation lengths, regime "
        "instead of the machining."),
    spacing_um: tuple[float, float] | None = typer.Option(
        None, "--spacing-um", help="Sample spacing dx dy (um) of a plain-array --from file."),
    height_unit: str = typer.Option("um", "--height-unit",
                                    help="Height unit of a plain-array --from file (mm, um, nm)."),
    radial_axis: str = typer.Option("y", "--radial-axis",
                                    help="Axis of the --from map across the turning grooves."),
    level: str = typer.Option("plane", "--level", help="Levelling of --from: none, mean, plane."),
    fill: str = typer.Option("nearest", "--fill",
                             help="Non-measured points of --from: error, nearest, mean."),
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
    from ..run.texture import run_texture

    import math

    _output_folder(output)
    if from_file is not None:
        return _texture_from(from_file, spacing_um, height_unit, radial_axis, level, fill,
                             wavelength_nm, incidence_deg, output, no_figure)
    if feed_um is None or nose_radius_mm is None:
        _fail("give --feed-um and --nose-radius-mm (the machining), or --from FILE (a measured "
              "topography)")
    if not (math.isfinite(incidence_deg) and 0 <= incidence_deg < 90):
        _fail(f"--incidence-deg must be at least 0 and below 90 deg (grazing incidence has no "
              f"reflection to measure), got {incidence_deg:g}")
    for name, value, low in (("--feed-um", feed_um, 0), ("--nose-radius-mm", nose_radius_mm, 0),
                             ("--wavelength-nm", wavelength_nm, 0),
                             ("--distance-mm", distance_mm, 0), ("--pitch-mm", pitch_mm, 0),
                             ("--correlation-um", correlation_um, 0)):
        if not (math.isfinite(value) and value > low):
            _fail(f"{name} must be a positive finite number, got {value:g}")
    if not (math.isfinite(rq_um) and rq_um >= 0):
        _fail(f"--rq-um must be a finite number >= 0, got {rq_um:g}")
    try:
        res = run_texture(output, figure=not no_figure, feed_um=feed_um,
                          nose_radius_mm=nose_radius_mm, rq_um=rq_um,
                          correlation_length_um=correlation_um, wavelength_nm=wavelength_nm,
                          incidence_deg=incidence_deg, distance_mm=distance_mm,
                          pixel_pitch_mm=pitch_mm)
    except ValueError as err:
        _fail(str(err))
    _print_report(res)


def _print_report(res) -> None:
    """The text table of ``pmdsim texture`` (either source) and the files it wrote."""
    console = _console()
    console.print(res.text, markup=False)
    if res.json is not None:
        console.print(f"table  {res.json}")
    if res.figure is not None:
        console.print(f"figure {res.figure}")


def _texture_from(path, spacing_um, height_unit, radial_axis, level, fill, wavelength_nm,
                  incidence_deg, output, no_figure) -> None:
    """``pmdsim texture --from FILE``: a measured topography's optical parameters."""
    import math

    from ..config import InputError
    from ..run.texture import run_topography

    if not (math.isfinite(wavelength_nm) and wavelength_nm > 0):
        _fail(f"--wavelength-nm must be a positive finite number, got {wavelength_nm:g}")
    if not (math.isfinite(incidence_deg) and 0 <= incidence_deg < 90):
        _fail(f"--incidence-deg must be at least 0 and below 90 deg, got {incidence_deg:g}")
    for name, value, allowed in (("--radial-axis", radial_axis, ("x", "y")),
                                 ("--level", level, ("none", "mean", "plane")),
                                 ("--fill", fill, ("error", "nearest", "mean")),
                                 ("--height-unit", height_unit, ("mm", "um", "nm"))):
        if value not in allowed:
            _fail(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
    spacing = None if spacing_um is None else (spacing_um[0] * 1e-3, spacing_um[1] * 1e-3)
    try:
        res = run_topography(path, output, figure=not no_figure, spacing_mm=spacing,
                             height_unit=height_unit, radial_axis=radial_axis, level=level,
                             fill=fill, wavelength_nm=wavelength_nm, incidence_deg=incidence_deg)
    except (InputError, ValueError) as err:
        _fail(str(err).replace("surface.file", "--from"))
    _print_report(res)


def fit(
    config: Path = typer.Argument(..., help="Run configuration (TOML) of the set-up and model; "
                                  "[patterns.fringes] describes the images."),
    images: list[Path] = typer.Argument(..., help="Fringe images, ordered direction, width, "
                                        "shift as [patterns.fringes] lists them."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for fit.json, fit.txt, "
                                "fit.png (created; an existing one only with --overwrite)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing fit folder."),
    max_chi2: float = typer.Option(2.0, "--max-chi2", min=1.0,
                                   help="Largest reduced chi-square (noise and model error) "
                                   "of a fit that counts as describing the images."),
    max_rays: int = typer.Option(6400, "--max-rays", min=1, max=10_000_000,
                                 help="Most rays per pixel when the fit refines its model (x4 "
                                 "steps from sampling.n_rays) to bound its numerical error."),
    no_figure: bool = typer.Option(False, "--no-figure", help="Do not draw the figure."),
    target_error_mrad: float | None = typer.Option(
        None, "--target-error-mrad",
        help="Raise the quadrature rule's order (n_rays) at the start values until the stated "
        "numerical phase error (P95 over pixels, every fringe) is below this "
        "(as [sampling] target_error_mrad); the fit starts from that order (reported in fit.json "
        "model.target), a target not met within sampling.max_rays is a warning."),
) -> None:
    """Images to parameters: fit alpha_x/alpha_y (tangential/radial) and a brightness scale
    of the configured BRDF to fringe images at several widths (closed-form start from the
    modulation, then least squares with the full simulator; docs/texture.md). A fit that
    did not converge or does not describe the images (reduced chi-square above --max-chi2)
    writes its files marked failed and exits 1; bad input exits 2."""
    from ..config import load_config
    from ..run.fit import check_fit_output, run_fit

    _output_folder(output)
    console = _console()
    with _guard():
        check_fit_output(output, overwrite)  # before reading or computing anything
        from ..config import with_target_error

        cfg = with_target_error(load_config(config), target_error_mrad)
        from ..config import check_resources

        check_resources(cfg)  # one simulation of the fit, before the first one runs
        t0 = time.perf_counter()
        try:
            with console.status(f"fitting {cfg.brdf.model} alphas to {len(images)} images"):
                res = run_fit(cfg, images, output, figure=not no_figure, overwrite=overwrite,
                              max_chi2=max_chi2, max_rays=max_rays)
        except (FileNotFoundError, ValueError) as err:
            _fail(str(err))
    console.print(f"pmdsim fit '{cfg.name}' ({time.perf_counter() - t0:.1f} s)")
    console.print(res.text, markup=False)
    console.print(f"table  {res.json}")
    if res.figure is not None:
        console.print(f"figure {res.figure}")
    for note in res.notes:
        _console(stderr=True).print(f"note: {note}", style="yellow", markup=False)
    if not res.result.success:
        _console(stderr=True).print(f"error: the fit failed: {res.result.reason} (files "
                                    f"written to {res.outdir}, marked failed)",
                                    style="bold red", markup=False)
        raise typer.Exit(1)
