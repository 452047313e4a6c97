"""One member of a run (the run itself, or one variant), as a list of named steps.

:func:`run_member` runs :data:`STEPS` in order over one state object (:class:`Member`):

``render``       the configured patterns through the scattered bundles
``capture``      what the camera writes (the EMVA sensor, when enabled)
``diagnostics``  the run diagnostics start in a thread (they need only the render's scene)
``dataset``      the run's dataset; the image files start being written (a thread)
``decode``       the fringes to phases and monitor coordinates
``compare``      against the ideal specular reference: deviations, masks, statistics
``reconstruct``  the surface's heights and slopes from both directions
``dots``         the dots' second moments (``dots.csv``)
``diagnose``     how converged the sampling is (``diag_*``): the thread's result
``write``        wait for the dataset and the images; config, statistics, summary
``draw``         wait for the figures (the dots' figures of a standalone run drawn here)

After every step the dataset is offered to the two things that run behind the steps: the
dataset writer (:class:`pmdsim.store.writer.DatasetWriter`, which writes into ``run.zarr``
whatever the store does not hold yet) and the figure schedule
(:class:`pmdsim.run.figures.FigureSchedule`, which starts every figure whose data exist).
Nothing waits for them until ``write`` and ``draw``; the run ends when the last ends.
"""

from __future__ import annotations

import contextlib
import json
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..config import RunConfig
from ..measure import chain
from ..render import FringeResult, Geometry, Simulation
from ..report.text import description, summary_text_of
from ..scene.sensor import Sensor, capture_dn
from ..studies import coverage
from ..store.schema import (CONFIG_NAME, DATASET_NAME, assign_to_dataset, build_dataset,
                            dot_dataset_variables)
from .diagnostics import RunDiagnostics, diagnose_run
from .figures import FigureSchedule
from .preload import dataset_imported, import_in_background
from .result import RunResult, _Steps, draw_safely
from .threads import numba_takes_two_threads
from ..store.writer import DatasetWriter
from ..patterns import Dot
from .reference import Reference
from ..store.images import exposure_factor, write_images
from ..store.tables import write_dot_csv, write_json

if TYPE_CHECKING:
    import xarray as xr


class RunInputs(NamedTuple):
    """What a run renders besides its fringes, resolved once for all its members."""

    dots: list[Dot]                  # the dots of ``patterns.dots``
    image_files: list[str]           # the monitor images of ``patterns.images``
    levels: np.ndarray | None        # their levels (Q, Hm, Wm) in [0, 1]
    n_tiles: int                     # tiles per render (progress)


@dataclass(eq=False)
class Member:
    """The state of one member's run, passed from step to step: what it was given (first
    block) and what the steps make of it (the rest, None until made)."""

    cfg: RunConfig
    sim: Simulation
    geometry: Geometry
    folder: Path
    steps: _Steps
    inputs: RunInputs
    reference: Reference | None = None  # when decoding
    standalone: bool = True
    diagnostics: bool = True
    figures: FigureSchedule | None = None
    writer: DatasetWriter | None = None
    images_writer: ThreadPoolExecutor | None = None
    helpers: ThreadPoolExecutor | None = None  # a thread for the diagnostics
    pilot: "EarlyPilot | None" = None  # the rule's choice, started before (start_pilot)

    fringes: FringeResult | None = None
    dot_images: np.ndarray | None = None  # (dots, H, W)
    dot_errors: np.ndarray | None = None  # (dots, H, W) numerical error of the rendered dot images
    images: np.ndarray | None = None      # (monitor images, H, W)
    off_monitor: np.ndarray | None = None  # (H, W) bundles that partly miss the monitor
    phase_error: dict | None = None  # direction -> (H, W) numerical phase error, finest width
    signed_phase_error: dict | None = None  # direction -> (H, W) its estimated signed pattern
    sensor: Sensor | None = None
    exposure: float = float("nan")
    ds: xr.Dataset | None = None   # replaced (never changed) by steps
    decoded: dict | None = None
    measured: chain.ChainResult | None = None
    stats: dict = field(default_factory=dict)        # the chain's (and reconstruction's)
    statistics: dict = field(default_factory=dict)   # statistics.json
    dot_table: list[dict] = field(default_factory=list)
    diagnosed: RunDiagnostics | None = None
    images_written: Future | None = None
    diagnosing: Future | None = None  # the diagnostics' thread (:func:`start_diagnose`)
    image_paths: list[Path] = field(default_factory=list)
    figure_paths: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def dots(self):
        return self.inputs[0]

    @property
    def decoding(self) -> bool:
        return self.reference is not None and self.fringes is not None


