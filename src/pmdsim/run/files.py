"""Writing and reading run outputs: integer images, the run dataset, atomic run folders.

Images
------
Camera values (estimator units, float) become unsigned integers with one *exposure*
factor per run, so that every image of a run is comparable::

    exposure = headroom * (2**bit_depth - 1) / max(finite values of every image of the run)
    pixel    = round(clip(value * exposure, 0, 2**bit_depth - 1)),   NaN (no surface) -> 0
    value    ~ pixel / exposure

``headroom`` is 0.95 by default (the brightest pixel of the run is 95 % of full scale).
TIFF is written with :mod:`tifffile` (zlib, horizontal predictor); PNG (grey, 8 or 16 bit)
with Pillow (:mod:`pmdsim.imagefile`).

Run folders
-----------
:func:`atomic_run_dir` writes a run into a temporary sibling folder ``<outdir>.tmp-<pid>``
and renames it to ``<outdir>`` only when everything is written: a folder named ``outdir``
is always complete. A run folder carries a manifest ``pmdsim-run.json`` (written last);
an existing folder is replaced only when asked (``overwrite=True``) and only if it is a
pmdsim run folder or empty, so a mistyped ``-o`` can never delete unrelated data.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import warnings
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from typing import Iterable, Iterator

import numpy as np

from .. import imagefile
from ..measure import chain
from . import claim

#: File name of the manifest that marks a complete pmdsim run folder.
MANIFEST = "pmdsim-run.json"
#: Default fraction of full scale given to the brightest pixel of a run.
HEADROOM = 0.95
IMAGE_SUFFIX = {"tiff": ".tif", "png": ".png"}


# ----------------------------------------------------------------------------- scaling
def full_scale(bit_depth: int) -> int:
    """Largest integer value of an image of ``bit_depth`` bits (8 -> 255, 16 -> 65535)."""
    if bit_depth not in (8, 16):
        raise ValueError(f"output.bit_depth: must be 8 or 16, got {bit_depth}")
    return (1 << bit_depth) - 1


def exposure_factor(arrays: Iterable[np.ndarray], bit_depth: int = 16,
                    headroom: float = HEADROOM) -> float:
    """One exposure factor for all ``arrays`` (camera values): the brightest finite value
    maps to ``headroom`` x full scale. Returns 1.0 when there is no positive finite value."""
    if not 0 < headroom <= 1:
        raise ValueError(f"headroom must be in (0, 1], got {headroom}")
    peak = 0.0
    for a in arrays:
        a = np.asarray(a)
        finite = np.isfinite(a)
        if finite.any():
            peak = max(peak, float(a[finite].max()))
    if peak <= 0:
        return 1.0
    return headroom * full_scale(bit_depth) / peak


def to_integer_image(values: np.ndarray, exposure: float, bit_depth: int = 16) -> np.ndarray:
    """``round(clip(values * exposure, 0, full scale))`` as uint8/uint16; NaN -> 0."""
    top = full_scale(bit_depth)
    # one float64 temporary, changed in place (the same numbers as the plain expression)
    scaled = np.multiply(values, exposure, dtype=np.float64)
    scaled[~np.isfinite(scaled)] = 0.0
    np.clip(scaled, 0.0, top, out=scaled)
    np.rint(scaled, out=scaled)
    return scaled.astype(np.uint16 if bit_depth == 16 else np.uint8)


# ----------------------------------------------------------------------------- image files
def write_image(path: str | Path, image: np.ndarray, image_format: str = "tiff",
                metadata: dict | None = None) -> Path:
    """Write one (H, W) uint8/uint16 image as TIFF or PNG; returns the path.

    ``metadata`` (JSON-serialisable) goes into the TIFF ImageDescription tag.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if image_format == "tiff":
        import tifffile

        desc = json.dumps(metadata) if metadata else None
        # zlib level 3 with horizontal differencing (TIFF predictor 2), lossless: on the
        # Fig. 3 run 1.0 CPU-s for 7.3 MB of TIFFs, where zlib's default level 6 takes 1.8 s
        # for 4.6 MB (the TIFFs are written beside the chain, on its cores)
        tifffile.imwrite(path, np.asarray(image), description=desc, metadata=None,
                         compression="zlib", compressionargs={"level": 3}, predictor=True)
    elif image_format == "png":
        imagefile.write_png(path, image)
    else:
        raise ValueError(f"output.image_format: must be 'tiff' or 'png', got {image_format!r}")
    return path


