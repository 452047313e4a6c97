"""What the measurement-chain figures share: the colours of the pixel classes, the deviation
quantities and their units, symmetric colour limits, the class overlay, map sizes and
number formatting (:mod:`pmdsim.report.chain_maps`, :mod:`pmdsim.report.overview`, :mod:`pmdsim.report.dots`)."""

from __future__ import annotations

import json
import math

import numpy as np
from matplotlib.colors import to_rgba
from matplotlib.patches import Patch

from ..measure.deviation import finite_values
from ..quantiles import percentile as quantile_of
from .scene import imshow


#: Colours of the pixel classes in deviation maps.
CLASS_COLOURS = {
    "valid": "#ffffff00",
    "low modulation": "#e377c2",
    "decode flagged": "#111111",
    "no valid reference": "#bdbdbd",
    "off surface": "#ffffff",
    "bundle off monitor": "#8c564b",
}


#: Colours of the decoder's flags (``pmdsim decode`` flags.png and the run's masks.png):
#: distinct hues, none near another or near the valid pixels' light blue.
FLAG_COLOURS = {
    "valid": "#9ecae1",
    "NAN_INPUT": "#d62728",
    "LOW_AMPLITUDE": "#111111",
    "ORDER_RESIDUAL": "#fd8d3c",
    "OUT_OF_RANGE": "#756bb1",
}


DEV_CMAP = "RdBu_r"


DIR_COLOURS = {"x": "#1f77b4", "y": "#ff7f0e"}


#: (dataset variable, scale to display units, label, short label) of the deviation maps.
DEVIATIONS = (
    ("phase_deviation", 1e3, "phase deviation (mrad)", "phase (mrad)"),
    ("coord_deviation_px", 1.0, "monitor coordinate deviation (monitor px)", "coord (px)"),
    ("slope_deviation_urad", 1.0, "slope deviation (urad)", "slope (urad)"),
)


#: Resolution of the overview page (22 in wide: 2200 px; its smallest text, 7 pt, is
#: 10 px high). The other figures use :data:`pmdsim.report.scene.DPI`.
OVERVIEW_DPI = 100


#: What each coordinate deviation is measured against, as the figures label it.
VS_MIRROR = "vs decoded mirror reference"


VS_EXACT = "vs exact specular point"


def coord_vs_exact(ds, d: str) -> np.ndarray:
    """(H, W) decoded monitor coordinate minus the exact specular point P (monitor px) on
    the valid pixels: what the surface's scattering does to the measurement, without the
    decoded mirror reference's own quantisation (which ``coord_deviation_px`` contains on a
    ``nearest`` monitor)."""
    exact = ds["specular_u" if d == "x" else "specular_v"].values
    coord = ds["monitor_coord_px"].sel(direction=d).values
    return np.where(ds["valid"].sel(direction=d).values, coord - exact, np.nan)


def _dirs(ds) -> list[str]:
    return [str(d) for d in ds["direction"].values]


def _label(ds, name: str | None = None) -> str:
    return name or str(ds.attrs.get("title", "")).removeprefix("pmdsim run ") or "run"


def _nice(x: float) -> float:
    """Round a positive limit up to 1, 2 or 5 x 10^n."""
    if not np.isfinite(x) or x <= 0:
        return 1.0
    e = math.floor(math.log10(x))
    for m in (1, 2, 2.5, 5, 10):
        if m * 10**e >= x * (1 - 1e-9):
            return m * 10**e
    return 10 ** (e + 1)


def symmetric_limit(arrays, percentile: float = 99.5) -> float:
    """A symmetric colour limit: the largest ``percentile`` of |a| over ``arrays``, rounded."""
    vals = []
    for a in arrays:
        a, _ = finite_values(a)
        np.abs(a, out=a)
        if a.size:
            vals.append(quantile_of(a, percentile, overwrite=True))
    lim = max(vals) if vals else 0.0
    return _nice(lim) if lim > 0 else 1e-6


def valid_only(ds, d: str, a) -> np.ndarray:
    """``a`` (H, W) on the valid pixels of direction ``d``, NaN elsewhere: what colour limits
    are taken from (a masked pixel's value must not stretch the scale of the others)."""
    return np.where(ds["valid"].sel(direction=d).values, a, np.nan)


def _classes(ds, d: str):
    """Boolean maps (valid, low, flagged, no_ref, off) of direction ``d``."""
    valid = ds["valid"].sel(direction=d).values.astype(bool)
    low = ds["low_modulation"].sel(direction=d).values.astype(bool)
    surface = ds["surface_mask"].values.astype(bool)
    considered = ds["reference_decode_flags"].sel(direction=d).values == 0
    flagged = considered & ~valid & ~low & ~_off_monitor(ds, d)
    no_ref = surface & ~considered
    return valid, low, flagged, no_ref, ~surface


def _off_monitor(ds, d: str) -> np.ndarray:
    """Considered pixels excluded because their bundle hangs off the monitor (not low
    modulation): their own class, ``lobe_off_monitor``; all False for older runs."""
    if "lobe_off_monitor" not in ds:
        return np.zeros(ds["surface_mask"].shape, bool)
    considered = ds["reference_decode_flags"].sel(direction=d).values == 0
    low = ds["low_modulation"].sel(direction=d).values.astype(bool)
    return considered & ds["lobe_off_monitor"].values.astype(bool) & ~low


