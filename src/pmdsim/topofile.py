"""Measured topographies from instrument files (layer 1, beside :mod:`pmdsim.imagefile`).

:func:`read_topography` reads a height map with its sample spacing and returns a
:class:`Topography` in millimetres (rows along y, columns along x), levelled and with the
non-measured points and outliers handled as asked:

- ``.x3p`` (ISO 25178-72) through **x3pio** (MIT; ``pip install pmdsim[topography]``):
  coordinates in metres in the file, spacing from its axes;
- the instrument formats read through **surfalize** (GPL-3.0, an optional extra of its own:
  ``pip install pmdsim[instruments]``) *that are tested* on files written by an independent
  writer or by surfalize's own writer (values, orientation and dx != dy spacing checked,
  ``tests/brdf/test_topography.py``, ``tests/config/test_topofile_formats.py``): Digital Surf
  ``.sur``, ISO 25178-71 ``.sdf``, Alicona ``.al3d``, ``.tmd`` (TrueMap), surfalize's own
  ``.sflz``, Keyence ``.vk4``/``.vk3`` (files written after Gwyddion's ``keyence.c``
  layout and read alike by Gwyddion itself) and Sensofar ``.plux`` (after
  SurfaceTopography's layout); surfalize works in micrometres;
- Sensofar ``.plu`` and Zygo ``.datx`` by pmdsim's own readers below (:data:`OWN_SUFFIXES`),
  because surfalize 0.19.2 misreads the first (see :func:`_read_plu`) and reads no
  ``.datx`` at all; ``.datx`` (HDF5) needs **h5py** (``pmdsim[instruments]``);
- plain arrays ``.npy``, ``.csv``/``.txt`` and float ``.tif``/``.tiff`` (no units and no
  spacing inside: the caller gives ``spacing_mm`` and ``height_unit``).

Every failure is a :class:`~pmdsim.config.files.FileInputError` (an ``InputError`` and a
``ConfigError``: exit code 2 in the command line; a missing file a ``MissingFileError``)
that names the configuration field and the file, raised before any long work; a truncated
or garbled instrument file is refused, never read as shifted or scaled heights. Plain
arrays are read by the readers of :data:`pmdsim.config.files.HEIGHT_MAP_READERS`. The
formats of :data:`NOT_READ` are refused with the reason: no file of them could be checked
against an independent writer or reader here (surfalize reads more of them; its ``.xyz``
spacing is (max - min) / n instead of / (n - 1)). Export such a measurement as X3P or SDF
from the instrument software.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import files
from .config.files import FileInputError as InputError
from .config.files import MissingFileError as MissingInputError

#: Suffixes read by x3pio, by surfalize, by pmdsim's own readers, and as plain arrays.
X3P_SUFFIXES = (".x3p",)
SURFALIZE_SUFFIXES = (".sur", ".sdf", ".al3d", ".tmd", ".sflz", ".vk4", ".vk3", ".plux")
OWN_SUFFIXES = (".plu", ".datx")
#: Instrument formats that are refused, with the reason (module doc).
_UNTESTED = ("surfalize reads it, but no file of it could be checked against an independent "
             "writer or a sample file, so its values and spacing are not trusted here")
NOT_READ = dict.fromkeys((".vk6", ".vk7", ".lext", ".oir", ".poir", ".opd", ".zon",
                          ".nms", ".os3d", ".gwy", ".hdat", ".zmg", ".fits", ".fit", ".fts",
                          ".dat"), _UNTESTED) | {
    ".xyz": "surfalize 0.19.2 takes the spacing as (max - min) / n instead of / (n - 1), and "
            "assumes metres",
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
    """True for a format that carries its own spacing and units (X3P, surfalize's, .plu,
    .datx)."""
    return Path(path).suffix.lower() in X3P_SUFFIXES + SURFALIZE_SUFFIXES + OWN_SUFFIXES


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
        if suffix in (".vk3", ".vk4"):
            _check_vk(path, field)
        elif suffix == ".plux":
            _check_plux(path, field)
        z, dx, dy, reader = _read_surfalize(path, field)
    elif suffix == ".plu":
        z, dx, dy, reader = _read_plu(path, field)
    elif suffix == ".datx":
        z, dx, dy, reader = _read_datx(path, field)
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
        read = X3P_SUFFIXES + SURFALIZE_SUFFIXES + OWN_SUFFIXES + ARRAY_SUFFIXES
        raise InputError(f"{field}: {path}: unknown topography format {suffix!r}; read are "
                         f"{', '.join(read)}")
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


# Sensofar .plu, after the layout Gwyddion's sensofar.c and SurfaceTopography's PLU.py read
# (both tested on instrument files): a 500-byte header -- date (128 bytes), time (uint32),
# comment (256), the axes' calibration (yres, xres, N_tall uint32; dy_multip, mppx, mppy,
# x_0, y_0, mpp_tall, z_0 float32: micrometres per pixel at bytes 404, 408), the
# measurement configuration (type uint32 at byte 428, 3 = topography; the number of layers
# at byte 489, the format version at byte 490) -- then per layer the grid's size (rows,
# columns uint32), the heights (float32 micrometres, row by row, 1000001 where not
# measured) and their minimum and maximum (float32).
_PLU_HEADER = 500
_PLU_NOT_MEASURED = 1000001.0
_PLU_TYPES = {0: "a confocal image", 1: "a profile", 2: "multiple profiles", 3: "a topography",
              4: "coordinates of multiple profiles", 5: "a single-point thickness",
              6: "a custom application", 7: "a coordinates topography map",
              8: "a coordinates thickness map"}


def _read_plu(path, field):
    """A Sensofar .plu topography: heights (mm), dx, dy (mm), reader. surfalize 0.19.2 is
    not used: it reads the heights from byte 500, where the two readers above (and the files
    they are tested on) have the grid's size, so its map is shifted by two values with the
    size read as two tiny heights. A file whose grid size at byte 500 does not fit (a
    truncated file, or a layout without it) is refused, not guessed."""
    what = f"{field}: {path} (Sensofar .plu)"
    try:
        data = path.read_bytes()
    except OSError as err:
        raise InputError(f"{what}: cannot read it: {err}") from None
    if len(data) < _PLU_HEADER + 8:
        raise InputError(f"{what}: {len(data)} bytes, shorter than the {_PLU_HEADER}-byte "
                         "header and the grid's size: the file is truncated or not a .plu file")
    kind, = struct.unpack_from("<I", data, 428)
    layers, version = data[489], data[490]
    if not (version == 0 or version >= 0xF0):
        raise InputError(f"{what}: format version byte {version} (byte 490) is none of "
                         "Sensofar's (0 or 240-255): the file is garbled or not a .plu file")
    if kind != 3:
        raise InputError(f"{what}: holds {_PLU_TYPES.get(kind, f'measurement type {kind}')}, "
                         "not a topography (type 3): export the topography")
    if layers < 1:
        raise InputError(f"{what}: holds no data layer")
    mppx, mppy = struct.unpack_from("<2f", data, 404)
    ny, nx = struct.unpack_from("<2I", data, _PLU_HEADER)
    need = _PLU_HEADER + 8 + 4 * ny * nx + 8
    if nx == 0 or ny == 0 or need > len(data):
        raise InputError(f"{what}: the grid's size before the heights ({ny} rows x {nx} "
                         f"columns, byte {_PLU_HEADER}) needs {need} bytes, the file has "
                         f"{len(data)}: it is truncated, or laid out without the grid's size "
                         "(not a layout read here)")
    z = np.frombuffer(data, "<f4", ny * nx, _PLU_HEADER + 8).astype(np.float64).reshape(ny, nx)
    z[z == _PLU_NOT_MEASURED] = np.nan
    return z * 1e-3, abs(mppx) * 1e-3, abs(mppy) * 1e-3, "pmdsim .plu reader"


# Zygo .datx (HDF5), after the layout SurfaceTopography's DATX.py and prysm's io.py read (MIT;
# both used on instrument files): a "MetaData" table of (Source, Link, Destination) strings
# leads from "Root" through "Measurement" and "Surface" to the surface dataset's "Path"
# (prysm takes the one dataset under /Data/Surface). The dataset (rows along y, columns along
# x: the image order of prysm and of the other open readers; SurfaceTopography takes the
# first axis as x, which differs only for unequal pixel sizes) carries "No Data" (the value
# of the points not measured), "Unit" and the compound "X/Y/Z Converter" (Category,
# BaseUnit, Parameters): lateral "LateralCat" with the spacing in metres in Parameters[1],
# heights "HeightCat" in BaseUnit.
DATX_HEIGHT_UNITS_MM = {"NanoMeters": 1e-6, "MicroMeters": 1e-3, "MilliMeters": 1.0,
                        "Meters": 1e3}
_DATX_SHORT_UNITS = {"nm": "NanoMeters", "um": "MicroMeters", "\u00b5m": "MicroMeters",
                     "\u03bcm": "MicroMeters", "mm": "MilliMeters", "m": "Meters"}


def _read_datx(path, field):
    """A Zygo .datx surface: heights (mm), dx, dy (mm), reader (the layout above)."""
    what = f"{field}: {path} (Zygo .datx)"
    try:
        import h5py
    except ImportError:
        raise InputError(f"{what}: reading it (HDF5) needs h5py: pip install h5py or "
                         "'pmdsim[instruments]'") from None
    try:
        with h5py.File(path, "r") as h5:
            ds = _datx_surface(h5, what)
            if ds.ndim != 2 or ds.dtype.kind not in "fiu":
                raise InputError(f"{what}: the surface dataset {ds.name} holds {ds.dtype} "
                                 f"data of shape {ds.shape}, not a 2-D grid of heights")
            z = np.asarray(ds[()], np.float64)
            attrs = {k: ds.attrs[k] for k in ds.attrs}
    except InputError:
        raise
    except Exception as err:  # noqa: BLE001 - h5py raises OSError, KeyError, ValueError...
        raise InputError(f"{what}: cannot read it as HDF5 ({type(err).__name__}: {err}): the "
                         "file is truncated, garbled or not a .datx file") from None
    dx, dy = (_datx_spacing(attrs, axis, what) for axis in "XY")
    category, base = (_datx_text(v) for v in _datx_converter(attrs, "Z", what)[:2])
    if category != "HeightCat":
        raise InputError(f"{what}: Z Converter category {category!r}, not 'HeightCat' "
                         "(heights): not read")
    if base not in DATX_HEIGHT_UNITS_MM:
        raise InputError(f"{what}: heights in {base!r}; read are "
                         f"{', '.join(DATX_HEIGHT_UNITS_MM)} (export the surface in a length "
                         "unit, not in fringes)")
    unit = _datx_text(np.asarray(attrs["Unit"]).reshape(-1)[0]) if "Unit" in attrs else base
    if _DATX_SHORT_UNITS.get(unit, unit) != base:
        raise InputError(f"{what}: the surface's Unit {unit!r} and its Z Converter's "
                         f"{base!r} disagree: the file is inconsistent, not read")
    bad = ~np.isfinite(z)
    if "No Data" in attrs:
        no_data = float(np.asarray(attrs["No Data"], np.float64).reshape(-1)[0])
        bad |= (z == no_data) | ((z >= no_data) if no_data >= 1e30 else False)
    z[bad] = np.nan
    return (z * DATX_HEIGHT_UNITS_MM[base], dx * 1e3, dy * 1e3,
            f"pmdsim .datx reader (h5py {h5py.__version__})")


def _datx_text(value):
    return value.decode("utf-8", "replace").strip("\0 ") if isinstance(value, bytes) else str(value)


def _datx_surface(h5, what):
    """The surface dataset: by the MetaData links, else the one dataset in /Data/Surface."""
    if "MetaData" in h5:
        links = {}
        for row in np.asarray(h5["MetaData"][()]).reshape(-1):
            source, link, dest = (_datx_text(v) for v in tuple(row)[:3])
            links[(source, link)] = dest
        node = links.get(("Root", "Measurement"))
        node = links.get((node, "Surface")) if node else None
        target = links.get((node, "Path")) if node else None
        if target is None or target not in h5:
            raise InputError(f"{what}: its MetaData table leads to no surface (Root -> "
                             f"Measurement -> Surface -> Path; got {target!r})")
        return h5[target]
    group = h5.get("Data/Surface")
    sets = [v for v in group.values() if hasattr(v, "shape")] if group is not None else []
    if len(sets) != 1:
        raise InputError(f"{what}: no MetaData table and {len(sets)} datasets under "
                         "/Data/Surface (one surface expected): not a .datx surface")
    return sets[0]


def _datx_converter(attrs, axis, what):
    """(Category, BaseUnit, Parameters) of the dataset's ``{axis} Converter``."""
    key = f"{axis} Converter"
    if key not in attrs:
        raise InputError(f"{what}: the surface has no {key!r} attribute (its units)")
    rec = np.asarray(attrs[key]).reshape(-1)[0]
    names = rec.dtype.names or ()
    if {"Category", "BaseUnit", "Parameters"} <= set(names):
        return rec["Category"], rec["BaseUnit"], np.asarray(rec["Parameters"], np.float64)
    try:
        return rec[0], rec[1], np.asarray(rec[-1], np.float64)
    except (IndexError, TypeError, ValueError):
        raise InputError(f"{what}: its {key!r} is not a (Category, BaseUnit, Parameters) "
                         "record") from None


