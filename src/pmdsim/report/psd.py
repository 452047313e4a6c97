"""PSD figures of the surface errors (:mod:`pmdsim.measure.areal`): a run's (``surface_psd.png``)
and the budget's height rows (``budget_psd.png``).

Log-log 1-D radial PSD (the map's unit^2 mm) against spatial frequency (1/mm; spatial period
on the top axis), the form / mid-spatial / high bands shaded with their band-limited RMS,
the PSD's numerical error dotted (above it the spectrum is resolved), the ISO 25178 areal
parameters in the titles as "value ± numerical error"."""

from __future__ import annotations

import json
import math

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.ticker import FuncFormatter, LogLocator, NullLocator

from .scene import _axes_at, _fixed_figure

BAND_COLOURS = {"form": "#dbe9f6", "mid": "#fde7cf", "high": "#e0f0d9"}
BAND_LABELS = {"form": "form", "mid": "mid-spatial", "high": "high"}


def _g(v, fmt=".3g") -> str:
    return "nan" if v is None or not math.isfinite(v) else format(v, fmt)


def pm(st: dict, key: str) -> str:
    """``st[key]`` as "value ± error" (the value alone where none is stated or it is 0)."""
    v, e = st.get(key), st.get(f"{key}_err")
    if e is None or not math.isfinite(e) or e == 0:
        return _g(v)
    return f"{_g(v)} ± {e:.2g}"


def areal_line(st: dict) -> str:
    """"Sq .. Sa .. Sz .. unit; Ssk .., Sku ..; Sdq .. unit/mm" of a map's areal statistics."""
    return (f"Sq {pm(st, 'sq')}  Sa {pm(st, 'sa')}  Sz {pm(st, 'sz')} {st.get('unit', '')}\n"
            f"Ssk {pm(st, 'ssk')}  Sku {pm(st, 'sku')}  Sdq {pm(st, 'sdq')} "
            f"{st.get('sdq_unit', '')}")


def band_text(st: dict) -> str:
    """"form a ± e, mid-spatial b, high c unit RMS" of a map's PSD statistics."""
    psd = st.get("psd") or {}
    rms, err = psd.get("band_rms", {}), psd.get("band_rms_err") or {}
    parts = []
    for b, v in rms.items():
        e = err.get(b)
        parts.append(f"{BAND_LABELS.get(b, b)} {_g(v)}" + (f" ± {e:.2g}" if e else ""))
    return ", ".join(parts) + f" {st.get('unit', '')} RMS"


def shade_bands(ax, bands: dict, f_lo: float, f_hi: float) -> None:
    """The form / mid-spatial / high bands as shaded spans, named at the top."""
    for b, (lo, hi) in bands.items():
        lo, hi = max(lo or f_lo, f_lo), min(hi if hi is not None else f_hi, f_hi)
        if hi <= lo:
            continue
        ax.axvspan(lo, hi, color=BAND_COLOURS.get(b, "0.95"), zorder=0, lw=0)
        ax.text(math.sqrt(lo * hi), 0.97, BAND_LABELS.get(b, b), transform=ax.get_xaxis_transform(),
                ha="center", va="top", fontsize=8, color="0.35")


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def power_label(v, _pos=None) -> str:
    """A log axis's tick label: ``10`` with a superscript exponent at a power of ten (plain
    text: matplotlib's mathtext, its default, took a third of the PSD figure's drawing),
    else ``v`` as ``%g``."""
    if not v > 0:
        return ""
    k = round(math.log10(v))
    if abs(v / 10.0**k - 1) < 1e-9:
        return "10" + str(k).translate(_SUPERSCRIPT)
    return f"{v:g}"


def log_ticks(axis) -> None:
    """A log axis labelled by :func:`power_label`, without minor ticks (each is a matplotlib
    artist of its own; the grid and the labels carry the scale)."""
    axis.set_major_formatter(FuncFormatter(power_label))
    axis.set_minor_locator(NullLocator())


def psd_axes(ax, f, unit: str) -> None:
    ax.set_xscale("log")
    ax.set_yscale("log")
    log_ticks(ax.yaxis)
    ax.set_xlabel("spatial frequency f (1/mm)")
    ax.set_ylabel(f"1-D radial PSD ({unit}\u00b2 mm)")
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlim(f[0] * 0.9, f[-1] * 1.1)
    top = ax.secondary_xaxis("top", functions=(lambda x: 1 / np.maximum(x, 1e-300),
                                               lambda x: 1 / np.maximum(x, 1e-300)))
    top.set_xlabel("spatial period (mm)", fontsize=8)
    for a in (ax.xaxis, top.xaxis):  # 1, 2, 5 x 10^k labelled: a span of under two decades
        a.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        a.set_minor_locator(NullLocator())
    top.tick_params(labelsize=7)


