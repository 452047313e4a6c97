"""``pmdsim export``: a run's surface maps in the formats surface-metrology software reads.

From a run's dataset (``run.zarr``), on the reconstruction grid (``surface_x_mm`` x
``surface_y_mm``, the surface's local frame):

- ``height_error_nm``: reconstructed minus true height after the run's removal;
- ``slope_error_x_urad`` / ``slope_error_y_urad``: reconstructed minus true dz/dx, dz/dy;
- ``reconstructed_height_mm``: the reconstructed sag (where the surface is simulated).

Formats:

- ``x3p``: ISO 25178-72 (one file per height quantity) through the x3pio library (optional
  extra ``pmdsim[x3p]``): a regular grid, x increment = dx, y increment = dy (metres), row r
  of the map at y = y_0 + r dy, the grid's first node placed at (x_0, y_0) (the placement's
  offset), heights in metres; unmeasured nodes are NaN. X3P's z axis is a length that every
  reader labels metres, so the slope maps are not written as X3P (a note says so and points
  to ``csv``/``xyz``, which carry their unit).
- ``csv``: one table of the measured nodes, one column per quantity, units in the header
  (``x_mm,y_mm,height_error_nm,...``) after ``#`` comment lines naming the run.
- ``xyz``: one whitespace-separated ``x y z`` file per quantity (``# x [mm] y [mm] z [nm]``).

Safety (:func:`export_run`): the run must be complete (its ``pmdsim-run.json``, or its
parent's listing it as a variant: a ``.tmp-<pid>`` folder of an unfinished run is refused),
its metadata parse, the exported variables exist and decode chunk by chunk with matching
checksums (a run written before them: a note says a changed byte cannot be seen), and each holds
measured nodes, the same chunks as the height error; every failure names the variable and
the file. The output folder is claimed (a lock, :func:`pmdsim.store.folder_lock.claim_output`)
while the targets are checked and written; every file is written under a temporary name
and then linked to its name without replacing anything (``os.link`` fails if the name
appeared meanwhile; ``--overwrite`` renames over it), so two exports never both report
the same file; a failure removes what this export placed. Temporary files of exports that
died (``.NAME.tmp-<pid>`` of a process that no longer exists) are removed, with a note.
The file's contents depend only on the run (the X3P's date is the run's creation time).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import re
from pathlib import Path

import numpy as np

from ..config import InputError

FORMATS = ("x3p", "csv", "xyz")

#: dataset variable -> (file stem, unit, factor to SI for X3P, description)
QUANTITIES = {
    "height_error_nm": ("height_error", "nm", 1e-9, "reconstructed minus true height"),
    "slope_error_x_urad": ("slope_error_x", "urad", 1e-6, "reconstructed minus true dz/dx"),
    "slope_error_y_urad": ("slope_error_y", "urad", 1e-6, "reconstructed minus true dz/dy"),
    "reconstructed_height_mm": ("reconstructed_height", "mm", 1e-3, "reconstructed sag"),
}
#: The quantities X3P can hold: its z axis is a length (metres to every reader).
X3P_QUANTITIES = ("height_error_nm", "reconstructed_height_mm")

_AGAIN = "the run folder is damaged or unfinished: run pmdsim simulate again (or restore it)"
_TMP_FILE = re.compile(r"^\.(?P<name>.+)\.tmp-(?P<pid>\d+)$")
_TMP_RUN = re.compile(r"\.(tmp|old)-\d+$")


def _one_line(text) -> str:
    """``text`` without line breaks or other control characters (a run name goes into a
    ``#`` comment line: a newline in it would start a data line)."""
    return re.sub(r"[\x00-\x1f\x7f\u2028\u2029]+", " ", str(text)).strip()


def surface_maps(ds) -> tuple[np.ndarray, np.ndarray, dict]:
    """(x_mm (W,), y_mm (H,), {variable: (H, W) array}) of the exportable maps of a run's
    dataset; :class:`InputError` when the run has no reconstruction."""
    have = [k for k in QUANTITIES if k in ds]
    xname = "surface_x_mm" if "surface_x_mm" in ds else "surface_x"
    yname = "surface_y_mm" if "surface_y_mm" in ds else "surface_y"
    if not have or xname not in ds.variables:
        raise InputError("the run has no reconstructed surface (height_error_nm): export needs a "
                         "run with fringes in x and y and reconstruct.enabled not false")
    x = np.asarray(ds[xname].values, np.float64)
    y = np.asarray(ds[yname].values, np.float64)
    return x, y, {k: np.asarray(ds[k].values, np.float64) for k in have}


def write_x3p(path: Path, z_si: np.ndarray, x: np.ndarray, y: np.ndarray, created, comment: str) -> None:
    """Write one X3P file at ``path`` (the caller places it: :func:`_place`)."""
    x3pio = _x3pio()
    from .._version import __version__

    meta = x3pio.Metadata.for_software("pmdsim", __version__, date=created)
    meta = x3pio.Metadata(date=meta.date, creator=meta.creator, instrument=meta.instrument,
                          calibration_date=meta.calibration_date,
                          probing_system=meta.probing_system, comment=_one_line(comment))
    dx = float(x[1] - x[0]) if len(x) > 1 else 1.0
    dy = float(y[1] - y[0]) if len(y) > 1 else 1.0
    with open(path, "wb") as fh:
        x3pio.write(fh, z_si, x_scale=dx * 1e-3, y_scale=dy * 1e-3, metadata=meta,
                    placement=x3pio.Placement.translation(x[0] * 1e-3, y[0] * 1e-3, 0.0),
                    coordinate_system=x3pio.CoordinateSystem.VIEW)


def _x3pio():
    try:
        import x3pio
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise InputError("--format x3p needs the x3pio library: pip install 'pmdsim[x3p]' "
                         "(or --format csv)") from err
    return x3pio


# ----------------------------------------------------------------------------- the run
def _check_complete(run: Path) -> None:
    """The run folder is a finished run: its manifest, or its parent's listing it."""
    from .folder import MANIFEST
    from .schema import DATASET_NAME

    if not run.exists():
        raise InputError(f"{run}: no such run folder; give a folder written by pmdsim simulate")
    if not run.is_dir():
        raise InputError(f"{run}: is a file, not a run folder; give the folder pmdsim simulate "
                         "wrote (the one with run.zarr)")
    if not (run / DATASET_NAME).is_dir():
        members = sorted(p.parent.name for p in run.glob(f"*/{DATASET_NAME}"))
        hint = (f"; a run with variants: export one of {run}/<variant> ({', '.join(members)})"
                if members else "")
        raise InputError(f"{run}: not a pmdsim run folder (no {DATASET_NAME}){hint}")
    unfinished = (f"{run}: an unfinished run (no {MANIFEST}, which pmdsim simulate writes "
                  "last: the run was interrupted or is still being written)")
    for folder in (run, run.parent):
        if _TMP_RUN.search(folder.absolute().name):
            raise InputError(f"{unfinished}; {folder.name} is a temporary folder: export the "
                             "finished run (without .tmp-<pid>)")
    if (run / MANIFEST).is_file():
        return
    parent = run.absolute().parent / MANIFEST
    try:
        listed = json.loads(parent.read_text()).get("variants", []) if parent.is_file() else []
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        raise InputError(f"{parent}: unreadable ({_AGAIN})") from None
    if run.absolute().name not in (listed or []):
        raise InputError(f"{unfinished}; {_AGAIN}")


def _check_store(store: Path, names: list[str], notes: list[str] | None = None) -> dict:
    """Metadata of every node parses; the exported variables are on disk, decode chunk by
    chunk (their checksums match) and have the same chunks on disk as height_error_nm.
    Returns the root's metadata; ``notes`` receives a note for a run written without
    checksums."""
    from .integrity import check_arrays, check_metadata, unchecked_note

    root = check_metadata(store)
    listed = set((root.get("consolidated_metadata") or {}).get("metadata") or {})
    have = [k for k in QUANTITIES if (store / k / "zarr.json").is_file()]
    if not have:
        raise InputError(f"{store}: the run has no reconstructed surface (height_error_nm): "
                         "export needs a run with fringes in x and y and reconstruct.enabled "
                         "not false")
    for k in QUANTITIES:
        if k not in have and (k in listed or k == "height_error_nm"):
            raise InputError(f"{store / k}: the variable {k!r} of the run's reconstruction is "
                             f"missing; {_AGAIN}")
    for k in ("surface_x", "surface_y"):
        if not (store / k / "zarr.json").is_file():
            raise InputError(f"{store / k}: the reconstruction grid's coordinate {k!r} is "
                             f"missing; {_AGAIN}")
    check_arrays(store, root, names=[*have, "surface_x", "surface_y"])
    note = unchecked_note(store, root, [*have, "surface_x", "surface_y"])
    if note is not None and notes is not None:
        notes.append(note)
    chunks = {k: {p.relative_to(store / k) for p in (store / k).rglob("*")
                  if p.is_file() and p.name != "zarr.json"} for k in have}
    ref = chunks["height_error_nm"]
    for k in have:
        lost = (ref - chunks[k]) or (chunks[k] - ref)
        if lost:
            odd = k if chunks[k] < ref else "height_error_nm"
            raise InputError(f"{store / odd / min(lost)}: a chunk of {odd!r} is missing "
                             f"(the other maps of the reconstruction have it); {_AGAIN}")
    return root


def _created(ds, store: Path) -> _dt.datetime:
    created = ds.attrs.get("created_utc")
    if created is None:
        return _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)
    try:
        out = _dt.datetime.fromisoformat(str(created))
    except ValueError:
        raise InputError(f"{store / 'zarr.json'}: the attribute created_utc = {created!r} is not "
                         f"an ISO 8601 time; {_AGAIN}") from None
    return out if out.tzinfo else out.replace(tzinfo=_dt.timezone.utc)


