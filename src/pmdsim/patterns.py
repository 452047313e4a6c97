"""Monitor patterns: fringes, dots, user images. Values are pattern levels in [0, 1]; the
monitor turns them into luminance (gamma, black and white levels).

Conventions (``docs/conventions.md``): monitor pixel centres at integer (u, v); a fringe of
width (period) ``w`` in direction ``x`` is ``0.5 + 0.5 cos(2 pi u / w + delta)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import DotConfig, ImageConfig, InputError, MissingInputError
from .imagefile import read_image_file

DIRECTIONS = ("x", "y")


def phase_shifts(k: int) -> np.ndarray:
    """The K equal phase shifts delta_k = 2 pi k / K, rad."""
    if k < 3:
        raise ValueError(f"shifts: phase shifting needs K >= 3, got {k}")
    return 2.0 * np.pi * np.arange(k) / k


def fringe_value(coord, width: float, shift: float) -> np.ndarray:
    """Pattern level of a fringe at monitor coordinate(s) ``coord`` (monitor px)."""
    return 0.5 + 0.5 * np.cos(2.0 * np.pi * np.asarray(coord, np.float64) / width + shift)


def fringe_image(monitor_shape: tuple[int, int], width: float, direction: str, shift: float) -> np.ndarray:
    """(H, W) pattern levels of one fringe image at the monitor pixel centres."""
    h, w = monitor_shape
    if direction == "x":
        return np.broadcast_to(fringe_value(np.arange(w), width, shift), (h, w)).copy()
    if direction == "y":
        return np.broadcast_to(fringe_value(np.arange(h), width, shift)[:, None], (h, w)).copy()
    raise ValueError(f"direction must be 'x' or 'y', got {direction!r}")


@dataclass(frozen=True)
class Dot:
    """A white square of ``size`` monitor px centred at (u, v) on black: it lights the
    monitor pixels whose centres lie in [u - size/2, u + size/2) x [v - size/2, v + size/2)."""

    u: float
    v: float
    size: float = 15.0

    def as_row(self) -> np.ndarray:
        return np.array([self.u, self.v, self.size / 2.0, self.size / 2.0])

    def image(self, monitor_shape) -> np.ndarray:
        h, w = monitor_shape
        uu = np.arange(w) - self.u
        vv = np.arange(h) - self.v
        h2 = self.size / 2.0
        mu = (uu >= -h2) & (uu < h2)
        mv = (vv >= -h2) & (vv < h2)
        return (mv[:, None] & mu[None, :]).astype(np.float64)


def dot_grid(monitor_shape, grid: tuple[int, int], size: float = 15.0, margin: float = 60.0) -> list[Dot]:
    """Dots on a (columns, rows) grid spread evenly over the monitor, ``margin`` px from the edges."""
    h, w = monitor_shape
    nc, nr = grid
    us = np.linspace(margin, w - 1 - margin, nc) if nc > 1 else np.array([(w - 1) / 2])
    vs = np.linspace(margin, h - 1 - margin, nr) if nr > 1 else np.array([(h - 1) / 2])
    return [Dot(float(np.round(u)), float(np.round(v)), size) for v in vs for u in us]


def load_monitor_image(path: str | Path, monitor_shape: tuple[int, int]) -> np.ndarray:
    """Read a monitor image (PNG/TIFF; grey or RGB(A) -> mean of RGB) as levels in [0, 1].

    Integer images are scaled by their type's maximum. The image must have the monitor's
    resolution.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"patterns.images.files: no such file: {path}")
    try:
        data = read_image_file(path)
    except Exception as exc:  # a corrupt, truncated or mislabelled file
        raise InputError(f"patterns.images.files: cannot read {path}: {exc}") from exc
    img = data.array
    if not data.channels and img.ndim == 3 and img.shape[0] == 1:
        img = img[0]  # a single-page stack
    if not data.channels and img.ndim != 2:
        raise InputError(f"patterns.images.files: {path} holds {data.what}: give one 2-D image")
    if np.issubdtype(img.dtype, np.integer):
        img = img.astype(np.float64) / np.iinfo(img.dtype).max
    img = np.asarray(img, np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=-1)
    if img.shape != tuple(monitor_shape):
        raise InputError(
            f"patterns.images.files: {path} is {img.shape[1]} x {img.shape[0]} px, but the monitor "
            f"is {monitor_shape[1]} x {monitor_shape[0]}: resize the image or fix monitor.resolution"
        )
    return np.clip(img, 0.0, 1.0)


def resolve_dots(dots: DotConfig | None, monitor_resolution) -> list[Dot]:
    """The dots of ``patterns.dots`` on a monitor of ``monitor_resolution`` (width, height):
    the grid (row by row) then the explicit positions."""
    d = dots
    if d is None:
        return []
    mshape = (monitor_resolution[1], monitor_resolution[0])
    dots = []
    if d.grid is not None:
        dots += dot_grid(mshape, d.grid, float(d.size_px), d.margin_px)
    dots += [Dot(float(u), float(v), float(d.size_px)) for u, v in d.positions_px]
    return dots



def resolve_images(images: ImageConfig | None, monitor_resolution) -> tuple[list[str], np.ndarray | None]:
    """Load the monitor images of ``patterns.images`` as levels (Q, Hm, Wm) in [0, 1], each
    the size of a monitor of ``monitor_resolution`` (width, height)."""
    im = images
    if im is None or not im.files:
        return [], None
    mshape = (monitor_resolution[1], monitor_resolution[0])
    levels = np.stack([load_monitor_image(f, mshape) for f in im.files])
    return list(im.files), levels
