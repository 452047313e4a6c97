"""Decode fringe image files (real camera images or a simulation's) into a small output folder.

The job behind ``pmdsim decode IMAGES... -o OUT``: read a TIFF/PNG stack
(:func:`pmdsim.decode.load_image_stack`), decode it with
:func:`pmdsim.decode.decode_sequence` and write, atomically (like a simulation run)::

    OUT/
      pmdsim-run.json      manifest (format "pmdsim-decode/1"), written last
      decode.zarr/         xarray Dataset: wrapped_phase, modulation, amplitude, offset
                           (width, row, col); absolute_phase, monitor_coord_px
                           [, monitor_coord_mm], order_residual, flags, valid (row, col)
      statistics.json      valid fraction, flag counts, modulation, coordinate range
                           [, comparison with the run's own decoding]
      figures/absolute_phase.png, monitor_coord.png, modulation.png, flags.png

Frame order: **width-major, then shift**: all K shifts of the first width, then all K of the
second, ...; frame ``j * K + k`` shows width ``widths[j]`` with shift ``2 pi k / K``. A
multi-page TIFF contributes its pages in order.

With ``from_run`` the widths (ascending: the order of the run's file names, so
``RUN/fringes/x_*.tif`` in shell order is right), K, the monitor extent and pixel pitch come
from a simulation's run folder; given values override them. pmdsim's own TIFFs carry their
direction, width and shift index: when every file has them, the frame order is checked.
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import InputError, MissingInputError
from ..measure import decode as dec
from ..measure.decode_plan import METHODS, unambiguous_range_px
from ..measure.images import load_image_stack
from ..measure.deviation import finite_median
from ..store.folder import MANIFEST, atomic_run_dir, check_output_dir, is_run_dir
from ..store.manifest import write_manifest
from ..store.tables import write_json

DATASET_NAME = "decode.zarr"
FORMAT = "pmdsim-decode/1"


@dataclass(frozen=True)
class DecodeSetup:
    """What the frames are: widths (monitor px, frame order), K, direction, monitor extent
    along it (monitor px), unwrapping method and monitor pixel pitch (mm, optional)."""

    widths_px: tuple[float, ...]
    shifts: int
    direction: str
    extent_px: float
    method: str
    pitch_mm: float | None
    source: str = "command line"


def setup_from_run(run: str | Path, direction: str) -> dict:
    """Widths (ascending), K, extent and pitch of a simulation run folder (or its dataset).

    Raises FileNotFoundError for a folder that is not a run, ValueError for a run without
    fringes or without that direction.
    """
    from ..config import RunConfig
    from ..store.schema import CONFIG_NAME, load_run, run_config

    run = Path(run)
    if (run / CONFIG_NAME).is_file() and is_run_dir(run):
        cfg = RunConfig.model_validate_json((run / CONFIG_NAME).read_text())
    else:
        try:
            cfg = run_config(load_run(run))
        except FileNotFoundError as err:
            raise MissingInputError(f"--from-run: {err}") from None
    fr = cfg.patterns.fringes
    if fr is None:
        raise InputError(f"--from-run: the run {run} has no fringes (patterns.fringes = false)")
    if direction not in fr.directions:
        raise InputError(f"--from-run: the run {run} has no {direction!r} fringes "
                         f"(directions {list(fr.directions)})")
    w, h = cfg.monitor.resolution
    method = cfg.decode.method if hasattr(cfg, "decode") else "hierarchical"
    return {"widths_px": tuple(sorted(float(x) for x in fr.widths_px)), "shifts": fr.shifts,
            "extent_px": float(w if direction == "x" else h),
            "pitch_mm": float(cfg.monitor.pixel_pitch_mm), "method": method,
            "variants": [v.name for v in cfg.variants]}


def make_setup(*, widths=None, shifts=None, direction="x", extent_px=None, method=None,
               pitch_mm=None, from_run=None) -> DecodeSetup:
    """Combine command-line values with those of a run (given values win); ValueError names
    the missing option."""
    if direction not in ("x", "y"):
        raise InputError(f"--direction must be 'x' or 'y', got {direction!r}")
    base: dict = {}
    source = "command line"
    if from_run is not None:
        base = setup_from_run(from_run, direction)
        source = f"run {from_run}"
    widths = tuple(float(x) for x in widths) if widths else base.get("widths_px")
    shifts = shifts if shifts is not None else base.get("shifts")
    extent_px = extent_px if extent_px is not None else base.get("extent_px")
    method = method or base.get("method") or "hierarchical"
    pitch_mm = pitch_mm if pitch_mm is not None else base.get("pitch_mm")
    missing = [name for name, v in (("--widths", widths), ("--shifts", shifts),
                                    ("--extent-px", extent_px)) if v is None]
    if missing:
        raise InputError(f"give {', '.join(missing)} (or --from-run RUN to read them from a "
                         "simulation's run folder)")
    if int(shifts) < 3:
        raise InputError(f"--shifts must be K >= 3 phase shifts, got {shifts}")
    if not extent_px > 0:
        raise InputError(f"--extent-px must be positive monitor px, got {extent_px}")
    if pitch_mm is not None and not pitch_mm > 0:
        raise InputError(f"--pitch-mm must be positive, got {pitch_mm}")
    if method not in METHODS:
        raise InputError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    try:
        reach = unambiguous_range_px(widths, method)
    except ValueError as err:
        raise InputError(f"--widths {list(widths)} do not fit --method {method}: {err}") from None
    if reach < extent_px:
        raise InputError(
            f"--widths {list(widths)} cannot be unwrapped over the monitor with --method "
            f"{method}: they reach {reach:g} monitor px, the monitor spans {extent_px:g} "
            f"(--extent-px); add a wider width (hierarchical) or choose other widths")
    return DecodeSetup(widths, int(shifts), direction, float(extent_px), method, pitch_mm,
                       source)


def _pmdsim_tags(path: Path) -> dict | None:
    """The direction/width/shift tags pmdsim writes into its TIFFs, or None."""
    if path.suffix.lower() not in (".tif", ".tiff"):
        return None
    try:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            if len(tif.pages) != 1:
                return None
            meta = json.loads(tif.pages[0].description or "")
        return meta if {"direction", "width_px", "k"} <= set(meta) else None
    except Exception:  # not pmdsim's: nothing to check
        return None


def check_frame_order(paths: list[Path], setup: DecodeSetup) -> None:
    """If every file carries pmdsim's tags, check they follow width-major, then shift."""
    tags = [_pmdsim_tags(p) for p in paths]
    if len(paths) != len(setup.widths_px) * setup.shifts or any(t is None for t in tags):
        return
    for q, (p, t) in enumerate(zip(paths, tags)):
        j, k = divmod(q, setup.shifts)
        want = (setup.direction, setup.widths_px[j], k)
        got = (t["direction"], float(t["width_px"]), int(t["k"]))
        if got != want:
            raise InputError(
                f"IMAGES: frame {q} ({p.name}) is direction {got[0]}, width {got[1]:g} px, "
                f"shift index {got[2]}, but the order width-major then shift with widths "
                f"{list(setup.widths_px)} and K = {setup.shifts} expects direction {want[0]}, "
                f"width {want[1]:g}, shift {want[2]}: reorder the files or fix --widths/"
                "--direction")


