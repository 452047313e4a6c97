"""The user's own files: one loader per kind, each a field-named error or a valid result.

A configuration names files the user made: a display response table
(``monitor.response_lut``), a flatness map of the display (``monitor.flatness_map``), a
measured surface (``surface.file``, ``reconstruct.prior.file``) and maps of the BRDF
parameters (``brdf.variation.file``). Each loader here reads its kind with the maintained
reader (the :mod:`csv` module, :func:`numpy.load` without pickles, :mod:`tifffile`),
validates what it returns (format, shape, finiteness, monotonicity, plausible units) and
turns *every* failure into a :class:`FileInputError` whose message starts with the field,
names the file and says what is wrong and how to fix it. :class:`FileInputError` is both an
:class:`~pmdsim.config.InputError` and a :class:`~pmdsim.config.ConfigError`, so callers
that catch either (the command line's exit code 2, the sweep's point validation) treat it
as bad input.

Height maps dispatch on the file's suffix (:data:`HEIGHT_MAP_READERS`); an
instrument-format reader plugs in with :func:`register_height_map_reader`.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .base import ConfigError, InputError

#: Largest file a loader reads (bytes): a user file beyond this is almost surely the wrong
#: file (a 1 GB CSV table of a display response), and reading it would take the memory.
MAX_FILE_BYTES = 2 * 2**30
#: Largest grid (elements) of a map: 2^28 float64 = 2 GB.
MAX_GRID_ELEMENTS = 2**28


class FileInputError(InputError, ConfigError):
    """A user file named by a configuration field cannot be used; the message starts with
    the field, names the file and says what is wrong (format, shape, NaN, monotonicity,
    units) and the fix."""


class MissingFileError(FileInputError, FileNotFoundError):
    """The file named by a configuration field does not exist."""


def _fail(field: str, path: Path, what: str) -> FileInputError:
    return FileInputError(f"{field}: {path}: {what}")


def check_regular_file(path, field: str) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it names a readable regular file of 1 byte to
    :data:`MAX_FILE_BYTES`; else a :class:`FileInputError` naming ``field`` and the file that
    says what it is instead (absent: :class:`MissingFileError`; a broken link or a link
    loop, a folder, a named pipe, a device or a socket, empty, too large, unreadable) and
    what to do. Nothing is opened, so a FIFO or ``/dev/zero`` cannot block or fill memory."""
    import errno
    import os
    import stat

    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        if path.is_symlink():
            raise _fail(field, path, f"is a symbolic link to {os.readlink(path)!r}, which does "
                        "not exist; name the measurement file itself") from None
        raise MissingFileError(f"{field}: file not found: {path} (check the path; relative "
                               "paths are relative to the configuration file)") from None
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise _fail(field, path, "is a symbolic link loop (the link points back to itself); "
                        "name the measurement file itself") from None
        raise _fail(field, path, f"cannot be looked at ({err.strerror or err}); check the "
                    "path and its folders' permissions") from None
    mode = st.st_mode
    kind = ("a folder" if stat.S_ISDIR(mode) else "a named pipe (FIFO)" if stat.S_ISFIFO(mode)
            else "a character device" if stat.S_ISCHR(mode) else "a block device"
            if stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else None)
    if kind == "a folder":
        raise _fail(field, path, "is a folder, not a file; name the measurement file inside it")
    if kind is not None or not stat.S_ISREG(mode):
        raise _fail(field, path, f"is {kind or 'not a regular file'}, not a file; save the "
                    "measurement to a file and name that")
    if st.st_size == 0:
        raise _fail(field, path, "is empty (0 bytes); was it written completely?")
    if st.st_size > MAX_FILE_BYTES:
        raise _fail(field, path, f"is {st.st_size / 2**30:.3g} GB, more than any map or table "
                    "pmdsim reads; is it the right file?")
    if not os.access(path, os.R_OK):
        raise _fail(field, path, "cannot be read (permission denied); make it readable")
    return path


def _existing(path, field: str) -> Path:
    return check_regular_file(path, field)


