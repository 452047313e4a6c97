"""Figures of the measurement chain (decode -> deviation) and of the dot scan.

For a metrologist's report: physical units on every colour bar, the variant and direction
in every title, symmetric colour scales for deviations, and masked pixels drawn in their
own colours with their counts (never hidden):

- :func:`plot_phase`: wrapped phase of every width and the absolute phase, per direction;
- :func:`plot_deviation`: phase (mrad), monitor coordinate (monitor px) and slope (urad)
  deviation maps;
- :func:`plot_histograms`: histograms of those deviations, X and Y;
- :func:`plot_modulation_ratio`: modulation ratio (surface / reference) per width;
- :func:`plot_masks`: which pixels were valid, masked for low modulation, flagged by the
  decoder, or had no valid reference;
- :func:`plot_overview`: one page with the essentials (fringes, modulation ratio,
  coordinate deviation, histogram, statistics);
- :func:`plot_variant_deviation`: the coordinate deviation of several variants on one
  common scale;
- :func:`plot_dot_contact_sheet`, :func:`plot_dot_shapes`: the dot scan;
- :func:`plot_decoded`: maps of a decoded image set (``pmdsim decode``).

All functions draw on Agg :class:`~matplotlib.figure.Figure` objects (no pyplot) and take
in-memory xarray Datasets with the variables of :func:`pmdsim.run.dataset.assign_to_dataset`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap, to_rgba
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse, Patch
from matplotlib.ticker import FixedLocator, MaxNLocator

from .scene import DPI, _axes_at, _figure, _fixed_figure, _save, imshow

#: Colours of the pixel classes in deviation maps.
CLASS_COLOURS = {
    "valid": "#ffffff00",
    "low modulation": "#e377c2",
    "decode flagged": "#111111",
    "no valid reference": "#bdbdbd",
    "off surface": "#ffffff",
    "bundle off monitor": "#8c564b",
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
        a = np.abs(np.asarray(a, np.float64))
        a = a[np.isfinite(a)]
        if a.size:
            vals.append(np.percentile(a, percentile))
    lim = max(vals) if vals else 0.0
    return _nice(lim) if lim > 0 else 1e-6


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


def _noticks(ax):
    ax.set_xticks([])
    ax.set_yticks([])


def _image_axes(ax):
    ax.set_xlabel("camera column", fontsize=8)
    ax.set_ylabel("camera row", fontsize=8)
    ax.tick_params(labelsize=7)
    # a few whole-pixel ticks (each tick is ~3 ms of drawing)
    ax.xaxis.set_major_locator(MaxNLocator(5, integer=True))
    ax.yaxis.set_major_locator(MaxNLocator(4, integer=True))


def _stats(ds) -> dict:
    return json.loads(ds.attrs["statistics_json"])


def _map_size(ds, cols: int, rows: int, panel: float = 3.6, extra_w: float = 1.2,
              extra_h: float = 0.9):
    h, w = ds["surface_mask"].shape
    return (panel * cols + extra_w, (panel * h / w + extra_h) * rows)


# ----------------------------------------------------------------------------- phase
def plot_phase(ds, path, name: str | None = None) -> Path:
    """Wrapped phase of every width (cyclic map, rad) and the absolute phase of the finest
    width (rad), rows = directions."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    widths = [float(x) for x in ds["width"].values]
    fig = _figure(_map_size(ds, len(widths) + 1, len(dirs), 3.4, 2.0))
    axes = fig.subplots(len(dirs), len(widths) + 1, squeeze=False)
    for i, d in enumerate(dirs):
        im = None
        for j, wd in enumerate(widths):
            ax = axes[i, j]
            im = imshow(ax, ds["wrapped_phase"].sel(direction=d, width=wd).values, cmap="twilight",
                           vmin=-np.pi, vmax=np.pi, interpolation="nearest")
            ax.set_title(f"{name}: {d.upper()} wrapped phase\nwidth {wd:g} monitor px", fontsize=8)
            _noticks(ax)
        cb = fig.colorbar(im, ax=list(axes[i, :len(widths)]), shrink=0.8, pad=0.01)
        cb.set_label("wrapped phase (rad)", fontsize=8)
        cb.set_ticks([-np.pi, -np.pi / 2, 0, np.pi / 2, np.pi],
                     labels=["-pi", "-pi/2", "0", "pi/2", "pi"])
        ax = axes[i, -1]
        absphase = ds["absolute_phase"].sel(direction=d).values
        absphase = np.where(ds["decode_flags"].sel(direction=d).values == 0, absphase, np.nan)
        im = imshow(ax, absphase, cmap="viridis", interpolation="nearest")
        ax.set_facecolor(CLASS_COLOURS["no valid reference"])
        ax.set_title(f"{name}: {d.upper()} absolute phase\nwidth {min(widths):g} px "
                     "(flagged pixels grey)", fontsize=8)
        _noticks(ax)
        cb = fig.colorbar(im, ax=ax, shrink=0.8, pad=0.01)
        cb.set_label("absolute phase (rad)", fontsize=8)
    return _save(fig, path)