# ----------------------------------------------------------------------------- the steps
def render(m: Member) -> None:
    """Render the configured fringes, dots and monitor images (one pass each); check that
    something was seen and flag the bundles that miss the monitor."""
    cfg, sim, steps = m.cfg, m.sim, m.steps
    dots, _, levels, n_tiles = m.inputs
    fr_cfg = cfg.patterns.fringes
    if fr_cfg is not None:
        import warnings

        from ..render.simulation import RuleTooSmall, TargetNotMet

        base = steps.done
        with warnings.catch_warnings(record=True) as caught:  # a note each, no source path
            warnings.simplefilter("always", TargetNotMet)
            warnings.simplefilter("always", RuleTooSmall)
            m.fringes = sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts,
                                           progress=steps.tiles(n_tiles),
                                           choice=None if m.pilot is None else m.pilot.result())
        for w in caught:
            if issubclass(w.category, (TargetNotMet, RuleTooSmall)):
                m.notes.append(str(w.message))
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        smp = m.fringes.sampling or {}
        if smp.get("n_rays") not in (None, sim.scene.sampling.n_rays):
            # a target's pick: the rule rendered is what the rest of the run speaks of
            m.sim = sim = sim.with_sampling(replace(sim.scene.sampling, n_rays=smp["n_rays"],
                                                    target_error=None))
        steps.finish_render(base, n_tiles)
    if dots:
        base = steps.done
        m.dot_images, m.dot_errors = sim.render_dots(dots, progress=steps.tiles(n_tiles),
                                                     with_error=True)
        steps.finish_render(base, n_tiles)
    if levels is not None:
        base = steps.done
        m.images = sim.render_images(levels, progress=steps.tiles(n_tiles))
        steps.finish_render(base, n_tiles)
    if m.fringes is not None and m.fringes.sampling is not None:  # every ray, pilot included
        m.fringes.sampling["rays_traced"] = sim.rays_traced
    # nothing empty is written as if it were a result; bundles off the monitor are flagged
    coverage.check_rendered(None if m.fringes is None else m.fringes.images, m.dot_images)
    m.off_monitor = None if m.fringes is None else coverage.off_monitor_mask(
        m.fringes.f_total, m.fringes.f_hit, m.geometry.surface_mask,
        cfg.diagnostics.max_off_monitor_fraction)


def capture(m: Member) -> None:
    """What the camera writes: digital numbers of the EMVA sensor model (docs/system.md),
    one noise stream per kind of image; nothing without ``[sensor]``."""
    m.sensor = sensor = Sensor.from_config(m.cfg.sensor)
    if not sensor.enabled:
        return
    if m.fringes is not None:
        m.fringes = replace(m.fringes, images=capture_dn(sensor, m.fringes.images, 0))
    if m.dot_images is not None:
        m.dot_images = capture_dn(sensor, m.dot_images, 2)
        m.dot_errors = None  # in digital numbers, with the sensor's noise: not the render's
    if m.images is not None:
        m.images = capture_dn(sensor, m.images, 3)


