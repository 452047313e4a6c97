"""Measured topographies from instrument files (layer 1, beside :mod:`pmdsim.imagefile`).

:func:`read_topography` reads a height map with its sample spacing and returns a
:class:`Topography` in millimetres (rows along y, columns along x), levelled and with the
non-measured points and outliers handled as asked. The readers (docs/texture.md, "Reading"):

- the instrument formats of :data:`ST_FORMATS` through **SurfaceTopography** (MIT,
  ``pip install pmdsim[instruments]``), each tested on a file measured on a real instrument
  (``tests/data/instrument-samples``: grid, physical size, unit and RMS height as
  SurfaceTopography's own tests state them, and as Gwyddion reads them where it can) or on
  a file written after the layout independent readers document
  (``tests/topofile_writers.py``: ``.datx``, ``.plux``, ``.vk4``/``.vk3``; ``.gwy`` by
  gwyfile);
- ``.x3p`` (ISO 25178-72) through **x3pio** (MIT; ``pmdsim[topography]``);
- NanoFocus ``.nms`` by pmdsim's own reader (:func:`_read_nms`): SurfaceTopography 1.27
  reads its spacing in millimetres where the file holds nanometres (``nms-1.nms``: a 160 um
  confocal field read as 160 m; surfalize reads 160 um);
- surfalize's own ``.sflz`` through **surfalize** (GPL-3.0: installed only by the user,
  ``pip install surfalize``; no other library reads it);
- plain arrays ``.npy``, ``.csv``/``.txt`` and float ``.tif``/``.tiff`` (no units and no
  spacing inside: the caller gives ``spacing_mm`` and ``height_unit``).

Every failure is a :class:`~pmdsim.config.files.FileInputError` (an ``InputError`` and a
``ConfigError``: exit code 2 in the command line; a missing file a ``MissingFileError``)
that names the configuration field and the file, raised before any long work; a truncated
or garbled instrument file is refused, never read as shifted or scaled heights. A grid
that a file declares larger than :data:`~pmdsim.config.files.MAX_GRID_ELEMENTS` (the plain
loaders' limit), and a compressed part that would unpack to more than
:data:`MAX_UNPACKED_BYTES`, are refused from the file's header before any height is read.
The other formats SurfaceTopography reads are refused with the reason (:data:`NOT_READ`):
no file of them could be checked here. Export such a measurement as X3P or SDF.
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import files
from .config.files import MAX_GRID_ELEMENTS
from .config.files import FileInputError as InputError

#: Instrument formats read through SurfaceTopography: suffix -> (its format id, name).
ST_FORMATS = {
    ".plu": ("plu", "Sensofar PLU"), ".plux": ("plux", "Sensofar PLUX"),
    ".opd": ("opd", "Wyko OPD"), ".dat": ("metropro", "Zygo MetroPro"),
    ".datx": ("datx", "Zygo DATX"), ".al3d": ("al3d", "Alicona AL3D"),
    ".tmd": ("tmd", "TrueMap TMD"), ".sdf": ("sdf", "ISO 25178-71 SDF"),
    ".sur": ("sur", "Digital Surf SUR"), ".mi": ("mi", "Molecular Imaging MI"),
    ".frt": ("frt", "FRT MicroProf"), ".di": ("di", "Bruker Nanoscope"),
    ".spm": ("di", "Bruker Nanoscope"), ".vk4": ("vk", "Keyence VK4"),
    ".vk3": ("vk", "Keyence VK3"), ".gwy": ("gwy", "Gwyddion GWY"),
}
X3P_SUFFIXES = (".x3p",)
OWN_SUFFIXES = (".nms",)
SURFALIZE_SUFFIXES = (".sflz",)
ARRAY_SUFFIXES = tuple(files.HEIGHT_MAP_READERS)
#: Largest part of a compressed file (a ZIP member, a zlib/LZMA layer) unpacked: the bytes
#: of MAX_GRID_ELEMENTS float64 heights.
MAX_UNPACKED_BYTES = 8 * MAX_GRID_ELEMENTS
_UNCHECKED = ("SurfaceTopography reads it, but no file of it was at hand to check its heights, "
              "unit and spacing against the instrument or an independent reader")
_GPL_ONLY = "only surfalize (GPL-3.0) reads it, and no file of it could be checked"
#: Instrument formats that are refused, with the reason.
NOT_READ = dict.fromkeys(
    (".vk6", ".vk7", ".zon", ".lext", ".oir", ".poir", ".zmg", ".os3d", ".opdx",
     ".mdt", ".ibw", ".mat", ".nc", ".h5", ".hfm", ".asc", ".xlsx", ".ezd", ".nid", ".bcr",
     ".bcrf", ".cur", ".stp", ".tom", ".top", ".jpk", ".mnt", ".qep", ".hgt", ".apx",
     ".001", ".002", ".003", ".004", ".005", ".zip"), _UNCHECKED) | dict.fromkeys(
    (".hdat", ".fits", ".fit", ".fts"), _GPL_ONLY) | {
    ".xyz": "scattered x, y, z points are not a grid with one spacing (SurfaceTopography "
            "reads them; surfalize 0.19.2 takes the spacing as (max - min) / n)",
    ".npz": "an archive of several arrays: save the height map alone as .npy",
}
HEIGHT_UNITS_MM = {"mm": 1.0, "um": 1e-3, "nm": 1e-6, "m": 1e3}
#: Length units of SurfaceTopography's channels, in mm.
#: ("\u00c2\u00b5m": the UTF-8 micro sign read as Latin-1, as surfalize writes it in .sur)
_LENGTH_MM = {"m": 1e3, "mm": 1.0, "\u00b5m": 1e-3, "\u03bcm": 1e-3, "\u00c2\u00b5m": 1e-3,
              "um": 1e-3, "nm": 1e-6, "pm": 1e-9, "\u00c5": 1e-7, "A": 1e-7, "km": 1e6}
LEVELS = ("none", "mean", "plane")
FILLS = ("error", "nearest", "mean")


@dataclass(frozen=True, eq=False)
class Topography:
    """A height map: ``heights`` (ny, nx) float64 mm, rows along y, columns along x,
    spacing ``dx``, ``dy`` mm. ``invalid`` counts the points that were not measured or were
    outliers (filled as asked), ``not_measured`` those of them the file marks as not
    measured or holds as NaN/inf; ``source`` is the file, ``reader`` what read it."""

    heights: np.ndarray
    dx: float
    dy: float
    source: str = ""
    reader: str = "array"
    invalid: int = 0
    not_measured: int = 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def size_mm(self) -> tuple[float, float]:
        ny, nx = self.heights.shape
        return nx * self.dx, ny * self.dy


def is_instrument_file(path) -> bool:
    """True for a format that carries its own spacing and units."""
    suffix = Path(path).suffix.lower()
    return suffix in ST_FORMATS or suffix in X3P_SUFFIXES + OWN_SUFFIXES + SURFALIZE_SUFFIXES


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
    files.check_regular_file(path, field)
    suffix = path.suffix.lower()
    if suffix in NOT_READ:
        raise InputError(f"{field}: {path}: {suffix} files are not read ({NOT_READ[suffix]}); "
                         "export the measurement as X3P (ISO 25178-72) or SDF (ISO 25178-71) "
                         "from the instrument software")
    known = (tuple(ST_FORMATS) + X3P_SUFFIXES + OWN_SUFFIXES + SURFALIZE_SUFFIXES
             + ARRAY_SUFFIXES)
    if suffix not in known:
        raise InputError(f"{field}: {path}: unknown topography format {suffix!r}; read are "
                         f"{', '.join(known)}")
    if suffix in ST_FORMATS:
        z, dx, dy, reader = _read_surfacetopography(path, field, *ST_FORMATS[suffix])
    elif suffix in X3P_SUFFIXES:
        _check_zip(path, field, "X3P", _x3p_declared_grid)
        z, dx, dy, reader = _read_x3p(path, field)
    elif suffix in OWN_SUFFIXES:
        z, dx, dy, reader = _read_nms(path, field)
    elif suffix in SURFALIZE_SUFFIXES:
        _check_sflz(path, field)
        z, dx, dy, reader = _read_surfalize(path, field)
    else:
        if spacing_mm is None:
            raise InputError(f"{field}: {path} holds no sample spacing; give spacing_mm = "
                             "[dx, dy] (or use an instrument file: X3P, .sur, .plu, ...)")
        if height_unit not in HEIGHT_UNITS_MM:
            raise InputError(f"{field}: height_unit must be one of {tuple(HEIGHT_UNITS_MM)}")
        z = _read_array(path, field) * HEIGHT_UNITS_MM[height_unit]
        dx, dy = (float(v) for v in spacing_mm)
        reader = "array"
    z = np.asarray(z, np.float64)
    if z.ndim != 2 or min(z.shape) < min_points:
        raise InputError(f"{field}: {path} must hold a 2-D grid of at least {min_points} x "
                         f"{min_points} heights, got shape {z.shape}")
    if not (np.isfinite(dx) and np.isfinite(dy) and dx > 0 and dy > 0):
        raise InputError(f"{field}: {path}: the sample spacing must be positive, got {dx}, {dy} mm")
    not_measured = int((~np.isfinite(z)).sum())
    z, invalid = clean_heights(z, level=level, fill=fill, outlier_sigma=outlier_sigma,
                               what=f"{field}: {path}")
    return Topography(z, float(dx), float(dy), str(path), reader, invalid, not_measured)


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
            before = int(valid.sum())
            valid &= np.abs(z - med) <= outlier_sigma * mad
            if valid.sum() < max(3, before // 2):
                raise InputError(
                    f"{what}: outlier_sigma = {outlier_sigma:g} marks {before - int(valid.sum())} "
                    f"of {before} measured points as outliers (robust sigma {mad:.3g}); an outlier "
                    "is a rare point: raise outlier_sigma (5 is usual) or leave it unset")
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


def _declared_grid(what, nx, ny):
    """Refuse a grid a file declares, before its heights are read: empty, or larger than the
    plain loaders' limit (:data:`~pmdsim.config.files.MAX_GRID_ELEMENTS`)."""
    nx, ny = int(nx), int(ny)
    if nx < 1 or ny < 1:
        raise InputError(f"{what}: declares a grid of {nx} x {ny} points, which holds no "
                         "heights: the file is garbled or not of this format; export it "
                         "again from the instrument software")
    if nx * ny > MAX_GRID_ELEMENTS:
        raise InputError(f"{what}: declares a grid of {nx} x {ny} = {nx * ny:,} points, more "
                         f"than the {MAX_GRID_ELEMENTS:,} pmdsim reads (2 GB of heights); not "
                         "read. Crop or resample the measurement in the instrument software")


