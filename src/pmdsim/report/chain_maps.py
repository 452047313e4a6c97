"""The measurement chain's maps, one figure each: phases, deviations, their histograms, the
modulation ratio, the masks, and the maps of a decoded image set (``pmdsim decode``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from ..quantiles import nanmedian
from .scene import _figure, _save, camera_axes, imshow
from .chain_common import (
    CLASS_COLOURS, DEVIATIONS, DEV_CMAP, DIR_COLOURS, FLAG_COLOURS, VS_EXACT, VS_MIRROR,
    _classes, _dirs, _g, _histogram, _label, _map_size, _off_monitor, _overlay,
    _pm, _stats, _with_error, coord_vs_exact, symmetric_limit, valid_only,
)


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
            camera_axes(ax)
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
        camera_axes(ax)
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
    coord_lim = symmetric_limit([valid_only(ds, d, m) for d, m in zip(dirs + dirs,
                                                                     coord_mirror + coord_exact)])
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
        lim = (symmetric_limit([valid_only(ds, d, m) for d, m in zip(dirs, maps)])
               if lim is None else lim)
        im = None
        for i, d in enumerate(dirs):
            ax = axes[i, j]
            im = imshow(ax, maps[i], cmap=DEV_CMAP, vmin=-lim, vmax=lim, interpolation="nearest")
            _overlay(ax, ds, d, legend=(j == 0))
            st = _with_error(stats[d], key)
            ax.set_title(f"{name}: {d.upper()} {title}\nmean {_g(st.get('mean'))}, "
                         f"RMS {_pm(st, 'rms')}, P95 {_pm(st, 'p95')} {unit}", fontsize=8)
            camera_axes(ax)
        cb = fig.colorbar(im, ax=list(axes[:, j]), orientation="horizontal", shrink=0.9,
                          extend="both", pad=0.02)
        cb.set_label(label + f"\nscale +-{lim:g} (P99.5 of |deviation|, valid pixels)"
                     + ("; ± in titles: numerical error" if j == 0 and any(
                         stats[d].get("numerical_error") for d in dirs) else ""), fontsize=8)
    return _save(fig, path)


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
                   {d.upper(): _with_error(stats[d], key) for d in dirs})
        ax.set_xlabel(label)
        ax.set_ylabel("pixels")
        ax.set_title(f"{name}: {label.split(' (')[0]}", fontsize=9)
    return _save(fig, path)


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
            med = nanmedian(r) if np.isfinite(r).any() else np.nan
            below = int(np.count_nonzero(r < thr))
            ax.set_title(f"{name}: {d.upper()}, width {wd:g} monitor px\nmedian ratio {med:.3f}; "
                         f"{below:,} px < {thr:g}", fontsize=8)
            camera_axes(ax)
    cb = fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, extend="max")
    cb.set_label("modulation / reference modulation (1)", fontsize=8)
    cb.ax.axhline(thr, color="#e377c2", linewidth=2)
    return _save(fig, path)


def plot_masks(ds, path, name: str | None = None) -> Path:
    """Pixel classes per direction: valid, low modulation (masked), decode flagged (by
    reason), no valid reference, off the surface; counts in the legend."""
    name = _label(ds, name)
    dirs = _dirs(ds)
    cols = [FLAG_COLOURS["valid"], CLASS_COLOURS["low modulation"], FLAG_COLOURS["LOW_AMPLITUDE"],
            FLAG_COLOURS["ORDER_RESIDUAL"], FLAG_COLOURS["OUT_OF_RANGE"],
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
        camera_axes(ax)
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
        camera_axes(ax)
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
                     f"{_g(nanmedian(m) if np.isfinite(m).any() else np.nan)}", fontsize=8)
        camera_axes(ax)
    fig.colorbar(im, ax=list(axes), shrink=0.85, extend="max").set_label("modulation B/A (1)",
                                                                       fontsize=8)
    paths.append(_save(fig, folder / "modulation.png"))
    labels = ["valid", "NAN_INPUT", "LOW_AMPLITUDE", "ORDER_RESIDUAL", "OUT_OF_RANGE"]
    cols = [FLAG_COLOURS[k] for k in labels]
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
    camera_axes(ax)
    paths.append(_save(fig, folder / "flags.png"))
    return paths
