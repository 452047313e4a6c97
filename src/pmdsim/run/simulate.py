"""From a configuration to a complete, self-describing run folder.

:func:`run_simulation` builds the :class:`~pmdsim.render.Simulation` of a
:class:`~pmdsim.config.RunConfig`, traces the vision rays (:meth:`Simulation.geometry`),
renders every configured pattern (all fringe widths, directions and shifts in one pass;
dots; monitor images) and writes, atomically (see :func:`pmdsim.store.folder.atomic_run_dir`)::

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
are decoded and compared (:mod:`pmdsim.measure.chain`); the decoded phases, monitor coordinates,
modulation, flags, the deviation maps, masks and statistics go into the dataset, and
``statistics.json``/``summary.txt`` beside it. Dot images get their second moments
(``dots.csv`` and ``dot_*`` variables). See ``docs/outputs.md``.

Run diagnostics (``diagnostics=True``, default; not for the mirror): on the coarse camera-pixel
grid of ``[diagnostics]`` (:mod:`pmdsim.studies.diagnostics`) the fraction of the lobe's energy inside
``theta_max`` (cone estimators), the effective sample size of the weights and, with fringes,
the standard error of the phase of every fringe (``[diagnostics] phase_method``) (one pass over the grid pixels'
rays); the maps go into the dataset (``diag_*`` on ``diag_row``/``diag_col``), the summary and
the :func:`pmdsim.studies.diagnostic_warnings.check` warnings (bounds from ``[diagnostics]``) into
``statistics.json``/``summary.txt``, the manifest and ``RunResult.warnings``.

With ``variants`` (a comparison of BRDFs, anisotropy frames or sampling on one set-up)
each variant is a complete run folder ``<outdir>/<variant>/`` as above, and ``<outdir>``
holds the manifest, ``config.json`` (variants included) and
``figures/fringes_variants.png`` (with decoding also ``figures/deviation_variants.png``,
``statistics.json`` and ``summary.txt`` of all variants; with dots ``dots.csv`` and the dot
figures of all variants); :func:`load_run` concatenates the variants along a
``variant`` dimension.

Image files are integers scaled by one run-wide exposure factor (one per variant; see
:mod:`pmdsim.store.images`). The dataset holds the float camera values, the per-pixel weight sums, the masks and the
exact specular monitor coordinates, with units and descriptions in the attributes and the
resolved configuration as JSON in ``attrs["config_json"]``, so that
``RunConfig.model_validate_json(load_run(path).attrs["config_json"])`` reproduces the run.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

from ..config import RESERVED_VARIANT_NAMES, ConfigError, RunConfig, check_resources
from ..studies.physics_checks import check_physics
from ..studies import coverage
from ..patterns import resolve_dots, resolve_images
from ..render import Simulation
from ..scene import resolved_camera
from ..store.manifest import write_run_manifest, write_variants_manifest
from .steps import RunInputs, run_member, start_pilot
from .reference import chain_mode, specular_reference
from .result import ProgressFn, RunResult, _Steps
from .threads import single_blas
from .variants import run_variants
from ..store.folder import atomic_run_dir, folder_sizes, size_text

#: Names a variant cannot have: they are files or folders of the run folder itself
#: (validated by the config already; kept here for configs built around the validators).
RESERVED_NAMES = RESERVED_VARIANT_NAMES


@dataclass
class RunPlan:
    """Everything a run needs, resolved and checked before anything is written."""

    cfg: RunConfig
    members: list[tuple[str, RunConfig, Simulation]]  # per variant (one without variants)
    inputs: RunInputs
    decoding: bool
    notes: list[str]
    figures: bool
    diagnostics: bool
    steps: _Steps

    @property
    def sim(self) -> Simulation:
        """The first member's simulation: geometry and reference are the same for all."""
        return self.members[0][2]


def resolve_roi(cfg: RunConfig) -> RunConfig:
    """``cfg`` with ``camera.roi = "auto"`` replaced by its window
    (:func:`pmdsim.scene.resolved_camera`); ``cfg`` itself otherwise."""
    camera = resolved_camera(cfg.camera, cfg.surface)
    return cfg if camera is cfg.camera else cfg.model_copy(update={"camera": camera})