def _read_surfacetopography(path, field, fmt, name):
    """Heights (mm, rows along y), dx, dy (mm), reader: the file's height channel through
    SurfaceTopography, its declared grid checked from the header before the heights."""
    what = f"{field}: {path} ({name})"
    try:
        import SurfaceTopography
        from SurfaceTopography.IO import open_topography
    except ImportError:
        raise InputError(f"{what}: reading it needs SurfaceTopography (MIT): pip install "
                         "'pmdsim[instruments]'") from None
    _check_zip(path, field, name, _plux_declared_grid if fmt == "plux" else None)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader = open_topography(str(path), format=fmt)
            channels = list(reader.channels)
    except MemoryError:
        raise InputError(f"{what}: its header asks for more memory than there is: the file is "
                         "garbled or not of this format") from None
    except Exception as err:  # noqa: BLE001 - the readers raise many kinds on damage
        raise InputError(_unreadable(what, path, err)) from None
    heights = [c for c in channels if getattr(c, "dim", 2) == 2
               and _unit_mm(getattr(c, "unit", None)) is not None]
    default = getattr(reader, "default_channel", None)
    channel = default if default in heights else (heights[0] if heights else None)
    if channel is None:
        found = ", ".join(f"{c.name!r} ({c.unit})" for c in channels) or "none"
        raise InputError(f"{what}: holds no areal map of heights in a length unit (channels: "
                         f"{found}); export the topography")
    _declared_grid(what, *channel.nb_grid_pts)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = reader.topography(channel_index=channel.index)
            h = t.heights()
            sizes = t.physical_sizes
    except MemoryError:
        raise InputError(f"{what}: needs more memory than there is to read") from None
    except Exception as err:  # noqa: BLE001
        raise InputError(_unreadable(what, path, err)) from None
    if sizes is None or len(sizes) != 2 or not getattr(t, "is_uniform", True):
        raise InputError(f"{what}: states no lateral size of a uniform grid; export it with "
                         "its lateral calibration")
    z = np.ma.filled(np.ma.asarray(h, np.float64), np.nan).T  # (nx, ny) -> rows along y
    if z.shape != tuple(channel.nb_grid_pts)[::-1]:
        raise InputError(f"{what}: holds {z.shape[1]} x {z.shape[0]} heights, its header "
                         f"states {channel.nb_grid_pts[0]} x {channel.nb_grid_pts[1]}: "
                         "inconsistent, not read; export it again from the instrument "
                         "software")
    scale = _unit_mm(t.unit)
    ny, nx = z.shape
    dx, dy = (float(s) * scale / n for s, n in zip(sizes, (nx, ny), strict=True))
    return (z * scale, dx, dy,
            f"SurfaceTopography {SurfaceTopography.__version__} ({channel.name})")


