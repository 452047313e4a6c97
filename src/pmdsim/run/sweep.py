"""Running a parameter study into one Zarr store, on Dask, resumably.

:func:`run_sweep` plans the sweep (:func:`pmdsim.studies.sweep.plan_sweep`: every field and
every point validated before anything runs), creates the store ``<outdir>/sweep.zarr``
(Zarr 3; created under a temporary name and renamed, so a store is always complete) and
computes the points that are not done yet as Dask tasks. Each task runs the measurement
chain of its point (:func:`pmdsim.studies.sweep.measure_point`) and writes its own region of
every variable, one chunk per point, then sets its element of the ``done`` mask. A sweep
killed at any moment therefore resumes with exactly the unfinished points (a point killed
half-written is not done, and is recomputed and overwritten), and a finished point is never
recomputed.

Store layout (see ``docs/sweeps.md``)::

    sweep.zarr/
      <parameter> ...          one coordinate per swept field (a dimension of its own for a
                               grid; along ``point`` for zip and random designs)
      point_index (sweep dims) flat index of each point (keys its random streams)
      point_seed  (sweep dims) the point's sampling.seed
      done        (sweep dims) bool: the point is complete
      deviation_stats (sweep dims, direction, quantity, statistic)
      modulation_median, modulation_ratio_median (sweep dims, direction, width)
      phase_deviation, slope_deviation_urad (sweep dims, direction, row, col)  decimated
      modulation (sweep dims, direction, width, row, col)                       decimated

Schedulers: ``"threads"`` (default: a local thread pool; the kernels release the GIL),
``"processes"`` (a ``dask.distributed`` LocalCluster of worker processes),
``"synchronous"``, a scheduler address (``tcp://host:8786``) or a
``dask.distributed.Client`` passed as ``client`` (e.g. one of a dask-jobqueue SLURM/PBS
cluster). The results do not depend on the scheduler.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..config import ConfigError, RunConfig, load_config
from ..studies.sweep import (MAP_VARIABLES, POINT_VARIABLES, SweepPlan, measure_point,
                             geometry_key, plan_sweep, reference_key)
from .threads import single_blas

STORE_NAME = "sweep.zarr"
CONFIG_NAME = "config.json"
FORMAT = "pmdsim-sweep/1"

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` did: the store, the points it computed now (flat indices), the
    points it found done, the wall time, the files written beside the store
    (``points.csv``, figures), the physics checks' notes and the ``empty`` points (one line
    each: a fringe direction without a valid pixel, :func:`empty_points`)."""

    outdir: Path
    store: Path
    computed: tuple[int, ...]
    skipped: tuple[int, ...]
    total: int
    seconds: float
    files: tuple = ()
    notes: tuple = ()
    empty: tuple = ()


# ----------------------------------------------------------------------------- the store
def _dims_of(plan: SweepPlan, name: str) -> tuple[str, ...]:
    spec = POINT_VARIABLES.get(name) or MAP_VARIABLES[name]
    return plan.dims + spec[0]


def _extent(plan: SweepPlan, dim: str) -> int:
    return {"direction": len(plan.directions), "quantity": len(_quantities()),
            "statistic": len(_statistics()), "width": plan.n_widths,
            "row": len(plan.map_rows), "col": len(plan.map_cols)}[dim]


def _quantities():
    from ..measure.chain import QUANTITIES
    return QUANTITIES


def _statistics():
    from ..measure.chain import STATISTICS
    return STATISTICS


