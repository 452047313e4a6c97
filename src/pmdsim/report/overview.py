"""The one-page overview of a run (fringes, modulation ratio, coordinate deviation,
histogram, statistics) and the variants' coordinate deviation on one common scale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import FixedLocator, MaxNLocator

from ..quantiles import nanmedian
from .scene import _axes_at, _figure, _fixed_figure, _save, camera_axes, imshow
from .chain_common import (
    CLASS_COLOURS, DEV_CMAP, DIR_COLOURS, OVERVIEW_DPI, VS_EXACT, VS_MIRROR, _dirs, _g,
    _histogram, _label, _overlay, _pm, _stats, _with_error, _wrap, coord_vs_exact,
    symmetric_limit, valid_only,
)


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
    # on a continuous monitor the decoded mirror is the exact point: one comparison column,
    # and the fourth column shows the slope deviation in urad instead
    same = references_coincide(maps, exact, lim)
    slope = [ds["slope_deviation_urad"].sel(direction=d).values for d in dirs]
    slim = symmetric_limit(slope)
    fr = [ds["fringes"].sel(direction=d, width=fine).isel(shift=0).values for d in dirs]
    vmax = max((float(np.nanmax(a)) for a in fr if np.isfinite(a).any()), default=1.0)
    last = {}
    for i, d in enumerate(dirs[:2]):
        ax = panel(i, 0)
        im = imshow(ax, fr[i], cmap="gray", vmin=0, vmax=vmax, interpolation="nearest")
        last["f"] = (ax, im)
        ax.set_title(f"{name}: {d.upper()} fringes, width {fine:g} monitor px, shift 0",
                     fontsize=9)
        camera_axes(ax)
        ax = panel(i, 1)
        r = ds["modulation_ratio"].sel(direction=d, width=fine).values
        im = imshow(ax, r, cmap="viridis", vmin=0, vmax=1, interpolation="nearest")
        last["m"] = (ax, im)
        ax.set_facecolor(CLASS_COLOURS["no valid reference"])
        ax.set_title(f"{name}: {d.upper()} modulation ratio (width {fine:g} px)\nmedian "
                     f"{_g(nanmedian(r) if np.isfinite(r).any() else np.nan)}", fontsize=9)
        camera_axes(ax)
        cols = ((maps[i], "vs mirror (= exact point)" if same else VS_MIRROR, "coord_px", lim),
                (slope[i], "3-D", "slope_urad", slim) if same else
                (exact[i], VS_EXACT, "coord_vs_exact_px", lim))
        for col, (m, against, key, lm) in enumerate(cols):
            ax = panel(i, 2 + col)
            im = imshow(ax, m, cmap=DEV_CMAP, vmin=-lm, vmax=lm, interpolation="nearest")
            last["c" + str(col)] = (ax, im)
            _overlay(ax, ds, d, legend=(col == 0))
            s = _with_error(st["directions"][d], key)
            unit = "urad" if key == "slope_urad" else "px"
            extra = ""
            if key == "coord_px":
                su = _with_error(st["directions"][d], "slope_urad")
                extra = f" ({_pm(su, 'rms')} urad)"
            ax.set_title(f"{name}: {d.upper()} {'slope' if unit == 'urad' else 'coordinate'} deviation"
                         f" {against}\nRMS {_pm(s, 'rms')} {unit}{extra}\nP95 {_pm(s, 'p95')} {unit}",
                         fontsize=8)
            camera_axes(ax)
    for col, (key, label, extend) in enumerate((
            ("f", "camera value", "neither"),
            ("m", "modulation / reference modulation (1)", "max"),
            ("c0", f"coordinate deviation {VS_MIRROR} (monitor px), +-{lim:g}", "both"),
            ("c1", f"slope deviation (urad, 3-D conversion), +-{slim:g}" if same else
             f"coordinate deviation {VS_EXACT} (monitor px), +-{lim:g}", "both"))):
        cax = _axes_at(fig, left + col * (pw + gap) + 0.075 * pw, bottom - 0.62, 0.85 * pw,
                       0.12)
        cb = fig.colorbar(last[key][1], cax=cax, orientation="horizontal", extend=extend)
        cb.set_label(label, fontsize=8)
        lm = slim if (key == "c1" and same) else lim
        # a narrow bar: five ticks (+-lim, +-lim/2, 0 on the symmetric deviation scales)
        cb.ax.xaxis.set_major_locator(FixedLocator([-lm, -lm / 2, 0, lm / 2, lm])
                                      if extend == "both" else MaxNLocator(6))
        cb.ax.tick_params(labelsize=7)
    ax = _axes_at(fig, x_hist, row_y[0], hist_w, ph)
    hist, colours, hstats, styles = {}, {}, {}, {}
    for i, d in enumerate(dirs):
        pairs = ((maps[i], "vs mirror", "coord_px", "-"),) if same else (
            (maps[i], "vs mirror", "coord_px", "-"), (exact[i], "vs exact", "coord_vs_exact_px", "--"))
        for m, tag, key, ls in pairs:
            k = f"{d.upper()} {tag}"
            hist[k], colours[k], styles[k] = m, DIR_COLOURS.get(d), ls
            hstats[k] = _with_error(st["directions"][d], key)
    _histogram(ax, hist, colours, hstats, lim=lim, styles=styles)
    ax.set_xlabel("coordinate deviation (monitor px)\n" + (
        "vs decoded mirror (= exact specular point)" if same else
        "solid: vs decoded mirror, dashed: vs exact specular point"), fontsize=7)
    ax.set_ylabel("pixels", fontsize=8)
    ax.set_title("histogram of the valid pixels", fontsize=9)
    ax = _axes_at(fig, x_hist, row_y[1], hist_w, ph)
    ax.axis("off")
    ax.text(0.0, 1.0, _stats_box(st, ds.attrs.get("estimator")), family="monospace", fontsize=7.2, va="top", ha="left",
            transform=ax.transAxes)
    est = ds.attrs.get("estimator")
    title = (f"{name}: phase measurement deviation from the ideal specular reference "
             + ("(decoded mirror = exact specular points)" if same else
                "(decoded mirror) and from the exact specular points")
             + (f"; {est} estimator" if est else "")
             + ("; value ± the rendering's numerical error"
                if any(v.get("numerical_error") for v in st["directions"].values()) else ""))
    if description:
        title += f"\n{description}"
    fig.suptitle(title, fontsize=11, y=1 - 0.08 / fig.get_size_inches()[1], va="top")
    return _save(fig, path, dpi=OVERVIEW_DPI)


def references_coincide(mirror_maps, exact_maps, lim: float) -> bool:
    """Do the deviations from the decoded mirror and from the exact point agree (to 0.1 %
    of the colour scale at every pixel, as on a continuous monitor)?"""
    for a, b in zip(mirror_maps, exact_maps):
        both = np.isfinite(a) & np.isfinite(b)
        if not both.any() or np.any(np.isfinite(a) != np.isfinite(b)):
            return False
        if np.max(np.abs(a[both] - b[both])) > 1e-3 * max(lim, 1e-12):
            return False
    return True


def _stats_box(st: dict, estimator: str | None = None) -> str:
    # Two header lines and 10-character columns: the box fits its panel (a long first line
    # was cut at the figure's edge, a negative mean ran into its label).
    lines = [f"{st['method']} unwrapping, K = {st['shifts']}"
             + (f", {estimator} estimator" if estimator else ""),
             f"widths {', '.join(f'{w:g}' for w in st['widths_px'])} px",
             f"{'':3}{'':>13}{'mean':>10}{'RMS':>10}{'P95':>10}"]
    for d, s in st["directions"].items():
        for q, lab in (("phase_mrad", "phase mrad"), ("coord_px", "coord px"),
                       ("coord_mm", "coord mm"), ("slope_urad", "slope urad")):
            r = s[q]
            lines.append(f"{d.upper():3}{lab:>13}" + "".join(f"{_g(r[k]):>10}"
                                                            for k in ("mean", "rms", "p95")))
            e = (s.get("numerical_error") or {}).get(q)
            if e:  # the rendering's numerical error of the RMS and P95 above
                lines.append(f"{'':3}{'± numerical':>13}{'':>10}"
                             + "".join(f"{_g(e.get(k), 2):>10}" for k in ("rms", "p95")))
        ex = s.get("coord_vs_exact_px") or {}
        lines.append(f"{d.upper():3}{'px vs exact':>13}" + "".join(f"{_g(ex.get(k)):>10}"
                                                               for k in ("mean", "rms", "p95")))
        p = s["pixels"]
        lines.append(f"   valid {p['valid']:,} / {p['considered']:,} "
                     f"({100 * (s['coord_px']['valid_fraction'] or 0):.1f} %)")
        lines.append(f"   masked: low mod. {p['low_modulation']:,}, "
                     f"flagged {p['decode_flagged']:,}, off monitor "
                     f"{p.get('lobe_off_monitor', 0):,}")
    rec = st.get("reconstruction") or {}
    if "height_error_nm" in rec:
        h = rec["height_error_nm"]
        lines.append(f"height error ({rec.get('removal', rec.get('removed', ''))}):")
        lines.append(f"   RMS {_g(h['rms'])} nm  PV {_g(h['pv'])} nm  P95 {_g(h['p95'])} nm")
    else:
        lines.append("height error (nm): surface_errors.png and summary.txt")
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
    lim = symmetric_limit([valid_only(datasets[n], d, maps[n, d]) for n in names for d in dirs])
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
            s = _with_error(st[d], "coord_px")
            ax.set_title(f"{n}: {d.upper()} coordinate deviation {VS_MIRROR}\nRMS {_pm(s, 'rms')} px, "
                         f"P95 {_pm(s, 'p95')} px, valid {100 * (s['valid_fraction'] or 0):.1f} %",
                         fontsize=8)
            camera_axes(ax)
        if descriptions.get(n):
            fig.axes[-len(dirs)].set_ylabel(_wrap(descriptions[n], 38), fontsize=7)
    cb = fig.colorbar(im, ax=map_axes, shrink=0.8, extend="both")
    cb.set_label(f"monitor coordinate deviation (monitor px), common scale +-{lim:g} "
                 "(P99.5 of |deviation| over the valid pixels)", fontsize=8)
    colours = ["#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf", "#7f7f7f"]
    for j, d in enumerate(dirs):
        ax = fig.add_subplot(gs[-1, j])
        _histogram(ax, {n: maps[n, d] for n in names},
                   {n: colours[k % len(colours)] for k, n in enumerate(names)},
                   {n: _with_error(_stats(datasets[n])["directions"][d], "coord_px")
                    for n in names},
                   lim=lim, log=True)
        ax.set_xlabel(f"{d.upper()} coordinate deviation {VS_MIRROR} (monitor px)", fontsize=8)
        ax.set_ylabel("pixels", fontsize=8)
    return _save(fig, path)