def _unreadable(what, path, err):
    """The message for a file SurfaceTopography refused: a feature its reader does not read
    (a unit or a layout it names), or damage."""
    name = type(err).__name__
    if name == "UnsupportedFormatFeature" or "unit" in str(err).lower():
        return (f"{what}: not read ({_brief(err)}); export the topography again from the "
                "instrument software, in a length unit, or as X3P or SDF")
    return (f"{what}: cannot read it ({_brief(err)}): the file is truncated, garbled or not a "
            f"{path.suffix.lower()} file; export it again from the instrument software")


def _unit_mm(unit):
    return _LENGTH_MM.get(str(unit).strip()) if unit is not None else None


def _brief(err):
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text[:200]}{'...' if len(text) > 200 else ''}"


def _check_zip(path, field, name, declared):
    """For a ZIP container (X3P, .plux, ...): refuse a member that would unpack to more than
    :data:`MAX_UNPACKED_BYTES` (Python's zipfile stops at the size the directory states),
    and check the grid ``declared(archive)`` returns ((nx, ny) or None) from its header."""
    import zipfile

    what = f"{field}: {path} ({name})"
    if not zipfile.is_zipfile(path):
        if declared is not None:
            raise InputError(f"{what}: is not a ZIP archive (an {name} file is one): the file "
                             "is truncated, garbled or not of this format; export it again")
        return
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if info.file_size > MAX_UNPACKED_BYTES:
                    raise InputError(f"{what}: its part {info.filename!r} unpacks to "
                                     f"{info.file_size / 2**30:.3g} GB, more than the "
                                     f"{MAX_UNPACKED_BYTES / 2**30:.3g} GB of the largest grid "
                                     "pmdsim reads; not read: is it the right file?")
            grid = declared(archive) if declared is not None else None
    except InputError:
        raise
    except ValueError as err:
        raise InputError(f"{what}: {err}; not read: export it again from the instrument "
                         "software") from None
    except Exception as err:  # noqa: BLE001 - zipfile/XML raise many kinds on damage
        raise InputError(f"{what}: not a readable ZIP archive ({_brief(err)}): truncated or "
                         "garbled; export it again from the instrument software") from None
    if grid is not None:
        _declared_grid(what, *grid)


