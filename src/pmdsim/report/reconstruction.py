"""The surface-error figure of a run or variant: slope errors (urad) and height error (nm)
of the monocular reconstruction against the configured surface, on the surface grid (the
surface's local frame, mm), with RMS / PV / P95 in the titles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .scene import _figure, _save

CMAP = "RdBu_r"


def _limit(a):
    f = np.abs(a[np.isfinite(a)])
    return float(np.percentile(f, 99.5)) if f.size else 1.0


def plot_surface_errors(ds, name: str = "", description: str = ""):
    """Figure: slope error x, slope error y (urad), height error (nm)."""
    x = ds["surface_x"].values
    y = ds["surface_y"].values
    ext = (x[0] - (x[1] - x[0]) / 2, x[-1] + (x[1] - x[0]) / 2,
           y[0] - (y[1] - y[0]) / 2, y[-1] + (y[1] - y[0]) / 2)
    stats = json.loads(ds.attrs.get("statistics_json", "{}")).get("reconstruction", {})
    fig = _figure((15.0, 4.8))
    axes = fig.subplots(1, 3)
    panels = (
        ("slope_error_x_urad", "slope error dz/dx", "urad", stats.get("slope_error_x_urad")),
        ("slope_error_y_urad", "slope error dz/dy", "urad", stats.get("slope_error_y_urad")),
        ("height_error_nm", "height error", "nm", stats.get("height_error_nm")),
    )
    for ax, (var, label, unit, st) in zip(axes, panels):
        a = ds[var].values
        lim = _limit(a) or 1.0
        im = ax.imshow(a, cmap=CMAP, vmin=-lim, vmax=lim, extent=ext, origin="lower",
                       interpolation="nearest")
        ax.set_xlabel("surface x (mm)")
        ax.set_ylabel("surface y (mm)")
        ax.set_aspect("equal")
        title = f"{label} ({unit})"
        if st:
            rms = st.get("rms_about_zero", st["rms"])
            title += f"\nRMS {rms:.3g}  PV {st['pv']:.3g}  P95 {st['p95']:.3g} {unit}"
        ax.set_title(title, fontsize=10)
        fig.colorbar(im, ax=ax, shrink=0.85, label=unit)
    removed = stats.get("removed", "")
    fig.suptitle(f"{name}: reconstructed minus true surface ({removed} removed from the height)"
                 + (f"\n{description}" if description else ""), fontsize=11)
    return fig


def reconstruction_figures(ds, folder, name: str = "", description: str = "") -> list[Path]:
    """``surface_errors.png`` into ``folder`` when the dataset has a reconstruction."""
    if "height_error_nm" not in ds:
        return []
    return [_save(plot_surface_errors(ds, name, description), Path(folder) / "surface_errors.png")]