def _overlay(ax, ds, d: str, legend: bool = False, counts: bool = True):
    """Draw the masked pixel classes over a map; returns legend handles."""
    valid, low, flagged, no_ref, off = _classes(ds, d)
    rgba = np.zeros(valid.shape + (4,))
    handles = []
    for name, m in (("off surface", off), ("no valid reference", no_ref),
                    ("decode flagged", flagged), ("low modulation", low),
                    ("bundle off monitor", _off_monitor(ds, d))):
        rgba[m] = to_rgba(CLASS_COLOURS[name])
        if m.any() or name in ("low modulation", "decode flagged"):
            lab = f"{name}: {int(m.sum()):,}" if counts else name
            handles.append(Patch(facecolor=CLASS_COLOURS[name], edgecolor="0.5", label=lab))
    imshow(ax, rgba, interpolation="nearest")
    if legend:
        ax.legend(handles=handles, loc="lower left", fontsize=6, framealpha=0.85)
    return handles


def _stats(ds) -> dict:
    return json.loads(ds.attrs["statistics_json"])


def _map_size(ds, cols: int, rows: int, panel: float = 3.6, extra_w: float = 1.2,
              extra_h: float = 0.9):
    h, w = ds["surface_mask"].shape
    return (panel * cols + extra_w, (panel * h / w + extra_h) * rows)


def _g(v, digits: int = 3) -> str:
    return "nan" if v is None or not np.isfinite(v) else f"{v:.{digits}g}"


#: The numerical error a deviation shares with another: the coordinate against the exact
#: specular point has the decoded coordinate's error (the exact point has none).
_ERROR_OF = {"coord_vs_exact_px": "coord_px"}


def _with_error(s_dir: dict, key: str) -> dict:
    """The statistics of deviation ``key`` of one direction's statistics, with ``"error"``:
    its numerical error's statistics (``numerical_error``, absent where none is stated)."""
    out = dict(s_dir.get(key) or {})
    err = (s_dir.get("numerical_error") or {}).get(_ERROR_OF.get(key, key))
    if err:
        out["error"] = err
    return out


def _pm(s: dict, stat: str, digits: int = 3) -> str:
    """Statistic ``stat`` (``"rms"``, ``"p95"``) of :func:`_with_error` statistics as
    "value ± numerical error" (the value alone where no error is stated)."""
    e = (s.get("error") or {}).get(stat)
    if e is None or not np.isfinite(e):
        return _g(s.get(stat), digits)
    return f"{_g(s.get(stat), digits)} ± {_g(e, 2)}"


def _histogram(ax, data: dict, colours: dict, stats: dict, bins: int = 121, lim=None,
               log: bool = False, styles: dict | None = None):
    """Step histograms of ``data`` (label -> values) on a symmetric range, labelled with
    ``stats`` (label -> :func:`_with_error` statistics: "RMS value ± error"); ``log``: a log
    count axis (set before the limits, so that the empty bins do not collapse it)."""
    lim = symmetric_limit(data.values(), 99.9) if lim is None else lim
    styles = styles or {}
    if log:
        ax.set_yscale("log")
    top = 0.0
    for key, a in data.items():
        a, _ = finite_values(a)
        if not a.size:
            continue
        s = stats.get(key, {})
        # bins and range, not an array of edges: NumPy's uniform-bin path (the same edges,
        # linspace(-lim, lim, bins + 1), and counts; no sort of the values)
        counts, _, _ = ax.hist(np.clip(a, -lim, lim), bins=bins, range=(-lim, lim),
                               histtype="step", linewidth=1.3, color=colours.get(key),
                               linestyle=styles.get(key, "-"),
                               label=f"{key}: RMS {_pm(s, 'rms')}, P95 {_pm(s, 'p95')}"
                               f"\n{'':>4}mean {_g(s.get('mean'))}, n = {a.size:,}")
        top = max(top, float(np.max(counts)) if np.size(counts) else 0.0)
    ax.axvline(0, color="0.5", linewidth=0.6)
    ax.set_xlim(-lim, lim)
    leg = ax.legend(fontsize=6.5, loc="upper left", title_fontsize=6,
                    title=f"(|values| > {lim:g} in the end bins)")
    # room above the highest bin for the legend (it spans the axes' width, so it would
    # cover a peak): the bins end below its lower edge
    fig = ax.get_figure()
    box = leg.get_window_extent(fig.canvas.get_renderer())
    axes_box = ax.get_window_extent()
    free = min(max((box.y0 - axes_box.y0) / axes_box.height - 0.04, 0.35), 0.95)
    top = max(top, 1.0)
    if log:
        ax.set_ylim(0.5, 0.5 * (2 * top) ** (1 / free))
    else:
        ax.set_ylim(0, top / free)
    ax.tick_params(labelsize=7)


def _wrap(text: str, width: int) -> str:
    import textwrap

    return textwrap.fill(text, width)