def _stats(res: dec.DecodeResult, setup: DecodeSetup) -> dict:
    valid = res.valid
    n = valid.size
    coord = res.monitor_coord_px[valid]
    med = [finite_median(m, valid) for m in res.modulation]
    return {
        "pixels": n,
        "valid": int(valid.sum()),
        "valid_fraction": float(valid.sum() / n) if n else 0.0,
        "flag_counts": {b.name: int(np.count_nonzero(res.flags & int(b))) for b in dec.DecodeFlag},
        "modulation_median_by_width": med,
        "monitor_coord_px_range": ([float(coord.min()), float(coord.max())] if coord.size
                                   else None),
    }


def _compare_with_run(res: dec.DecodeResult, run: Path, variant: str | None,
                      direction: str) -> dict | None:
    """Decoded-from-files minus the run's own decoding (of its float images), if stored."""
    from ..measure.deviation import deviation_stats
    from ..store.schema import load_run

    try:
        ds = load_run(run, variant=variant)
    except FileNotFoundError:
        return None
    if "variant" in ds.dims or "monitor_coord_px" not in ds:
        return None
    ours = res.monitor_coord_px
    try:
        theirs = ds["monitor_coord_px"].sel(direction=direction).values
        flags = ds["decode_flags"].sel(direction=direction).values
    except Exception:  # noqa: BLE001 - a damaged chunk: the integrity check names it
        from ..store.integrity import check_arrays, check_metadata
        from ..store.schema import dataset_path

        store = dataset_path(run, variant)
        check_arrays(store, check_metadata(store))  # raises InputError naming the chunk
        raise
    both = res.valid & (flags == 0)
    if ours.shape != theirs.shape:
        return None
    s = deviation_stats(ours - theirs, both, res.valid | both).as_dict()
    s["what"] = ("monitor coordinate decoded from the image files minus the run's own decoding "
                 "of its float camera values (monitor px): the integer quantisation of the files")
    s["variant"] = variant
    return s