def _plux_declared_grid(archive):
    """(IMAGE_SIZE_X, _Y) of a Sensofar .plux's index.xml (the layout of SurfaceTopography's
    PLUX.py), whose LAYER_0.raw must hold exactly that many float32 heights: the reader
    takes the first nx x ny values whatever follows."""
    import xml.etree.ElementTree as ET

    info = archive.getinfo("index.xml")
    if info.file_size > 16 * 2**20:
        raise ValueError(f"index.xml of {info.file_size} bytes")
    root = ET.fromstring(archive.read(info))
    try:
        nx, ny = (int(root.find(f"GENERAL/IMAGE_SIZE_{a}").text) for a in "XY")
    except (AttributeError, TypeError, ValueError):
        raise ValueError("index.xml states no GENERAL/IMAGE_SIZE_X and _Y") from None
    raw = archive.getinfo("LAYER_0.raw").file_size
    if 0 < nx * ny <= MAX_GRID_ELEMENTS and raw != 4 * nx * ny:
        raise ValueError(f"LAYER_0.raw holds {raw} bytes, index.xml states {ny} x {nx} float32 "
                         f"heights ({4 * nx * ny} bytes): inconsistent")
    return nx, ny


def _x3p_declared_grid(archive):
    """(SizeX, SizeY) of an X3P's main.xml (Record3/MatrixDimension), from at most 16 MB of
    XML (external entities are not resolved by ElementTree)."""
    import xml.etree.ElementTree as ET

    info = archive.getinfo("main.xml")
    if info.file_size > 16 * 2**20:
        raise ValueError(f"main.xml of {info.file_size} bytes")
    root = ET.fromstring(archive.read(info))
    sizes = {el.tag.rsplit("}", 1)[-1]: (el.text or "").strip() for el in root.iter()
             if el.tag.rsplit("}", 1)[-1] in ("SizeX", "SizeY", "SizeZ")}
    if "SizeX" not in sizes or "SizeY" not in sizes:
        raise ValueError("main.xml states no MatrixDimension SizeX and SizeY")
    if int(sizes.get("SizeZ") or 1) != 1:
        raise ValueError(f"main.xml states SizeZ = {sizes['SizeZ']} layers, not one")
    nx, ny = int(sizes["SizeX"]), int(sizes["SizeY"])
    need = 8 * nx * ny + 4096  # float64 heights at most (and a bit mask of valid points)
    for part in archive.infolist():
        if part.filename != "main.xml" and part.file_size > need:
            raise ValueError(f"its part {part.filename!r} unpacks to {part.file_size:,} bytes, "
                             f"more than the {nx} x {ny} heights main.xml declares can fill "
                             f"({need:,}): inconsistent")
    return nx, ny


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
    except ImportError:  # pragma: no cover - _check_sflz asks for it first
        raise InputError(f"{field}: reading {path} needs surfalize (GPL-3.0): pip install "
                         "surfalize") from None
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = surfalize.Surface.load(path)
    except Exception as err:  # noqa: BLE001 - any reader failure is bad input, named
        raise InputError(f"{field}: cannot read {path}: {type(err).__name__}: {err}") from None
    z = np.asarray(s.data, np.float64) * 1e-3  # um -> mm
    return z, float(s.step_x) * 1e-3, float(s.step_y) * 1e-3, "surfalize"