# ----------------------------------------------------------------------------- deviation
def plot_deviation(ds, path, name: str | None = None) -> Path:
    """Phase (mrad), monitor coordinate (monitor px) and slope (urad) deviation maps, rows =
    directions. The coordinate deviation is shown twice, labelled on the figure: against the
    decoded mirror reference (what a PMD system compares with; on a ``nearest`` monitor it
    contains the mirror's own +-0.5 px pixel quantisation) and against the exact specular
    point P (what the scattering does). One symmetric colour scale per quantity (X and Y
    comparable; both coordinate columns share one)."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    stats = _stats(ds)["directions"]
    coord_mirror = [ds["coord_deviation_px"].sel(direction=d).values for d in dirs]
    coord_exact = [coord_vs_exact(ds, d) for d in dirs]
    coord_lim = symmetric_limit(coord_mirror + coord_exact)
    panels = [  # (maps, colour limit, title, unit, statistics key, colour-bar label)
        ([ds["phase_deviation"].sel(direction=d).values * 1e3 for d in dirs], None,
         f"phase deviation {VS_MIRROR}", "mrad", "phase_mrad", "phase deviation (mrad)"),
        (coord_mirror, coord_lim, f"coordinate deviation\n{VS_MIRROR}", "px", "coord_px",
         f"monitor coordinate {VS_MIRROR} (monitor px)"),
        (coord_exact, coord_lim, f"coordinate deviation\n{VS_EXACT}", "px",
         "coord_vs_exact_px", f"monitor coordinate {VS_EXACT} (monitor px)"),
        ([ds["slope_deviation_urad"].sel(direction=d).values for d in dirs], None,
         f"slope deviation {VS_MIRROR}", "urad", "slope_urad", "slope deviation (urad)"),
    ]
    fig = _figure(_map_size(ds, len(panels), len(dirs), 3.9, 1.6, 1.4))
    axes = fig.subplots(len(dirs), len(panels), squeeze=False)
    for j, (maps, lim, title, unit, key, label) in enumerate(panels):
        lim = symmetric_limit(maps) if lim is None else lim
        im = None
        for i, d in enumerate(dirs):
            ax = axes[i, j]
            im = imshow(ax, maps[i], cmap=DEV_CMAP, vmin=-lim, vmax=lim, interpolation="nearest")
            _overlay(ax, ds, d, legend=(j == 0))
            st = stats[d].get(key) or {}
            ax.set_title(f"{name}: {d.upper()} {title}\nmean {_g(st.get('mean'))}, "
                         f"RMS {_g(st.get('rms'))}, P95 {_g(st.get('p95'))} {unit}", fontsize=8)
            _image_axes(ax)
        cb = fig.colorbar(im, ax=list(axes[:, j]), orientation="horizontal", shrink=0.9,
                          extend="both", pad=0.02)
        cb.set_label(label + f"\nscale +-{lim:g} (P99.5)", fontsize=8)
    return _save(fig, path)


def _g(v, digits: int = 3) -> str:
    return "nan" if v is None or not np.isfinite(v) else f"{v:.{digits}g}"


def plot_histograms(ds, path, name: str | None = None) -> Path:
    """Histograms of the phase, coordinate and slope deviations (valid pixels), X and Y."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    stats = _stats(ds)["directions"]
    keys = ("phase_mrad", "coord_px", "slope_urad")
    fig = _figure((13.5, 4.0))
    axes = fig.subplots(1, 3)
    for ax, (var, scale, label, _), key in zip(axes, DEVIATIONS, keys):
        _histogram(ax, {d.upper(): ds[var].sel(direction=d).values * scale for d in dirs},
                   {d.upper(): DIR_COLOURS.get(d, None) for d in dirs},
                   {d.upper(): stats[d][key] for d in dirs})
        ax.set_xlabel(label)
        ax.set_title(f"{name}: {label.split(' (')[0]}", fontsize=9)
    axes[0].set_ylabel("pixels")
    return _save(fig, path)


def _histogram(ax, data: dict, colours: dict, stats: dict, bins: int = 121, lim=None,
               log: bool = False, styles: dict | None = None):
    """Step histograms of ``data`` (label -> values) on a symmetric range; ``log``: a log
    count axis (set before the limits, so that the empty bins do not collapse it)."""
    lim = symmetric_limit(data.values(), 99.9) if lim is None else lim
    styles = styles or {}
    if log:
        ax.set_yscale("log")
    edges = np.linspace(-lim, lim, bins + 1)
    top = 0.0
    for key, a in data.items():
        a = np.asarray(a, np.float64)
        a = a[np.isfinite(a)]
        if not a.size:
            continue
        s = stats.get(key, {})
        counts, _, _ = ax.hist(np.clip(a, -lim, lim), bins=edges, histtype="step",
                               linewidth=1.3, color=colours.get(key),
                               linestyle=styles.get(key, "-"),
                               label=f"{key}: mean {_g(s.get('mean'))}, "
                               f"RMS {_g(s.get('rms'))}, P95 {_g(s.get('p95'))}, n = {a.size:,}")
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


