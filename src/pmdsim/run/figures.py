"""Which figures a run draws, and drawing them in worker processes from the run folder.

Figures are named (:data:`FIGURES`); a run draws ``output.figure_set`` of them:
``summary`` (default: ``setup`` and ``overview``, or without decoding ``setup``,
``fringes`` and ``modulation``) or ``all``. Every figure is drawn from the run's dataset
alone (the set-up figure rebuilds the simulation from ``attrs["config_json"]``), so
:func:`draw_figures` can draw them in separate processes that each open ``run.zarr``, and
``pmdsim report RUN`` can draw any of them later.

A run draws its figures off its critical path (:class:`Drawing`): on Linux a forked
process draws from the run's *in-memory* data while the run goes on (the set-up figure
and the fringe figures as soon as the images exist, the chain's figures as soon as the
deviation and its statistics exist, the reconstruction's figure while the Zarr store is
written), so the run waits only for what is left when everything else is done. The drawing
processes run at nice 10: the run's own threads get the cores first.
Elsewhere (no safe ``fork``) the run draws them itself at the end.

``pmdsim report RUN`` draws from the folder: in separate (spawned) processes that each
open ``run.zarr`` when there are several figures (each imports matplotlib and pmdsim,
about 1.5 s), by default one per core for 4 figures or more (``--workers``).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
from pathlib import Path

from ..store.schema import DATASET_NAME, load_run
from .preload import imports_done

#: Every per-run figure: name -> (file, needs) with needs "fringes" (fringe images in the
#: dataset), "chain" (the measurement chain's variables), "reconstruction" (slope and
#: height error maps of ``[reconstruct]``) or None.
FIGURES = {
    "setup": ("setup.png", None),
    "fringes": ("fringes.png", "fringes"),
    "modulation": ("modulation.png", "fringes"),
    "overview": ("overview.png", "chain"),
    "phase": ("phase.png", "chain"),
    "deviation": ("deviation.png", "chain"),
    "histograms": ("histograms.png", "chain"),
    "modulation_ratio": ("modulation_ratio.png", "chain"),
    "masks": ("masks.png", "chain"),
    "surface_errors": ("surface_errors.png", "reconstruction"),
    "surface_psd": ("surface_psd.png", "psd"),
}
SUMMARY_DECODED = ("setup", "overview", "surface_errors", "surface_psd")
SUMMARY = ("setup", "fringes", "modulation")


def _has(ds, needs: str | None) -> bool:
    if needs is None:
        return True
    if needs == "fringes":
        return "fringes" in ds
    if needs == "reconstruction":
        return "height_error_nm" in ds
    if needs == "psd":
        return "height_error_psd" in ds
    return "phase_deviation" in ds


def figure_names(ds, which="summary") -> list[str]:
    """The figures of ``which`` (``"summary"``, ``"all"`` or a list of names) that the
    dataset ``ds`` can give."""
    if which == "all":
        names = list(FIGURES)
    elif which == "summary":
        names = list(SUMMARY_DECODED if "phase_deviation" in ds else SUMMARY)
    else:
        names = list(which)
        unknown = [n for n in names if n not in FIGURES]
        if unknown:
            raise ValueError(f"unknown figure(s) {unknown}; choose from {list(FIGURES)}")
    return [n for n in names if _has(ds, FIGURES[n][1])]


def _simulation(ds):
    """The simulation a run's dataset was rendered with: its configuration, at the rule a
    target's pilot picked (``statistics_json``'s ``sampling.n_rays``) where it had one."""
    from ..config import RunConfig, with_sampling
    from ..render import Simulation

    cfg = RunConfig.model_validate_json(ds.attrs["config_json"])
    smp = json.loads(ds.attrs.get("statistics_json") or "{}").get("sampling") or {}
    if cfg.sampling.target_error_mrad is not None and smp.get("n_rays"):
        cfg = with_sampling(cfg, n_rays=int(smp["n_rays"]), target_error_mrad=None)
    return Simulation.from_config(cfg)


def draw_one(ds, name: str, folder: Path, run_name: str, description: str = "",
             sim=None) -> Path:
    """Draw figure ``name`` of dataset ``ds`` into ``folder``."""
    from ..report import scene as plot
    from ..report.chain_maps import (plot_deviation, plot_histograms, plot_masks,
                                     plot_modulation_ratio, plot_phase)
    from ..report.overview import plot_overview

    path = Path(folder) / FIGURES[name][0]
    if name == "setup":
        return plot.plot_setup(sim if sim is not None else _simulation(ds), path)
    if name == "fringes":
        return plot.plot_fringe_images(ds, path)
    if name == "modulation":
        return plot.plot_modulation(ds, path)
    if name == "overview":
        return plot_overview(ds, path, run_name, description)
    if name == "surface_errors":
        from ..report.reconstruction import plot_surface_errors
        from ..report.scene import _save

        return _save(plot_surface_errors(ds, run_name, description), path)
    if name == "surface_psd":
        from ..report.psd import plot_surface_psd
        from ..report.scene import _save

        return _save(plot_surface_psd(ds, run_name, description), path)
    fn = {"phase": plot_phase, "deviation": plot_deviation,
          "histograms": plot_histograms,
          "modulation_ratio": plot_modulation_ratio,
          "masks": plot_masks}[name]
    return fn(ds, path, run_name)


def _draw_here(ds, names, folder: Path, run_name: str, description: str, sim,
               failed) -> dict:
    """Draw ``names`` in this process: {name: path} of those drawn; ``failed(name, error)``
    is called for the others (it may raise). The dataset's lazy variables are read on Dask's
    synchronous scheduler (views of arrays this process holds: never shipped to a
    cluster)."""
    import dask

    from ..render import local_scheduler

    drawn = {}
    with dask.config.set(scheduler=local_scheduler("synchronous")):
        for n in names:
            try:
                drawn[n] = draw_one(ds, n, folder, run_name, description, sim)
            except Exception as err:  # noqa: BLE001 - the caller decides (note or raise)
                failed(n, err)
    return drawn


def _draw_from_folder(run_folder: str, name: str, folder: str, run_name: str,
                      description: str) -> str:
    """Worker process job: open the run's dataset and draw one figure."""
    return str(draw_one(load_run(Path(run_folder) / DATASET_NAME, dask=False), name, Path(folder), run_name, description))