# NanoFocus .nms (the layout of SurfaceTopography's NMS.py, read alike by surfalize): a
# 3468-byte header with the heights' range (zmin, zmax: float64 micrometres at byte 16) and
# the grid (nx, ny: uint32; dx, dy: float64 at byte 1368), then ny rows of nx uint16
# heights scaled between zmin and zmax over 0 .. 65534. The spacing is in nanometres:
# nms-1.nms (tests/data/instrument-samples) holds 312.5 on a 512 x 512 grid, a 160 um
# confocal field (surfalize reads that); SurfaceTopography 1.27 takes millimetres and
# reports a field of 160 m.
_NMS_HEADER = 3468


def _read_nms(path, field):
    """A NanoFocus .nms topography: heights (mm), dx, dy (mm), reader (the layout above)."""
    what = f"{field}: {path} (NanoFocus .nms)"
    try:
        with open(path, "rb") as fh:
            head = fh.read(_NMS_HEADER)
            if len(head) < _NMS_HEADER:
                raise InputError(f"{what}: {len(head)} bytes, shorter than its "
                                 f"{_NMS_HEADER}-byte header: truncated or not a .nms file; "
                                 "export it again")
            zmin, zmax = struct.unpack_from("<2d", head, 16)
            nx, ny, dx_nm, dy_nm = struct.unpack_from("<2I2d", head, 1368)
            _declared_grid(what, nx, ny)
            raw = np.fromfile(fh, "<u2", nx * ny)
    except InputError:
        raise
    except OSError as err:
        raise InputError(f"{what}: cannot read it: {err}") from None
    if raw.size != nx * ny:
        raise InputError(f"{what}: its header states {nx} x {ny} heights, the file holds "
                         f"{raw.size}: truncated, not read; export it again from the "
                         "instrument software")
    if not (np.isfinite([zmin, zmax, dx_nm, dy_nm]).all() and zmax >= zmin
            and 0 < dx_nm < 1e9 and 0 < dy_nm < 1e9):
        raise InputError(f"{what}: height range {zmin:g} .. {zmax:g} um and spacing "
                         f"{dx_nm:g} x {dy_nm:g} nm in its header are not plausible: garbled "
                         "or not a .nms file; export it again from the instrument software")
    z = raw.reshape(ny, nx).astype(np.float64) / 65534.0 * (zmax - zmin) + zmin
    return z * 1e-3, dx_nm * 1e-6, dy_nm * 1e-6, "pmdsim .nms reader"


