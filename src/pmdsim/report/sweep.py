"""Figures of a parameter study: any deviation statistic against one or two swept
parameters (matplotlib, Agg canvas, PNG).

- :func:`plot_statistic`: a statistic (``rms`` of ``slope_urad``, ``p95`` of
  ``phase_mrad``, ``valid_fraction``...) against one swept parameter, one line per value of
  a second (grid designs), one panel per fringe direction; for zip and random designs a
  scatter against one parameter, coloured by a second;
- :func:`plot_modulation_ratio`: the median modulation ratio to the specular reference
  (finest width) in the same layout;
- :func:`sweep_figures`: the default figures of a sweep folder.

Points that are not done are left out (NaN in the store). Grid parameters beyond the two
plotted are held at their first value (said in the title).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

DPI = 110
UNITS = {"phase_mrad": "mrad", "coord_px": "monitor px", "coord_mm": "mm", "slope_urad": "urad"}
LABELS = {"phase_mrad": "phase deviation", "coord_px": "monitor coordinate deviation",
          "coord_mm": "monitor coordinate deviation", "slope_urad": "slope deviation"}
STAT_LABELS = {"rms": "RMS", "p95": "P95 |dev|", "max": "max |dev|", "mean": "mean",
               "std": "std", "valid_fraction": "valid fraction", "n_valid": "valid pixels",
               "n_masked": "masked pixels"}


def _figure(size) -> Figure:
    # laid out by hand (_draw), not "constrained": the layout engine measured every tick
    # label of every axes before each draw, half of the figures' CPU time
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def _margins(fig: Figure, colorbars: bool) -> None:
    """Fixed margins in inches: y label and ticks on the left, two title lines and the
    panel titles on top, x label below; room for a colour bar beside each panel."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=0.8 / w, right=1 - 0.15 / w, bottom=0.6 / h, top=1 - 0.75 / h,
                        wspace=0.45 if colorbars else 0.06)


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # zlib level 1, as the run's figures (report.scene._save): a fraction of the encoding time
    fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": 1})
    return path


def _parameters(ds) -> list[str]:
    return list(ds.attrs["parameters"])


def _axes_of(ds, x: str | None, hue: str | None) -> tuple[str, str | None]:
    params = _parameters(ds)
    x = x or params[0]
    if x not in params:
        raise ValueError(f"x: {x!r} is not a swept parameter ({params})")
    if hue is None:
        rest = [p for p in params if p != x]
        hue = rest[0] if rest else None
    elif hue not in params or hue == x:
        raise ValueError(f"hue: {hue!r} must be another swept parameter ({params})")
    return x, hue


def _numeric(values) -> bool:
    return np.asarray(values).dtype.kind in "iuf"


def _log_scale(values) -> bool:
    v = np.asarray(values, float) if _numeric(values) else np.zeros(0)
    v = v[np.isfinite(v)]
    return v.size > 1 and v.min() > 0 and v.max() / v.min() > 20


def _fixed(ds, x, hue) -> tuple[dict, str]:
    """Grid dimensions other than x and hue: held at index 0 (and the note saying so)."""
    if ds.attrs["design"] != "grid":
        return {}, ""
    others = [p for p in _parameters(ds) if p not in (x, hue)]
    sel = {p: 0 for p in others}
    note = ", ".join(f"{p} = {ds[p].values[0]}" for p in others)
    return sel, (f" ({note})" if note else "")


