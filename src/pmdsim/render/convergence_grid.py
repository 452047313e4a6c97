"""The grid of pixels that the second embedded rule of a rule's error estimate is rendered
on (every 2nd or 4th camera row and column on large pinhole cameras; all pixels
otherwise): :func:`convergence_stride`, :func:`keep_grid`, :func:`grid_share`."""

from __future__ import annotations
import numpy as np
from ..kernels import bundle as kb

#: The second embedded rule of a rule's error estimate enters nothing but medians over each
#: fringe's pixels (the observed convergence, :func:`pmdsim.render.results.
#: convergence_of_ratios`): where a grid of every 2nd (4th) camera row and column still
#: holds this many pixels, it is rendered on that grid alone (:func:`convergence_stride`).
#: Fig. 3 (1.3 MP): every 4th, 81,920 pixels, 1/16 of the pass's rays (it was 14 % of the
#: render's); the factors moved by 0.02-0.6 % of themselves against all pixels.
CONVERGENCE_GRID_PIXELS = 65536


def convergence_stride(sampling, camera) -> int:
    """The grid step (1, 2 or 4 camera px) of the pixels a render of ``sampling`` traces:
    1 but for the second embedded rule (``mode`` "rule", ``part`` 2) on a pinhole camera of
    at least ``s^2`` :data:`CONVERGENCE_GRID_PIXELS` pixels, then the largest such ``s``;
    the other pixels of that pass are left out (:func:`keep_grid`: NaN, no rays). Cameras
    with sub-rays per pixel (a lens, a footprint) render it on every pixel."""
    if (getattr(sampling, "mode", None) != "rule" or getattr(sampling, "part", 0) != 2
            or not camera.is_simple_pinhole):
        return 1
    n = camera.width * camera.height
    return next((s for s in (4, 2) if n >= s * s * CONVERGENCE_GRID_PIXELS), 1)


def keep_grid(geo, r0: int, r1: int, width: int, stride: int) -> None:
    """Mark the geometry rows ``geo`` of camera rows ``r0:r1`` (``width`` pixels each)
    invalid (``G_VALID = 0``: the kernels trace no ray there and write NaN) but for the
    pixels whose row and column are multiples of ``stride``: the same pixels, whatever
    the tiling."""
    if stride <= 1:
        return
    off = ((np.arange(r0, r1) % stride != 0)[:, None]
           | (np.arange(width) % stride != 0)[None, :]).ravel()
    geo[off, kb.G_VALID] = 0.0


def grid_share(mask, stride: int) -> float:
    """The share of the pixels of ``mask`` (H, W) (surface pixels) on the grid of
    ``stride``: what a pass of that stride traces of a full pass."""
    if stride <= 1:
        return 1.0
    total = int(np.count_nonzero(mask))
    return int(np.count_nonzero(mask[::stride, ::stride])) / total if total else 0.0