def describe_error(sampling: dict | None) -> str:
    """How a render's numerical error was estimated, in words."""
    s = sampling or {}
    if s.get("error") == "pilot":
        p = s.get("pilot") or {}
        return (f"{s.get('rule')}: its phase difference to the {p.get('finer_rule')} on a grid "
                f"of every {p.get('grid_step_px')}th row and column, times {p.get('safety')}, "
                "carried to each pixel by the largest over the 3 x 3 grid pixels around it "
                f"(the pixel's own difference at {p.get('local_pixels')} pixels where a lobe "
                "leaves the monitor or the grid is incomplete), plus the float32 storage of "
                "the images (3 sigma) and the kernels' round-off; pi for rules of fewer than "
                "16 nodes")
    if s.get("error") == "embedded":
        return (f"{s.get('rule')} against the embedded {s.get('embedded_rule')}: the phase "
                "difference to the first embedded rule plus 0.1 |dS|/|S| (its error, a bound), "
                "scaled where the rule is asymptotic by the convergence factor observed "
                "against the second (times 10 on the phase difference)")
    if s.get("control_variate"):
        return (f"control variate: {s['control_variate']}; t(0.975) standard error of the "
                f"residual's mean (95 % per pixel) plus the embedded {s.get('embedded_rule')}'s "
                "statement of the smooth part")
    if s.get("error") == "replicates":
        return (f"t(0.975) standard error of the mean of {s.get('passes')} scrambled Sobol "
                f"replicates of {s.get('nodes')} points (95 % per pixel)")
    return "none"


def dataset(m: Member) -> None:
    """The run's dataset from the rendered arrays (the writer starts on it after this
    step), and the image files, written by a thread while the chain runs."""
    dataset_imported()  # xarray, imported while the render ran
    cfg, out, sensor = m.cfg, m.cfg.output, m.sensor
    _, image_files, _, _ = m.inputs
    stacks = [a for a in (None if m.fringes is None else m.fringes.images, m.dot_images,
                          m.images) if a is not None]
    m.exposure = (exposure_factor(stacks, out.bit_depth) if not sensor.enabled
                  else 2.0 ** min(0, out.bit_depth - sensor.bit_depth))
    ds = build_dataset(cfg, m.geometry, m.fringes, m.dots, m.dot_images, image_files,
                       m.images, m.exposure, m.sim.scene.rays_per_pixel)
    if m.off_monitor is not None:
        ds["lobe_off_monitor"] = (("row", "col"), m.off_monitor, {
            "units": "bool", "description": "surface pixels whose bundle puts more than "
            f"diagnostics.max_off_monitor_fraction = {cfg.diagnostics.max_off_monitor_fraction:g}"
            " of its weight off the monitor (never valid; counted)"})
    m.phase_error = None
    pe = None if m.fringes is None else m.fringes.phase_error()  # computed, not stored: once
    if pe is not None:
        from ..measure.numerical import finest_phase_error

        ds["fringe_phase_error"] = (("direction", "width", "row", "col"), pe.astype("float32"), {
            "units": "rad", "description": "numerical (quadrature) error of the phase each "
            "fringe sum decodes to, per direction and width: "
            + describe_error(m.fringes.sampling)})
        m.phase_error = {d: finest_phase_error(m.fringes, d, pe) for d in m.fringes.directions}
    if m.fringes is not None and m.fringes.signed_phase_error is not None:
        m.signed_phase_error = dict(zip(m.fringes.directions, m.fringes.signed_phase_error))
    m.ds = ds
    if m.fringes is not None and m.fringes.sums is not None:
        # the dataset holds the sums' real and imaginary parts: free the complex copy
        # (2 directions x 3 widths x 16 bytes per pixel, 480 MB at 5 MP), and the complex
        # errors of the sums, whose phase statement ``pe`` is all that is used of them
        # (``phase_error()`` returns it from now on; half their memory)
        m.fringes = replace(m.fringes, sums=None,
                            **({} if pe is None else {"sums_err": None, "stated_phase_error": pe}))
    if out.write_images:  # zlib and NumPy release the GIL
        m.images_written = m.images_writer.submit(
            write_images, m.folder, cfg, m.fringes, m.dots, m.dot_images, image_files,
            m.images, m.exposure, workers=1)
    m.steps.advance()


