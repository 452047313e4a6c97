"""The one image-file reader and PNG writer of pmdsim (tifffile for TIFF, Pillow for PNG
and the other formats Pillow reads): monitor images (:func:`pmdsim.patterns.load_monitor_image`),
camera images (:func:`pmdsim.measure.images.load_image_stack`) and a run's own image files
(:func:`pmdsim.store.images.read_image`) all come through :func:`read_image_file`.

Values are returned as stored (raw integer counts or floats, no rescaling); the caller
decides what they mean.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

TIFF_SUFFIXES = (".tif", ".tiff")
#: Pillow modes of single-channel images (8/16/32-bit integers, float)
GREY_MODES = ("1", "L", "I", "I;16", "I;16B", "I;16L", "F")


@dataclass(frozen=True)
class ImageData:
    """``array``: (H, W), (pages, H, W) for a multi-page TIFF, or (H, W, C) when
    ``channels`` (colour samples: RGB, RGBA, ...); ``what`` describes the layout for
    messages."""

    array: np.ndarray
    channels: bool
    what: str


def read_image_file(path: str | Path) -> ImageData:
    """Read an image file as stored. Raises :class:`OSError`/:class:`ValueError` from the
    libraries for files they cannot read (callers name the file and the setting)."""
    path = Path(path)
    if path.suffix.lower() in TIFF_SUFFIXES:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            arr = np.asarray(series.asarray())
            channels = "S" in series.axes
            return ImageData(arr, channels, f"TIFF axes {series.axes!r}, shape {series.shape}")
    from PIL import Image

    with Image.open(path) as img:
        mode = img.mode
        if mode == "P":  # palette: its colours
            img = img.convert("RGBA" if "transparency" in img.info else "RGB")
            mode = img.mode
        arr = np.asarray(img)
    if mode == "1":
        arr = arr.astype(np.uint8)
    return ImageData(arr, mode not in GREY_MODES, f"{path.suffix.lstrip('.').upper()} mode {mode!r}")


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write a (H, W) uint8 or uint16 grey image as PNG (Pillow)."""
    from PIL import Image

    img = np.asarray(image)
    if img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG: need a (H, W) uint8/uint16 image, got {img.dtype} {img.shape}")
    path = Path(path)
    # Pillow picks the mode from the dtype: uint8 -> "L", uint16 -> "I;16" (16-bit grey PNG)
    Image.fromarray(np.ascontiguousarray(img)).save(path, format="PNG")
    return path