# ----------------------------------------------------------------------------- modulation
def plot_modulation_ratio(ds, path, name: str | None = None) -> Path:
    """Modulation of the surface relative to the specular reference, per width (rows =
    directions), with the masking threshold in the colour bar."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    widths = [float(x) for x in ds["width"].values]
    thr = float(ds.attrs.get("min_modulation_ratio", 0.1))
    fig = _figure(_map_size(ds, len(widths), len(dirs), 3.6, 1.4))
    axes = fig.subplots(len(dirs), len(widths), squeeze=False)
    im = None
    for i, d in enumerate(dirs):
        for j, wd in enumerate(widths):
            r = ds["modulation_ratio"].sel(direction=d, width=wd).values
            ax = axes[i, j]
            im = imshow(ax, r, cmap="viridis", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_facecolor(CLASS_COLOURS["no valid reference"])
            med = np.nanmedian(r) if np.isfinite(r).any() else np.nan
            below = int(np.count_nonzero(r < thr))
            ax.set_title(f"{name}: {d.upper()}, width {wd:g} monitor px\nmedian ratio {med:.3f}; "
                         f"{below:,} px < {thr:g}", fontsize=8)
            _noticks(ax)
    cb = fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, extend="max")
    cb.set_label("modulation / reference modulation (1)", fontsize=8)
    cb.ax.axhline(thr, color="#e377c2", linewidth=2)
    return _save(fig, path)


def plot_masks(ds, path, name: str | None = None) -> Path:
    """Pixel classes per direction: valid, low modulation (masked), decode flagged (by
    reason), no valid reference, off the surface; counts in the legend."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    cols = ["#9ecae1", CLASS_COLOURS["low modulation"], "#111111", "#fd8d3c", "#8c6d31",
            CLASS_COLOURS["no valid reference"], "#ffffff", CLASS_COLOURS["bundle off monitor"]]
    labels = ["valid", "low modulation (masked)", "flagged: low amplitude",
              "flagged: order residual", "flagged: out of range / other",
              "no valid reference", "off surface", "bundle off the monitor (masked)"]
    cmap = ListedColormap(cols)
    h, w = ds["surface_mask"].shape
    fig = _figure((4.6 * len(dirs) + 0.4, 4.6 * h / w + 1.9))
    gs = fig.add_gridspec(2, len(dirs), height_ratios=[4.6 * h / w, 1.0])
    for k_dir, d in enumerate(dirs):
        ax = fig.add_subplot(gs[0, k_dir])
        lax = fig.add_subplot(gs[1, k_dir])
        lax.set_axis_off()
        valid, low, flagged, no_ref, off = _classes(ds, d)
        flags = ds["decode_flags"].sel(direction=d).values
        cls = np.full(valid.shape, 6)
        cls[no_ref] = 5
        cls[flagged] = 4
        cls[flagged & (flags & 4 > 0)] = 3
        cls[flagged & (flags & 2 > 0)] = 2
        cls[low] = 1
        cls[_off_monitor(ds, d)] = 7
        cls[valid] = 0
        imshow(ax, cls, cmap=cmap, vmin=-0.5, vmax=7.5, interpolation="nearest")
        handles = [Patch(facecolor=c, edgecolor="0.5", label=f"{lab}: {int((cls == k).sum()):,}")
                   for k, (c, lab) in enumerate(zip(cols, labels))]
        lax.legend(handles=handles, loc="upper center", ncol=2, fontsize=7, frameon=False)
        ax.set_title(f"{name}: {d.upper()} pixel classes", fontsize=9)
        _noticks(ax)
    return _save(fig, path)