def decode(m: Member) -> None:
    """Decode the surface's fringes (phase shifting, unwrapping, flags)."""
    if not m.decoding:
        return
    sensor = m.sensor
    m.decoded = chain.decode_fringes(m.fringes, m.cfg.monitor.resolution, m.cfg.decode,
                                     sensor.saturation_dn if sensor.enabled else None,
                                     keep_amplitude=False)


def compare(m: Member) -> None:
    """Compare the decoded surface with the decoded specular reference: deviations, masks
    and statistics (with the render's numerical error, when it states one) into the
    dataset."""
    if m.decoded is None:
        return
    cfg, geometry, reference = m.cfg, m.geometry, m.reference
    m.measured = chain.compare(
        m.decoded, reference.decoded, geometry, reference.distance_mm,
        cfg.monitor.pixel_pitch_mm, cfg.decode, len(m.fringes.shifts),
        slope_geometry=chain.SlopeGeometry(geometry.points, m.sim.scene.camera.viewpoint,
                                           m.sim.scene.monitor),
        off_monitor=m.off_monitor, phase_error=m.phase_error,
        signed_phase_error=m.signed_phase_error)
    m.decoded = None
    m.stats = chain.statistics(m.measured, cfg.name)
    if m.fringes is not None and m.fringes.sampling:  # the rule rendered (order used)
        m.stats["sampling"] = m.fringes.sampling
    m.ds = assign_to_dataset(m.ds, m.measured, m.stats)


def reconstruct(m: Member) -> None:
    """Reconstruct the surface from both decoded directions (``[reconstruct]``)."""
    measured, m.measured = m.measured, None  # the dataset holds views of what it needs
    if measured is None:
        return
    from . import reconstruction as recon

    if not recon.wanted(m.cfg, measured.directions):
        return
    rvars, rstats = recon.from_chain(m.cfg, m.sim.scene, measured,
                                     m.reference.reconstruction)
    m.stats.update(rstats)
    coords = {}
    for name in ("surface_x_mm", "surface_y_mm", *recon.PSD_COORDS):
        if name in rvars:
            dims, data, attrs = rvars.pop(name)
            coords[dims[0]] = (dims, data, attrs)
    m.ds = m.ds.assign_coords(coords).assign(rvars).assign_attrs(
        statistics_json=json.dumps(m.stats))


def dots(m: Member) -> None:
    """The dot images' second moments: ``dot_*`` variables and ``dots.csv``."""
    if m.dot_images is None:
        return
    m.dot_table = chain.dot_table(m.dot_images, m.dots, m.cfg.name, dot_errors=m.dot_errors)
    m.ds = m.ds.assign(dot_dataset_variables(m.dot_table))
    write_dot_csv(m.folder / "dots.csv", m.dot_table)


def start_diagnose(m: Member) -> None:
    """Start the run diagnostics (with a lobe) in a thread: they need the rendered scene and
    the bundles off the monitor, nothing of the chain, and run (mostly NumPy, the GIL
    released) beside the decoding, which leaves a core to them (about 1 s less wall on
    Fig. 3). Their compiled kernels may be parallel: in a thread only with a Numba
    threading layer that takes launches from two threads (else :func:`diagnose` runs
    them)."""
    if not m.diagnostics or m.helpers is None or not numba_takes_two_threads():
        return
    m.diagnosing = m.helpers.submit(diagnose_run, m.cfg, m.sim, m.geometry,
                                    exclude=m.off_monitor)