@single_blas
def run_simulation(cfg: RunConfig, outdir: str | Path, progress: ProgressFn | None = None,
                   *, overwrite: bool = False, figures: bool | None = None,
                   decode: bool | None = None, diagnostics: bool = True,
                   client=None) -> RunResult:
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
    client : dask.distributed.Client, optional
        Render the run's tiles (geometry, reference, patterns, diagnostics) on this
        client's cluster instead of ``compute.scheduler``; the results are byte for byte
        those of a local run (the stored configuration is unchanged). Everything else (the
        chain, writing, figures) runs here. See docs/performance.md, "One run across a
        cluster".

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
    cfg = resolve_roi(cfg)  # camera.roi = "auto": the window that sees the part, stored as such
    plan = plan_run(cfg, progress, figures, decode, diagnostics)
    if client is not None:
        on_cluster(plan, client)
    with atomic_run_dir(outdir, overwrite=overwrite) as tmp, _current(client), \
            contextlib.ExitStack() as stack:
        # the pilot's choice of the rule needs no camera render: in a thread while the
        # vision rays and the specular reference are rendered (stopped on any error)
        pilot = None if client is not None or cfg.variants else start_pilot(cfg, plan.sim)
        if pilot is not None:
            stack.callback(pilot.stop)
        t = time.perf_counter()
        # The vision rays and the ideal specular reference do not depend on what a variant
        # may change (BRDF, anisotropy frame, sampling): one of each for all.
        geometry = plan.sim.geometry()
        # a set-up that sees nothing stops here, before any scattered ray is traced
        view = coverage.check_view(geometry.surface_mask, geometry.monitor_mask,
                                   cfg.diagnostics.min_view_fraction, roi=cfg.camera.roi)
        if view.warning:
            plan.notes.append(view.warning)
        t_geometry = time.perf_counter() - t
        plan.steps.advance()
        reference = None
        if plan.decoding:
            reference = specular_reference(cfg, plan.sim, geometry, plan.steps, plan.inputs[3])
            plan.notes += list(reference.notes)
        shared = {"geometry": t_geometry}
        if reference is not None:
            shared["reference"] = reference.seconds
        try:
            if cfg.variants:
                result = run_variants(plan, geometry, reference, tmp, shared)
            else:
                result, _ = run_member(plan, cfg, plan.sim, geometry, tmp,
                                       reference=reference, standalone=True, pilot=pilot)
                result = replace(result, notes=tuple(plan.notes) + result.notes,
                                 timings=dict(result.timings, **shared))
        finally:
            if reference is not None:  # a failed or interrupted run leaves no thread behind
                reference.settle()
        result = replace(result, notes=result.notes + _check_valid(cfg, result))
        timings = dict(result.timings, total=time.perf_counter() - t_start)
        result = replace(result, timings=timings)
        # the folder's size, measured now that everything but the manifest is written
        sizes = folder_sizes(tmp)
        result = replace(result, sizes=sizes)
        summary = tmp / "summary.txt"
        if summary.is_file():
            with open(summary, "a") as fh:
                fh.write("\n" + size_text(sizes) + "\n")
        if cfg.variants:
            write_variants_manifest(tmp, cfg, result)
        else:
            write_run_manifest(tmp, cfg, result, timings)
    return moved(result, tmp, Path(outdir).absolute())


def _check_valid(cfg: RunConfig, result: RunResult) -> tuple[str, ...]:
    """Refuse (before the folder is kept) a decoded run with a fringe direction without a
    valid pixel, naming the stage that removed them (:mod:`pmdsim.studies.valid_pixels`);
    notes when ``diagnostics.allow_no_valid_pixels`` keeps it."""
    from ..studies.valid_pixels import check_valid

    h, w = result.shape
    notes: list[str] = []
    for sub in result.variants or (result,):
        notes += check_valid(sub.statistics or {}, h * w, cfg.diagnostics.allow_no_valid_pixels,
                             sub.config.name if result.variants else "")
    return tuple(notes)