def default_workers(n_figures: int) -> int:
    """Processes for ``n_figures`` figures: 1 (the run's own) below 4 figures, else one per
    core, at most one per figure."""
    return 1 if n_figures < 4 else max(1, min(os.cpu_count() or 1, n_figures))


def draw_figures(run_folder: str | Path, names, run_name: str, description: str = "",
                 ds=None, sim=None, workers: int | None = None,
                 folder: str | Path | None = None, notes: list | None = None) -> list[Path]:
    """Draw the figures ``names`` of the run folder ``run_folder`` into ``folder`` (default
    ``run_folder/figures``).

    With one worker they are drawn here, from ``ds`` (and ``sim``) when given, else from the
    folder's dataset; with more, each is drawn by a separate process that opens the
    dataset (which must have been written). Returns the paths in the order of ``names``.

    With ``notes`` (a list), a figure that cannot be drawn is a note appended to it (the
    run's data are complete without it) and the others are still drawn; without, the
    error propagates.
    """
    def failed(name, err) -> None:
        if notes is None:
            raise err
        notes.append(f"figure {name} could not be drawn ({type(err).__name__}: {err}); the "
                     "data are complete (run.zarr, statistics.json)")

    run_folder = Path(run_folder)
    folder = Path(folder) if folder is not None else run_folder / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    names = list(names)
    workers = default_workers(len(names)) if workers is None else workers
    if workers <= 1 or len(names) <= 1:
        if ds is None:
            ds = load_run(Path(run_folder) / DATASET_NAME, dask=False)
        drawn = _draw_here(ds, names, folder, run_name, description, sim, failed)
        return [drawn[n] for n in names if n in drawn]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    # The slowest figures first, so that the pool ends together.
    order = sorted(names, key=lambda n: n != "overview" and n != "deviation")
    with ProcessPoolExecutor(min(workers, len(names)), mp_context=mp.get_context("spawn")) as ex:
        futures = {n: ex.submit(_draw_from_folder, str(run_folder), n, str(folder), run_name,
                                description) for n in order}
        paths = []
        for n in names:
            try:
                paths.append(Path(futures[n].result()))
            except Exception as err:  # noqa: BLE001 - reported in notes (or re-raised)
                failed(n, err)
        return paths