def diagnose(m: Member) -> None:
    """The run diagnostics (with a lobe): maps, summary and warnings (the thread's, when
    :func:`start_diagnose` started one)."""
    m.statistics = dict(m.stats)  # statistics.json: the chain's (when decoded) + diagnostics
    if not m.diagnostics:
        return
    if m.diagnosing is not None:
        m.diagnosed, m.diagnosing = m.diagnosing.result(), None
    else:
        m.diagnosed = diagnose_run(m.cfg, m.sim, m.geometry, exclude=m.off_monitor)
    if m.diagnosed is None:
        return
    m.statistics.setdefault("name", m.cfg.name)
    m.statistics["diagnostics"] = m.diagnosed.summary
    m.ds = m.ds.assign_coords(m.diagnosed.coords).assign(m.diagnosed.variables).assign_attrs(
        statistics_json=json.dumps(m.statistics))
    m.steps.advance()


def write(m: Member) -> None:
    """Wait for the dataset (its last parts, attributes and consolidated metadata) and the
    image files; write config.json, statistics.json and summary.txt."""
    m.writer.finish(m.ds)
    (m.folder / CONFIG_NAME).write_text(m.cfg.model_dump_json(indent=2) + "\n")
    if m.statistics:
        write_json(m.folder / "statistics.json", m.statistics)
        (m.folder / "summary.txt").write_text(summary_text_of(m.statistics))
    m.image_paths = m.images_written.result() if m.images_written is not None else []
    m.steps.advance()


def draw(m: Member) -> None:
    """Wait for what the drawing processes have left to do; a standalone run draws its dot
    figures here (a run with variants draws them for all variants together)."""
    if m.figures is None:
        return
    m.figure_paths = m.figures.paths(m.notes)
    if m.dot_table and m.standalone:
        from ..report.dots import dot_figures

        m.figure_paths += draw_safely(m.notes, "of the dots", dot_figures,
                                      m.folder / "figures", {m.cfg.name: m.dot_images},
                                      {m.cfg.name: m.dot_table}, m.sim, {})
    m.steps.advance()


#: The steps of a member, in order, with the timing (``RunResult.timings``) each adds to.
STEPS = ((render, "render"), (capture, "render"), (start_diagnose, "diagnostics"),
         (dataset, "write"), (decode, "decode"),
         (compare, "decode"), (reconstruct, "decode"), (dots, "decode"),
         (diagnose, "diagnostics"), (write, "write"), (draw, "figures"))


# ----------------------------------------------------------------------------- the pilot
class EarlyPilot:
    """The pilot's choice of the fringes' rule (:meth:`Simulation.choose_rule
    <pmdsim.render.Simulation.choose_rule>`) made in a thread from the start of a run: it
    needs no camera render, and the vision rays and the specular reference leave a core
    idle part of the time (their compiled kernels and the pilot's release the GIL). The
    render step takes its :meth:`result`; :meth:`stop` ends it early (a run that fails
    before its render) and waits for the thread."""

    def __init__(self, sim: Simulation, widths, directions, shifts):
        import threading

        self.cancel = threading.Event()
        pool = ThreadPoolExecutor(1, thread_name_prefix="pmdsim-pilot")
        self.future = pool.submit(sim.choose_rule, widths, directions, shifts, self.cancel)
        pool.shutdown(wait=False)  # its one thread ends with the job

    def result(self):
        """The :class:`~pmdsim.render.simulation.RuleChoice` (waits; raises its error)."""
        return self.future.result()

    def stop(self) -> None:
        """Cancel what is left of the pilot and wait for its thread (its error, if any, is
        the render's to raise, not this one's)."""
        self.cancel.set()
        self.future.exception()


def start_pilot(cfg: RunConfig, sim: Simulation) -> EarlyPilot | None:
    """An :class:`EarlyPilot` for the fringes of ``cfg`` where the pilot applies
    (:meth:`~pmdsim.render.Simulation.pilot_applies`) and Numba takes parallel kernels
    from two threads at once (:func:`~pmdsim.run.threads.numba_takes_two_threads`);
    else None (the render step runs the pilot itself: the same result)."""
    fr = cfg.patterns.fringes
    if fr is None or not sim.pilot_applies() or not numba_takes_two_threads(choose=True):
        return None
    return EarlyPilot(sim, fr.widths_px, fr.directions, fr.shifts)