def _datx_spacing(attrs, axis, what):
    category, _, params = _datx_converter(attrs, axis, what)
    if _datx_text(category) != "LateralCat" or params.size < 2:
        raise InputError(f"{what}: {axis} Converter category {_datx_text(category)!r} with "
                         f"{params.size} parameters, not 'LateralCat' with the spacing in "
                         "metres: not read")
    return float(params[1])


def _check_vk(path, field):
    """Refuse a Keyence .vk3/.vk4 file that surfalize would misread or fail on obscurely:
    the checks of Gwyddion's keyence.c (magic, four zero bytes, the measurement conditions'
    size, the height image's offset, bit depth and byte size within the file). Offsets: a
    12-byte header, the offset table (the measurement conditions first, the first height
    image seventh), the conditions from byte 84 (.vk4; 80 in .vk3)."""
    what = f"{field}: {path} (Keyence {path.suffix.lower()})"
    try:
        data = path.read_bytes()
    except OSError as err:
        raise InputError(f"{what}: cannot read it: {err}") from None
    magic = path.suffix.upper()[1:].encode() + b"_"
    if data[:4] != magic or data[8:12] != bytes(4):
        raise InputError(f"{what}: does not start with {magic.decode()!r} and four zero bytes: "
                         "the file is garbled or not a Keyence file")
    if len(data) < 12 + 68 + 304:
        raise InputError(f"{what}: {len(data)} bytes, shorter than its header: truncated")
    (conds_at,), (height_at,) = struct.unpack_from("<I", data, 12), struct.unpack_from("<I", data, 36)
    size = struct.unpack_from("<I", data, conds_at)[0] if conds_at + 4 <= len(data) else 0
    if size < 304 or conds_at + size > len(data):
        raise InputError(f"{what}: the measurement conditions (byte {conds_at}, {size} bytes) "
                         "do not fit the file: truncated or garbled")
    if height_at == 0 or height_at + 796 > len(data):
        raise InputError(f"{what}: no height image within the file (offset {height_at}): "
                         "truncated, or an image without heights")
    width, height, depth, _, nbytes = struct.unpack_from("<5I", data, height_at)
    if depth not in (16, 32) or nbytes != width * height * depth // 8 or not width * height:
        raise InputError(f"{what}: height image of {width} x {height} at {depth} bits in "
                         f"{nbytes} bytes: inconsistent, or a bit depth not read (16 or 32)")
    if height_at + 796 + nbytes > len(data):
        raise InputError(f"{what}: the height image needs {height_at + 796 + nbytes} bytes, "
                         f"the file has {len(data)}: truncated")