def plot_line(ax, f, psd, err, colour, label, ls="-"):
    """One radial PSD and, dotted, its numerical error (where stated and > 0)."""
    psd = np.asarray(psd, np.float64)
    ok = np.isfinite(psd) & (psd > 0)
    ax.plot(f[ok], psd[ok], ls, color=colour, lw=1.4, label=label)
    if err is not None:
        err = np.asarray(err, np.float64)
        ok = np.isfinite(err) & (err > 0)
        if ok.any():
            ax.plot(f[ok], err[ok], ":", color=colour, lw=1.1,
                    label=f"{label.split(':')[0]}: its numerical error")


def _limits(ax, arrays):
    vals = np.concatenate([np.asarray(a, np.float64).ravel() for a in arrays if a is not None])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    if vals.size:
        top = vals.max()
        ax.set_ylim(max(vals.min(), top * 1e-12) / 3, top * 30)


def _below(ax, text: str) -> None:
    """Text under an axes' legend (the areal parameters)."""
    ax.text(0.0, -0.45, text, transform=ax.transAxes, va="top", ha="left", fontsize=8,
            family="monospace")


def plot_surface_psd(ds, name: str = "", description: str = ""):
    """Figure: the radial PSD of the height error (with the specular reference's, the
    chain's floor), of the slope errors dz/dx and dz/dy, and the 2-D PSD of the height
    error; band RMS in the legends, the areal parameters under them."""
    stats = json.loads(ds.attrs.get("statistics_json", "{}")).get("reconstruction", {})
    ar = stats.get("areal", {})
    f = np.asarray(ds["psd_f"].values, np.float64)
    fig = _fixed_figure((18.2, 8.0))
    w, h, bottom = 4.9, 4.0, 2.9
    ax_h = _axes_at(fig, 0.85, bottom, w, h)
    ax_s = _axes_at(fig, 0.85 + w + 0.95, bottom, w, h)
    ax_2 = _axes_at(fig, 0.85 + 2 * (w + 0.95), bottom, h, h)
    cax = _axes_at(fig, 0.85 + 2 * (w + 0.95) + h + 0.1, bottom, 0.15, h)

    def get(v):
        return np.asarray(ds[v].values, np.float64) if v in ds else None

    hst = ar.get("height_error_nm", {})
    bands = {k: (lo, math.inf if hi is None else hi)
             for k, (lo, hi) in (hst.get("psd") or {}).get("bands_per_mm", {}).items()}
    # the height error
    shade_bands(ax_h, bands, f[0] * 0.9, f[-1] * 1.1)
    plot_line(ax_h, f, get("height_error_psd"), get("height_error_psd_err"), "tab:red",
              "height error: " + band_text(hst))
    text = "height error  " + areal_line(hst).replace("\n", "\n              ")
    if "reference_height_error_psd" in ds:
        rst = ar.get("reference_height_error_nm", {})
        plot_line(ax_h, f, get("reference_height_error_psd"), None, "0.35",
                  "specular reference (the chain's floor): " + band_text(rst), ls="--")
        text += "\nreference     " + areal_line(rst).replace("\n", "\n              ")
    psd_axes(ax_h, f, "nm")
    _limits(ax_h, [get("height_error_psd"), get("height_error_psd_err"),
                   get("reference_height_error_psd")])
    ax_h.set_title(f"height error ({stats.get('removed', '')} removed)", fontsize=10, pad=28)
    ax_h.legend(loc="upper left", bbox_to_anchor=(0.0, -0.13), fontsize=7.5, frameon=False)
    _below(ax_h, text)
    # the slope errors
    shade_bands(ax_s, bands, f[0] * 0.9, f[-1] * 1.1)
    lines = []
    for var, key, colour, lab in (("slope_error_x", "slope_error_x_urad", "tab:blue", "dz/dx"),
                                  ("slope_error_y", "slope_error_y_urad", "tab:green", "dz/dy")):
        st = ar.get(key, {})
        plot_line(ax_s, f, get(f"{var}_psd"), get(f"{var}_psd_err"), colour,
                  f"slope error {lab}: " + band_text(st))
        lines.append(f"{lab}  " + areal_line(st).replace("\n", "\n       "))
    psd_axes(ax_s, f, "urad")
    _limits(ax_s, [get(f"slope_error_{k}_psd{e}") for k in "xy" for e in ("", "_err")])
    ax_s.set_title("slope errors (surface frame)", fontsize=10, pad=28)
    ax_s.legend(loc="upper left", bbox_to_anchor=(0.0, -0.13), fontsize=7.5, frameon=False)
    _below(ax_s, "\n".join(lines))
    # the 2-D PSD of the height error
    p2 = get("height_error_psd_2d")
    fx, fy = np.asarray(ds["psd_fx"].values), np.asarray(ds["psd_fy"].values)
    pos = p2[np.isfinite(p2) & (p2 > 0)]
    vmax = pos.max() if pos.size else 1.0
    vmin = max(float(np.percentile(pos, 2)), vmax * 1e-9) if pos.size else vmax * 1e-9
    import matplotlib

    cmap = matplotlib.colormaps["magma"]
    cmap = cmap.with_extremes(bad=cmap(0.0), under=cmap(0.0))
    im = ax_2.imshow(np.where(p2 > 0, p2, np.nan), origin="lower", cmap=cmap,
                     norm=LogNorm(vmin=vmin, vmax=vmax, clip=True),
                     interpolation="nearest",
                     extent=(fx[0] - (fx[1] - fx[0]) / 2, fx[-1] + (fx[1] - fx[0]) / 2,
                             fy[0] - (fy[1] - fy[0]) / 2, fy[-1] + (fy[1] - fy[0]) / 2),
                     aspect="auto")
    ax_2.set_xlabel("f along surface x (1/mm)")
    ax_2.set_ylabel("f along surface y (1/mm)")
    # framed to 3 x the radius holding 99.9 % of the power (the rest is orders below)
    rad = get("height_error_psd")
    frame = f[-1]
    if rad is not None and np.nansum(rad) > 0:
        cum = np.nancumsum(rad) / np.nansum(rad)
        frame = min(3 * f[min(int(np.searchsorted(cum, 0.999)), f.size - 1)], f[-1])
        frame = max(frame, min(10 * f[0], f[-1]))
    ax_2.set_xlim(-frame, frame)
    ax_2.set_ylim(-frame, frame)
    ax_2.set_title("height error: 2-D PSD, |f| < 3 x the radius of 99.9 % of its power\n"
                   "(ridges: directional structure; streaks normal to the measured\n"
                   "region's edges: window leakage)", fontsize=8.5)
    fig.colorbar(im, cax=cax).set_label("2-D PSD (nm\u00b2 mm\u00b2)", fontsize=8)
    log_ticks(cax.yaxis)
    fig.suptitle(f"{name}: power spectral density of the reconstructed minus true surface; "
                 "bands shaded, band-limited RMS in the legends; dotted: numerical error "
                 "(the spectrum is resolved above it)"
                 + (f"\n{description}" if description else ""), fontsize=10,
                 y=1 - 0.06 / fig.get_size_inches()[1], va="top")
    return fig