# ----------------------------------------------------------------------------- the output
def _output_folder(out: Path) -> None:
    """Create ``out`` or refuse, naming -o and what to do."""
    if out.exists() and not out.is_dir():
        raise InputError(f"-o {out}: exists and is a file, not a folder; choose another -o "
                         "(a folder for the exported files)")
    blocker = next((p for p in out.absolute().parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise InputError(f"-o {out}: {blocker} is a file, so no folder can be made below it; "
                         "choose another -o")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"-o {out}: cannot create the folder ({err.strerror or err}); choose "
                         "another -o") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise InputError(f"-o {out}: the folder is not writable; choose another -o")


def _remove_stale(out: Path) -> list[str]:
    """Remove ``.NAME.tmp-<pid>`` files of exports whose process no longer exists."""
    from .folder_lock import _pid_alive

    notes = []
    for p in sorted(out.iterdir()):
        m = _TMP_FILE.match(p.name)
        if m and p.is_file() and int(m["pid"]) != os.getpid() and not _pid_alive(int(m["pid"])):
            try:
                p.unlink()
            except OSError:
                continue
            notes.append(f"removed {p}: the unfinished file of an export that was stopped "
                         f"(process {m['pid']} no longer runs)")
    return notes


def _check_targets(targets: list[Path], overwrite: bool) -> None:
    for t in targets:
        if t.is_dir() and not t.is_symlink():
            raise InputError(f"{t}: is a folder, so the file cannot be written (not even with "
                             "--overwrite); remove or rename it, or -o another folder")
        if (t.exists() or t.is_symlink()) and not overwrite:
            raise InputError(f"{t}: exists; pass --overwrite to replace it, or -o another folder")


def _place(tmp: Path, final: Path, overwrite: bool) -> None:
    """Give the complete file ``tmp`` its name ``final``: without ``overwrite`` never over an
    existing name (a hard link fails if the name appeared meanwhile), else by rename."""
    if overwrite:
        os.replace(tmp, final)
        return
    try:
        os.link(tmp, final)
    except FileExistsError:
        raise InputError(f"{final}: appeared while this export ran (another export into the "
                         "same folder?); nothing of this export was kept: pass --overwrite or "
                         "-o another folder") from None
    except OSError:  # a file system without hard links: rename if the name is still free
        if final.exists():
            raise InputError(f"{final}: exists; pass --overwrite or -o another folder") from None
        os.rename(tmp, final)
    else:
        tmp.unlink()


def _write_all(jobs: list[tuple[Path, object]], overwrite: bool) -> None:
    """Write each (final path, writer(tmp)) to a temporary name, then place them all; on any
    failure remove the temporaries and the files placed by this call (never another's)."""
    tmps, placed = [], []
    try:
        for final, write in jobs:
            tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}")
            tmps.append(tmp)
            write(tmp)
        for (final, _), tmp in zip(jobs, tmps):
            _place(tmp, final, overwrite)
            placed.append(final)
    except BaseException as err:
        for t in tmps:
            if t.exists():
                t.unlink()
        if not overwrite:
            for f in placed:
                f.unlink(missing_ok=True)
        if isinstance(err, OSError) and not isinstance(err, (FileExistsError, PermissionError)):
            where = getattr(err, "filename", None) or jobs[len(placed)][0]
            raise InputError(f"{where}: cannot be written ({err.strerror or err}); nothing of "
                             "this export was kept: free space or choose another -o") from None
        raise