def _create_store(plan: SweepPlan, path: Path) -> None:
    """Write the empty store (coordinates, metadata, no data chunks) at ``path``."""
    import zarr

    g = zarr.open_group(path, mode="w-", zarr_format=3)
    g.attrs.update({
        "format": FORMAT,
        "design": plan.sweep.design,
        "parameters": list(plan.parameters),
        "dims": list(plan.dims),
        "decimation": plan.sweep.decimation,
        "identity": plan.identity(),
        "config_json": plan.base.model_dump_json(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    })

    def coord(name, values, dims, attrs=None):
        values = np.asarray(values)
        dtype = str if values.dtype.kind == "U" else values.dtype
        a = g.create_array(name, shape=values.shape, dtype=dtype, dimension_names=list(dims),
                           attributes=attrs or {})
        a[...] = values.astype(object) if dtype is str else values

    for p, (dims, values) in plan.coords.items():
        coord(p, values, dims, {"description": f"swept configuration field {p}"})
    if plan.dims == ("point",):
        coord("point", np.arange(plan.shape[0]), ("point",))
    coord("direction", np.array(plan.directions), ("direction",))
    coord("quantity", np.array(list(_quantities())), ("quantity",))
    coord("statistic", np.array(list(_statistics())), ("statistic",))
    coord("width", np.arange(plan.n_widths), ("width",),
          {"description": "index into patterns.fringes.widths_px"})
    if plan.sweep.decimation:
        coord("row", plan.map_rows, ("row",), {"description": "camera pixel row"})
        coord("col", plan.map_cols, ("col",), {"description": "camera pixel column"})
    index = np.zeros(plan.shape, np.int64)
    seed = np.zeros(plan.shape, np.int64)
    for p in plan.points:
        index[p.position] = p.index
        seed[p.position] = p.config.sampling.seed
    coord("point_index", index, plan.dims, {"description": "flat index of the point"})
    coord("point_seed", seed, plan.dims, {"description": "sampling.seed of the point"})
    one = (1,) * len(plan.dims)
    g.create_array("done", shape=plan.shape, dtype=bool, chunks=one, fill_value=False,
                   dimension_names=list(plan.dims),
                   attributes={"description": "True where the point is complete"})
    variables = dict(POINT_VARIABLES)
    if plan.sweep.decimation:
        variables.update(MAP_VARIABLES)
    for name, (dims, dtype, attrs) in variables.items():
        shape = plan.shape + tuple(_extent(plan, d) for d in dims)
        g.create_array(name, shape=shape, dtype=dtype, chunks=one + shape[len(one):],
                       fill_value=np.nan, dimension_names=list(plan.dims + dims),
                       attributes=attrs)


def _open_or_create(plan: SweepPlan, outdir: Path, overwrite: bool) -> Path:
    import zarr

    store = outdir / STORE_NAME
    if outdir.exists() and not outdir.is_dir():
        raise FileExistsError(f"{outdir} exists and is not a folder: choose another -o")
    if store.exists():
        try:
            attrs = dict(zarr.open_group(store, mode="r").attrs)
        except Exception as err:  # noqa: BLE001 - any unreadable store
            raise FileExistsError(f"{store} is not a readable sweep store ({err}); remove it or "
                                  "choose another -o") from None
        if attrs.get("format") != FORMAT:
            raise FileExistsError(f"{store} is not a pmdsim sweep store; choose another -o")
        if attrs.get("identity") != plan.identity():
            if not overwrite:
                raise FileExistsError(
                    f"{outdir} holds a different sweep (its configuration or [sweep] table "
                    "differs): choose another -o, or --overwrite to start again")
            shutil.rmtree(store)
        else:
            return store
    elif outdir.exists() and any(outdir.iterdir()) and not overwrite:
        raise FileExistsError(f"{outdir} exists and is not a sweep folder: choose another -o")
    outdir.mkdir(parents=True, exist_ok=True)
    tmp = outdir / f".{STORE_NAME}.tmp-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        _create_store(plan, tmp)
        tmp.rename(store)
    except BaseException:  # interrupted or failed: no half-made store left behind
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    (outdir / CONFIG_NAME).write_text(plan.base.model_dump_json(indent=2) + "\n")
    return store


def done_mask(store: str | Path) -> np.ndarray:
    """The ``done`` mask of a sweep store (sweep dims, bool)."""
    import zarr

    return np.asarray(zarr.open_group(Path(store), mode="r")["done"][...], bool)


# ----------------------------------------------------------------------------- claim
@contextlib.contextmanager
def claim_sweep(outdir: str | Path):
    """Hold the sweep folder ``outdir`` for the ``with`` block, as ``simulate`` holds its
    run folder (:func:`pmdsim.store.folder_lock.claim_output`: a lock on ``<outdir>.lock``, released
    by the operating system however the process ends). A second sweep on the same folder
    fails at once with :class:`~pmdsim.store.folder_lock.OutputBusy`; under the claim, temporary
    stores (``.sweep.zarr.tmp-<pid>``) of processes that no longer exist are removed."""
    from ..store.folder_lock import claim_output

    outdir = Path(outdir)
    with claim_output(outdir) as lock:
        remove_stale_stores(outdir)
        yield lock


def remove_stale_stores(outdir: str | Path) -> list[Path]:
    """Remove the ``.sweep.zarr.tmp-<pid>`` folders in ``outdir`` of processes that no
    longer run (or of this one); returns them."""
    from ..store.folder_lock import _pid_alive, remove_tree

    outdir = Path(outdir)
    removed = []
    if not outdir.is_dir():
        return removed
    prefix = f".{STORE_NAME}.tmp-"
    for p in outdir.iterdir():
        pid = p.name[len(prefix):] if p.name.startswith(prefix) else ""
        if pid.isdigit() and (int(pid) == os.getpid() or not _pid_alive(int(pid))):
            remove_tree(p, drain=False, settle_s=0.0)
            removed.append(p)
    return removed


def _labels(plan: SweepPlan) -> list[str]:
    return [f"sweep point {p.index} (" + ", ".join(f"{k} = {v!r}" for k, v in p.values.items())
            + ")" for p in plan.points]


def check_sweep_physics(plan: SweepPlan) -> list[str]:
    """The physics sanity of every point (:func:`pmdsim.studies.physics_checks.check_each`), before
    anything is created: a sensor, display or BRDF that leaves no signal is refused naming
    the point, its values and the field; returns the notes, each naming its point."""
    from ..studies.physics_checks import check_each

    return check_each([p.config for p in plan.points], _labels(plan))


def check_sweep_resources(plan: SweepPlan, scheduler: str, num_workers: int | None,
                          local: bool = True):
    """Refuse, before anything is created, a sweep whose largest point does not fit this
    machine's memory with the points that run at once (``local`` schedulers: the workers),
    or whose points together exceed ``compute.max_cpu_hours``; the message names
    ``sweep.parameters``, the point and the setting (:func:`pmdsim.config.resources.check_study`)."""
    from ..config.resources import check_study

    at_once = 1 if scheduler == "synchronous" or not local else (num_workers or os.cpu_count() or 1)
    labels = [f"point {p.index} (" + ", ".join(f"{k} = {v!r}" for k, v in p.values.items()) + ")"
              for p in plan.points]
    return check_study([p.config for p in plan.points], "sweep.parameters", concurrent=at_once,
                       labels=labels, available_bytes=None if local else 2**62)


def connect_scheduler(address: str, timeout_s: float = 5.0):
    """A ``dask.distributed.Client`` of the scheduler at ``address``; an
    :class:`~pmdsim.config.InputError` naming ``--scheduler`` within ``timeout_s`` when
    nothing answers there (or dask.distributed is not installed)."""
    from ..config import InputError

    try:
        from distributed import Client
    except ImportError:
        raise InputError(f"--scheduler {address}: a scheduler address needs dask.distributed "
                         "(pip install 'dask[distributed]')") from None
    try:
        return Client(address, timeout=f"{timeout_s}s")
    except (OSError, TimeoutError) as err:
        raise InputError(f"--scheduler {address}: no Dask scheduler answers there within "
                         f"{timeout_s:g} s ({type(err).__name__}); start one (dask scheduler) "
                         "or use --scheduler threads/processes") from None


# ----------------------------------------------------------------------------- one point
@single_blas
def compute_point(store: str, position: tuple, config_json: str, decimation: int,
                  index: int) -> int:
    """The Dask task of one point: measure it and write its region of every variable, then
    its ``done`` element (last, so that a point killed half-written is not done)."""
    import zarr

    cfg = RunConfig.model_validate_json(config_json)
    values = measure_point(cfg, decimation)
    g = zarr.open_group(store, mode="r+")
    position = tuple(int(i) for i in position)
    for name, data in values.items():
        g[name][position] = data
    g["done"][position] = True
    return index


# ----------------------------------------------------------------------------- scheduling
def _local(tasks, keys, scheduler: str, num_workers, progress):
    import dask
    from dask.callbacks import Callback

    from ..render import local_scheduler

    kwargs = {"scheduler": local_scheduler(scheduler)}
    if num_workers is not None and scheduler != "synchronous":
        kwargs["num_workers"] = num_workers
    total, done = len(tasks), [0]
    wanted = set(keys)

    class _Progress(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            if key in wanted:
                done[0] += 1
                if progress is not None:
                    progress(done[0], total)

    with _Progress():
        return list(dask.compute(*tasks, **kwargs))


def _distributed(tasks, client, progress):
    from distributed import as_completed

    futures = client.compute(tasks)
    out = []
    for k, fut in enumerate(as_completed(futures), start=1):
        out.append(fut.result())
        if progress is not None:
            progress(k, len(tasks))
    return out


@single_blas
def run_sweep(cfg: RunConfig | str | Path, outdir: str | Path, *, scheduler: str = "threads",
              client=None, num_workers: int | None = None,
              progress: ProgressFn | None = None, overwrite: bool = False,
              figures: bool = True) -> SweepResult:
    """Compute every unfinished point of the sweep of ``cfg`` into ``<outdir>/sweep.zarr``.

    Parameters
    ----------
    cfg : RunConfig or path
        A configuration with a ``[sweep]`` table.
    outdir : path
        The sweep folder: ``sweep.zarr`` and ``config.json`` (figures go to ``figures/``,
        see :func:`pmdsim.report.sweep.sweep_figures`). An existing sweep folder of the same
        sweep is resumed.
    scheduler : str
        ``"threads"`` (default), ``"synchronous"``, ``"processes"`` (a local
        ``dask.distributed`` cluster of ``num_workers`` single-threaded processes) or the
        address of a running Dask scheduler (``tcp://host:8786``).
    client : dask.distributed.Client, optional
        Run on this client's cluster (overrides ``scheduler``).
    num_workers : int, optional
        Threads or processes of a local scheduler (default: all cores).
    progress : callable(done, total), optional
        Called after each point.
    overwrite : bool
        Start again when ``outdir`` holds a different sweep.
    figures : bool
        Draw ``figures/phase_rms.png``, ``slope_rms.png`` and ``modulation_ratio.png``
        (:func:`pmdsim.report.sweep.sweep_figures`) at the end; ``points.csv`` is always
        written.

    Raises
    ------
    ConfigError
        Before anything is created or run: no sweep, an unknown field, an invalid point.
    FileExistsError
        ``outdir`` holds something else (or a different sweep, without ``overwrite``).
    """
    t0 = time.perf_counter()
    if not isinstance(cfg, RunConfig):
        cfg = load_config(cfg)
    plan = plan_sweep(cfg)
    is_address = "://" in scheduler or (":" in scheduler and scheduler.split(":")[-1].isdigit())
    if client is None and not is_address and scheduler not in ("threads", "synchronous",
                                                                "processes"):
        raise ConfigError(f"scheduler: {scheduler!r} is not 'threads', 'synchronous', "
                          "'processes' or a scheduler address such as tcp://host:8786")
    outdir = Path(outdir)
    check_sweep_resources(plan, scheduler, num_workers, local=client is None and not is_address)
    notes = check_sweep_physics(plan)  # every point's sensor, display and BRDF, named
    remote = connect_scheduler(scheduler) if client is None and is_address else None
    try:
        with claim_sweep(outdir):
            result = _run_claimed(plan, outdir, overwrite, client or remote, scheduler,
                                  num_workers, progress, figures, t0)
            return replace(result, notes=tuple(notes))
    finally:
        if remote is not None:
            remote.close()


def _run_claimed(plan: SweepPlan, outdir: Path, overwrite: bool, client, scheduler: str,
                 num_workers, progress, figures: bool, t0: float) -> SweepResult:
    """:func:`run_sweep` under the claim on ``outdir``."""
    store = _open_or_create(plan, outdir, overwrite)
    done = done_mask(store)
    # Points that share a geometry and a specular reference run next to each other (each
    # process keeps the last two of each: pmdsim.studies.sweep.GEOMETRIES, REFERENCES).
    todo = sorted((p for p in plan.points if not done[p.position]),
                  key=lambda p: (geometry_key(p.config), reference_key(p.config), p.index))
    skipped = tuple(p.index for p in plan.points if done[p.position])
    import dask

    dec = plan.sweep.decimation
    # Dask runs independent tasks in the order of their keys (dask.order breaks ties by
    # key; the local schedulers take them last first): the rank in ``todo`` keeps the
    # points that share a geometry and a reference together
    keys = [f"pmdsim-sweep-point-{rank:06d}-{p.index}" for rank, p in enumerate(todo)]
    tasks = [dask.delayed(compute_point, pure=False)(
        str(store), p.position, p.config.model_dump_json(), dec, p.index, dask_key_name=k)
        for p, k in zip(todo, keys)]
    if progress is not None:
        progress(0, len(tasks))
    if not tasks:
        computed = []
    elif client is not None:
        computed = _distributed(tasks, client, progress)
    elif scheduler == "processes":
        from distributed import Client, LocalCluster

        n = num_workers or os.cpu_count() or 1
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as c:
            computed = _distributed(tasks, c, progress)
    else:
        computed = _local(tasks, keys, scheduler, num_workers, progress)
    ds = _read_store(store)
    files = [write_points_csv(ds, outdir / "points.csv")]
    if figures:
        from ..report.sweep import sweep_figures

        files += sweep_figures(ds, outdir / "figures")
    return SweepResult(outdir, store, tuple(sorted(computed)), skipped, len(plan.points),
                       time.perf_counter() - t0, tuple(files), empty=empty_points(plan, ds))


def empty_points(plan: SweepPlan, ds) -> tuple[str, ...]:
    """One line per finished point with a fringe direction without a valid pixel (its
    statistics are NaN in the store), unless its ``diagnostics.allow_no_valid_pixels``
    says that is wanted: a sweep with such points is not a complete result (the command
    line exits 1 naming them)."""
    valid = ds["deviation_stats"].sel(quantity="phase_mrad", statistic="n_valid").load()
    done = ds["done"].values
    out = []
    for p in plan.points:
        if not done[p.position] or p.config.diagnostics.allow_no_valid_pixels:
            continue
        n = valid.isel(dict(zip(plan.dims, p.position)))
        dirs = [str(d) for d, v in zip(ds["direction"].values, n.values) if not v > 0]
        if dirs:
            shown = ", ".join(f"{k} = {v!r}" for k, v in p.values.items())
            out.append(f"sweep point {p.index} ({shown}): no valid pixel in the "
                       f"{' and '.join(dirs)} fringes")
    return tuple(out)


def load_sweep(path: str | Path):
    """The sweep store of a sweep folder (or the store itself) as an xarray Dataset
    (lazy). ``ds.done`` marks the finished points; unfinished ones hold NaN."""
    import xarray as xr

    path = Path(path)
    if (path / STORE_NAME).exists():
        path = path / STORE_NAME
    if not (path / "zarr.json").exists():
        raise FileNotFoundError(f"{path}: no sweep store here (expected {STORE_NAME})")
    return xr.open_zarr(path, consolidated=False)


def _read_store(path: Path):
    """The finished store as :func:`load_sweep` opens it, but lazily indexed without Dask
    arrays (the sweep reads only its small variables; importing ``dask.array`` would cost
    about a CPU-second of a sweep's process)."""
    import xarray as xr

    from ..store.lazy_arrays import xarray_without_dask_import

    xarray_without_dask_import()
    return xr.open_zarr(path, consolidated=False, chunks=None)


def points_table(ds) -> list[dict]:
    """One row per point: its parameters, done, and the RMS phase and slope deviations and
    valid fractions per direction (for ``points.csv``)."""
    params = json.loads(ds.attrs["config_json"])["sweep"]["parameters"]
    dims = list(ds.attrs["dims"])
    da = ds["deviation_stats"].transpose(*dims, "direction", "quantity", "statistic")
    stats = np.asarray(da.values, np.float64)
    quantity = {str(q): k for k, q in enumerate(ds["quantity"].values)}
    statistic = {str(q): k for k, q in enumerate(ds["statistic"].values)}
    index = np.asarray(ds["point_index"].transpose(*dims).values)
    values = {p: ds[p].load() for p in params}
    rows = []
    done = ds["done"].transpose(*dims).values
    for pos in np.ndindex(*done.shape):
        sel = dict(zip(dims, pos))
        row = {"point": int(index[pos])}
        for p in params:
            row[p] = values[p].isel({k: v for k, v in sel.items() if k in values[p].dims}).item()
        row["done"] = bool(done[pos])
        s = stats[pos]
        for di, d in enumerate(ds["direction"].values):
            def val(q, st):
                return float(s[di, quantity[q], statistic[st]])
            row[f"{d}_phase_rms_mrad"] = val("phase_mrad", "rms")
            row[f"{d}_slope_rms_urad"] = val("slope_urad", "rms")
            row[f"{d}_valid_fraction"] = val("phase_mrad", "valid_fraction")
        rows.append(row)
    return rows


def write_points_csv(ds, path: str | Path) -> Path:
    """Write :func:`points_table` as CSV."""
    import csv

    rows = points_table(ds)
    path = Path(path)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return path


__all__ = ["run_sweep", "claim_sweep", "remove_stale_stores", "connect_scheduler", "SweepResult", "compute_point", "load_sweep", "done_mask",
           "points_table", "write_points_csv", "STORE_NAME"]