def _check_rule_size(cfg: RunConfig, sim) -> None:
    """Refuse fringes of a Gauss rule (mode ``rule``) of fewer nodes than its error
    statement needs (:data:`pmdsim.render.pilot.MIN_NODES`): its phase is known only to
    within pi, and its widths' phases disagree (the decoding would flag every pixel)."""
    from ..render.pilot import MIN_NODES

    samp = sim.scene.sampling
    if (cfg.patterns.fringes is None or sim.scene.brdf.is_delta or samp.mode != "rule"
            or samp.target_error is not None):
        return
    nodes = samp.rule(sim._lobe).n
    if nodes < MIN_NODES:
        raise ConfigError(
            f"invalid configuration:\n  sampling.n_rays: {samp.n_rays} gives a Gauss rule of "
            f"{nodes} nodes, too few to state its numerical error or to decode the fringes "
            f"(their phases are known only to within pi); raise sampling.n_rays to >= "
            f"{MIN_NODES}, or set sampling.target_error_mrad instead (or mode = 'stratified' "
            "for the paper's sample set)")


def plan_run(cfg: RunConfig, progress: ProgressFn | None, figures: bool | None,
             decode: bool | None, diagnostics: bool) -> RunPlan:
    """Resolve and check the inputs of a run (variant names, dots, monitor images, whether
    the fringes can be decoded) and count its progress steps, before anything is written."""
    figures = cfg.output.figures if figures is None else figures
    check_resources(cfg)  # memory and time from the configuration, before any allocation
    for k, v in enumerate(cfg.variants):
        if v.name in RESERVED_NAMES or v.name.startswith("."):
            raise ConfigError(
                f"invalid configuration:\n  variants.{k}.name: {v.name!r} cannot name a sub-folder of the run (reserved "
                f"or hidden: {sorted(RESERVED_NAMES)}); choose another name")
    members = [(name, c, Simulation.from_config(c)) for name, c in cfg.expand()]
    dots = resolve_dots(cfg.patterns.dots, cfg.monitor.resolution)
    image_files, levels = resolve_images(cfg.patterns.images, cfg.monitor.resolution)
    decoding, notes = chain_mode(cfg, decode)
    for _, c, s in members:  # a rule too small to state its error: refused before any work
        _check_rule_size(c, s)
    for _, c, s in members:  # sensor, display and BRDF that leave no signal: refused here
        notes += [n for n in check_physics(c, s.scene) if n not in notes]
    n_calls = (cfg.patterns.fringes is not None) + bool(dots) + (levels is not None)
    sim = members[0][2]
    n_tiles = math.ceil(sim.shape[0] / sim.tile_rows)
    top_figures = bool(cfg.variants) and figures and (cfg.patterns.fringes is not None
                                                      or bool(dots))
    n_diagnosed = sum(not s.scene.brdf.is_delta for _, _, s in members) if diagnostics else 0
    steps = _Steps(progress, 1 + len(members) * (n_calls * n_tiles + 2 + int(figures))
                   + int(top_figures) + (n_tiles if decoding else 0) + n_diagnosed)
    return RunPlan(cfg, members, RunInputs(dots, image_files, levels, n_tiles), decoding, notes,
                   figures, diagnostics, steps)


def on_cluster(plan: RunPlan, client) -> None:
    """Render the tiles of every member of ``plan`` on ``client``'s cluster (the
    simulations' scheduler becomes ``"distributed"``; the configuration is unchanged)."""
    if "Client" not in type(client).__name__ or not hasattr(client, "get"):
        raise TypeError(f"client: expected a dask.distributed.Client, got {client!r}")
    for _, _, sim in plan.members:
        sim.scheduler = "distributed"


def _current(client):
    """``client`` as the current Dask client of this thread (the tiles' ``dask.compute``
    finds it), or nothing."""
    import contextlib

    return client.as_current() if client is not None else contextlib.nullcontext()


def moved(result: RunResult, tmp: Path, final: Path, **changes) -> RunResult:
    """The result with every path moved from the temporary folder to the final one."""
    def mv(p):
        return None if p is None else final / Path(p).relative_to(tmp)

    return replace(
        result, outdir=mv(result.outdir), dataset_path=mv(result.dataset_path),
        image_paths=tuple(mv(p) for p in result.image_paths),
        figure_paths=tuple(mv(p) for p in result.figure_paths),
        variants=tuple(moved(r, tmp, final) for r in result.variants), **changes)


__all__ = [ "RunPlan", "run_simulation", "plan_run", "on_cluster"]
