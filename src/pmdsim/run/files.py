"""Writing and reading run outputs: integer images, the run dataset, atomic run folders.

Images
------
Camera values (estimator units, float) become unsigned integers with one *exposure*
factor per run, so that every image of a run is comparable::

    exposure = headroom * (2**bit_depth - 1) / max(finite values of every image of the run)
    pixel    = round(clip(value * exposure, 0, 2**bit_depth - 1)),   NaN (no surface) -> 0
    value    ~ pixel / exposure

``headroom`` is 0.95 by default (the brightest pixel of the run is 95 % of full scale).
TIFF is written with :mod:`tifffile`; PNG (grey, 8 or 16 bit) with the small encoder below
(zlib only, no extra dependency).

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
import os
import re
import shutil
import struct
import zlib
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from typing import Iterable, Iterator

import numpy as np

from ..measure import chain

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
    scaled = np.asarray(values, np.float64) * exposure
    scaled = np.where(np.isfinite(scaled), scaled, 0.0)
    out = np.rint(np.clip(scaled, 0.0, top))
    return out.astype(np.uint16 if bit_depth == 16 else np.uint8)


# ----------------------------------------------------------------------------- image files
def _png_bytes(image: np.ndarray) -> bytes:
    """Encode a (H, W) uint8 or uint16 grey image as PNG (no filtering, zlib level 6)."""
    img = np.asarray(image)
    if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG: need a (H, W) uint8/uint16 image, got {img.dtype} {img.shape}")
    h, w = img.shape
    depth = 8 * img.dtype.itemsize
    rows = img.astype(">u2" if depth == 16 else "u1", copy=False)
    raw = np.zeros((h, 1 + w * img.dtype.itemsize), np.uint8)  # filter byte 0 per row
    raw[:, 1:] = rows.view(np.uint8).reshape(h, -1)

    def chunk(tag: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", w, h, depth, 0, 0, 0, 0)  # grey, no interlace
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + chunk(b"IEND", b""))


def read_png(path: str | Path) -> np.ndarray:
    """Read a grey 8/16-bit PNG as written by :func:`write_image` (filter type 0 only)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG file")
    pos, idat, header = 8, [], None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat.append(body)
        pos += 12 + n
    if header is None:
        raise ValueError(f"{path}: PNG without IHDR")
    w, h, depth, colour, _, _, interlace = header
    if colour != 0 or depth not in (8, 16) or interlace:
        raise ValueError(f"{path}: only grey, non-interlaced 8/16-bit PNGs are supported")
    size = depth // 8
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8).reshape(h, 1 + w * size)
    if np.any(raw[:, 0] != 0):
        raise ValueError(f"{path}: filtered PNG rows are not supported by this reader")
    body = np.ascontiguousarray(raw[:, 1:])
    return body.view(">u2" if size == 2 else "u1").reshape(h, w).astype(
        np.uint16 if size == 2 else np.uint8)


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
        tifffile.imwrite(path, np.asarray(image), description=desc, metadata=None,
                         compression="zlib")
    elif image_format == "png":
        path.write_bytes(_png_bytes(image))
    else:
        raise ValueError(f"output.image_format: must be 'tiff' or 'png', got {image_format!r}")
    return path


def read_image(path: str | Path) -> np.ndarray:
    """Read an image written by :func:`write_image` (TIFF or PNG) as stored (integers)."""
    path = Path(path)
    if path.suffix.lower() in (".tif", ".tiff"):
        import tifffile

        return tifffile.imread(path)
    return read_png(path)


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
    if not overwrite:
        raise FileExistsError(
            f"output folder {final} exists: choose another folder or pass --overwrite "
            "(overwrite=True) to replace it"
        )
    if final.is_symlink() or not final.is_dir():
        raise FileExistsError(f"{final} exists and is not a folder: refusing to replace it")
    if not is_run_dir(final, marker) and any(final.iterdir()):
        kind = "pmdsim run folder" if marker == MANIFEST else "pmdsim output folder"
        raise FileExistsError(
            f"{final} is not empty and not a {kind} (no {marker}): refusing to "
            "replace it even with overwrite; choose another output folder"
        )


@contextlib.contextmanager
def atomic_run_dir(outdir: str | Path, overwrite: bool = False, marker: str = MANIFEST) -> Iterator[Path]:
    """Context manager yielding a fresh temporary folder that becomes ``outdir`` on success.

    The temporary folder is the sibling ``<outdir>.tmp-<pid>``. On normal exit it is
    renamed to ``outdir`` (an existing run folder is first moved aside to
    ``<outdir>.old-<pid>`` and deleted only after the rename succeeded, so a failure never
    loses the old run). On an exception the temporary folder is removed and the exception
    propagates; ``outdir`` is untouched.

    Raises
    ------
    FileExistsError
        ``outdir`` exists and ``overwrite`` is false, or it is not a pmdsim run folder.
    """
    final = Path(outdir).absolute()
    check_output_dir(final, overwrite, marker)  # fail before doing any work
    final.parent.mkdir(parents=True, exist_ok=True)
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
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def write_manifest(folder: str | Path, content: dict) -> Path:
    """Write the run manifest (JSON) into ``folder``; call it last."""
    path = Path(folder) / MANIFEST
    path.write_text(json.dumps(content, indent=2, sort_keys=False) + "\n")
    return path


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
                  images, exposure: float) -> list[Path]:
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
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        return list(pool.map(write, jobs))
