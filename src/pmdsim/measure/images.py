"""Reading camera images (TIFF stacks, PNG) into ``(frames, H, W)`` arrays of raw counts."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import numpy as np

from ..config import InputError, MissingInputError
from ..imagefile import read_image_file


_TIFF_SUFFIXES = (".tif", ".tiff")



_PNG_SUFFIXES = (".png",)



def _read_one(path: Path) -> np.ndarray:
    """(pages, H, W) array of one file, raw counts."""
    suffix = path.suffix.lower()
    if suffix not in _TIFF_SUFFIXES + _PNG_SUFFIXES:
        raise InputError(f"paths: {str(path)!r} is neither TIFF (.tif, .tiff) nor PNG (.png)")
    try:
        data = read_image_file(path)
    except Exception as exc:  # a corrupt, truncated or mislabelled file
        raise InputError(f"paths: cannot read image file {str(path)!r}: {exc}") from exc
    img = data.array
    channels = data.what if data.channels else None
    if channels is not None or img.ndim < 2 or img.dtype.kind not in "uif":
        what = channels or f"array shape {img.shape}, dtype {img.dtype}"
        raise InputError(
            f"paths: {str(path)!r} is not a single-channel image ({what}); convert it to "
            "grayscale"
        )
    return img.reshape((-1,) + img.shape[-2:])



def load_image_stack(paths: Iterable[str | os.PathLike]) -> np.ndarray:
    """Read camera images (TIFF or PNG) into one stack.

    Parameters
    ----------
    paths : iterable of str or path-like
        Image files in frame order; ``.tif``/``.tiff`` (read with tifffile; a multi-page file
        contributes all its pages) or ``.png`` (read with Pillow). Single-channel images only;
        raw counts are kept (no rescaling).

    Returns
    -------
    frames : (frames, H, W) ndarray of float64, counts

    Raises
    ------
    FileNotFoundError
        If a file does not exist (the message names it).
    ValueError
        If ``paths`` is empty, a file has an unknown suffix, cannot be read, is not
        single-channel, or differs in size from the first file (the message names it).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    path_list = [Path(p) for p in paths]
    if not path_list:
        raise InputError("paths must name at least one image file")
    stack = []
    shape = dtype = None
    for path in path_list:
        if not path.is_file():
            raise MissingInputError(f"paths: image file {str(path)!r} does not exist")
        img = _read_one(path)
        if shape is None:
            shape, dtype = img.shape[1:], img.dtype
        elif img.shape[1:] != shape:
            raise InputError(
                f"paths: {str(path)!r} has size {img.shape[1:]} but the first image has {shape}"
            )
        elif img.dtype != dtype:
            # 8-bit and 16-bit counts of one sequence differ by a factor ~257: decoding them
            # together gives wrong phases silently
            raise InputError(
                f"paths: {str(path)!r} holds {img.dtype} values but the first image holds "
                f"{dtype}: all frames of a sequence must come from one camera setting (convert "
                "them to one bit depth first)")
        stack.append(img.astype(np.float64))
    return np.concatenate(stack, axis=0)
