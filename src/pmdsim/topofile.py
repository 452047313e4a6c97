"""Measured topographies from instrument files (layer 1, beside :mod:`pmdsim.imagefile`).

:func:`read_topography` reads a height map with its sample spacing and returns a
:class:`Topography` in millimetres (rows along y, columns along x), levelled and with the
non-measured points and outliers handled as asked:

- ``.x3p`` (ISO 25178-72) through **x3pio** (MIT; ``pip install pmdsim[topography]``):
  coordinates in metres in the file, spacing from its axes;
- the instrument formats read through **surfalize** (GPL-3.0, an optional extra of its own:
  ``pip install pmdsim[instruments]``) *that are tested* on files written by an independent
  writer or by surfalize's own writer (values, orientation and dx != dy spacing checked,
  ``tests/test_topography.py``): Digital Surf ``.sur``, ISO 25178-71 ``.sdf``, Alicona
  ``.al3d``, ``.tmd`` (TrueMap) and surfalize's own ``.sflz``; surfalize works in
  micrometres;
- plain arrays ``.npy``, ``.csv``/``.txt`` and float ``.tif``/``.tiff`` (no units and no
  spacing inside: the caller gives ``spacing_mm`` and ``height_unit``).

Every failure is a :class:`~pmdsim.config.files.FileInputError` (an ``InputError`` and a
``ConfigError``: exit code 2 in the command line; a missing file a ``MissingFileError``)
that names the configuration field and the file, raised before any long work. Plain arrays
are read by the readers of :data:`pmdsim.config.files.HEIGHT_MAP_READERS`. The formats of :data:`NOT_READ` are refused with the reason: no reader of them could be
tested here (surfalize reads more of them, but a file laid out as Gwyddion's reader
describes Sensofar ``.plu`` reads two values shifted in surfalize 0.19.2, and its ``.xyz``
spacing is (max - min) / n instead of / (n - 1)); Zygo ``.datx`` (HDF5) is read by neither
maintained library (surfalize 0.19.2, x3pio 2.0.0) and its HDF5 layout is not published.
Export such a measurement as X3P or SDF from the instrument software.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import files
from .config.files import FileInputError as InputError
from .config.files import MissingFileError as MissingInputError

#: Suffixes read by x3pio, by surfalize, and as plain arrays.
X3P_SUFFIXES = (".x3p",)
SURFALIZE_SUFFIXES = (".sur", ".sdf", ".al3d", ".tmd", ".sflz")
#: Instrument formats that are refused, with the reason (module doc).
_UNTESTED = ("surfalize reads it, but no file of it could be checked against an independent "
             "writer or a sample file, so its values and spacing are not trusted here")
NOT_READ = dict.fromkeys((".plux", ".vk3", ".vk4", ".vk6", ".vk7", ".lext", ".oir", ".poir",
                          ".opd", ".zon", ".nms", ".os3d", ".gwy", ".hdat", ".zmg", ".fits",
                          ".fit", ".fts", ".dat"), _UNTESTED) | {
    ".plu": "a file laid out as Gwyddion's reader describes (the grid's size before the "
            "heights) reads shifted by two values in surfalize 0.19.2; which layout real files "
            "have could not be checked",
    ".xyz": "surfalize 0.19.2 takes the spacing as (max - min) / n instead of / (n - 1), and "
            "assumes metres",
    ".datx": "Zygo's HDF5 layout is not published and no maintained reader (surfalize 0.19.2, "
             "x3pio 2.0.0) reads it",
}
ARRAY_SUFFIXES = tuple(files.HEIGHT_MAP_READERS)
HEIGHT_UNITS_MM = {"mm": 1.0, "um": 1e-3, "nm": 1e-6, "m": 1e3}
LEVELS = ("none", "mean", "plane")
FILLS = ("error", "nearest", "mean")


@dataclass(frozen=True, eq=False)
class Topography:
    """A height map: ``heights`` (ny, nx) float64 mm, rows along y, columns along x,
    spacing ``dx``, ``dy`` mm. ``invalid`` counts the points that were not measured or were
    outliers (filled as asked); ``source`` is the file, ``reader`` what read it."""

    heights: np.ndarray
    dx: float
    dy: float
    source: str = ""
    reader: str = "array"
    invalid: int = 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def size_mm(self) -> tuple[float, float]:
        ny, nx = self.heights.shape
        return nx * self.dx, ny * self.dy


def is_instrument_file(path) -> bool:
    """True for a format that carries its own spacing and units (X3P and surfalize's)."""
    return Path(path).suffix.lower() in X3P_SUFFIXES + SURFALIZE_SUFFIXES


def read_topography(path, field: str = "surface.file", *, spacing_mm=None,
                    height_unit: str = "mm", level: str = "none", fill: str = "error",
                    outlier_sigma: float | None = None, min_points: int = 4) -> Topography:
    """A measured height map from ``path`` in mm (see the module doc for the formats).

    ``spacing_mm`` (dx, dy) and ``height_unit`` are needed for plain arrays and ignored for
    instrument files (units and spacing from the file). ``level``: ``"none"``, ``"mean"``
    (subtract the mean) or ``"plane"`` (subtract the least-squares plane of the valid
    points). ``outlier_sigma``: points farther than this many robust standard deviations
    (1.4826 x the median absolute deviation) from the levelled heights are treated as not
    measured. ``fill`` says what happens to the points not measured (NaN in the file) and
    the outliers: ``"error"`` (refuse), ``"nearest"`` (the nearest valid point) or
    ``"mean"`` (the mean height). ``field`` names the configuration field in errors."""
    path = Path(path)
    if level not in LEVELS:
        raise InputError(f"{field}: level must be one of {LEVELS}, got {level!r}")
    if fill not in FILLS:
        raise InputError(f"{field}: fill must be one of {FILLS}, got {fill!r}")
    if not path.is_file():
        raise MissingInputError(f"{field}: topography file not found: {path} (check the path)")
    suffix = path.suffix.lower()
    if suffix in X3P_SUFFIXES:
        z, dx, dy, reader = _read_x3p(path, field)
    elif suffix in SURFALIZE_SUFFIXES:
        z, dx, dy, reader = _read_surfalize(path, field)
    elif suffix in ARRAY_SUFFIXES:
        if spacing_mm is None:
            raise InputError(f"{field}: {path} holds no sample spacing; give spacing_mm = "
                             "[dx, dy] (or use an instrument file: X3P, .sur, .plu, ...)")
        if height_unit not in HEIGHT_UNITS_MM:
            raise InputError(f"{field}: height_unit must be one of {tuple(HEIGHT_UNITS_MM)}")
        z = _read_array(path, field) * HEIGHT_UNITS_MM[height_unit]
        dx, dy = (float(v) for v in spacing_mm)
        reader = "array"
    elif suffix in NOT_READ:
        raise InputError(f"{field}: {path}: {suffix} files are not read ({NOT_READ[suffix]}); "
                         "export the measurement as X3P (ISO 25178-72) or SDF (ISO 25178-71) "
                         "from the instrument software")
    else:
        raise InputError(f"{field}: {path}: unknown topography format {suffix!r}; read are "
                         f"{', '.join(X3P_SUFFIXES + SURFALIZE_SUFFIXES + ARRAY_SUFFIXES)}")
    z = np.asarray(z, np.float64)
    if z.ndim != 2 or min(z.shape) < min_points:
        raise InputError(f"{field}: {path} must hold a 2-D grid of at least {min_points} x "
                         f"{min_points} heights, got shape {z.shape}")
    if not (np.isfinite(dx) and np.isfinite(dy) and dx > 0 and dy > 0):
        raise InputError(f"{field}: {path}: the sample spacing must be positive, got {dx}, {dy} mm")
    z, invalid = clean_heights(z, level=level, fill=fill, outlier_sigma=outlier_sigma,
                               what=f"{field}: {path}")
    return Topography(z, float(dx), float(dy), str(path), reader, invalid)


def clean_heights(z, *, level="none", fill="error", outlier_sigma=None, what="heights"):
    """Level ``z``, mark outliers, fill invalid points: (heights, number of invalid points)."""
    z = np.array(z, np.float64)
    valid = np.isfinite(z)
    if valid.sum() < 3:
        raise InputError(f"{what}: fewer than 3 measured points")
    z = _level(z, valid, level)
    if outlier_sigma is not None:
        if not outlier_sigma > 0:
            raise InputError(f"{what}: outlier_sigma must be > 0, got {outlier_sigma}")
        med = np.median(z[valid])
        mad = 1.4826 * np.median(np.abs(z[valid] - med))
        if mad > 0:
            valid &= np.abs(z - med) <= outlier_sigma * mad
            z = _level(np.where(valid, z, np.nan), valid, level)
    invalid = int((~valid).sum())
    if invalid:
        if fill == "error":
            raise InputError(f"{what}: {invalid} points not measured (NaN) or outliers; set "
                             "fill = 'nearest' or 'mean' to fill them")
        if fill == "mean":
            z = np.where(valid, z, z[valid].mean())
        else:
            from scipy import ndimage

            idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
            z = z[tuple(idx)]
    return z, invalid


def _level(z, valid, level):
    if level == "none":
        return z
    if level == "mean":
        return z - z[valid].mean()
    ny, nx = z.shape
    yy, xx = np.mgrid[0:ny, 0:nx].astype(np.float64)
    a = np.stack([np.ones(valid.sum()), xx[valid], yy[valid]], -1)
    c, *_ = np.linalg.lstsq(a, z[valid], rcond=None)
    return z - (c[0] + c[1] * xx + c[2] * yy)


def _read_array(path, field):
    try:
        z = files.HEIGHT_MAP_READERS[path.suffix.lower()](path, field)
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 - any reader failure is bad input, named
        raise InputError(f"{field}: cannot read {path}: {err}") from None
    z = np.asarray(z)
    if z.dtype.kind not in "fiu":
        raise InputError(f"{field}: {path} holds {z.dtype} data, not heights: save a plain "
                         "float array")
    return np.asarray(z, np.float64)


def _read_x3p(path, field):
    try:
        import x3pio
    except ImportError:
        raise InputError(f"{field}: reading {path} (X3P) needs x3pio: pip install "
                         "'pmdsim[topography]'") from None
    try:
        f = x3pio.read(path)
    except Exception as err:  # noqa: BLE001 - x3pio raises X3pError and OSError subclasses
        raise InputError(f"{field}: cannot read {path} as X3P: {err}") from None
    if not isinstance(f, x3pio.Surface):
        raise InputError(f"{field}: {path} holds a {type(f).__name__}, not a surface (a grid "
                         "of heights); export the areal measurement")
    layer = f.layers[0]
    spacing = getattr(layer, "spacing", None)
    if not getattr(f, "is_regular_grid", True) or spacing is None or None in tuple(spacing):
        raise InputError(f"{field}: {path} is not on a regular grid (absolute x or y axes); "
                         "export it on a regular grid")
    z = np.asarray(layer.z, np.float64) * 1e3  # metres -> mm
    dx, dy = (float(v) * 1e3 for v in spacing)
    return z, dx, dy, f"x3pio {getattr(x3pio, '__version__', '')}".strip()


def _read_surfalize(path, field):
    try:
        import surfalize
    except ImportError:
        raise InputError(f"{field}: reading {path} needs surfalize (GPL-3.0): pip install "
                         "'pmdsim[instruments]'") from None
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = surfalize.Surface.load(path)
    except Exception as err:  # noqa: BLE001 - any reader failure is bad input, named
        raise InputError(f"{field}: cannot read {path}: {type(err).__name__}: {err}") from None
    z = np.asarray(s.data, np.float64) * 1e-3  # um -> mm
    return z, float(s.step_x) * 1e-3, float(s.step_y) * 1e-3, "surfalize"