def read_image(path: str | Path) -> np.ndarray:
    """Read an image written by :func:`write_image` (TIFF or PNG) as stored (integers),
    with the one reader of the package (:func:`pmdsim.imagefile.read_image_file`)."""
    return imagefile.read_image_file(path).array


# ----------------------------------------------------------------------------- run folders
def is_run_dir(path: str | Path, marker: str = MANIFEST) -> bool:
    """True if ``path`` is a folder with a pmdsim manifest (a complete run); ``marker`` names
    the manifest file of other kinds of output folders (e.g. a convergence study)."""
    return (Path(path) / marker).is_file()


def check_output_dir(final: str | Path, overwrite: bool = False, marker: str = MANIFEST) -> None:
    """Raise :class:`FileExistsError` unless ``final`` may be (re)created as a run folder:
    it does not exist, or ``overwrite`` is true and it is an empty folder or a folder with
    the manifest ``marker``."""
    final = Path(final)
    if not final.exists() and not final.is_symlink():
        return
    if final.is_symlink() or not final.is_dir():
        what = "a link" if final.is_symlink() else "a file, not a folder"
        raise FileExistsError(f"output folder {final} exists and is {what}: choose another "
                              "output folder (-o); --overwrite replaces only a run folder")
    if not overwrite:
        raise FileExistsError(
            f"output folder {final} exists: choose another folder or pass --overwrite "
            "(overwrite=True) to replace it"
        )
    if not is_run_dir(final, marker) and any(final.iterdir()):
        kind = "pmdsim run folder" if marker == MANIFEST else "pmdsim output folder"
        raise FileExistsError(
            f"{final} is not empty and not a {kind} (no {marker}): refusing to "
            "replace it even with overwrite; choose another output folder"
        )


@contextlib.contextmanager
def atomic_run_dir(outdir: str | Path, overwrite: bool = False, marker: str = MANIFEST) -> Iterator[Path]:
    """Context manager yielding a fresh temporary folder that becomes ``outdir`` on success.

    The output folder is first *claimed* (:func:`pmdsim.run.claim.claim_output`, a lock on
    ``<outdir>.lock``): a second run on the same target fails at once with
    :class:`~pmdsim.run.claim.OutputBusy`, before any computation. Under the claim,
    temporary folders that dead processes left (``<outdir>.tmp-<pid>``, ``.old-<pid>``) are
    removed (a :class:`StaleTemporaryWarning` says which).

    The temporary folder is the sibling ``<outdir>.tmp-<pid>``. On normal exit it is
    renamed to ``outdir`` (an existing run folder is first moved aside to
    ``<outdir>.old-<pid>`` and deleted only after the rename succeeded, so a failure never
    loses the old run). On an exception, SIGINT (KeyboardInterrupt) or SIGTERM (turned into
    :class:`~pmdsim.run.claim.Terminated` inside the block) the temporary folder is removed
    after the writers have stopped, and the exception propagates; ``outdir`` is untouched.

    Raises
    ------
    FileExistsError
        ``outdir`` exists and ``overwrite`` is false, or it is not a pmdsim run folder;
        :class:`~pmdsim.run.claim.OutputBusy` when another live run writes it.
    """
    final = Path(outdir).absolute()
    check_output_dir(final, overwrite, marker)  # fail before doing any work
    final.parent.mkdir(parents=True, exist_ok=True)
    with claim.signals_as_interrupt(), claim.claim_output(final):
        removed, kept = claim.remove_stale(final)
        for p in removed:
            warnings.warn(f"removed {p}: the temporary folder of an interrupted run whose "
                          "process no longer exists", StaleTemporaryWarning, stacklevel=3)
        for p in kept:
            warnings.warn(f"{p} belongs to a running process that does not hold the "
                          "output's lock (an older pmdsim?): left alone", StaleTemporaryWarning,
                          stacklevel=3)
        tmp = final.with_name(f"{final.name}.tmp-{os.getpid()}")
        if tmp.exists():
            shutil.rmtree(tmp)  # leftover of a crashed run of this very process id
        tmp.mkdir()
        try:
            yield tmp
            check_output_dir(final, overwrite, marker)  # it may have appeared meanwhile
            old = None
            if final.exists():
                old = final.with_name(f"{final.name}.old-{os.getpid()}")
                if old.exists():
                    shutil.rmtree(old)
                os.replace(final, old)
            try:
                os.replace(tmp, final)
            except BaseException:
                if old is not None:
                    os.replace(old, final)
                raise
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        except BaseException:
            claim.remove_tree(tmp)
            raise