def plot_budget_psd(height_rows: list[dict], path, title: str = "error budget"):
    """The radial PSD of every height row's height error (nm^2 mm) and slope errors (urad^2
    mm), one line per row, the bands shaded; band RMS in the legend."""
    import matplotlib

    from .scene import _save

    rows = [r for r in height_rows if (r.get("areal") or {}).get("height_error_nm", {}).get("psd")]
    entries = len(rows) + sum(r["part"] == "surface" for r in rows)  # the legend's lines
    legend_h = 0.17 * entries + 0.3
    w, h, bottom = 6.4, 4.3, 0.9 + legend_h
    fig = _fixed_figure((2 * w + 2.6, bottom + h + 1.1))
    axes = [_axes_at(fig, 0.9, bottom, w, h), _axes_at(fig, 0.9 + w + 1.0, bottom, w, h)]
    if not rows:
        for ax in axes:
            ax.set_axis_off()
        axes[0].text(0.5, 0.5, "no height rows with a PSD", ha="center")
        return _save(fig, path)
    colours = {"system": "Blues", "surface": "Oranges", "calibration": "Greens"}
    counts: dict = {}
    f_all = []
    for r in rows:
        counts[r["part"]] = counts.get(r["part"], 0) + 1
    seen: dict = {}
    for r in rows:
        ar = r["areal"]
        part = r["part"]
        seen[part] = seen.get(part, 0) + 1
        cmap = matplotlib.colormaps[colours.get(part, "Greys")]
        colour = cmap(0.45 + 0.5 * seen[part] / max(counts[part], 1))
        for ax, key in ((axes[0], "height_error_nm"), (axes[1], "slope_error_x_urad")):
            st = ar.get(key) or {}
            psd = st.get("psd")
            if not psd:
                continue
            f = np.asarray(psd["frequency_per_mm"], np.float64)
            f_all.append(f)
            rad = np.asarray([np.nan if v is None else v for v in psd["radial"]], np.float64)
            err = psd.get("radial_err")
            err = None if err is None else np.asarray([np.nan if v is None else v for v in err])
            plot_line(ax, f, rad, err if part == "surface" else None, colour,
                      f"{r['label'][:38]} [{part}]: " + band_text(st))
    f = np.unique(np.concatenate(f_all))
    bands = {k: (lo, math.inf if hi is None else hi) for k, (lo, hi) in
             rows[0]["areal"]["height_error_nm"]["psd"]["bands_per_mm"].items()}
    for ax, unit, what in ((axes[0], "nm", "height error after the removal"),
                           (axes[1], "urad", "slope error dz/dx")):
        shade_bands(ax, bands, f[0] * 0.9, f[-1] * 1.1)
        psd_axes(ax, f, unit)
        ax.set_title(what, fontsize=9, pad=26)
        ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.6 / h), fontsize=7, frameon=False)
    fig.suptitle(f"{title}: radial PSD of each height row (blue: system, orange: surface, "
                 "green: calibration); dotted: numerical error of the surface rows",
                 fontsize=10, y=1 - 0.08 / fig.get_size_inches()[1], va="top")
    return _save(fig, path)