def _check_plux(path, field):
    """Refuse a Sensofar .plux file (a ZIP: index.xml with GENERAL/IMAGE_SIZE_X, _Y and the
    spacing FOV_X, _Y in micrometres; the float32 heights in LAYER_0.raw, the layout of
    SurfaceTopography's PLUX.py) that surfalize would misread: its heights must be exactly
    the grid the index states (surfalize reads the first nx x ny values whatever follows)."""
    import zipfile
    import xml.etree.ElementTree as ET

    what = f"{field}: {path} (Sensofar .plux)"
    try:
        with zipfile.ZipFile(path) as archive:
            root = ET.fromstring(archive.read("index.xml"))
            raw = archive.getinfo("LAYER_0.raw").file_size
    except Exception as err:  # noqa: BLE001 - zipfile/XML raise many kinds on damage
        raise InputError(f"{what}: not a readable .plux archive ({type(err).__name__}: "
                         f"{err}): truncated or garbled") from None
    try:
        nx, ny = (int(root.find(f"GENERAL/IMAGE_SIZE_{a}").text) for a in "XY")
    except (AttributeError, TypeError, ValueError):
        raise InputError(f"{what}: index.xml states no GENERAL/IMAGE_SIZE_X and _Y") from None
    if nx < 1 or ny < 1 or raw != 4 * nx * ny:
        raise InputError(f"{what}: LAYER_0.raw holds {raw} bytes, index.xml states {ny} x {nx} "
                         f"float32 heights ({4 * nx * ny} bytes): inconsistent, not read")