class StaleTemporaryWarning(UserWarning):
    """A temporary folder of an earlier, interrupted run was found next to the output."""


def json_safe(obj):
    """NaN/inf -> None and NumPy scalars -> Python numbers, recursively (strict JSON: a
    result file never holds NaN, which strict parsers refuse; None reads as "undefined")."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def write_json(path: str | Path, content, indent: int | None = 2) -> Path:
    """Write ``content`` as strict JSON (:func:`json_safe`; ``allow_nan=False``)."""
    path = Path(path)
    path.write_text(json.dumps(json_safe(content), indent=indent, allow_nan=False) + "\n")
    return path


def write_manifest(folder: str | Path, content: dict) -> Path:
    """Write the run manifest (JSON) into ``folder``; call it last."""
    return write_json(Path(folder) / MANIFEST, content)


# ----------------------------------------------------------------------------- dataset
def write_dataset(ds, path: str | Path) -> Path:
    """Write an xarray Dataset to Zarr (format 3, no consolidated metadata)."""
    path = Path(path)
    ds.to_zarr(path, mode="w-", consolidated=False)
    return path


def open_dataset(path: str | Path):
    """Open a Zarr dataset written by :func:`write_dataset` (lazily, Dask-backed)."""
    import xarray as xr

    return xr.open_zarr(Path(path), consolidated=False)


def write_dot_csv(path, table: list[dict]) -> None:
    """Write :func:`dot_table` rows as CSV (header :data:`DOT_COLUMNS`)."""
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(chain.DOT_COLUMNS))
        w.writeheader()
        for r in table:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k])
                        for k in chain.DOT_COLUMNS})


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



def write_images(folder: Path, cfg, fringes, dots, dot_images, image_files,
                 images, exposure: float, workers: int | None = None) -> list[Path]:
    """Write every camera image of a run as an integer image file (``exposure``, see the
    module docstring); ``workers`` threads (default up to 4) convert and compress."""
    out = cfg.output
    suffix = IMAGE_SUFFIX[out.image_format]
    jobs = []

    def put(rel: str, values: np.ndarray, meta: dict) -> None:
        jobs.append((rel, values, dict(meta, exposure=exposure,
                                       scaling="pixel = value * exposure; 0 = no surface")))

    def write(job) -> Path:
        rel, values, meta = job
        img = to_integer_image(values, exposure, out.bit_depth)
        return write_image(folder / rel, img, out.image_format, meta)

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
    workers = min(4, os.cpu_count() or 1) if workers is None else workers
    if workers <= 1:
        return [write(job) for job in jobs]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(write, jobs))


def folder_sizes(folder: str | Path) -> dict:
    """Bytes of a run folder: ``total`` and its parts ``run.zarr`` (every dataset, variants
    included), ``images`` (fringes/, dots/, images/), ``figures`` and ``other``."""
    folder = Path(folder)
    sizes = {"total": 0, "run.zarr": 0, "images": 0, "figures": 0, "other": 0}
    for p in folder.rglob("*"):
        if not p.is_file():
            continue
        n = p.stat().st_size
        parts = p.relative_to(folder).parts
        if any(x.endswith(".zarr") for x in parts):
            key = "run.zarr"
        elif any(x in ("fringes", "dots", "images") for x in parts[:-1]):
            key = "images"
        elif "figures" in parts[:-1]:
            key = "figures"
        else:
            key = "other"
        sizes[key] += n
        sizes["total"] += n
    return sizes


def size_text(sizes: dict) -> str:
    """``run folder: 86.3 MB (run.zarr 73.1 MB, images 11.0 MB, figures 1.9 MB)``"""
    mb = lambda n: f"{n / 1e6:.1f} MB"  # noqa: E731
    parts = ", ".join(f"{k} {mb(sizes[k])}" for k in ("run.zarr", "images", "figures")
                      if sizes.get(k))
    return f"run folder: {mb(sizes.get('total', 0))}" + (f" ({parts})" if parts else "")