def export_run(run: str | Path, fmt: str, output: str | Path | None = None,
               overwrite: bool = False, notes: list[str] | None = None) -> list[Path]:
    """Write the surface maps of the run folder ``run`` (a member folder with
    ``run.zarr``) as ``fmt`` into ``output`` (default ``RUN/export``); returns the files.
    ``notes`` (a list) receives what the caller should tell (slopes left out of X3P,
    removed temporaries)."""
    from .folder_lock import claim_output
    from .schema import DATASET_NAME, load_run

    notes = [] if notes is None else notes
    if fmt not in FORMATS:
        raise InputError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "x3p":
        _x3pio()
    run = Path(run)
    _check_complete(run)
    store = run / DATASET_NAME
    _check_store(store, list(QUANTITIES), notes)
    try:
        ds = load_run(run)
        x, y, maps = surface_maps(ds)
    except InputError as err:
        raise InputError(f"{store}: {err}") from None
    except Exception as err:  # noqa: BLE001 - xarray/zarr: name the store
        raise InputError(f"{store}: cannot be read ({type(err).__name__}: {err}); {_AGAIN}") from None
    for k, a in maps.items():
        if not np.isfinite(a).any():
            raise InputError(f"{store / k}: {k!r} has no measured node (every value is NaN): "
                             "nothing to export; the run's reconstruction is empty or its chunks "
                             "were lost: run pmdsim simulate again")
    for name, c in (("surface_x", x), ("surface_y", y)):
        steps = np.diff(c)
        if (c.size < 1 or not np.isfinite(c).all() or (steps.size and not (
                np.all(steps > 0) and np.ptp(steps) <= 1e-6 * abs(steps[0])))):
            raise InputError(f"{store / name}: the reconstruction grid's {name} is empty, not "
                             f"finite or not evenly spaced; {_AGAIN}")
    name = _one_line(ds.attrs.get("title", str(run)))
    created = _created(ds, store)
    desc = {k: _one_line(ds[k].attrs.get("description", QUANTITIES[k][3])) for k in maps}
    if fmt == "x3p":
        left = [k for k in maps if k not in X3P_QUANTITIES]
        if left:
            notes.append(f"{', '.join(left)} not written as X3P: X3P's z axis is a length that "
                         "every reader labels metres, not a slope; export them with --format "
                         "csv or xyz (units in the header)")
        maps = {k: v for k, v in maps.items() if k in X3P_QUANTITIES}
    out = Path(output) if output is not None else run / "export"
    _output_folder(out)
    targets = ([out / "surface.csv"] if fmt == "csv"
               else [out / f"{QUANTITIES[k][0]}.{fmt}" for k in maps])
    _check_targets(targets, overwrite)  # before any work
    xx, yy = np.meshgrid(x, y)
    dx = x[1] - x[0] if x.size > 1 else float("nan")
    dy = y[1] - y[0] if y.size > 1 else float("nan")
    jobs = []
    if fmt == "x3p":
        for k, t in zip(maps, targets):
            comment = (f"{name}: {k} ({desc[k]}); z in m; grid in the surface's local frame")
            jobs.append((t, lambda tmp, k=k, comment=comment: write_x3p(
                tmp, maps[k] * QUANTITIES[k][2], x, y, created, comment)))
    elif fmt == "csv":
        ok = np.zeros(xx.shape, bool)
        for a in maps.values():
            ok |= np.isfinite(a)
        cols = [xx[ok], yy[ok]] + [maps[k][ok] for k in maps]
        head = "x_mm,y_mm," + ",".join(maps)
        lines = [f"# {name}: surface maps on the reconstruction grid (surface's local frame)",
                 f"# dx = {dx:.9g} mm, dy = {dy:.9g} mm; empty = not measured"]
        lines += [f"# {k}: {desc[k]} [{QUANTITIES[k][1]}]" for k in maps]

        def write_csv(tmp):
            with open(tmp, "w") as fh:
                fh.write("\n".join(lines) + "\n" + head + "\n")
                for row in zip(*cols):
                    fh.write(",".join("" if not np.isfinite(v) else f"{v:.10g}" for v in row) + "\n")
        jobs.append((targets[0], write_csv))
    else:
        for k, t in zip(maps, targets):
            a = maps[k]
            ok = np.isfinite(a)
            data = np.stack([xx[ok], yy[ok], a[ok]], axis=1)
            head = (f"{name}: {k} ({desc[k]}), measured nodes only\n"
                    f"x [mm] y [mm] z [{QUANTITIES[k][1]}]")
            jobs.append((t, lambda tmp, data=data, head=head: np.savetxt(
                tmp, data, fmt="%.10g", header=head, comments="# ")))
    with claim_output(out / ".pmdsim-export"):  # one export at a time into this folder
        notes += _remove_stale(out)
        _check_targets(targets, overwrite)  # again, under the claim
        _write_all(jobs, overwrite)
    return targets