def _draw(fig, ds, values, x, hue, ylabel, title, logy=False):
    """``values``: DataArray with the sweep dims (after selection) and ``direction``."""
    directions = [str(d) for d in ds["direction"].values]
    axes = fig.subplots(1, len(directions), sharey=True, squeeze=False)[0]
    grid = ds.attrs["design"] == "grid"
    _margins(fig, colorbars=not grid and hue is not None and _numeric(ds[hue].values))
    for ax, d in zip(axes, directions):
        v = values.sel(direction=d)
        if grid:
            xs = ds[x].values
            if hue is None:
                ax.plot(xs, v.transpose(x).values, "o-", color="C0")
            else:
                for k, hv in enumerate(ds[hue].values):
                    ax.plot(xs, v.isel({hue: k}).transpose(x).values, "o-", color=f"C{k % 10}",
                            label=f"{hv:g}" if _numeric([hv]) else str(hv))
                ax.legend(title=hue, fontsize=8, title_fontsize=8)
        else:
            xs = ds[x].values
            c = ds[hue].values if hue is not None and _numeric(ds[hue].values) else None
            sc = ax.scatter(xs, v.values, c=c, s=18, cmap="viridis")
            if c is not None:
                fig.colorbar(sc, ax=ax, label=hue)
        if _log_scale(ds[x].values):
            from matplotlib.ticker import NullLocator

            ax.set_xscale("log")
            if grid:  # the swept values as ticks, plainly written; no unlabelled minor ticks
                ax.set_xticks(xs, [f"{t:g}" for t in xs])
                ax.xaxis.set_minor_locator(NullLocator())
        if logy:
            ax.set_yscale("log")
        ax.set_xlabel(x)
        ax.set_title(f"{d.upper()} fringes", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(ylabel)
    fig.suptitle(title, fontsize=10)


def plot_statistic(ds, path, quantity: str = "slope_urad", statistic: str = "rms",
                   x: str | None = None, hue: str | None = None) -> Path:
    """``statistic`` of ``quantity`` (see ``ds.quantity``/``ds.statistic``) against the swept
    parameter ``x`` (default: the first), one line per value of ``hue`` (default: the
    second parameter, if any)."""
    if quantity not in ds["quantity"].values:
        raise ValueError(f"quantity: {quantity!r} is not one of {list(ds['quantity'].values)}")
    if statistic not in ds["statistic"].values:
        raise ValueError(f"statistic: {statistic!r} is not one of "
                         f"{list(ds['statistic'].values)}")
    x, hue = _axes_of(ds, x, hue)
    sel, note = _fixed(ds, x, hue)
    values = ds["deviation_stats"].sel(quantity=quantity, statistic=statistic).isel(sel)
    values = values.where(ds["done"].isel(sel))
    unit = "" if statistic in ("valid_fraction", "n_valid", "n_masked") else \
        f" ({UNITS[quantity]})"
    label = f"{LABELS[quantity]}, {STAT_LABELS.get(statistic, statistic)}{unit}"
    if statistic in ("valid_fraction", "n_valid", "n_masked"):
        label = STAT_LABELS[statistic]
    cfg = json.loads(ds.attrs["config_json"])
    title = (f"{cfg['name']}: {label} vs {x}{note}\nfinest fringe width against the ideal "
             f"specular reference, {int(ds['done'].sum())} of {ds['done'].size} points done")
    fig = _figure((4.2 * ds.sizes["direction"] + 0.6, 3.6))
    _draw(fig, ds, values.load(), x, hue, label, title)
    return _save(fig, path)


def plot_modulation_ratio(ds, path, x: str | None = None, hue: str | None = None,
                          width: int = 0) -> Path:
    """Median modulation ratio (surface / specular reference) of fringe width index
    ``width`` (0 = the first of ``widths_px``) against the swept parameters."""
    x, hue = _axes_of(ds, x, hue)
    sel, note = _fixed(ds, x, hue)
    values = ds["modulation_ratio_median"].isel(width=width).isel(sel)
    values = values.where(ds["done"].isel(sel)).load()
    cfg = json.loads(ds.attrs["config_json"])
    title = (f"{cfg['name']}: fringe contrast left by the scattering vs {x}{note}\n"
             f"median modulation ratio to the specular reference, widths_px[{width}]")
    fig = _figure((4.2 * ds.sizes["direction"] + 0.6, 3.6))
    _draw(fig, ds, values, x, hue, "modulation ratio (1)", title)
    for ax in fig.axes:
        if ax.get_label() != "<colorbar>":
            ax.set_ylim(0, 1.05)
    return _save(fig, path)


def sweep_figures(ds, folder) -> list[Path]:
    """The default figures of a sweep (its store as a Dataset, see
    :func:`pmdsim.run.sweep.load_sweep`): RMS phase and slope deviation and the modulation
    ratio against the swept parameters, into ``folder``."""
    folder = Path(folder)
    return [
        plot_statistic(ds, folder / "phase_rms.png", "phase_mrad", "rms"),
        plot_statistic(ds, folder / "slope_rms.png", "slope_urad", "rms"),
        plot_modulation_ratio(ds, folder / "modulation_ratio.png"),
    ]


__all__ = ["plot_statistic", "plot_modulation_ratio", "sweep_figures"]