# ----------------------------------------------------------------------------- the run
def run_member(plan, cfg: RunConfig, sim: Simulation, geometry: Geometry, folder: Path,
               reference=None, standalone: bool = True,
               pilot: "EarlyPilot | None" = None) -> tuple[RunResult, object]:
    """Render one configuration ``cfg`` (no variants; one member of the
    :class:`~pmdsim.run.simulate.RunPlan` ``plan``, which gives the inputs, the progress
    steps and whether to draw and diagnose) and write its images, dataset, config and
    figures into ``folder`` (no manifest): :data:`STEPS`. Returns its result and its
    in-memory dataset.

    With a ``reference`` the fringes are decoded and compared with it (statistics.json,
    summary.txt, chain variables and figures). Dots get their moments (dots.csv); their
    figures are drawn here only for a ``standalone`` run (a run with variants draws them
    for all variants together). With ``diagnostics`` (and a lobe) the run diagnostics go
    into the dataset, statistics.json and summary.txt, and their warnings into the result."""
    folder.mkdir(parents=True, exist_ok=True)
    m = Member(cfg, sim, geometry, folder, plan.steps, plan.inputs, reference, standalone,
               plan.diagnostics, pilot=pilot)
    m.timings = {"render": 0.0, "write": 0.0, "decode": 0.0, "diagnostics": 0.0,
                 "figures": 0.0}
    with contextlib.ExitStack() as stack:
        # on an error: the image thread finishes its file, the dataset writer its part,
        # the drawing processes end (last registered, first undone)
        m.images_writer = stack.enter_context(
            ThreadPoolExecutor(1, thread_name_prefix="pmdsim-images"))
        m.helpers = stack.enter_context(
            ThreadPoolExecutor(1, thread_name_prefix="pmdsim-diagnostics"))
        m.writer = DatasetWriter(folder / DATASET_NAME)
        stack.callback(m.writer.close)
        # xarray (and matplotlib with figures), while the render runs without the GIL
        import_in_background(figures=plan.figures)
        if plan.figures:
            m.figures = FigureSchedule(
                cfg.output.figure_set, reference is not None and cfg.patterns.fringes is not None,
                folder / "figures", cfg.name, description(cfg), sim, cfg.output.figure_workers,
                # no fork while the reference's reconstruction thread runs, nor while the
                # dataset writer writes a part (it holds Dask's locks)
                before_fork=None if reference is None else reference.settle,
                fork_guard=m.writer.paused)
            stack.callback(m.figures.close)
        offered = None
        for step, timing in STEPS:
            t = time.perf_counter()
            step(m)
            m.timings[timing] += time.perf_counter() - t
            if m.ds is not offered and step is not write:  # something new to draw or write
                offered = m.ds
                if m.figures is not None:  # first: a fork waits for a part being written
                    m.figures.offer(m.ds, m.sim)
                m.writer.offer(m.ds)
    return result(m), m.ds


def result(m: Member) -> RunResult:
    """The :class:`RunResult` of a finished member."""
    sim = m.sim
    mask = m.geometry.surface_mask
    # the rule rendered (a target's pick) and every ray the kernels traced, pilot included
    nodes = (m.fringes.sampling.get("nodes") if m.fringes is not None and m.fringes.sampling
             else None) or sim.scene.rays_per_pixel
    rays = int(nodes) * sim.scene.camera.rays_per_pixel
    surface_pixels = int(mask.sum())
    return RunResult(
        outdir=m.folder, dataset_path=m.folder / DATASET_NAME,
        image_paths=tuple(m.image_paths), figure_paths=tuple(m.figure_paths),
        exposure=m.exposure, shape=sim.shape, surface_pixels=surface_pixels,
        rays_per_pixel=rays, rays_traced=sim.rays_traced,
        timings=m.timings, config=m.cfg, statistics=m.statistics, notes=tuple(m.notes),
        warnings=() if m.diagnosed is None else m.diagnosed.warnings)