def _infer_variant(paths: list[Path], run: Path, names: list[str]) -> str | None:
    """The variant whose folder holds all the image files, if any."""
    run = run.resolve()
    for n in names:
        folder = run / n
        if all(folder in p.resolve().parents for p in paths):
            return n
    return None


@dataclass(frozen=True)
class DecodeFilesResult:
    outdir: Path
    setup: DecodeSetup
    statistics: dict
    figure_paths: tuple[Path, ...]
    seconds: dict


def decode_files(paths, outdir, setup: DecodeSetup, *, min_relative_amplitude: float = 0.1,
                 max_order_residual: float = 0.25, overwrite: bool = False,
                 figures: bool = True, from_run=None, variant: str | None = None
                 ) -> DecodeFilesResult:
    """Decode the image files ``paths`` (frame order: width-major, then shift) into ``outdir``.

    Raises
    ------
    FileNotFoundError
        An image file is missing.
    FileExistsError
        ``outdir`` exists (without ``overwrite``) or is not a pmdsim output folder.
    ValueError
        Unreadable images, a wrong number of frames for widths x shifts, frames out of
        order (pmdsim TIFFs), bad thresholds.
    """
    import time

    import xarray as xr

    from .._version import __version__

    t0 = time.perf_counter()
    paths = [Path(p) for p in paths]
    check_output_dir(outdir, overwrite)
    frames = load_image_stack(paths)
    n_w, k = len(setup.widths_px), setup.shifts
    if frames.shape[0] != n_w * k:
        raise InputError(
            f"IMAGES: {frames.shape[0]} frames were read ({len(paths)} files) but "
            f"{n_w} widths x {k} shifts = {n_w * k} are needed (order: width-major, then shift)")
    check_frame_order(paths, setup)
    t_read = time.perf_counter() - t0
    t = time.perf_counter()
    h, w = frames.shape[1:]
    res = dec.decode_sequence(frames.reshape(n_w, k, h, w), setup.widths_px, k, setup.extent_px,
                              setup.method, min_relative_amplitude=min_relative_amplitude,
                              max_order_residual=max_order_residual, dtype=np.float32)
    t_decode = time.perf_counter() - t
    stats = _stats(res, setup)
    if from_run is not None:
        if variant is None:
            try:
                names = json.loads((Path(from_run) / MANIFEST).read_text()).get("variants", [])
            except (OSError, ValueError):
                names = []
            variant = _infer_variant(paths, Path(from_run), names) if names else None
        cmp = _compare_with_run(res, Path(from_run), variant, setup.direction)
        if cmp is not None:
            stats["compared_with_run"] = cmp
    stats = {"setup": {"direction": setup.direction, "widths_px": list(setup.widths_px),
                       "shifts": k, "extent_px": setup.extent_px, "method": setup.method,
                       "pitch_mm": setup.pitch_mm, "from": setup.source,
                       "frame_order": "width-major, then shift"},
             "thresholds": {"min_relative_amplitude": min_relative_amplitude,
                            "max_order_residual": max_order_residual}, **stats}

    ds = xr.Dataset(coords={"width": ("width", np.asarray(setup.widths_px)),
                            "row": ("row", np.arange(h)), "col": ("col", np.arange(w))})
    ds["width"].attrs = {"units": "monitor px", "description": "fringe width = period"}
    W, P = ("width", "row", "col"), ("row", "col")
    ds["wrapped_phase"] = (W, res.wrapped_phase, {"units": "rad", "description": "(-pi, pi]"})
    ds["modulation"] = (W, res.modulation, {"units": "1", "description": "B/A"})
    ds["amplitude"] = (W, res.amplitude, {"units": "image counts", "description": "B"})
    ds["offset"] = (W, res.offset, {"units": "image counts", "description": "A"})
    ds["absolute_phase"] = (P, res.absolute_phase, {
        "units": "rad", "description": f"absolute phase of the finest width "
                                       f"({res.finest_width_px:g} monitor px)"})
    ds["monitor_coord_px"] = (P, res.monitor_coord_px, {
        "units": "monitor px", "description": f"decoded monitor coordinate "
                                              f"({'u' if setup.direction == 'x' else 'v'}; "
                                              "0-based, centres at integers)"})
    if setup.pitch_mm is not None:
        ds["monitor_coord_mm"] = (P, dec.monitor_px_to_mm(res.monitor_coord_px, setup.pitch_mm),
                                  {"units": "mm", "description": "monitor_coord_px x pitch, "
                                                                 "from the centre of pixel 0"})
    ds["order_residual"] = (P, res.order_residual, {"units": "1"})
    ds["flags"] = (P, res.flags, {"description": "1 NAN_INPUT, 2 LOW_AMPLITUDE, "
                                                 "4 ORDER_RESIDUAL, 8 OUT_OF_RANGE, 16 SATURATED; 0 = valid"})
    ds["valid"] = (P, res.valid, {"description": "flags == 0"})
    ds.attrs = {"title": "pmdsim decode", "direction": setup.direction,
                "finest_width_px": res.finest_width_px, "shifts": k, "method": setup.method,
                "extent_px": setup.extent_px, "pitch_mm": setup.pitch_mm or 0.0,
                "frame_order": "width-major, then shift",
                "inputs": json.dumps([str(p) for p in paths]),
                "statistics_json": json.dumps(stats), "pmdsim_version": __version__}

    with atomic_run_dir(outdir, overwrite=overwrite) as tmp:
        t = time.perf_counter()
        ds.to_zarr(tmp / DATASET_NAME, mode="w-", consolidated=False)
        write_json(tmp / "statistics.json", stats)
        figure_paths = []
        if figures:
            from ..report.chain_maps import plot_decoded

            figure_paths = plot_decoded(ds, tmp / "figures")
        seconds = {"read": t_read, "decode": t_decode, "write": time.perf_counter() - t}
        write_manifest(tmp, {
            "format": FORMAT, "pmdsim_version": __version__,
            "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "dataset": DATASET_NAME, "statistics": "statistics.json",
            "figures": [str(p.relative_to(tmp)) for p in figure_paths],
            "inputs": [str(p) for p in paths],
            "timings_s": {k_: round(v, 4) for k_, v in seconds.items()},
        })
    final = Path(outdir).absolute()
    moved = tuple(final / p.relative_to(tmp) for p in figure_paths)
    return DecodeFilesResult(final, setup, stats, moved, seconds)


__all__ = ["DecodeSetup", "DecodeFilesResult", "make_setup", "setup_from_run",
           "check_frame_order", "decode_files"]