def _check_sflz(path, field):
    """Refuse a surfalize .sflz file whose layers declare a grid above the limit or whose
    compressed layers unpack to other than their declared size, before surfalize reads it
    (the layout of surfalize's sflz.py: magic, version, header, metadata, then per layer a
    header and the zlib- or LZMA-compressed data)."""
    import lzma
    import zlib

    what = f"{field}: {path} (surfalize .sflz)"
    try:
        from surfalize.file.sflz import LAYOUT_HEADER, LAYOUT_LAYER_HEADER, MAGIC
    except ImportError:
        raise InputError(f"{what}: reading it needs surfalize (GPL-3.0; the only reader of its "
                         "own format): pip install surfalize, or save the surface as SDF or "
                         "X3P from surfalize") from None
    try:
        with open(path, "rb") as fh:
            if fh.read(len(MAGIC)) != MAGIC:
                raise InputError(f"{what}: does not start with {MAGIC!r}: garbled or not a "
                                 ".sflz file")
            fh.read(10)
            header = LAYOUT_HEADER.read(fh)
            fh.seek(header["metadata_size"], 1)
            for _ in range(header["num_layers"]):
                layer = LAYOUT_LAYER_HEADER.read(fh)
                _declared_grid(what, layer["width"], layer["height"])
                dtype = layer["datatype"]
                dtype = dtype.decode() if isinstance(dtype, bytes) else str(dtype)
                itemsize = np.dtype(dtype.strip("\0 ")).itemsize
                declared = layer["width"] * layer["height"] * max(layer["channels"], 1) * itemsize
                data = fh.read(layer["size"])
                algo = header["compression_algorithm"]
                if algo == "zlib":
                    size = len(zlib.decompressobj().decompress(data, declared + 1))
                elif algo == "lzma":
                    size = len(lzma.LZMADecompressor().decompress(data, declared + 1))
                else:
                    size = len(data)
                if size != declared:
                    raise InputError(f"{what}: a layer of {layer['width']} x {layer['height']} "
                                     f"declares {declared} bytes and unpacks to "
                                     f"{'more' if size > declared else size}: garbled, not "
                                     "read; save the surface again from surfalize")
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 - struct/zlib/lzma/dtype raise many kinds
        raise InputError(f"{what}: cannot read its header ({_brief(err)}): truncated or "
                         "garbled; save the surface again from surfalize") from None