# ----------------------------------------------------------------------------- overview
def plot_overview(ds, path, name: str | None = None, description: str = "") -> Path:
    """One page: X and Y fringe image (finest width), modulation ratio (finest width),
    coordinate deviation (monitor px, masks drawn), histogram and a statistics box."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    st = _stats(ds)
    fine = float(min(ds["width"].values))
    h, w = ds["surface_mask"].shape
    # laid out by hand (inches): 4 image columns and a histogram column, two rows (X, Y),
    # the colour bars under the bottom row
    pw, ph = 3.5, 3.5 * h / w
    left, gap, gap_hist, hist_w, right = 0.62, 0.72, 0.9, 4.0, 0.2
    top, between, bottom = 1.0, 0.85, 1.2
    fig = _fixed_figure((left + 4 * pw + 3 * gap + gap_hist + hist_w + right,
                         top + 2 * ph + between + bottom))
    x_hist = left + 4 * pw + 3 * gap + gap_hist
    row_y = (bottom + ph + between, bottom)

    def panel(row, col):
        return _axes_at(fig, left + col * (pw + gap), row_y[row], pw, ph)

    maps = [ds["coord_deviation_px"].sel(direction=d).values for d in dirs]
    exact = [coord_vs_exact(ds, d) for d in dirs]
    lim = symmetric_limit(maps + exact)
    fr = [ds["fringes"].sel(direction=d, width=fine).isel(shift=0).values for d in dirs]
    vmax = max((float(np.nanmax(a)) for a in fr if np.isfinite(a).any()), default=1.0)
    last = {}
    for i, d in enumerate(dirs[:2]):
        ax = panel(i, 0)
        im = imshow(ax, fr[i], cmap="gray", vmin=0, vmax=vmax, interpolation="nearest")
        last["f"] = (ax, im)
        ax.set_title(f"{name}: {d.upper()} fringes, width {fine:g} monitor px, shift 0",
                     fontsize=9)
        _image_axes(ax)
        ax = panel(i, 1)
        r = ds["modulation_ratio"].sel(direction=d, width=fine).values
        im = imshow(ax, r, cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
        last["m"] = (ax, im)
        ax.set_facecolor(CLASS_COLOURS["no valid reference"])
        ax.set_title(f"{name}: {d.upper()} modulation ratio (width {fine:g} px)\nmedian "
                     f"{_g(np.nanmedian(r) if np.isfinite(r).any() else np.nan)}", fontsize=9)
        _image_axes(ax)
        for col, (m, against, key) in enumerate(((maps[i], VS_MIRROR, "coord_px"),
                                                 (exact[i], VS_EXACT, "coord_vs_exact_px"))):
            ax = panel(i, 2 + col)
            im = imshow(ax, m, cmap=DEV_CMAP, vmin=-lim, vmax=lim, interpolation="nearest")
            last["c" + str(col)] = (ax, im)
            _overlay(ax, ds, d, legend=(col == 0))
            s = st["directions"][d].get(key) or {}
            ax.set_title(f"{name}: {d.upper()} coordinate deviation\n{against}: "
                         f"RMS {_g(s.get('rms'))} px, P95 {_g(s.get('p95'))} px", fontsize=9)
            _image_axes(ax)
    for col, (key, label, extend) in enumerate((
            ("f", "camera value", "neither"),
            ("m", "modulation / reference modulation (1)", "max"),
            ("c0", f"coordinate deviation {VS_MIRROR} (monitor px), +-{lim:g}", "both"),
            ("c1", f"coordinate deviation {VS_EXACT} (monitor px), +-{lim:g}", "both"))):
        cax = _axes_at(fig, left + col * (pw + gap) + 0.075 * pw, bottom - 0.62, 0.85 * pw,
                       0.12)
        cb = fig.colorbar(last[key][1], cax=cax, orientation="horizontal", extend=extend)
        cb.set_label(label, fontsize=8)
        # a narrow bar: five ticks (+-lim, +-lim/2, 0 on the symmetric deviation scales)
        cb.ax.xaxis.set_major_locator(FixedLocator([-lim, -lim / 2, 0, lim / 2, lim])
                                      if extend == "both" else MaxNLocator(6))
        cb.ax.tick_params(labelsize=7)
    ax = _axes_at(fig, x_hist, row_y[0], hist_w, ph)
    hist, colours, hstats, styles = {}, {}, {}, {}
    for i, d in enumerate(dirs):
        for m, tag, key, ls in ((maps[i], "vs mirror", "coord_px", "-"),
                                (exact[i], "vs exact", "coord_vs_exact_px", "--")):
            k = f"{d.upper()} {tag}"
            hist[k], colours[k], styles[k] = m, DIR_COLOURS.get(d), ls
            hstats[k] = st["directions"][d].get(key) or {}
    _histogram(ax, hist, colours, hstats, lim=lim, styles=styles)
    ax.set_xlabel("coordinate deviation (monitor px)\nsolid: vs decoded mirror, dashed: vs "
                  "exact specular point", fontsize=7)
    ax.set_ylabel("pixels", fontsize=8)
    ax.set_title("histogram of the valid pixels", fontsize=9)
    ax = _axes_at(fig, x_hist, row_y[1], hist_w, ph)
    ax.axis("off")
    ax.text(0.0, 1.0, _stats_box(st), family="monospace", fontsize=7.2, va="top", ha="left",
            transform=ax.transAxes)
    title = (f"{name}: phase measurement deviation from the ideal specular reference "
             "(decoded mirror) and from the exact specular points")
    if description:
        title += f"\n{description}"
    fig.suptitle(title, fontsize=11, y=1 - 0.08 / fig.get_size_inches()[1], va="top")
    return _save(fig, path, dpi=OVERVIEW_DPI)


def _stats_box(st: dict) -> str:
    lines = [f"{st['method']} unwrapping, widths {', '.join(f'{w:g}' for w in st['widths_px'])}"
             f" px, K = {st['shifts']}",
             f"{'':3}{'':>13}{'mean':>9}{'RMS':>9}{'P95':>9}"]
    for d, s in st["directions"].items():
        for q, lab in (("phase_mrad", "phase mrad"), ("coord_px", "coord px"),
                       ("coord_mm", "coord mm"), ("slope_urad", "slope urad")):
            r = s[q]
            lines.append(f"{d.upper():3}{lab:>13}" + "".join(f"{_g(r[k]):>9}"
                                                            for k in ("mean", "rms", "p95")))
        ex = s.get("coord_vs_exact_px") or {}
        lines.append(f"{d.upper():3}{'px vs exact':>13}" + "".join(f"{_g(ex.get(k)):>9}"
                                                               for k in ("mean", "rms", "p95")))
        p = s["pixels"]
        lines.append(f"   valid {p['valid']:,} / {p['considered']:,} "
                     f"({100 * (s['coord_px']['valid_fraction'] or 0):.1f} %)")
        lines.append(f"   masked: low mod. {p['low_modulation']:,}, "
                     f"flagged {p['decode_flagged']:,}, off monitor "
                     f"{p.get('lobe_off_monitor', 0):,}")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- variants
def plot_variant_deviation(datasets: dict, path, descriptions: dict | None = None) -> Path:
    """Coordinate deviation (monitor px) of every variant (rows) and direction (columns) on
    one common symmetric scale, plus histograms of all variants per direction."""
    descriptions = descriptions or {}
    names = list(datasets)
    first = datasets[names[0]]
    dirs = _dirs(first)
    maps = {(n, d): datasets[n]["coord_deviation_px"].sel(direction=d).values
            for n in names for d in dirs}
    lim = symmetric_limit(maps.values())
    h, w = first["surface_mask"].shape
    ph = 4.6 * h / w
    fig = _figure((4.6 * len(dirs) + 1.6, (ph + 0.7) * len(names) + 3.2))
    gs = fig.add_gridspec(len(names) + 1, len(dirs),
                          height_ratios=[ph + 0.7] * len(names) + [2.6])
    im = None
    map_axes = []
    for i, n in enumerate(names):
        st = _stats(datasets[n])["directions"]
        for j, d in enumerate(dirs):
            ax = fig.add_subplot(gs[i, j])
            map_axes.append(ax)
            im = imshow(ax, maps[n, d], cmap=DEV_CMAP, vmin=-lim, vmax=lim,
                           interpolation="nearest")
            _overlay(ax, datasets[n], d, legend=True)
            s = st[d]["coord_px"]
            ax.set_title(f"{n}: {d.upper()} coordinate deviation {VS_MIRROR}\nRMS {_g(s['rms'])} px, "
                         f"P95 {_g(s['p95'])} px, valid {100 * (s['valid_fraction'] or 0):.1f} %",
                         fontsize=8)
            _noticks(ax)
        if descriptions.get(n):
            fig.axes[-len(dirs)].set_ylabel(_wrap(descriptions[n], 38), fontsize=7)
    cb = fig.colorbar(im, ax=map_axes, shrink=0.8, extend="both")
    cb.set_label(f"monitor coordinate deviation (monitor px), common scale +-{lim:g}",
                 fontsize=8)
    colours = ["#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf", "#7f7f7f"]
    for j, d in enumerate(dirs):
        ax = fig.add_subplot(gs[-1, j])
        _histogram(ax, {n: maps[n, d] for n in names},
                   {n: colours[k % len(colours)] for k, n in enumerate(names)},
                   {n: _stats(datasets[n])["directions"][d]["coord_px"] for n in names},
                   lim=lim, log=True)
        ax.set_xlabel(f"{d.upper()} coordinate deviation {VS_MIRROR} (monitor px)", fontsize=8)
        ax.set_ylabel("pixels", fontsize=8)
    return _save(fig, path)


def _wrap(text: str, width: int) -> str:
    import textwrap

    return textwrap.fill(text, width)


# ----------------------------------------------------------------------------- dots
def _grid_layout(table: list[dict]):
    """(n_rows, n_cols, {dot: (row, col)}) arranging the dots like on the monitor (a regular
    grid of their distinct u and v; a near-square grid in dot order when they are scattered)."""
    us = sorted({r["dot_u_px"] for r in table})
    vs = sorted({r["dot_v_px"] for r in table})
    if len(us) * len(vs) == len(table) or len(us) * len(vs) <= 4 * len(table):
        return len(vs), len(us), {r["dot"]: (vs.index(r["dot_v_px"]), us.index(r["dot_u_px"]))
                                  for r in table}
    n = len(table)
    nc = math.ceil(math.sqrt(n))
    return math.ceil(n / nc), nc, {r["dot"]: divmod(k, nc) for k, r in enumerate(table)}


def dot_crop_size(tables: dict, factor: float = 3.0, lo: int = 15, hi: int = 241) -> int:
    """Odd crop size (camera px) that holds +-``factor`` sigma_major of every dot."""
    sig = [r["sigma_major_px"] for t in tables.values() for r in t
           if np.isfinite(r["sigma_major_px"])]
    s = 2 * math.ceil(factor * max(sig, default=5.0)) + 1
    return int(min(max(s, lo), hi)) | 1


def _crop(img: np.ndarray, cc: float, rc: float, size: int) -> np.ndarray:
    h, w = img.shape
    half = size // 2
    out = np.full((size, size), np.nan)
    if not (np.isfinite(cc) and np.isfinite(rc)):
        return out
    c0, r0 = int(round(cc)) - half, int(round(rc)) - half
    rs, cs = slice(max(r0, 0), min(r0 + size, h)), slice(max(c0, 0), min(c0 + size, w))
    out[rs.start - r0:rs.stop - r0, cs.start - c0:cs.stop - c0] = img[rs, cs]
    return out


def plot_dot_contact_sheet(images: dict, tables: dict, path,
                           descriptions: dict | None = None) -> Path:
    """For each variant a grid of crops (same size for all) around each dot's centroid,
    arranged like the dot grid on the monitor; variants side by side.

    Parameters
    ----------
    images : {variant: (n_dots, H, W) ndarray}
        Camera images of the dots.
    tables : {variant: list of dict}
        :func:`pmdsim.measure.chain.dot_table` of each variant.
    """
    descriptions = descriptions or {}
    names = list(images)
    size = dot_crop_size(tables)
    # Rows and columns of dots that no variant sees (off the camera's view of the monitor)
    # are left out of the sheet, and counted in the title.
    seen = {r["dot"] for t in tables.values() for r in t if np.isfinite(r["elongation"])}
    layout_rows = [r for r in tables[names[0]] if r["dot"] in seen] or tables[names[0]]
    nr, nc, where = _grid_layout(layout_rows)
    unseen = len(tables[names[0]]) - len(seen)
    cell = 0.75 if nc * len(names) <= 12 else 0.55
    fig = _figure((len(names) * (nc * cell + 0.9) + 0.3, nr * cell + 1.7))
    subs = fig.subfigures(1, len(names), squeeze=False)[0] if len(names) > 1 else [fig]
    for sub, n in zip(subs, names):
        table = tables[n]
        stack = images[n]  # (n_dots, H, W); may be lazy (xarray): one image read per dot
        peak = max((r["peak"] for r in table if np.isfinite(r["peak"])), default=1.0)
        axes = sub.subplots(nr, nc, squeeze=False, gridspec_kw={"wspace": 0.04, "hspace": 0.04})
        for ax in axes.ravel():
            ax.set_axis_off()
        im = None
        for r in table:
            if r["dot"] not in where:
                continue
            i, j = where[r["dot"]]
            ax = axes[i, j]
            ax.set_axis_on()
            crop = _crop(np.asarray(stack[r["dot"]], np.float64), r["centroid_col"],
                         r["centroid_row"], size)
            im = imshow(ax, crop, cmap="gray", vmin=0, vmax=peak, interpolation="nearest")
            _noticks(ax)
            if not np.isfinite(r["elongation"]):
                ax.set_facecolor("0.85")
                ax.text(0.5, 0.5, "not\nseen", ha="center", va="center", fontsize=6,
                        color="0.3", transform=ax.transAxes)
            else:
                ax.text(0.03, 0.97, f"{r['elongation']:.2f}", ha="left", va="top", fontsize=5,
                        color="#ffd92f", transform=ax.transAxes)
            for s in ax.spines.values():
                s.set_color("0.6")
            if i == nr - 1:
                ax.set_xlabel(f"u {r['dot_u_px']:g}", fontsize=6)
            if j == 0:
                ax.set_ylabel(f"v {r['dot_v_px']:g}", fontsize=6)
        title = n
        if descriptions.get(n):
            title += ": " + descriptions[n]
        title = _wrap(title, int(12 * nc))
        sub.suptitle(title, fontsize=8)
        if im is not None:
            sub.colorbar(im, ax=axes.ravel().tolist(), shrink=0.7, pad=0.02).set_label(
                f"camera value (0 .. brightest dot {peak:.3g})", fontsize=7)
    size_px = tables[names[0]][0].get("dot_size_px") if tables[names[0]] else None
    dot = f"{size_px:g} x {size_px:g} monitor px " if size_px else ""
    fig.suptitle(_wrap(f"dot scan: camera images of the reflected {dot}dot, arranged as the "
                       f"dots on the monitor (u right, v down); crops of {size} x {size} camera "
                       "px around each centroid, in camera orientation; yellow: elongation"
                       + (f"; {unseen} dots that the camera does not see are left out"
                          if unseen else ""),
                       int(fig.get_figwidth() * 13)), fontsize=9)
    return _save(fig, path)


def plot_dot_shapes(images: dict, tables: dict, path, centre_px=None,
                    descriptions: dict | None = None) -> Path:
    """Dot size and shape over the camera frame: 2-sigma ellipses (true scale) at each
    centroid, coloured by elongation, over a faint composite of all dot images; a last panel
    shows the major-axis direction relative to the radial direction from the turning centre
    (``centre_px`` = its image (col, row)), which is constant for a rotationally symmetric
    change in shape.
    """
    import matplotlib as mpl

    descriptions = descriptions or {}
    names = list(images)
    first = next(iter(images.values()))
    h, w = first.shape[1:]
    el = [r["elongation"] for t in tables.values() for r in t if np.isfinite(r["elongation"])]
    norm = mpl.colors.Normalize(1.0, max(2.0, _nice(max(el, default=2.0))))
    cmap = mpl.colormaps["plasma"]
    n_panels = len(names) + (centre_px is not None)
    fig = _figure((5.0 * n_panels + 1.0, 5.0 * h / w + 1.6))
    axes = fig.subplots(1, n_panels, squeeze=False)[0]
    for ax, n in zip(axes, names):
        comp = np.zeros((h, w))
        for q in range(images[n].shape[0]):  # one dot at a time (the stack may be lazy)
            img = np.nan_to_num(np.asarray(images[n][q], np.float64), nan=0.0)
            peak = img.max()
            if peak > 0:
                np.maximum(comp, img / peak, out=comp)
        imshow(ax, comp, cmap="gray_r", vmin=0, vmax=1.5, interpolation="nearest")
        for r in tables[n]:
            if not np.isfinite(r["sigma_major_px"]):
                continue
            e = Ellipse((r["centroid_col"], r["centroid_row"]), 4 * r["sigma_major_px"],
                        4 * r["sigma_minor_px"], angle=r["angle_deg"], fill=False,
                        edgecolor=cmap(norm(r["elongation"])), linewidth=1.4)
            ax.add_patch(e)
            ax.plot(r["centroid_col"], r["centroid_row"], "+", color="k", markersize=3)
        if centre_px is not None:
            ax.plot(*centre_px, marker="x", color="#2ca02c", markersize=9, mew=2)
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_aspect("equal")
        _image_axes(ax)
        sm = [r["sigma_major_px"] for r in tables[n] if np.isfinite(r["sigma_major_px"])]
        em = [r["elongation"] for r in tables[n] if np.isfinite(r["elongation"])]
        ax.set_title(f"{n}: 2-sigma ellipses (true scale)\nsigma_major {min(sm):.2g}-"
                     f"{max(sm):.3g} px, elongation {min(em):.2g}-{max(em):.3g}"
                     if sm else f"{n}: no dots seen", fontsize=8)
    sm = mpl.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=list(axes[:len(names)]), shrink=0.8, pad=0.01).set_label(
        "elongation sigma_major / sigma_minor", fontsize=8)
    if centre_px is not None:
        ax = axes[-1]
        markers = ["o", "s", "^", "D"]
        for k, n in enumerate(names):
            az, rel, size, round_ = [], [], [], []
            for r in tables[n]:
                if not np.isfinite(r["sigma_major_px"]):
                    continue
                if r["elongation"] < 1.1:  # orientation undefined for a round dot
                    dx, dy = r["centroid_col"] - centre_px[0], r["centroid_row"] - centre_px[1]
                    round_.append(math.degrees(math.atan2(dy, dx)))
                    continue
                dx, dy = r["centroid_col"] - centre_px[0], r["centroid_row"] - centre_px[1]
                radial = math.degrees(math.atan2(dy, dx))
                diff = (r["angle_deg"] - radial + 90) % 180 - 90
                az.append(radial)
                rel.append(diff)
                size.append(r["elongation"])
            ax.scatter(az, rel, c=size, cmap=cmap, norm=norm, marker=markers[k % 4],
                       edgecolor="k", linewidth=0.4, s=30, label=n)
            if round_:  # drawn on the zero line, hollow: no orientation to speak of
                ax.scatter(round_, np.zeros(len(round_)), marker=markers[k % 4],
                           facecolor="none", edgecolor="0.5", linewidth=0.6, s=30)
        ax.axhline(0, color="0.5", linewidth=0.6)
        ax.set_ylim(-90, 90)
        ax.set_yticks([-90, -45, 0, 45, 90])
        ax.set_xlabel("azimuth of the dot about the turning centre in the image (deg)",
                      fontsize=8)
        ax.set_ylabel("major axis - radial direction (deg)", fontsize=8)
        ax.set_title("orientation of the dot's major axis\n0 = radial, +-90 = tangential "
                     "(colour: elongation; hollow: round, elongation < 1.1)", fontsize=8)
        ax.legend(handles=[Line2D([], [], marker=markers[k % 4], linestyle="", color="0.5",
                                  label=n) for k, n in enumerate(names)], fontsize=7)
        ax.tick_params(labelsize=7)
    fig.suptitle("dot scan: size and elongation per position (second moments above "
                 "5 % of each dot's maximum); x: turning centre", fontsize=9)
    return _save(fig, path)


# ----------------------------------------------------------------------------- decode CLI
def plot_decoded(ds, folder) -> list[Path]:
    """PNG maps of a decoded image set: absolute phase, monitor coordinate, modulation
    (per width) and flags."""
    folder = Path(folder)
    d = str(ds.attrs.get("direction", "x")).upper()
    flags = ds["flags"].values
    valid = flags == 0
    paths = []
    h, w = flags.shape
    size = (6.4, 6.4 * h / w + 0.9)

    def one(arr, fname, title, label, cmap="viridis", **kw):
        fig = _figure(size)
        ax = fig.subplots()
        im = imshow(ax, arr, cmap=cmap, interpolation="nearest", **kw)
        ax.set_facecolor(CLASS_COLOURS["no valid reference"])
        ax.set_title(title, fontsize=9)
        _image_axes(ax)
        fig.colorbar(im, ax=ax, shrink=0.85).set_label(label, fontsize=8)
        paths.append(_save(fig, folder / fname))

    n_valid = int(valid.sum())
    one(np.where(valid, ds["absolute_phase"].values, np.nan), "absolute_phase.png",
        f"{d} absolute phase, width {ds.attrs['finest_width_px']:g} monitor px "
        f"(flagged pixels grey; {n_valid:,} valid)", "absolute phase (rad)")
    coord = np.where(valid, ds["monitor_coord_px"].values, np.nan)
    one(coord, "monitor_coord.png", f"{d} decoded monitor coordinate ({n_valid:,} valid px)",
        "monitor coordinate (monitor px)" + (
            f"; x {ds.attrs['pitch_mm']:g} mm/px" if ds.attrs.get("pitch_mm") else ""))
    widths = [float(x) for x in ds["width"].values]
    fig = _figure((4.2 * len(widths) + 1.0, 4.2 * h / w + 0.9))
    axes = fig.subplots(1, len(widths), squeeze=False)[0]
    im = None
    for ax, wd in zip(axes, widths):
        m = ds["modulation"].sel(width=wd).values
        im = imshow(ax, m, cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(f"{d} modulation B/A, width {wd:g} px\nmedian "
                     f"{_g(np.nanmedian(m) if np.isfinite(m).any() else np.nan)}", fontsize=8)
        _noticks(ax)
    fig.colorbar(im, ax=list(axes), shrink=0.85, extend="max").set_label("modulation B/A (1)",
                                                                       fontsize=8)
    paths.append(_save(fig, folder / "modulation.png"))
    cols = ["#9ecae1", "#111111", "#1f77b4", "#fd8d3c", "#8c6d31"]
    labels = ["valid", "NAN_INPUT", "LOW_AMPLITUDE", "ORDER_RESIDUAL", "OUT_OF_RANGE"]
    cls = np.zeros(flags.shape, int)
    cls[flags & 8 > 0] = 4
    cls[flags & 4 > 0] = 3
    cls[flags & 2 > 0] = 2
    cls[flags & 1 > 0] = 1
    fig = _figure((size[0], size[1] + 0.8))
    gs = fig.add_gridspec(2, 1, height_ratios=[size[1] - 0.9, 0.8])
    ax = fig.add_subplot(gs[0])
    lax = fig.add_subplot(gs[1])
    lax.set_axis_off()
    imshow(ax, cls, cmap=ListedColormap(cols), vmin=-0.5, vmax=4.5, interpolation="nearest")
    counts = [n_valid] + [int(np.count_nonzero(flags & (1 << (k - 1)))) for k in range(1, 5)]
    lax.legend(handles=[Patch(facecolor=c, edgecolor="0.5", label=f"{lab}: {n:,}")
                        for c, lab, n in zip(cols, labels, counts)],
               loc="upper center", ncol=3, fontsize=7, frameon=False)
    ax.set_title(f"{d} decode flags (a pixel with several flags shows the first)", fontsize=9)
    _noticks(ax)
    paths.append(_save(fig, folder / "flags.png"))
    return paths


def chain_figures(ds, folder, name: str | None = None, description: str = "") -> list[Path]:
    """All measurement-chain figures of one run or variant into ``folder``."""
    folder = Path(folder)
    return [
        plot_overview(ds, folder / "overview.png", name, description),
        plot_phase(ds, folder / "phase.png", name),
        plot_deviation(ds, folder / "deviation.png", name),
        plot_histograms(ds, folder / "histograms.png", name),
        plot_modulation_ratio(ds, folder / "modulation_ratio.png", name),
        plot_masks(ds, folder / "masks.png", name),
    ]


__all__ = ["plot_phase", "plot_deviation", "plot_histograms", "plot_modulation_ratio",
           "plot_masks", "plot_overview", "plot_variant_deviation", "plot_dot_contact_sheet",
           "plot_dot_shapes", "plot_decoded", "chain_figures", "dot_figures", "symmetric_limit", "DPI"]


def dot_figures(folder: Path, images: dict, tables: dict, sim, descriptions: dict) -> list[Path]:
    """The dot contact sheet and the dot shapes figure (``sim`` for the turning centre in
    camera px, drawn when the anisotropy frame is rotational)."""
    centre = None
    an = sim.scene.anisotropy
    if an.kind == "rotational":
        centre = tuple(float(x) for x in sim.scene.camera.project(an.centre))
    return [plot_dot_contact_sheet(images, tables, folder / "dot_contact_sheet.png",
                                              descriptions),
            plot_dot_shapes(images, tables, folder / "dot_shapes.png", centre,
                                       descriptions)]
