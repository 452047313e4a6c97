"""Camera images on disk: integer TIFF/PNG files with one exposure factor per run.

Camera values (estimator units, float) become unsigned integers with one *exposure*
factor per run, so that every image of a run is comparable::

    exposure = headroom * (2**bit_depth - 1) / max(finite values of every image of the run)
    pixel    = round(clip(value * exposure, 0, 2**bit_depth - 1)),   NaN (no surface) -> 0
    value    ~ pixel / exposure

``headroom`` is 0.95 by default (the brightest pixel of the run is 95 % of full scale).
TIFF is written with :mod:`tifffile` (zlib, horizontal predictor); PNG (grey, 8 or 16 bit)
with Pillow (:mod:`pmdsim.imagefile`).
"""

from __future__ import annotations
import json
import os
import re
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from typing import Iterable
import numpy as np
from .. import imagefile


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
    from ..kernels.images import finite_max

    peak = 0.0
    for a in arrays:
        a = np.asarray(a)
        if a.size and a.dtype.kind == "f":  # one compiled pass (no mask, no copy)
            m, found = finite_max(a.reshape(-1))
        else:
            finite = np.isfinite(a)
            found = bool(finite.any())
            m = float(a[finite].max()) if found else 0.0
        if found:
            peak = max(peak, float(m))
    if peak <= 0:
        return 1.0
    return headroom * full_scale(bit_depth) / peak


def to_integer_image(values: np.ndarray, exposure: float, bit_depth: int = 16) -> np.ndarray:
    """``round(clip(values * exposure, 0, full scale))`` as uint8/uint16; NaN -> 0."""
    from ..kernels.images import to_integer

    top = full_scale(bit_depth)
    values = np.asarray(values)
    out = np.empty(values.shape, np.uint16 if bit_depth == 16 else np.uint8)
    if values.dtype.kind != "f":  # integers: as floats (the kernel's own types)
        values = values.astype(np.float64)
    # one compiled pass (the numbers of multiply in float64, clip, rint and the cast)
    to_integer(np.ascontiguousarray(values).reshape(-1), float(exposure), float(top),
               out.reshape(-1))
    return out


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
