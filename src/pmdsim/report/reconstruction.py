"""The surface-error figure of a run or variant: slope errors (urad) and height error (nm)
of the monocular reconstruction against the configured surface, on the surface grid (the
surface's local frame, mm), with RMS / PV / P95 in the titles."""

from __future__ import annotations

import json
import textwrap

import matplotlib.colors
import numpy as np

from ..quantiles import percentile
from .scene import _axes_at, _fixed_figure
from .text import excluded_text
from .text import value_pm as _pm

CMAP = "RdBu_r"
#: excluded nodes: one light grey
_GREY = matplotlib.colors.ListedColormap(["0.8"])


def _limit(a):
    f = np.abs(a[np.isfinite(a)])
    return percentile(f, 99.5, overwrite=True) if f.size else 1.0


def plot_surface_errors(ds, name: str = "", description: str = ""):
    """Figure: slope error x, slope error y (urad), height error (nm), each on a symmetric
    scale (P99.5 of |error|), framed to the grid nodes that hold a value."""
    x = ds["surface_x"].values
    y = ds["surface_y"].values
    names = ("slope_error_x_urad", "slope_error_y_urad", "height_error_nm")
    # frame: the bounding box of the reconstructed nodes (a part may fill a corner of its grid)
    data = np.zeros((y.size, x.size), bool)
    for var in names:
        data |= np.isfinite(ds[var].values)
    rows, cols = np.nonzero(data.any(axis=1))[0], np.nonzero(data.any(axis=0))[0]
    keep = ((slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)) if rows.size >= 2
            and cols.size >= 2 else (slice(None), slice(None)))
    x, y = x[keep[1]], y[keep[0]]
    ext = (x[0] - (x[1] - x[0]) / 2, x[-1] + (x[1] - x[0]) / 2,
           y[0] - (y[1] - y[0]) / 2, y[-1] + (y[1] - y[0]) / 2)
    stats = json.loads(ds.attrs.get("statistics_json", "{}")).get("reconstruction", {})
    # laid out by hand (inches): three maps of the surface's aspect, each with its bar
    left, pw, cb_gap, cb_w, cb_room = 0.8, 3.2, 0.12, 0.15, 0.85
    aspect = abs(ext[3] - ext[2]) / max(abs(ext[1] - ext[0]), 1e-12)
    ph = min(pw * aspect, 4.0)
    pw = ph / aspect if ph < pw * aspect else pw
    top, bottom = (1.45 if "excluded_nodes" in stats else 1.05), 0.6
    step = left + pw + cb_gap + cb_w + cb_room
    fig = _fixed_figure((3 * step + 0.1, top + ph + bottom))
    axes = [_axes_at(fig, left + k * step, bottom, pw, ph) for k in range(3)]
    caxes = [_axes_at(fig, left + k * step + pw + cb_gap, bottom, cb_w, ph) for k in range(3)]
    panels = (
        ("slope_error_x_urad", "slope error dz/dx", "urad", stats.get("slope_error_x_urad")),
        ("slope_error_y_urad", "slope error dz/dy", "urad", stats.get("slope_error_y_urad")),
        ("height_error_nm", "height error", "nm", stats.get("height_error_nm")),
    )
    excluded = None
    if "reconstruction_node_status" in ds:  # excluded nodes (codes >= 2; -1: off the aperture)
        excluded = ds["reconstruction_node_status"].values[keep] >= 2
    for ax, cax, (var, label, unit, st) in zip(axes, caxes, panels):
        a = ds[var].values[keep]
        lim = _limit(a) or 1.0
        if excluded is not None:  # aperture nodes not reported: grey under the map
            ax.imshow(np.where(excluded, 1.0, np.nan), cmap=_GREY, vmin=0, vmax=1, extent=ext,
                      origin="lower", interpolation="nearest")
        im = ax.imshow(a, cmap=CMAP, vmin=-lim, vmax=lim, extent=ext, origin="lower",
                       interpolation="nearest")
        ax.set_xlabel("surface x (mm)")
        ax.set_ylabel("surface y (mm)")
        ax.set_aspect("equal")
        title = f"{label} ({unit})"
        if st:
            rms = "rms_about_zero" if "rms_about_zero" in st else "rms"
            title += (f"\nRMS {_pm(st, rms)}  PV {_pm(st, 'pv')}  P95 {_pm(st, 'p95')} {unit}")
        ax.set_title(title, fontsize=10)
        fig.colorbar(im, cax=cax, label=f"{unit}, scale +-{lim:.3g} (P99.5 of |error|)")
    removed = stats.get("removed", "")
    note = ""
    if "excluded_nodes" in stats:  # wrapped to the figure's width (about 12 characters an inch)
        text = excluded_text(stats)
        if stats["excluded_nodes"]["total"]:
            text = text.replace("not reported:", "not reported (grey):", 1)
        note = "\n" + textwrap.fill(text, int(fig.get_size_inches()[0] * 11))
    fig.suptitle(f"{name}: reconstructed minus true surface ({removed} removed from the height)"
                 + note + (f"\n{description}" if description else ""), fontsize=11,
                 y=1 - 0.08 / fig.get_size_inches()[1], va="top")
    return fig

