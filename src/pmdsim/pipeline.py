"""From a configuration to a complete, self-describing run folder.

:func:`run_simulation` builds the :class:`~pmdsim.render.Simulation` of a
:class:`~pmdsim.config.RunConfig`, traces the vision rays (:meth:`Simulation.geometry`),
renders every configured pattern (all fringe widths, directions and shifts in one pass;
dots; monitor images) and writes, atomically (see :func:`pmdsim.io.atomic_run_dir`)::

    <outdir>/
      pmdsim-run.json            manifest: files, exposure, timings (written last)
      config.json                the full resolved configuration
      run.zarr/                  the xarray Dataset (see below)
      fringes/x_w0050_k0.tif     direction, width (period, monitor px), shift index
      dots/dot000_u0060_v0060.tif
      images/00_<file stem>.tif
      figures/setup.png, fringes.png, modulation.png
      statistics.json, summary.txt   the measurement chain (below), when fringes are decoded,
                                     and the run diagnostics (below), when the BRDF has a lobe
      figures/overview.png, phase.png, deviation.png, histograms.png,
              modulation_ratio.png, masks.png
      dots.csv, figures/dot_contact_sheet.png, dot_shapes.png   (with dots)

The measurement chain (``decode.enabled``, default ``"auto"``): the fringe images of the
surface and of its ideal specular reference (rendered once per run, shared by the variants)
are decoded and compared (:mod:`pmdsim.chain`); the decoded phases, monitor coordinates,
modulation, flags, the deviation maps, masks and statistics go into the dataset, and
``statistics.json``/``summary.txt`` beside it. Dot images get their second moments
(``dots.csv`` and ``dot_*`` variables). See ``docs/outputs.md``.

Run diagnostics (``diagnostics=True``, default; not for the mirror): on the coarse camera-pixel
grid of ``[diagnostics]`` (:mod:`pmdsim.diagnostics`) the fraction of the lobe's energy inside
``theta_max`` (cone estimators), the effective sample size of the weights and, with fringes,
the standard error of the phase of every fringe (``[diagnostics] phase_method``) (one pass over the grid pixels'
rays); the maps go into the dataset (``diag_*`` on ``diag_row``/``diag_col``), the summary and
the :func:`pmdsim.diagnostics.check` warnings (bounds from ``[diagnostics]``) into
``statistics.json``/``summary.txt``, the manifest and ``RunResult.warnings``.

With ``variants`` (a comparison of BRDFs, anisotropy frames or sampling on one set-up)
each variant is a complete run folder ``<outdir>/<variant>/`` as above, and ``<outdir>``
holds the manifest, ``config.json`` (variants included) and
``figures/fringes_variants.png`` (with decoding also ``figures/deviation_variants.png``,
``statistics.json`` and ``summary.txt`` of all variants; with dots ``dots.csv`` and the dot
figures of all variants); :func:`load_run` concatenates the variants along a
``variant`` dimension.

Image files are integers scaled by one run-wide exposure factor (one per variant; see
:mod:`pmdsim.io`). The dataset holds the float camera values, the per-pixel weight sums, the masks and the
exact specular monitor coordinates, with units and descriptions in the attributes and the
resolved configuration as JSON in ``attrs["config_json"]``, so that
``RunConfig.model_validate_json(load_run(path).attrs["config_json"])`` reproduces the run.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import re
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from . import chain
from . import io as pio
from . import patterns as pat
from .config import RESERVED_VARIANT_NAMES, RunConfig
from .render import FringeResult, Geometry, Simulation

ProgressFn = Callable[[int, int], None]

DATASET_NAME = "run.zarr"
CONFIG_NAME = "config.json"
#: Names a variant cannot have: they are files or folders of the run folder itself
#: (validated by the config already; kept here for configs built around the validators).
RESERVED_NAMES = RESERVED_VARIANT_NAMES



def _version() -> str:
    from . import __version__

    return __version__


@dataclass(frozen=True)
class RunResult:
    """What :func:`run_simulation` did.

    Attributes
    ----------
    outdir : Path
        The complete run folder.
    dataset_path : Path or None
        ``outdir / "run.zarr"``; None for a run with variants (see ``variants``).
    image_paths, figure_paths : tuple of Path
        Written image files (empty when ``output.write_images`` is false) and figures.
    exposure : float
        Run-wide factor from camera values to image integers (``pixel = value * exposure``);
        NaN for a run with variants (each variant has its own).
    shape : (int, int)
        Camera (height, width), px.
    surface_pixels : int
        Pixels whose vision ray hits the surface.
    rays_per_pixel : int
        Rays of each pixel's bundle (N, P included; 1 for the mirror).
    rays_traced : int
        Scattered rays traced in all render passes (surface pixels x N x passes).
    timings : dict
        Wall times in s: ``geometry``, ``render``, ``write``, ``figures``, ``total``.
    config : RunConfig
    variants : tuple of RunResult
        One result per variant (folder ``outdir/<name>``); empty without variants.
    notes : tuple of str
        What was skipped and why (e.g. decoding, when the fringe widths do not allow it).
    statistics : dict
        The content of ``statistics.json``: the measurement chain's statistics (when
        decoded) and the run diagnostics under ``"diagnostics"`` (when computed);
        ``{variant: ...}`` for a run with variants; empty when there is neither.
    warnings : tuple of pmdsim.diagnostics.DiagnosticWarning
        The diagnostics' warnings for this run (each names the setting that fixes it);
        empty for a run with variants (see each variant's).
    """

    outdir: Path
    dataset_path: Path | None
    image_paths: tuple[Path, ...]
    figure_paths: tuple[Path, ...]
    exposure: float
    shape: tuple[int, int]
    surface_pixels: int
    rays_per_pixel: int
    rays_traced: int
    timings: dict = field(default_factory=dict)
    config: RunConfig | None = None
    variants: tuple["RunResult", ...] = ()
    notes: tuple[str, ...] = ()
    statistics: dict = field(default_factory=dict)
    warnings: tuple = ()

    @property
    def rays_per_second(self) -> float:
        """Scattered rays per second of render time."""
        t = self.timings.get("render", 0.0)
        return self.rays_traced / t if t > 0 else float("nan")


class _Steps:
    """Turns the per-render-call tile callbacks into one run-wide ``progress(done, total)``."""

    def __init__(self, progress: ProgressFn | None, total: int):
        self.progress = progress
        self.total = total
        self.done = 0

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)

    def tiles(self) -> ProgressFn | None:
        """A callback for one render call: reports its tiles on top of the steps so far."""
        if self.progress is None:
            return None
        base = self.done
        seen = [0]

        def cb(done: int, total: int) -> None:
            if done > seen[0]:
                self.done = base + done
                seen[0] = done
                self.progress(min(self.done, self.total), self.total)

        return cb

    def finish_render(self, base_tiles: int, n_tiles: int) -> None:
        """Make sure a render call counts exactly ``n_tiles`` steps."""
        self.done = base_tiles + n_tiles
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)


# ----------------------------------------------------------------------------- naming
def _number_tag(x: float, digits: int = 0) -> str:
    """``50 -> '0050'`` (digits=4), ``37.5 -> '037p5'``: sortable, filename-safe."""
    text = np.format_float_positional(float(x), trim="-")
    whole, _, frac = text.partition(".")
    sign = "m" if whole.startswith("-") else ""
    whole = whole.lstrip("-").zfill(digits)
    return sign + whole + ("p" + frac if frac else "")


def fringe_file_name(direction: str, width: float, k: int, widths=None, shifts: int = 10,
                     suffix: str = ".tif") -> str:
    """``x_w0050_k0.tif``: direction, fringe period (monitor px), phase-shift index."""
    widths = widths or [width]
    digits = max(3, len(str(int(max(widths)))))
    kd = len(str(max(shifts - 1, 0)))
    return f"{direction}_w{_number_tag(width, digits)}_k{k:0{kd}d}{suffix}"


def _safe_stem(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", Path(name).stem) or "image"


# ----------------------------------------------------------------------------- patterns
def resolve_dots(cfg: RunConfig) -> list[pat.Dot]:
    """The dots of ``patterns.dots``: the grid (row by row) then the explicit positions."""
    d = cfg.patterns.dots
    if d is None:
        return []
    mshape = (cfg.monitor.resolution[1], cfg.monitor.resolution[0])
    dots = []
    if d.grid is not None:
        dots += pat.dot_grid(mshape, d.grid, float(d.size_px), d.margin_px)
    dots += [pat.Dot(float(u), float(v), float(d.size_px)) for u, v in d.positions_px]
    return dots


def resolve_images(cfg: RunConfig) -> tuple[list[str], np.ndarray | None]:
    """Load the monitor images of ``patterns.images`` as levels (Q, Hm, Wm) in [0, 1]."""
    im = cfg.patterns.images
    if im is None or not im.files:
        return [], None
    mshape = (cfg.monitor.resolution[1], cfg.monitor.resolution[0])
    levels = np.stack([pat.load_monitor_image(f, mshape) for f in im.files])
    return list(im.files), levels


# ----------------------------------------------------------------------------- dataset
def build_dataset(cfg: RunConfig, geometry: Geometry, fringes: FringeResult | None,
                  dots: list[pat.Dot], dot_images: np.ndarray | None,
                  image_files: list[str], images: np.ndarray | None, exposure: float,
                  rays_per_pixel: int):
    """The run's xarray Dataset (in memory): see the module docstring for its contents."""
    import xarray as xr

    h, w = geometry.surface_mask.shape
    estimator = cfg.sampling.estimator
    value_units = (
        "camera value: (1/N) sum_p f_p L_p, BRDF units (1/sr) x monitor luminance"
        if estimator == "paper" else
        "camera value: sum_p f_p L_p / sum_p f_p, monitor luminance units"
    )
    pix = {"row": ("row", np.arange(h)), "col": ("col", np.arange(w))}
    ds = xr.Dataset(coords=pix)
    ds["row"].attrs = {"units": "camera px", "description": "camera pixel row (0-based, centre)"}
    ds["col"].attrs = {"units": "camera px", "description": "camera pixel column (0-based, centre)"}
    ds["surface_mask"] = (("row", "col"), geometry.surface_mask, {
        "description": "True where the vision ray hits the front of the surface"})
    ds["monitor_mask"] = (("row", "col"), geometry.monitor_mask, {
        "description": "True where the principal reflection P also hits the monitor"})
    ds["specular_u"] = (("row", "col"), geometry.specular_u, {
        "units": "monitor px", "description": "exact monitor column u hit by P (NaN: misses)"})
    ds["specular_v"] = (("row", "col"), geometry.specular_v, {
        "units": "monitor px", "description": "exact monitor row v hit by P (NaN: misses)"})
    if fringes is not None:
        ds = ds.assign_coords(
            direction=("direction", np.array(fringes.directions, dtype=object)),
            width=("width", np.asarray(fringes.widths, np.float64)),
            shift=("shift", np.asarray(fringes.shifts, np.float64)),
        )
        ds["direction"].attrs = {"description": "x: phase along monitor columns u (vertical "
                                 "fringe lines); y: along rows v"}
        ds["width"].attrs = {"units": "monitor px", "description": "fringe width = period"}
        ds["shift"].attrs = {"units": "rad", "description": "phase shift delta_k = 2 pi k / K; "
                             "pattern 0.5 + 0.5 cos(2 pi c / width + delta_k)"}
        ds["fringes"] = (("direction", "width", "shift", "row", "col"), fringes.images, {
            "units": value_units, "description": "camera fringe images; NaN: no surface"})
        ds["f_total"] = (("row", "col"), fringes.f_total, {
            "description": "normalised sum of the BRDF weights of all rays of the bundle"})
        ds["f_hit"] = (("row", "col"), fringes.f_hit, {
            "description": "normalised sum of the weights of the rays that hit the monitor"})
        if fringes.sums is not None:
            desc = ("normalised sum_p f_p exp(i 2 pi c_p / width), c = u (x) or v (y) in "
                    "monitor px; arg = decoded phase, |.|/f_hit = modulation (gamma 1)")
            ds["fringe_sums_real"] = (("direction", "width", "row", "col"),
                                      fringes.sums.real.copy(), {"description": "real part of " + desc})
            ds["fringe_sums_imag"] = (("direction", "width", "row", "col"),
                                      fringes.sums.imag.copy(), {"description": "imaginary part of " + desc})
    if dot_images is not None:
        ds = ds.assign_coords(
            dot_u=("dot", np.array([d.u for d in dots])),
            dot_v=("dot", np.array([d.v for d in dots])),
            dot_size=("dot", np.array([d.size for d in dots])),
        )
        ds["dot_u"].attrs = {"units": "monitor px", "description": "dot centre column"}
        ds["dot_v"].attrs = {"units": "monitor px", "description": "dot centre row"}
        ds["dot_size"].attrs = {"units": "monitor px", "description": "dot side length"}
        ds["dots"] = (("dot", "row", "col"), dot_images, {
            "units": value_units, "description": "camera images of white square dots on black"})
    if images is not None:
        ds = ds.assign_coords(image_file=("image", np.array(image_files, dtype=object)))
        ds["images"] = (("image", "row", "col"), images, {
            "units": value_units, "description": "camera images of the monitor images"})
    ds["exposure"] = ((), float(exposure), {
        "units": "image integer per camera value",
        "description": "image file pixel = round(clip(value * exposure, 0, 2**bit_depth - 1))"})
    ds.attrs = {
        "title": f"pmdsim run {cfg.name}",
        "pmdsim_version": _version(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "config_json": cfg.model_dump_json(),
        "estimator": estimator,
        "rays_per_pixel": int(rays_per_pixel),
        "exposure": float(exposure),
        "bit_depth": int(cfg.output.bit_depth),
        "image_format": cfg.output.image_format,
        "conventions": "pmdsim docs/conventions.md: lengths mm, angles rad, monitor and "
                       "camera pixel centres at integers, images (frames, height, width)",
        "python": platform.python_version(),
        "numpy": np.__version__,
    }
    return ds


def _encoding(ds) -> dict:
    """One chunk per camera image for the image stacks (every variable with dimensions
    (..., row, col) and at least one more)."""
    enc = {}
    for name, var in ds.data_vars.items():
        if var.ndim >= 3 and var.dims[-2:] == ("row", "col"):
            shape = var.shape
            enc[name] = {"chunks": (1,) * (len(shape) - 2) + tuple(shape[-2:])}
    return enc


def load_run(path: str | Path, variant: str | None = None):
    """Open the dataset of a run (lazily, Dask-backed).

    ``path`` is a run folder or its ``run.zarr``. For a run with variants, ``variant``
    selects one (the same as opening ``<path>/<variant>``); without it the variants are
    concatenated along a new leading ``variant`` dimension and ``attrs["config_json"]`` is
    the whole configuration (variants included).

    ``RunConfig.model_validate_json(ds.attrs["config_json"])`` gives the configuration that
    reproduces the dataset (:func:`run_config`).
    """
    path = Path(path)
    if variant is not None:
        path = path / variant
    if (path / DATASET_NAME).is_dir():
        path = path / DATASET_NAME
    if path.name == DATASET_NAME or (path / "zarr.json").is_file():
        if not path.is_dir():
            raise FileNotFoundError(f"no pmdsim run dataset at {path}")
        import xarray as xr

        return xr.open_zarr(path, consolidated=False)
    manifest = path / pio.MANIFEST
    if not manifest.is_file():
        raise FileNotFoundError(f"no pmdsim run at {path} (no {DATASET_NAME}, no {pio.MANIFEST})")
    names = json.loads(manifest.read_text()).get("variants", [])
    if not names:
        raise FileNotFoundError(f"no pmdsim run dataset in {path}")
    import xarray as xr

    parts = [load_run(path / n) for n in names]
    # The geometry and the specular reference are the same for every variant.
    shared = {"surface_mask", "monitor_mask", "specular_u", "specular_v", "surface_to_monitor_mm"}
    shared |= {v for v in parts[0].data_vars if str(v).startswith("reference_")}
    # A variable some variants lack (the diagnostics of a mirror variant) is NaN for them.
    templates: dict = {}
    for p in parts:
        for v in p.data_vars:
            templates.setdefault(v, p[v])
    parts = [p.assign({v: xr.full_like(t, np.nan, dtype=np.float64)
                       for v, t in templates.items() if v not in p.data_vars}) for p in parts]
    per_variant = [v for v in templates if v not in shared]
    ds = xr.concat(parts, dim=xr.DataArray(np.array(names, dtype=object), dims="variant",
                                           name="variant"),
                   data_vars=per_variant,
                   coords="minimal", compat="override", combine_attrs="drop_conflicts",
                   join="exact")
    ds.attrs["config_json"] = (path / CONFIG_NAME).read_text()
    return ds


def run_config(ds) -> RunConfig:
    """The resolved configuration stored with a run dataset."""
    return RunConfig.model_validate_json(ds.attrs["config_json"])


# ----------------------------------------------------------------------------- the run
def run_simulation(cfg: RunConfig, outdir: str | Path, progress: ProgressFn | None = None,
                   *, overwrite: bool = False, figures: bool | None = None,
                   decode: bool | None = None, diagnostics: bool = True) -> RunResult:
    """Simulate ``cfg`` and write a complete run folder ``outdir``.

    With ``cfg.variants`` every variant (:meth:`RunConfig.expand`) becomes a complete run
    folder ``outdir/<variant>`` of its own (its own exposure, dataset and figures, its
    configuration without variants); ``outdir`` then holds the manifest, the whole
    configuration and ``figures/fringes_variants.png`` comparing the variants.

    Parameters
    ----------
    cfg : RunConfig
    outdir : path
        The run folder to create. Written as ``<outdir>.tmp-<pid>`` and renamed when
        complete; on any error nothing named ``outdir`` is created or changed.
    progress : callable(done, total), optional
        Called as work advances; steps are the geometry, every camera tile of every render
        call, the images, the dataset and the figures (of every variant).
    overwrite : bool
        Replace an existing run folder (never a folder that is not a pmdsim run).
    figures : bool, optional
        Draw the figures; default ``cfg.output.figures``.
    decode : bool, optional
        Run the measurement chain (decode, deviation from the specular reference): True
        requires it (an error when the fringes cannot be decoded), False turns it off;
        default ``cfg.decode.enabled`` (``"auto"``: whenever the fringes allow it, otherwise
        skipped with a note in ``RunResult.notes`` and the manifest).
    diagnostics : bool
        Compute the run diagnostics of every configuration with a lobe (not the mirror):
        lobe energy inside theta_max (cone estimators), effective sample size, phase
        standard error (``[diagnostics] phase_method``) on the ``[diagnostics]`` grid; maps ``diag_*`` in the
        dataset, summary and warnings in statistics.json, summary.txt, the manifest and
        ``RunResult.warnings`` (bounds from ``[diagnostics]``).

    Returns
    -------
    RunResult
        For a run with variants, ``variants`` holds each variant's result, and the paths,
        rays and timings are totals.

    Raises
    ------
    FileExistsError
        ``outdir`` exists (without ``overwrite``), or is not a run folder.
    FileNotFoundError, ValueError
        A monitor image is missing or has the wrong size; decoding was required but the
        fringe widths do not allow it (the message names ``patterns.fringes.widths_px``).
    """
    t_start = time.perf_counter()
    figures = cfg.output.figures if figures is None else figures
    for k, v in enumerate(cfg.variants):
        if v.name in RESERVED_NAMES or v.name.startswith("."):
            raise ValueError(
                f"variants.{k}.name: {v.name!r} cannot name a sub-folder of the run (reserved "
                f"or hidden: {sorted(RESERVED_NAMES)}); choose another name")
    members = cfg.expand()
    sims = [(name, c, Simulation.from_config(c)) for name, c in members]
    # Resolve inputs before anything is written: bad input fails fast.
    dots = resolve_dots(cfg)
    image_files, levels = resolve_images(cfg)
    decoding, notes = _chain_mode(cfg, decode)
    n_calls = (cfg.patterns.fringes is not None) + bool(dots) + (levels is not None)
    n_tiles = math.ceil(sims[0][2].shape[0] / sims[0][2].tile_rows)
    compare = bool(cfg.variants) and figures and cfg.patterns.fringes is not None
    top_figures = bool(cfg.variants) and figures and (cfg.patterns.fringes is not None
                                                      or bool(dots))
    n_diagnosed = sum(not s.scene.brdf.is_delta for _, _, s in sims) if diagnostics else 0
    steps = _Steps(progress, 1 + len(sims) * (n_calls * n_tiles + 2 + int(figures))
                   + int(top_figures) + (n_tiles if decoding else 0) + n_diagnosed)
    inputs = (dots, image_files, levels, n_tiles)

    with pio.atomic_run_dir(outdir, overwrite=overwrite) as tmp:
        t = time.perf_counter()
        # The vision rays do not depend on what a variant may change (BRDF, anisotropy
        # frame, sampling): one geometry for all.
        geometry = sims[0][2].geometry()
        t_geometry = time.perf_counter() - t
        steps.advance()
        reference = None
        if decoding:
            # The ideal specular reference does not depend on the BRDF, anisotropy frame or
            # sampling of a variant: rendered and decoded once for all.
            reference = _reference(cfg, sims[0][2], geometry, steps, n_tiles)
            notes += list(reference.notes)
        if not cfg.variants:
            result, _ = _run_member(cfg, sims[0][2], geometry, tmp, steps, figures, inputs,
                                    reference=reference, standalone=True,
                                    diagnostics=diagnostics)
            timings = dict(result.timings, geometry=t_geometry,
                           total=time.perf_counter() - t_start)
            if reference is not None:
                timings["reference"] = reference.seconds
            result = replace(result, notes=tuple(notes))
            final = Path(outdir).absolute()
            _write_manifest(tmp, cfg, result, timings)
            return _moved(result, tmp, final, timings=timings)

        subs, datasets = [], {}
        for name, c, sim in sims:
            res, ds = _run_member(c, sim, geometry, tmp / name, steps, figures, inputs,
                                  reference=reference, standalone=False,
                                  diagnostics=diagnostics)
            res = replace(res, notes=tuple(notes))
            _write_manifest(tmp / name, c, res, dict(res.timings, geometry=t_geometry))
            subs.append(res)
            if compare:  # keep only what the comparison figure needs (finest width, k = 0)
                keep = [n for n in ("fringes", "fringe_sums_real", "fringe_sums_imag", "f_hit")
                        if n in ds]
                iw = int(np.argmin(ds["width"].values))
                datasets[name] = ds[keep].isel(width=[iw], shift=[0]).copy(deep=True)
            del ds
        (tmp / CONFIG_NAME).write_text(cfg.model_dump_json(indent=2) + "\n")
        figure_paths: list[Path] = []
        t = time.perf_counter()
        descriptions = {v.name: v.description for v in cfg.variants}
        if compare:
            from . import plot

            figure_paths.append(plot.plot_variant_fringes(
                datasets, tmp / "figures" / "fringes_variants.png",
                descriptions=descriptions))
        figure_paths += _write_variant_outputs(cfg, tmp, [name for name, _ in members], subs,
                                               figures, descriptions, sims[0][2])
        if top_figures:
            steps.advance()
        timings = {k: sum(r.timings.get(k, 0.0) for r in subs)
                   for k in ("render", "write", "decode", "diagnostics", "figures")}
        timings["figures"] += time.perf_counter() - t
        timings["geometry"] = t_geometry
        if reference is not None:
            timings["reference"] = reference.seconds
        timings["total"] = time.perf_counter() - t_start
        top = RunResult(
            outdir=tmp, dataset_path=None,
            image_paths=tuple(p for r in subs for p in r.image_paths),
            figure_paths=tuple(figure_paths) + tuple(p for r in subs for p in r.figure_paths),
            exposure=float("nan"), shape=subs[0].shape, surface_pixels=subs[0].surface_pixels,
            rays_per_pixel=subs[0].rays_per_pixel, rays_traced=sum(r.rays_traced for r in subs),
            timings=timings, config=cfg, variants=tuple(subs), notes=tuple(notes),
            statistics={r.config.name: r.statistics for r in subs if r.statistics})
        pio.write_manifest(tmp, {
            "format": "pmdsim-run/1",
            "name": cfg.name,
            "pmdsim_version": _version(),
            "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "config": CONFIG_NAME,
            "variants": [name for name, _ in members],
            "figures": [str(p.relative_to(tmp)) for p in figure_paths],
            "rays_traced": top.rays_traced,
            "notes": list(notes),
            "warnings": {r.config.name: [w.message for w in r.warnings] for r in subs},
            "timings_s": {k: round(v, 4) for k, v in timings.items()},
        })

    return _moved(top, tmp, Path(outdir).absolute())


def _moved(result: RunResult, tmp: Path, final: Path, **changes) -> RunResult:
    """The result with every path moved from the temporary folder to the final one."""
    def mv(p):
        return None if p is None else final / Path(p).relative_to(tmp)

    return replace(
        result, outdir=mv(result.outdir), dataset_path=mv(result.dataset_path),
        image_paths=tuple(mv(p) for p in result.image_paths),
        figure_paths=tuple(mv(p) for p in result.figure_paths),
        variants=tuple(_moved(r, tmp, final) for r in result.variants), **changes)


def _write_manifest(folder: Path, cfg: RunConfig, result: RunResult, timings: dict) -> None:
    rel = lambda ps: [str(Path(p).relative_to(folder)) for p in ps]  # noqa: E731
    pio.write_manifest(folder, {
        "format": "pmdsim-run/1",
        "name": cfg.name,
        "pmdsim_version": _version(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "dataset": DATASET_NAME,
        "config": CONFIG_NAME,
        "images": rel(result.image_paths),
        "figures": rel(result.figure_paths),
        "exposure": result.exposure,
        "image_scaling": "pixel = round(clip(value * exposure, 0, 2**bit_depth - 1)); "
                         "NaN (no surface) -> 0",
        "bit_depth": cfg.output.bit_depth,
        "camera_shape": list(result.shape),
        "surface_pixels": result.surface_pixels,
        "rays_per_pixel": result.rays_per_pixel,
        "rays_traced": result.rays_traced,
        "notes": list(result.notes),
        "warnings": [w.message for w in result.warnings],
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    })


def _run_member(cfg: RunConfig, sim: Simulation, geometry: Geometry, folder: Path,
                steps: _Steps, figures: bool, inputs, reference: "_Reference | None" = None,
                standalone: bool = True, diagnostics: bool = True) -> tuple[RunResult, object]:
    """Render one configuration (no variants) and write its images, dataset, config and
    figures into ``folder`` (no manifest). Returns its result and its in-memory dataset.

    With a ``reference`` the fringes are decoded and compared with it (statistics.json,
    summary.txt, chain variables and figures). Dots get their moments (dots.csv); their
    figures are drawn here only for a ``standalone`` run (a run with variants draws them
    for all variants together). With ``diagnostics`` (and a lobe) the run diagnostics go
    into the dataset, statistics.json and summary.txt, and their warnings into the result."""
    dots, image_files, levels, n_tiles = inputs
    folder.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    fr_cfg = cfg.patterns.fringes
    n_calls = (fr_cfg is not None) + bool(dots) + (levels is not None)

    t = time.perf_counter()
    fringes = dot_images = images = None
    if fr_cfg is not None:
        base = steps.done
        fringes = sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts,
                                     progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    if dots:
        base = steps.done
        dot_images = sim.render_dots(dots, progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    if levels is not None:
        base = steps.done
        images = sim.render_images(levels, progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    timings["render"] = time.perf_counter() - t

    t = time.perf_counter()
    out = cfg.output
    stacks = [a for a in (None if fringes is None else fringes.images, dot_images, images)
              if a is not None]
    exposure = pio.exposure_factor(stacks, out.bit_depth)
    image_paths = _write_images(folder, cfg, fringes, dots, dot_images, image_files, images,
                                exposure) if out.write_images else []
    steps.advance()
    ds = build_dataset(cfg, geometry, fringes, dots, dot_images, image_files, images,
                       exposure, sim.scene.rays_per_pixel)
    timings["write"] = time.perf_counter() - t

    t = time.perf_counter()
    stats: dict = {}
    if reference is not None and fringes is not None:
        measured = chain.compare(
            chain.decode_fringes(fringes, cfg.monitor.resolution, cfg.decode),
            reference.decoded, geometry, reference.distance_mm, cfg.monitor.pixel_pitch_mm,
            cfg.decode, len(fringes.shifts))
        stats = chain.statistics(measured, cfg.name)
        ds = chain.assign_to_dataset(ds, measured, stats)
        del measured
    dot_table = []
    if dot_images is not None:
        dot_table = chain.dot_table(dot_images, dots, cfg.name)
        for name, var in chain.dot_dataset_variables(dot_table).items():
            ds[name] = var
        chain.write_dot_csv(folder / "dots.csv", dot_table)
    timings["decode"] = time.perf_counter() - t

    t = time.perf_counter()
    statistics = dict(stats)  # statistics.json: the chain's (when decoded) + diagnostics
    diagnosed = _diagnose(cfg, sim, geometry) if diagnostics else None
    if diagnosed is not None:
        ds = ds.assign_coords(diagnosed.coords)
        for name, var in diagnosed.variables.items():
            ds[name] = var
        statistics.setdefault("name", cfg.name)
        statistics["diagnostics"] = diagnosed.summary
        ds.attrs["statistics_json"] = json.dumps(statistics)
        steps.advance()
    timings["diagnostics"] = time.perf_counter() - t

    t = time.perf_counter()
    ds.to_zarr(folder / DATASET_NAME, mode="w-", consolidated=False, encoding=_encoding(ds))
    (folder / CONFIG_NAME).write_text(cfg.model_dump_json(indent=2) + "\n")
    if statistics:
        (folder / "statistics.json").write_text(json.dumps(statistics, indent=2) + "\n")
        (folder / "summary.txt").write_text(_summary_text(statistics))
    steps.advance()
    timings["write"] += time.perf_counter() - t

    figure_paths: list[Path] = []
    t = time.perf_counter()
    if figures:
        from . import plot  # matplotlib only when figures are made

        figure_paths = plot.run_figures(sim, ds, folder / "figures")
        if stats or (dot_table and standalone):
            from . import plot_chain

            if stats:
                figure_paths += plot_chain.chain_figures(ds, folder / "figures", cfg.name,
                                                         _description(cfg))
            if dot_table and standalone:
                figure_paths += _dot_figures(folder / "figures", {cfg.name: dot_images},
                                             {cfg.name: dot_table}, sim, {})
        steps.advance()
    timings["figures"] = time.perf_counter() - t

    surface_pixels = int(geometry.surface_mask.sum())
    result = RunResult(
        outdir=folder, dataset_path=folder / DATASET_NAME, image_paths=tuple(image_paths),
        figure_paths=tuple(figure_paths), exposure=exposure, shape=sim.shape,
        surface_pixels=surface_pixels, rays_per_pixel=sim.scene.rays_per_pixel,
        rays_traced=surface_pixels * sim.scene.rays_per_pixel * n_calls, timings=timings,
        config=cfg, statistics=statistics,
        warnings=() if diagnosed is None else diagnosed.warnings)
    return result, ds


# ----------------------------------------------------------------------------- diagnostics
#: Quadrature points per grid pixel for the lobe-energy fraction of a run (``diagnose``'s
#: default is 16 384). On the Fig. 3 scene 4096 points give the median fraction to 2e-4 and
#: the 95 % cone angle to 0.01 deg of a 65 536-point quadrature, in a quarter of the time.
DIAGNOSTICS_ENERGY_SAMPLES = 4096


class _KnownGeometry:
    """A :class:`Simulation` whose :meth:`geometry` is the one the run has already traced
    (:func:`pmdsim.diagnostics.diagnose` asks for the surface mask); everything else is the
    simulation's own."""

    def __init__(self, sim: Simulation, geometry: Geometry):
        self._sim = sim
        self._geometry = geometry

    def geometry(self) -> Geometry:
        return self._geometry

    def __getattr__(self, name):
        return getattr(self._sim, name)


@dataclass(frozen=True, eq=False)
class _Diagnosed:
    """The run diagnostics of one configuration: ``summary`` (statistics.json
    ``"diagnostics"``), the :class:`~pmdsim.diagnostics.DiagnosticWarning` s, and the
    dataset ``coords`` and ``variables`` ``{name: (dims, data, attrs)}``."""

    summary: dict
    warnings: tuple
    coords: dict
    variables: dict


def _json_safe(obj):
    """NaN/inf -> None and NumPy scalars -> Python numbers, recursively (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _diagnose(cfg: RunConfig, sim: Simulation, geometry: Geometry) -> _Diagnosed | None:
    """Energy fraction inside theta_max (cone estimators), effective sample size and the
    phase standard error (``[diagnostics] phase_method``) of every fringe (with fringes) on the coarse pixel
    grid of ``[diagnostics]``, and the :func:`~pmdsim.diagnostics.check` warnings for its
    bounds. None for the mirror (no lobe)."""
    if sim.scene.brdf.is_delta:
        return None
    from dataclasses import asdict

    from . import diagnostics as dg

    fr = cfg.patterns.fringes
    cone = cfg.sampling.estimator in dg.CONE_ESTIMATORS
    widths = fr.widths_px if fr is not None else (50.0,)
    directions = fr.directions if fr is not None else ("x",)
    # The radiometric estimator has no cone: its energy fraction is not used (a token
    # quadrature keeps diagnose() cheap) and is dropped below.
    # target_fraction = the bound, so that check() can name the cone angle that meets it
    diag = dg.diagnose(_KnownGeometry(sim, geometry), widths, directions,
                       grid=cfg.diagnostics.grid,
                       target_fraction=cfg.diagnostics.min_energy_fraction,
                       phase_method=cfg.diagnostics.phase_method,
                       n_samples=DIAGNOSTICS_ENERGY_SAMPLES if cone else 16)
    summary = dict(diag.summary)
    if not cone:
        diag = replace(diag, energy=None)
        summary.pop("energy", None)
    if fr is None:  # no fringes: no phase to judge
        diag = replace(diag, phase_se=None)
        for key in ("phase_se_method", "phase_se_rad", "modulation_median"):
            summary.pop(key, None)
    warnings = tuple(dg.check(diag, bounds=cfg.diagnostics))
    grid = diag.grid
    summary["grid"] = {"columns": int(grid.cols.size), "rows": int(grid.rows.size)}
    if diag.energy is not None:
        summary["energy"]["quadrature_points"] = DIAGNOSTICS_ENERGY_SAMPLES
    summary["bounds"] = cfg.diagnostics.model_dump(mode="json")
    summary["warnings"] = [asdict(w) for w in warnings]
    summary = _json_safe(summary)

    coords = {
        "diag_row": ("diag_row", grid.rows.astype(np.int64), {
            "units": "camera px", "description": "camera row of the diagnostics grid pixels"}),
        "diag_col": ("diag_col", grid.cols.astype(np.int64), {
            "units": "camera px", "description": "camera column of the diagnostics grid pixels"}),
    }
    where = "; on the coarse grid diag_row x diag_col, NaN: no surface"
    dims = ("diag_row", "diag_col")
    variables: dict = {}
    if diag.energy is not None:
        e = diag.energy
        variables["diag_energy_fraction"] = (dims, e.fraction, {
            "units": "1", "description": "fraction of the lobe's reflected energy "
            f"(integral of f cos theta_o) inside the sampling cone theta <= {e.theta_max_deg:g} "
            "deg about P" + where})
        variables["diag_theta_needed_deg"] = (dims, e.theta_needed_deg, {
            "units": "deg", "description": f"smallest cone half angle about P holding "
            f"{100 * e.target:g} % of the lobe's reflected energy" + where})
    if diag.rays is not None:
        variables["diag_effective_sample_size"] = (dims, diag.rays.ess, {
            "units": "rays", "description": "effective sample size (sum w)^2 / sum w^2 of the "
            f"weights of the monitor-hitting rays, of N = {diag.n_rays}" + where})
    if diag.phase_se is not None:
        variables["diag_phase_se"] = (("direction", "width") + dims, diag.phase_se, {
            "units": "rad", "description": "Monte-Carlo standard error of the decoded phase, "
            + ("spread over independent rotations of the sample set (seeds)"
               if diag.phase_se_method == "seeds" else
               "delta method: std of the per-ray terms / (sqrt(N) |mean|), the error of N "
               "independent rays (an upper bound for the lattice sample sets)") + where})
    return _Diagnosed(summary, warnings, coords, variables)


def _fmt(x, spec: str = ".3g") -> str:
    return "nan" if x is None else format(x, spec)


def warning_text(message: str, setting: str, suggested=None) -> str:
    """A diagnostics warning as printed: its message, followed by the setting that fixes
    it (``[setting: sampling.theta_max_deg = 4]``) unless the message names it already."""
    if not setting or setting in message:
        return message
    if suggested is None:
        return f"{message} [setting: {setting}]"
    value = format(suggested, "g") if isinstance(suggested, float) else str(suggested)
    return f"{message} [setting: {setting} = {value}]"


def diagnostics_text(name: str, d: dict) -> str:
    """A short human-readable account of the ``"diagnostics"`` of statistics.json."""
    g = d.get("grid", {})
    lines = [f"pmdsim run diagnostics: {name}",
             f"{d['estimator']} estimator, N = {d['n_rays']}"
             + (f", theta_max {d['theta_max_deg']:g} deg" if "energy" in d else "")
             + f"; {g.get('columns', '?')} x {g.get('rows', '?')} camera-pixel grid", ""]
    e = d.get("energy")
    if e and "fraction_median" in e:
        pc = lambda x: _fmt(None if x is None else 100 * x, ".1f")  # noqa: E731
        lines.append(f"lobe energy inside theta_max: median {pc(e['fraction_median'])} %, "
                     f"min {pc(e['fraction_min'])} %; {100 * e['target']:g} % needs "
                     f"theta_max {_fmt(e['theta_needed_deg_max'], '.2f')} deg (largest over the grid)")
    if "ess_median" in d:
        lines.append(f"effective sample size: median {_fmt(d['ess_median'], '.1f')}, "
                     f"min {_fmt(d['ess_min'], '.1f')} of {d['n_rays']} rays")
    if "phase_se_rad" in d:
        lines.append(f"phase standard error ({d['phase_se_method']} method: N independent rays, "
                     "an upper bound for the lattice), mrad, median / P95; fringe modulation:")
        for key, v in d["phase_se_rad"].items():
            direction, width = key.split("/")
            med = None if v["median"] is None else 1e3 * v["median"]
            p95 = None if v["p95"] is None else 1e3 * v["p95"]
            mod = d.get("modulation_median", {}).get(key)
            lines.append(f"  {direction.upper()} {width:>6} px  {_fmt(med):>8} / {_fmt(p95):<8}"
                         f"  modulation {_fmt(mod)}")
    warnings = d.get("warnings", [])
    b = d.get("bounds", {})
    lines.append("")
    if warnings:
        lines += [f"warning: {warning_text(w['message'], w['setting'], w['suggested'])}"
                  for w in warnings]
    else:
        lines.append("no warnings (bounds: energy fraction >= "
                     f"{b.get('min_energy_fraction')}, phase error <= "
                     f"{b.get('max_phase_error_mrad')} mrad, ESS >= "
                     f"{b.get('min_ess_fraction')} N)")
    return "\n".join(lines).rstrip() + "\n"


def _summary_text(statistics: dict) -> str:
    """summary.txt of one run: the chain's table (when decoded), then the diagnostics."""
    parts = []
    if "directions" in statistics:
        parts.append(chain.summary_text(statistics))
    if "diagnostics" in statistics:
        parts.append(diagnostics_text(statistics.get("name", ""), statistics["diagnostics"]))
    return "\n".join(parts)


# ----------------------------------------------------------------------------- the chain
@dataclass(frozen=True, eq=False)
class _Reference:
    """The decoded ideal specular reference of a run (shared by its variants)."""

    decoded: dict
    distance_mm: np.ndarray
    seconds: float
    notes: tuple = ()


def _chain_mode(cfg: RunConfig, decode: bool | None) -> tuple[bool, list[str]]:
    """(run the measurement chain?, notes). Raises ValueError when decoding is required
    (``decode.enabled = true`` or ``decode=True``) but impossible."""
    enabled = cfg.decode.enabled if decode is None else decode
    if enabled is False:
        return False, []
    problem = chain.decode_problem(cfg)
    if problem is None:
        return True, []
    if enabled is True:
        raise ValueError(f"decoding was requested (decode.enabled = true or --decode), but "
                         f"{problem}")
    if cfg.patterns.fringes is None:
        return False, []  # nothing to decode, nothing to say
    return False, [f"decoding skipped: {problem}"]


def _reference(cfg: RunConfig, sim: Simulation, geometry: Geometry, steps: _Steps,
               n_tiles: int) -> _Reference:
    """Render and decode the fringes of the ideal specular reference (mirror BRDF, one ray
    per pixel, the same camera, surface and monitor model)."""
    t = time.perf_counter()
    fr_cfg = cfg.patterns.fringes
    ref_sim = Simulation(sim.scene.specular(), sim.tile_rows, sim.scheduler, sim.num_workers)
    base = steps.done
    fr = ref_sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts,
                                progress=steps.tiles())
    steps.finish_render(base, n_tiles)
    decoded = chain.decode_fringes(fr, cfg.monitor.resolution, cfg.decode)
    del fr
    distance = chain.surface_to_monitor_mm(sim, geometry)
    notes = []
    for d, res in decoded.items():
        exact = geometry.specular_u if d == "x" else geometry.specular_v
        q = (res.monitor_coord_px - exact)[res.valid]
        rms = float(np.sqrt(np.mean(q**2))) if q.size else 0.0
        if rms > 0.05:
            notes.append(
                f"the specular reference decodes {rms:.2f} monitor px RMS ({d.upper()}) away from "
                "the exact specular points: on a 'nearest' monitor a mirror sees single pixels, "
                "so every deviation contains that quantisation; monitor.pixel_model = "
                "'continuous' shows the scattering alone (statistics.json: "
                "reference_vs_exact_px)")
            break
    return _Reference(decoded, distance, time.perf_counter() - t, tuple(notes))


def _description(cfg: RunConfig) -> str:
    b = cfg.brdf
    text = f"BRDF {b.model}"
    if hasattr(b, "alphas"):
        ax, ay = b.alphas
        names = (("tangential", "radial") if cfg.anisotropy.frame == "rotational"
                 else ("x", "y"))
        text += f" alpha_{names[0]} {ax:g}, alpha_{names[1]} {ay:g}"
    s = cfg.sampling
    return (text + f"; {s.estimator} estimator, N = {s.n_rays}, theta_max {s.theta_max_deg:g} "
            f"deg, {s.mode}; monitor pixel model {cfg.monitor.pixel_model}")


def _dot_figures(folder: Path, images: dict, tables: dict, sim: Simulation,
                 descriptions: dict) -> list[Path]:
    from . import plot_chain

    centre = None
    an = sim.scene.anisotropy
    if an.kind == "rotational":
        centre = tuple(float(x) for x in sim.scene.camera.project(an.centre))
    return [plot_chain.plot_dot_contact_sheet(images, tables, folder / "dot_contact_sheet.png",
                                              descriptions),
            plot_chain.plot_dot_shapes(images, tables, folder / "dot_shapes.png", centre,
                                       descriptions)]


def _write_variant_outputs(cfg: RunConfig, tmp: Path, names: list[str], subs, figures: bool,
                           descriptions: dict, sim: Simulation) -> list[Path]:
    """Top-level outputs of a run with variants: statistics.json and summary.txt of all
    variants (deviation statistics and diagnostics), dots.csv, and the comparison figures (deviation, dots). Reads the variants'
    datasets back lazily from their folders."""
    stats = {r.config.name: r.statistics for r in subs if r.statistics}
    if stats:
        (tmp / "statistics.json").write_text(json.dumps({"variants": stats}, indent=2) + "\n")
        (tmp / "summary.txt").write_text("\n".join(_summary_text(s) for s in stats.values()))
    decoded = any("directions" in s for s in stats.values())
    has_dots = cfg.patterns.dots is not None
    tables = {}
    if has_dots:
        import csv

        rows = []
        for n in names:
            with open(tmp / n / "dots.csv", newline="") as fh:
                part = list(csv.DictReader(fh))
            tables[n] = [{k: (v if k == "variant" else (int(v) if k == "dot" else float(v)))
                          for k, v in r.items()} for r in part]
            rows += tables[n]
        chain.write_dot_csv(tmp / "dots.csv", rows)
    paths: list[Path] = []
    if not figures or not (decoded or has_dots):
        return paths
    from . import plot_chain

    datasets = {n: load_run(tmp / n) for n in names}
    if decoded:
        paths.append(plot_chain.plot_variant_deviation(
            datasets, tmp / "figures" / "deviation_variants.png", descriptions))
    if has_dots:
        images = {n: datasets[n]["dots"] for n in names}  # lazy: one dot image at a time
        paths += _dot_figures(tmp / "figures", images, tables, sim, descriptions)
    return paths


def _write_images(folder: Path, cfg: RunConfig, fringes, dots, dot_images, image_files,
                  images, exposure: float) -> list[Path]:
    out = cfg.output
    suffix = pio.IMAGE_SUFFIX[out.image_format]
    jobs = []

    def put(rel: str, values: np.ndarray, meta: dict) -> None:
        jobs.append((rel, values, dict(meta, exposure=exposure,
                                       scaling="pixel = value * exposure; 0 = no surface")))

    def write(job) -> Path:
        rel, values, meta = job
        img = pio.to_integer_image(values, exposure, out.bit_depth)
        return pio.write_image(folder / rel, img, out.image_format, meta)

    if fringes is not None:
        for di, d in enumerate(fringes.directions):
            for wi, w in enumerate(fringes.widths):
                for k, delta in enumerate(fringes.shifts):
                    name = fringe_file_name(d, w, k, fringes.widths, len(fringes.shifts), suffix)
                    put(f"fringes/{name}", fringes.images[di, wi, k],
                        {"direction": d, "width_px": w, "shift_rad": float(delta), "k": k})
    if dot_images is not None:
        for q, dot in enumerate(dots):
            name = f"dot{q:03d}_u{_number_tag(dot.u, 4)}_v{_number_tag(dot.v, 4)}{suffix}"
            put(f"dots/{name}", dot_images[q], {"dot_u_px": dot.u, "dot_v_px": dot.v,
                                               "dot_size_px": dot.size})
    if images is not None:
        for q, f in enumerate(image_files):
            put(f"images/{q:02d}_{_safe_stem(f)}{suffix}", images[q], {"monitor_image": str(f)})
    # zlib and NumPy release the GIL: a few threads overlap compression and conversion.
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        return list(pool.map(write, jobs))


__all__ = ["RunResult", "run_simulation", "load_run", "run_config", "build_dataset",
           "resolve_dots", "resolve_images", "fringe_file_name"]