# ----------------------------------------------------------------------------- in a run
def can_fork() -> bool:
    """Whether a run may draw in forked processes: Linux only (macOS's system libraries are
    not fork-safe once threads ran, Windows has no fork)."""
    return sys.platform.startswith("linux")


@contextlib.contextmanager
def _signals_deferred():
    """SIGINT and SIGTERM held back while the block runs, then delivered.

    ``os.fork`` runs Python callbacks around the fork (``logging`` takes and releases its
    lock in them); a KeyboardInterrupt raised inside one is swallowed by the interpreter
    and can leave that lock taken, so that the run hangs at its next log call instead of
    stopping. Outside the main thread (which runs every Python signal handler) nothing is
    needed."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    sigs = (signal.SIGINT, signal.SIGTERM)
    old = {s: signal.getsignal(s) for s in sigs}
    if any(h is None for h in old.values()):  # a handler not set from Python: leave it
        yield
        return
    for s in sigs:
        signal.signal(s, lambda n, frame: pending.append(n))
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        for n in pending:
            signal.raise_signal(n)


@contextlib.contextmanager
def _no_compilation():
    """Numba's compiler lock held while the block runs (it waits for a thread that is
    compiling or loading a kernel): a fork in the middle of another thread's compilation
    would leave the forked process with LLVM's lock taken, and it would hang at its first
    kernel of a new signature (a figure's float32 map). The forked process inherits the
    lock as held by its own (forking) thread, which may take it again: the lock is
    re-entrant."""
    if "numba" not in sys.modules:
        yield
        return
    from numba.core.compiler_lock import global_compiler_lock

    with global_compiler_lock:
        yield


def _draw_in_child(conn, names, folder, run_name, description, ds, sim) -> None:
    """Forked process: draw ``names`` from the inherited in-memory data; send back
    ``[(name, path or None, error or None)]``."""
    import signal

    # the run's process decides: it ends this one if it is interrupted
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    # lower priority than the run's own threads: on a busy machine the chain (the critical
    # path) gets the cores first, the figures the time left over
    os.nice(10)
    errors = {}

    def failed(name, err):  # sent back, reported as a note
        errors[name] = f"{type(err).__name__}: {err}"

    drawn = _draw_here(ds, names, Path(folder), run_name, description, sim, failed)
    conn.send([(n, str(drawn[n]) if n in drawn else None, errors.get(n)) for n in names])
    conn.close()


class Drawing:
    """Figures ``names`` of a run drawn from its in-memory dataset ``ds`` (and ``sim``)
    while the run goes on: by a forked process where :func:`can_fork`, else here, when
    :meth:`paths` is called. The data must not change until then (the run only adds
    variables to a new dataset, and writes).

    :meth:`paths` waits and returns the paths (a figure that could not be drawn is a note
    in ``notes``); :meth:`close` ends the process if it still runs (on an error or an
    interrupt of the run)."""

    def __init__(self, names, folder: Path, run_name: str, description: str, ds, sim,
                 fork: bool | None = None):
        self.names = list(names)
        self.folder = Path(folder)
        self.args = (run_name, description, ds, sim)
        self.proc = self.conn = None
        if not self.names:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        if can_fork() if fork is None else fork:
            import multiprocessing as mp

            imports_done()  # fork after the imports, never in the middle of one
            ctx = mp.get_context("fork")
            self.conn, send = ctx.Pipe(duplex=False)
            self.proc = ctx.Process(target=_draw_in_child, name="pmdsim-figures",
                                    args=(send, self.names, str(self.folder), *self.args),
                                    daemon=True)
            try:
                with _signals_deferred(), _no_compilation():
                    self.proc.start()
            except OSError:  # no fork (e.g. strict memory overcommit): drawn here, later
                send.close()
                self.conn.close()
                self.proc = self.conn = None
                return
            except BaseException:
                send.close()
                self.close()  # interrupted: end the process that was just started
                raise
            send.close()
            self.args = None  # the process holds what it needs

    def paths(self, notes: list | None = None) -> list[Path]:
        def failed(name, msg):
            if notes is None:
                raise RuntimeError(f"figure {name} could not be drawn ({msg})")
            notes.append(f"figure {name} could not be drawn ({msg}); the data are complete "
                         "(run.zarr, statistics.json)")

        if not self.names:
            return []
        if self.proc is None:
            run_name, description, ds, sim = self.args
            return draw_figures(self.folder, self.names, run_name, description, ds=ds,
                                sim=sim, workers=1, folder=self.folder, notes=notes)
        try:
            results = self.conn.recv()
        except EOFError:
            results = [(n, None, f"the drawing process ended with code "
                        f"{self.proc.exitcode}") for n in self.names]
        finally:
            self.close(wait=True)
        out = []
        for name, path, err in results:
            if path is None:
                failed(name, err)
            else:
                out.append(Path(path))
        return out

    def close(self, wait: bool = False) -> None:
        """End the drawing process: with ``wait`` let it finish (it has sent its results),
        else terminate it (the run failed or was interrupted)."""
        if self.proc is None:
            return
        if wait:
            self.proc.join(timeout=30.0)
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join()
        self.conn.close()
        self.proc = None


#: Rough drawing cost of each figure (CPU-s on the Fig. 3 run), to share them out.
_COST = {"overview": 1.5, "deviation": 1.2, "phase": 1.2, "masks": 0.8, "histograms": 0.6,
         "modulation_ratio": 0.8, "fringes": 0.5, "modulation": 0.6, "setup": 0.5,
         "surface_errors": 0.4, "surface_psd": 0.5}
#: Drawing cost (CPU-s, :data:`_COST`) that a process of its own must have by default: a
#: fork of the run's process (gigabytes on a real camera) costs it copy-on-write page
#: faults while the drawing process lives, and the process its own start and teardown
#: (the Fig. 3 run with its four default figures in two processes instead of four: about
#: 0.5 CPU-s less, docs/performance.md).
PROCESS_COST = 2.0


def default_processes(names) -> int:
    """Processes for drawing ``names`` together by default: one per :data:`PROCESS_COST`
    of their drawing cost, at least one, at most one per core and per figure."""
    cost = sum(_COST.get(n, 1.0) for n in names)
    return max(1, min(int(cost // PROCESS_COST), os.cpu_count() or 1, len(names)))


def start_drawings(names, folder: Path, run_name: str, description: str, ds, sim,
                   workers: int | None = None) -> list[Drawing]:
    """:class:`Drawing` jobs for ``names``: ``workers`` processes (default
    :func:`default_processes`; at most one per figure), each given figures of about equal
    drawing cost."""
    names = list(names)
    if not names:
        return []
    workers = min(len(names), workers or default_processes(names))
    groups: list[list[str]] = [[] for _ in range(workers)]
    load = [0.0] * workers
    for n in sorted(names, key=lambda n: -_COST.get(n, 1.0)):
        k = load.index(min(load))
        groups[k].append(n)
        load[k] += _COST.get(n, 1.0)
    return [Drawing(g, folder, run_name, description, ds, sim) for g in groups if g]


def planned_names(which, decoding: bool) -> list[str]:
    """The figures of ``which`` (``"summary"``, ``"all"`` or a list of names) that a run
    that decodes (``decoding``) or not may draw: each is drawn once its dataset holds what
    it needs (:class:`FigureSchedule`)."""
    if which == "summary":
        return list(SUMMARY_DECODED if decoding else SUMMARY)
    if which == "all":
        return list(FIGURES)
    names = list(which)
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        raise ValueError(f"unknown figure(s) {unknown}; choose from {list(FIGURES)}")
    return names


class FigureSchedule:
    """When a run's figures start: the one mechanism for all of them.

    The run calls :meth:`offer` with its dataset after every step; each planned figure
    (:func:`planned_names`) starts (:func:`start_drawings`, forked processes) at the first
    offer whose dataset holds what it needs (:data:`FIGURES`): the set-up and fringe
    figures once the images exist, the chain's once the deviation exists, the
    reconstruction's once the surface is reconstructed. In a run that decodes, the
    figures that need only the images wait for the chain's and are drawn with them (one
    fork of the run's process fewer: :data:`PROCESS_COST`). ``before_fork`` is called before
    the first start (the run waits there for the reference's reconstruction thread);
    every start runs inside ``fork_guard()`` (a context manager: the run's dataset writer
    pauses, so that no thread holds a lock the forked process needs).
    :meth:`paths` waits for them; :meth:`close` ends them (an error or an interrupt)."""

    def __init__(self, which, decoding: bool, folder: Path, run_name: str,
                 description: str, sim, workers: int | None = None, before_fork=None,
                 fork_guard=None):
        self.planned = planned_names(which, decoding)
        self.folder, self.run_name, self.description = Path(folder), run_name, description
        self.sim, self.workers, self.before_fork = sim, workers, before_fork
        self.fork_guard = fork_guard or contextlib.nullcontext
        self.started: list[str] = []
        self.drawings: list[Drawing] = []
        self.held = None  # (names, dataset): figures waiting for the chain's

    def offer(self, ds, sim=None) -> list[str]:
        """Start the planned figures that ``ds`` can give and that have not started;
        returns their names. ``sim``: the run's simulation now (a target's pick replaces
        the one the schedule was made with: the set-up figure draws the rule rendered)."""
        if sim is not None:
            self.sim = sim
        names = [n for n in self.planned
                 if n not in self.started and _has(ds, FIGURES[n][1])]
        chain = [n for n in self.planned if FIGURES[n][1] == "chain"]
        self.held = None
        if chain and not any(n in self.started or n in names for n in chain):
            # the chain's figures are still to come: the others wait to be drawn with them
            # (or, should they never come, at the end: :meth:`paths`)
            early = [n for n in names if FIGURES[n][1] in (None, "fringes")]
            self.held = (early, ds) if early else None
            names = [n for n in names if n not in early]
        self._start(names, ds)
        return names

    def _start(self, names, ds) -> None:
        if not names:
            return
        if self.before_fork is not None:
            self.before_fork()
            self.before_fork = None
        self.started += names
        with self.fork_guard():
            self.drawings += start_drawings(names, self.folder, self.run_name,
                                            self.description, ds, self.sim, self.workers)

    def paths(self, notes: list) -> list[Path]:
        """Wait for every started figure; their paths in the order of :data:`FIGURES` (a
        figure that could not be drawn is a note). Figures held for the chain's, which
        never came, start now."""
        if self.held is not None:
            names, ds = self.held
            self.held = None
            self._start([n for n in names if n not in self.started], ds)
        out: list[Path] = []
        for d in self.drawings:
            out += d.paths(notes)
        order = {n: i for i, n in enumerate(FIGURES)}
        return sorted(out, key=lambda p: order.get(p.stem, len(order)))

    def close(self) -> None:
        for d in self.drawings:
            d.close()


__all__ = ["FIGURES", "figure_names", "draw_figures", "draw_one", "default_workers",
           "Drawing", "start_drawings", "default_processes", "PROCESS_COST", "can_fork",
           "planned_names", "FigureSchedule"]