# ----------------------------------------------------------------------------- text tables
def _number(cell: str) -> float:
    return float(cell.strip())


def read_table(path, field: str, *, columns: int | None = None) -> np.ndarray:
    """(rows, cols) float64 of a text table: comma-, semicolon-, tab- or space-separated
    numbers; ``#`` comment lines, blank lines and one header line before the numbers are
    skipped. Every row must have the same number of cells (``columns`` if given) and every
    cell must be a number. Raises :class:`FileInputError` naming ``field``."""
    path = _existing(path, field)
    raw = path.read_bytes()
    if b"\x00" in raw[:65536]:
        raise _fail(field, path, "is a binary file, not a text table (save it as CSV: one "
                    "row per line, numbers separated by commas)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        try:
            text = raw.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes every byte
            raise _fail(field, path, "is not a text file") from None
    lines = [(k + 1, ln) for k, ln in enumerate(text.splitlines())
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise _fail(field, path, "holds no numbers (only blank or # comment lines)")
    sample = "\n".join(ln for _, ln in lines[:20])
    # ';' first: a file with both is one with decimal commas (caught below, by the line)
    delim = next((d for d in (";", ",", "\t") if d in sample), None)
    rows: list[tuple[int, list[float]]] = []
    header = None
    for lineno, line in lines:
        cells = next(csv.reader(io.StringIO(line), delimiter=delim)) if delim else line.split()
        if delim and cells and not cells[-1].strip():
            cells = cells[:-1]  # a trailing separator
        try:
            values = [_number(c) for c in cells]
        except ValueError:
            if not rows and header is None:
                header = (lineno, line)  # one header line before the numbers
                continue
            raise _fail(field, path, f"line {lineno} is not a row of numbers: {line.strip()[:80]!r}"
                        f" (every row must hold {len(rows[0][1]) if rows else 'the same number of'}"
                        f" numbers{'' if delim else ' separated by commas or spaces'})") from None
        if not values:
            continue
        rows.append((lineno, values))
    if not rows:
        raise _fail(field, path, "has a header line but no rows of numbers")
    width = len(rows[0][1])
    for lineno, values in rows:
        if len(values) != width:
            raise _fail(field, path, f"rows of different lengths: line {rows[0][0]} has {width} "
                        f"numbers, line {lineno} has {len(values)} (every row must be complete)")
    if columns is not None and width != columns:
        raise _fail(field, path, f"needs {columns} columns per row, found {width}"
                    + (" (is the separator ',' or ';'?)" if width == 1 else ""))
    a = np.array([v for _, v in rows], np.float64)
    _finite(a, field, path)
    return a


def _finite(a: np.ndarray, field: str, path: Path) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise _fail(field, path, f"has {int(bad.sum())} non-finite values (NaN or inf; the first "
                    f"at index {idx}); fill or remove them first")


# ----------------------------------------------------------------------------- the display
def read_response_lut(path, field: str = "monitor.response_lut") -> tuple[np.ndarray, np.ndarray]:
    """(drive, relative luminance) of a display response table: CSV rows ``drive,
    luminance`` (one header line allowed), at least 2 rows, drive >= 0 strictly increasing,
    luminance non-decreasing and not constant. The drive is scaled to [0, 1] by its maximum,
    the luminance to r(0) = 0, r(1) = 1."""
    a = read_table(path, field, columns=2)
    path = Path(path)
    if a.shape[0] < 2:
        raise _fail(field, path, f"needs at least 2 rows (drive, luminance), found {a.shape[0]}")
    drive, lum = a[:, 0], a[:, 1]
    if drive[0] < 0:
        raise _fail(field, path, f"drive values must be >= 0 (found {drive[0]:g})")
    step = np.diff(drive)
    if np.any(step <= 0):
        k = int(np.argmax(step <= 0))
        raise _fail(field, path, f"drive must increase from row to row (rows {k + 1} and {k + 2}: "
                    f"{drive[k]:g} then {drive[k + 1]:g}); sort the table by drive")
    if np.any(np.diff(lum) < 0):
        k = int(np.argmax(np.diff(lum) < 0))
        raise _fail(field, path, f"luminance must not decrease with the drive (rows {k + 1} and "
                    f"{k + 2}: {lum[k]:g} then {lum[k + 1]:g})")
    if lum[-1] - lum[0] <= 0 or not np.isfinite(lum[-1] - lum[0]):
        raise _fail(field, path, "luminance is constant: such a display shows no fringes (is the "
                    "second column the measured luminance?)")
    d = drive / drive[-1]
    rel = (lum - lum[0]) / (lum[-1] - lum[0])
    if not (np.isfinite(d).all() and np.isfinite(rel).all()):
        raise _fail(field, path, "values too large to normalise (overflow); rescale the table")
    return d, rel


def read_flatness_map(path, field: str = "monitor.flatness_map") -> np.ndarray:
    """(rows, cols) float64 heights (mm) of the display's emitting surface: a finite 2-D grid
    of at least 2 x 2 from a .npy, .csv/.txt or float .tif/.tiff file."""
    return read_grid(path, field, min_size=2, what="heights (mm)")


# ----------------------------------------------------------------------------- grids
def _read_npy(path: Path, field: str) -> np.ndarray:
    try:
        a = np.load(path, allow_pickle=False)
    except ValueError as err:
        if "pickle" in str(err).lower():
            raise _fail(field, path, "holds Python objects (a pickled array), not numbers; save "
                        "a float array (numpy.save of a float64 array)") from None
        raise _fail(field, path, f"is not a readable .npy array ({err})") from None
    except MemoryError:
        raise
    except Exception as err:  # noqa: BLE001 - OSError, EOFError, BadZipFile (a 'PK' start), ...
        raise _fail(field, path, f"is not a complete .npy file ({type(err).__name__}: {err}); "
                    "was it truncated?") from None
    if hasattr(a, "files"):  # np.load of a renamed .npz archive
        a.close()
        raise _fail(field, path, "is a .npz archive, not a .npy array; rename it to .npz")
    return a


def _read_tiff(path: Path, field: str) -> np.ndarray:
    try:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            a = np.asarray(tif.series[0].asarray())
    except MemoryError:
        raise
    except Exception as err:  # noqa: BLE001 - tifffile/imagecodecs raise many kinds
        raise _fail(field, path, f"is not a readable TIFF ({type(err).__name__}: {err}); was it "
                    "truncated?") from None
    if a.dtype.kind != "f":
        raise _fail(field, path, f"holds {a.dtype} data; store heights as a 32- or 64-bit float "
                    "TIFF (integer TIFFs carry no unit)")
    return a


def _read_text_grid(path: Path, field: str) -> np.ndarray:
    return read_table(path, field)


#: Height-map readers by lower-case suffix: ``reader(path, field) -> ndarray`` (any
#: numeric dtype, validated by :func:`read_grid`). Extend with
#: :func:`register_height_map_reader`.
HEIGHT_MAP_READERS: dict[str, Callable[[Path, str], np.ndarray]] = {
    ".npy": _read_npy,
    ".csv": _read_text_grid,
    ".txt": _read_text_grid,
    ".tif": _read_tiff,
    ".tiff": _read_tiff,
}


def register_height_map_reader(suffixes, reader: Callable[[Path, str], np.ndarray]) -> None:
    """Let :func:`read_grid` (height maps, flatness maps) read files with these suffixes
    (e.g. ``(".x3p",)``) with ``reader(path, field)``, which returns the heights as an array
    (validated afterwards) and raises :class:`FileInputError` (naming ``field``) for a file
    it cannot read; any other exception it raises is wrapped into one."""
    for s in ([suffixes] if isinstance(suffixes, str) else suffixes):
        HEIGHT_MAP_READERS[s.lower() if s.startswith(".") else "." + s.lower()] = reader


def _as_real_grid(a, field: str, path: Path, what: str, min_size: int) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.names is not None or a.dtype.kind in "OSUVMmb":
        raise _fail(field, path, f"holds {a.dtype} data, not {what}: save a plain float array")
    if a.dtype.kind == "c":
        raise _fail(field, path, f"holds complex numbers ({a.dtype}); {what} are real: save the "
                    "real part (or the modulus) yourself")
    if a.ndim == 3 and 1 in a.shape[:1]:
        a = a[0]  # a single-page stack
    if a.ndim != 2:
        raise _fail(field, path, f"must hold a 2-D grid of {what} (rows, columns), got {a.ndim}-D "
                    f"shape {a.shape}")
    if min(a.shape) < min_size:
        raise _fail(field, path, f"must hold at least {min_size} x {min_size} {what}, got shape "
                    f"{a.shape}")
    if a.size > MAX_GRID_ELEMENTS:
        raise _fail(field, path, f"grid of {a.shape} is too large (more than {MAX_GRID_ELEMENTS:,} "
                    "values); resample it")
    a = np.asarray(a, np.float64)
    _finite(a, field, path)
    return a


def read_grid(path, field: str, *, min_size: int = 2, what: str = "values") -> np.ndarray:
    """A finite (rows, cols) float64 grid of at least ``min_size`` x ``min_size`` from a
    file whose suffix has a reader in :data:`HEIGHT_MAP_READERS` (.npy, .csv/.txt, float
    .tif/.tiff, and registered ones). Raises :class:`FileInputError` naming ``field``."""
    path = _existing(path, field)
    suffix = path.suffix.lower()
    reader = HEIGHT_MAP_READERS.get(suffix)
    if reader is None:
        known = ", ".join(sorted(HEIGHT_MAP_READERS))
        raise _fail(field, path, f"unknown format {suffix or '(no suffix)'!r}; use one of {known}")
    try:
        a = reader(path, field)
    except (FileInputError, MemoryError):
        raise
    except Exception as err:  # noqa: BLE001 - a plugged-in reader: name the file
        raise _fail(field, path, f"cannot be read ({type(err).__name__}: {err})") from None
    return _as_real_grid(a, field, path, what, min_size)


def read_height_map(path, field: str = "surface.file") -> np.ndarray:
    """(rows, cols) float64 heights of a measured surface, in the file's unit (the
    configuration's ``height_unit`` scales it): .npy, .csv/.txt (one header line allowed),
    a 32/64-bit float .tif/.tiff, or a registered instrument format; at least 4 x 4."""
    return read_grid(path, field, min_size=4, what="heights")


# ----------------------------------------------------------------------------- archives
def read_npz(path, field: str) -> dict[str, np.ndarray]:
    """Every array of a ``.npz`` archive (no pickles), as stored. Raises
    :class:`FileInputError` naming ``field`` for a file that is not a complete archive."""
    path = _existing(path, field)
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):
                raise ValueError("a single .npy array, not a .npz archive")
            return {k: np.asarray(z[k]) for k in z.files}
    except MemoryError:
        raise
    except Exception as err:  # noqa: BLE001 - zipfile/zlib/numpy raise many kinds
        msg = ("holds Python objects (pickles), not numbers" if "pickle" in str(err).lower()
               else f"is not a readable .npz archive ({type(err).__name__}: {err}); was it "
               "truncated?")
        raise _fail(field, path, msg) from None


def read_slope_table(path, field: str = "brdf.file") -> dict[str, np.ndarray]:
    """A slope histogram (``counts`` (nx, ny) >= 0, not all 0; ``edges_x`` (nx + 1,),
    ``edges_y`` (ny + 1,) strictly increasing) or a height map (``heights``: a .npz array or
    a .npy file), validated, as float64 arrays under those names."""
    path = _existing(path, field)
    if path.suffix.lower() == ".npy":
        return {"heights": read_grid(path, field, min_size=4, what="heights")}
    if path.suffix.lower() != ".npz":
        raise _fail(field, path, "a slope table must be .npz (counts + edges_x/edges_y, or "
                    "heights) or .npy (a height map)")
    data = read_npz(path, field)
    if "counts" in data:
        missing = [k for k in ("edges_x", "edges_y") if k not in data]
        if missing:
            raise _fail(field, path, f"a slope histogram needs {missing} beside counts")
        counts = _as_real_grid(data["counts"], field, path, "histogram counts", 1)
        if (counts < 0).any() or counts.sum() <= 0:
            raise _fail(field, path, "counts must be >= 0 and not all 0")
        out = {"counts": counts}
        for k, n in (("edges_x", counts.shape[0] + 1), ("edges_y", counts.shape[1] + 1)):
            e = np.asarray(data[k])
            if e.dtype.kind not in "iuf" or e.shape != (n,):
                raise _fail(field, path, f"{k} must hold {n} numbers (one more than counts has "
                            f"along that axis), got {e.dtype} {e.shape}")
            e = e.astype(np.float64)
            _finite(e, field, path)
            if np.any(np.diff(e) <= 0):
                raise _fail(field, path, f"{k} must increase strictly")
            out[k] = e
        return out
    if "heights" in data:
        return {"heights": _as_real_grid(data["heights"], field, path, "heights", 4)}
    raise _fail(field, path, f"expected arrays 'counts', 'edges_x', 'edges_y' or 'heights' (it "
                f"has {list(data)})")


# ----------------------------------------------------------------------------- BRDF maps
#: The quantities of a BRDF parameter map and their allowed ranges (low, high, low open).
VARIATION_QUANTITIES = {
    "alpha_tangential": (0.0, 2.0, True),
    "alpha_radial": (0.0, 2.0, True),
    "rho_s_scale": (0.0, None, False),
}


def read_variation_map(path, quantity: str | None,
                       field: str = "brdf.variation.file") -> dict[str, np.ndarray]:
    """{quantity: (rows, cols) float64 grid} of BRDF parameter maps: a .npz with arrays
    named after the quantities (:data:`VARIATION_QUANTITIES`), or a .npy/.csv/.txt/.tif
    holding ``quantity``. All grids share one shape (at least 2 x 2), are finite and lie in
    the quantity's range."""
    path = _existing(path, field)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        arrays = read_npz(path, field)
        raw = {k: arrays[k] for k in VARIATION_QUANTITIES if k in arrays}
        if not raw:
            raise _fail(field, path, f"holds none of the arrays {list(VARIATION_QUANTITIES)} (it "
                        f"has {list(arrays)})")
    elif suffix in HEIGHT_MAP_READERS:
        if quantity is None:
            raise _fail(field, path, "a single map needs brdf.variation.quantity (which of "
                        f"{list(VARIATION_QUANTITIES)} it holds)")
        raw = {quantity: HEIGHT_MAP_READERS[suffix](path, field)}
    else:
        raise _fail(field, path, f"unknown map format {suffix or '(no suffix)'!r} (use .npz, "
                    ".npy or .csv)")
    grids: dict[str, np.ndarray] = {}
    shape = None
    for k, a in raw.items():
        g = _as_real_grid(a, field, path, f"{k} values", 2)
        if shape is not None and g.shape != shape:
            raise _fail(field, path, f"the arrays differ in shape ({shape} and {g.shape} of {k})")
        shape = g.shape
        lo, hi, open_low = VARIATION_QUANTITIES.get(k, (None, None, False))
        if lo is not None and ((g <= lo).any() if open_low else (g < lo).any()):
            raise _fail(field, path, f"{k} must be {'>' if open_low else '>='} {lo:g} everywhere "
                        f"(min {g.min():g})")
        if hi is not None and (g > hi).any():
            raise _fail(field, path, f"{k} must be <= {hi:g} everywhere (max {g.max():g})")
        grids[k] = g
    return grids


__all__ = [
    "HEIGHT_MAP_READERS",
    "VARIATION_QUANTITIES",
    "FileInputError",
    "MissingFileError",
    "check_regular_file",
    "read_flatness_map",
    "read_grid",
    "read_height_map",
    "read_npz",
    "read_response_lut",
    "read_slope_table",
    "read_table",
    "read_variation_map",
    "register_height_map_reader",
]
