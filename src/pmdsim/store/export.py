"""``pmdsim export``: a run's surface maps in the formats surface-metrology software reads.

From a run's dataset (``run.zarr``), on the reconstruction grid (``surface_x_mm`` x
``surface_y_mm``, the surface's local frame):

- ``height_error_nm``: reconstructed minus true height after the run's removal;
- ``slope_error_x_urad`` / ``slope_error_y_urad``: reconstructed minus true dz/dx, dz/dy;
- ``reconstructed_height_mm``: the reconstructed sag (where the surface is simulated).

Formats:

- ``x3p``: ISO 25178-72 (one file per quantity) through the x3pio library (optional extra
  ``pmdsim[x3p]``): a regular grid, x increment = dx, y increment = dy (metres), row r of
  the map at y = y_0 + r dy, the grid's first node placed at (x_0, y_0) (the placement's
  offset), heights in metres; unmeasured nodes are NaN. X3P's z axis is a length: the slope
  files hold the slope in rad as "metres" (the file's comment says so).
- ``csv``: one table of the measured nodes, one column per quantity, units in the header
  (``x_mm,y_mm,height_error_nm,...``) after ``#`` comment lines naming the run.
- ``xyz``: one whitespace-separated ``x y z`` file per quantity (``# x [mm] y [mm] z [nm]``).

Every file is written under a temporary name and renamed when complete; the file's
contents depend only on the run (the X3P's date is the run's creation time).
"""

from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path

import numpy as np

from ..config import InputError

FORMATS = ("x3p", "csv", "xyz")

#: dataset variable -> (file stem, unit, factor to SI for X3P, description)
QUANTITIES = {
    "height_error_nm": ("height_error", "nm", 1e-9, "reconstructed minus true height"),
    "slope_error_x_urad": ("slope_error_x", "urad", 1e-6, "reconstructed minus true dz/dx (rad in X3P)"),
    "slope_error_y_urad": ("slope_error_y", "urad", 1e-6, "reconstructed minus true dz/dy (rad in X3P)"),
    "reconstructed_height_mm": ("reconstructed_height", "mm", 1e-3, "reconstructed sag"),
}


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


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
    try:
        import x3pio
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise InputError("--format x3p needs the x3pio library: pip install 'pmdsim[x3p]'") from err
    from .._version import __version__

    meta = x3pio.Metadata.for_software("pmdsim", __version__, date=created)
    meta = x3pio.Metadata(date=meta.date, creator=meta.creator, instrument=meta.instrument,
                          calibration_date=meta.calibration_date,
                          probing_system=meta.probing_system, comment=comment)
    dx = float(x[1] - x[0]) if len(x) > 1 else 1.0
    dy = float(y[1] - y[0]) if len(y) > 1 else 1.0

    def write(tmp):
        with open(tmp, "wb") as fh:
            x3pio.write(fh, z_si, x_scale=dx * 1e-3, y_scale=dy * 1e-3, metadata=meta,
                        placement=x3pio.Placement.translation(x[0] * 1e-3, y[0] * 1e-3, 0.0),
                        coordinate_system=x3pio.CoordinateSystem.VIEW)
    _atomic_write(path, write)


def export_run(run: str | Path, fmt: str, output: str | Path | None = None,
               overwrite: bool = False) -> list[Path]:
    """Write the surface maps of the run folder ``run`` (a member folder with
    ``run.zarr``) as ``fmt`` into ``output`` (default ``RUN/export``); returns the files."""
    from .schema import DATASET_NAME, load_run

    if fmt not in FORMATS:
        raise InputError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    run = Path(run)
    if not (run / DATASET_NAME).is_dir():
        members = sorted(p.parent.name for p in run.glob(f"*/{DATASET_NAME}"))
        hint = (f"; a run with variants: export one of {run}/<variant> ({', '.join(members)})"
                if members else "")
        raise InputError(f"{run}: not a pmdsim run folder (no {DATASET_NAME}){hint}")
    ds = load_run(run)
    x, y, maps = surface_maps(ds)
    out = Path(output) if output is not None else run / "export"
    out.mkdir(parents=True, exist_ok=True)
    name = ds.attrs.get("title", str(run))
    created = ds.attrs.get("created_utc")
    created = (_dt.datetime.fromisoformat(created) if created
               else _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc))
    desc = {k: ds[k].attrs.get("description", QUANTITIES[k][3]) for k in maps}
    if fmt == "csv":
        targets = [out / "surface.csv"]
    else:
        targets = [out / f"{QUANTITIES[k][0]}.{fmt}" for k in maps]
    existing = [t for t in targets if t.exists()]
    if existing and not overwrite:
        raise InputError(f"{existing[0]} exists: use --overwrite to replace it, or -o another folder")
    xx, yy = np.meshgrid(x, y)
    if fmt == "x3p":
        for k, t in zip(maps, targets):
            write_x3p(t, maps[k] * QUANTITIES[k][2], x, y, created,
                 f"{name}: {k} ({desc[k]}); z in {'m' if k.endswith(('_nm', '_mm')) else 'rad'}; "
                 "grid in the surface's local frame")
    elif fmt == "csv":
        ok = np.zeros(xx.shape, bool)
        for a in maps.values():
            ok |= np.isfinite(a)
        cols = [xx[ok], yy[ok]] + [maps[k][ok] for k in maps]
        head = "x_mm,y_mm," + ",".join(maps)
        lines = [f"# {name}: surface maps on the reconstruction grid (surface's local frame)",
                 f"# dx = {x[1] - x[0]:.9g} mm, dy = {y[1] - y[0]:.9g} mm; empty = not measured"]
        lines += [f"# {k}: {desc[k]} [{QUANTITIES[k][1]}]" for k in maps]

        def write(tmp):
            with open(tmp, "w") as fh:
                fh.write("\n".join(lines) + "\n" + head + "\n")
                for row in zip(*cols):
                    fh.write(",".join("" if not np.isfinite(v) else f"{v:.10g}" for v in row) + "\n")
        _atomic_write(targets[0], write)
    else:
        for k, t in zip(maps, targets):
            a = maps[k]
            ok = np.isfinite(a)
            data = np.stack([xx[ok], yy[ok], a[ok]], axis=1)
            unit = QUANTITIES[k][1]
            head = (f"{name}: {k} ({desc[k]}), measured nodes only\n"
                    f"x [mm] y [mm] z [{unit}]")

            def write(tmp, data=data, head=head):
                np.savetxt(tmp, data, fmt="%.10g", header=head, comments="# ")
            _atomic_write(t, write)
    return targets
