"""The error budget's bar figure and text table (:mod:`pmdsim.studies.budget`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def _g(v, scale=1.0) -> str:
    return "nan" if v is None or not math.isfinite(v) else f"{v * scale:.3g}"


def _pm(r: dict, key: str, scale: float = 1.0) -> str:
    """``"value ± numerical error"`` of ``r[key]`` (the value alone where the row states no
    error: the numerical error rows themselves)."""
    v, e = r.get(key), r.get(f"{key}_err")
    if e is None or not math.isfinite(e) or v is None or not math.isfinite(v):
        return _g(v, scale)
    return f"{v * scale:.3g} ± {e * scale:.2g}"


def height_text(height_rows: list[dict], settings: dict | None = None) -> str:
    """The metrologist's table: per effect, slope error X / Y (urad RMS, surface frame, from
    the reconstruction) and height error after the removal (nm RMS / PV / P95)."""
    if not height_rows:
        return ""
    head = (f"{'part':11s} {'effect':52s} {'slope X urad':>17s} {'slope Y urad':>17s} "
            f"{'RMS nm':>17s} {'PV nm':>17s} {'P95 nm':>17s}")
    lines = []
    if settings:
        lines.append(f"height error after: {settings.get('removed', '')}; estimator "
                     f"{settings.get('estimator', '')}; slopes dz/dx, dz/dy RMS about zero; "
                     "value ± numerical error")
    lines += [head, "-" * len(head)]
    for r in height_rows:
        lines.append(f"{r['part']:11s} {r['label'][:52]:52s} {_pm(r, 'slope_rms_x_urad'):>17s} "
                     f"{_pm(r, 'slope_rms_y_urad'):>17s} {_pm(r, 'height_rms_nm'):>17s} "
                     f"{_pm(r, 'height_pv_nm'):>17s} {_pm(r, 'height_p95_nm'):>17s}")
    if any(r["part"] == "calibration" for r in height_rows):
        lines.append("calibration rows: sensitivity x uncertainty (one reconstruction per "
                     "component off by +1 sigma; components and rows in quadrature)")
    for r in height_rows:
        if r.get("sphere"):
            sp = r["sphere"]
            lines.append(f"best-fit sphere, {r['effect']}: radius {sp['radius_measured_mm']:.8g} mm "
                         f"(reference {sp['radius_true_mm']:.8g} mm), curvature change "
                         f"{sp['curvature_change_per_mm'] * 1e3:+.3g} 1/m")
    return "\n".join(lines) + "\n"


def areal_text(height_rows: list[dict]) -> str:
    """Per height row, the ISO 25178 areal parameters of its height error (nm; Sdq urad)
    and its band-limited RMS (form / mid-spatial / high, nm), value ± numerical error."""
    rows = [r for r in height_rows if (r.get("areal") or {}).get("height_error_nm")]
    if not rows:
        return ""
    cols = ("sq", "sa", "sz", "ssk", "sku", "sdq")
    head = (f"{'part':11s} {'effect':40s} " + " ".join(f"{c.capitalize():>17s}" for c in cols)
            + " " + " ".join(f"{b + ' RMS':>17s}" for b in ("form", "mid", "high")))
    lines = [("height error after the removal: ISO 25178 areal parameters (nm; Sdq nm/mm = "
              "urad) and band-limited RMS of its PSD (nm); value ± numerical error"),
             head, "-" * len(head)]
    for r in rows:
        st = r["areal"]["height_error_nm"]
        psd = st.get("psd") or {}
        rms, err = psd.get("band_rms") or {}, psd.get("band_rms_err") or {}
        bands = " ".join(f"{_pm({'v': rms.get(b), 'v_err': err.get(b)}, 'v'):>17s}"
                         for b in ("form", "mid", "high"))
        lines.append(f"{r['part']:11s} {r['label'][:40]:40s} "
                     + " ".join(f"{_pm(st, c):>17s}" for c in cols) + " " + bands)
    bands = (rows[0]["areal"]["height_error_nm"].get("psd") or {}).get("bands_per_mm")
    if bands:
        lines.append(f"bands: form below {bands['form'][1]:.3g} 1/mm (periods > "
                     f"{1 / bands['form'][1]:.3g} mm), high above {bands['high'][0]:.3g} 1/mm "
                     f"(periods < {1 / bands['high'][0]:.3g} mm); radial PSDs in budget.json, "
                     "budget_psd.png")
    return "\n".join(lines) + "\n"


def budget_text(rows: list[dict], height_rows: list[dict] = (), settings: dict | None = None,
                quantity: str = "urad") -> str:
    """Fixed-width tables: the height rows (:func:`height_text`) and one line per (effect,
    direction), RMS and P95 in every unit (slope: the 3-D conversion)."""
    head = (f"{'part':9s} {'effect':44s} {'dir':3s} {'RMS mrad':>17s} {'P95 mrad':>17s} "
            f"{'RMS px':>17s} {'P95 px':>17s} {'RMS um':>17s} {'RMS urad':>17s} {'P95 urad':>17s}")
    lines = ([height_text(list(height_rows), settings), areal_text(list(height_rows))]
             if height_rows else [])
    lines += ["per fringe direction: decoded minus exact (system) or minus the mirror (surface); "
              "value ± numerical error",
              head, "-" * len(head)]
    for r in rows:
        def f(k, scale=1.0):
            return _pm(r, k, scale)
        lines.append(
            f"{r['part']:9s} {r['label'][:44]:44s} {r['direction'].upper():3s} {f('rms_mrad'):>17s} "
            f"{f('p95_mrad'):>17s} {f('rms_px'):>17s} {f('p95_px'):>17s} {f('rms_mm', 1e3):>17s} "
            f"{f('rms_urad'):>17s} {f('p95_urad'):>17s}")
    if settings and settings.get("sampling"):
        for name, smp in settings["sampling"].items():
            lines.append(f"{name}: {smp.get('mode')}, {smp.get('rule')}, n_rays = {smp.get('n_rays')}; "
                         f"numerical error from {smp.get('error_from')}"
                         + (f"; target {smp['target_error_mrad']:g} mrad "
                            f"{'met' if smp.get('target_met') else 'NOT met'}"
                            if smp.get("target_error_mrad") is not None else ""))
    for w in (settings or {}).get("warnings", ()):
        lines.append(f"warning: {w}")
    return "\n".join(lines) + "\n"


def _err(row, key) -> float:
    e = None if row is None else row.get(f"{key}_err")
    return float("nan") if e is None else float(e)


_COLOURS = {"system": "tab:blue", "surface": "tab:orange", "calibration": "tab:green",
            "numerical": "tab:gray"}


def _bars(ax, labels, pairs, colours, xlabel, log=False, errs=None):
    """Two bars per row (``pairs``: (light, solid) arrays) with their values written;
    ``errs``: their numerical errors (error bars and "± e" where finite and > 0)."""
    y = np.arange(len(labels))
    (a_lab, a), (b_lab, b) = pairs
    ea, eb = errs if errs is not None else (np.full(len(a), np.nan), np.full(len(b), np.nan))
    ax.barh(y - 0.2, a, 0.4, color=colours, alpha=0.45, label=a_lab)
    ax.barh(y + 0.2, b, 0.4, color=colours, label=b_lab)
    for off, vals, es in ((-0.2, a, ea), (0.2, b, eb)):
        ok = np.isfinite(es) & (es > 0) & np.isfinite(vals)
        if ok.any():
            ax.errorbar(vals[ok], y[ok] + off, xerr=es[ok], fmt="none", ecolor="black",
                        elinewidth=0.8, capsize=2)
    for yi in range(len(labels)):
        for val, e, off in ((a[yi], ea[yi], -0.2), (b[yi], eb[yi], 0.2)):
            if math.isfinite(val):
                txt = f" {val:.3g}" if abs(val) >= 0.01 else " < 0.01"
                if math.isfinite(e) and e > 0:
                    txt += f" ± {e:.2g}"
                ax.text(val, yi + off, txt, va="center", fontsize=7)
    ax.set_xlabel(xlabel)
    ax.grid(axis="x", alpha=0.3)
    fin = np.r_[a, b][np.isfinite(np.r_[a, b]) & (np.r_[a, b] > 0)]
    if log and fin.size:
        ax.set_xscale("log")
        ax.set_xlim(fin.min() / 2, fin.max() * 8)
    else:
        ax.set_xlim(0, (fin.max() if fin.size else 1e-12) * 1.25)
    ax.set_yticks(y)
    ax.invert_yaxis()


def plot_budget(rows: list[dict], path: Path, title: str = "error budget", quantity: str = "urad",
                height_rows: list[dict] = (), settings: dict | None = None) -> Path:
    """Horizontal bars of RMS and P95 per effect and fringe direction (slope, urad, the 3-D
    conversion), and, with ``height_rows``, of the height error after removal (nm RMS and
    PV, log scale) and the reconstruction's slope errors X / Y (urad RMS): system effects
    blue, the surface orange, calibration errors green."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dirs = sorted({r["direction"] for r in rows})
    labels = []
    for r in rows:
        key = (r["part"], r["label"])
        if key not in labels:
            labels.append(key)
    n = len(labels)
    nh = len(height_rows)
    top = 0.45 * n + 1.2
    bottom = 0.45 * nh + 1.2 if nh else 0.0
    fig = plt.figure(figsize=(6.5 * max(len(dirs), 2), top + bottom + 0.8))
    gs = fig.add_gridspec(2 if nh else 1, max(len(dirs), 2), height_ratios=[top, bottom] if nh else [1])
    unit = {"urad": "slope deviation, urad (3-D conversion)", "px": "monitor px", "mrad": "phase, mrad",
            "mm": "mm"}[quantity]
    axes = [fig.add_subplot(gs[0, k]) for k in range(len(dirs))]
    for ax, d in zip(axes, dirs):
        by = {(r["part"], r["label"]): r for r in rows if r["direction"] == d}
        rms = np.array([by[k][f"rms_{quantity}"] if k in by else np.nan for k in labels], float)
        p95 = np.array([by[k][f"p95_{quantity}"] if k in by else np.nan for k in labels], float)
        colours = [_COLOURS.get(k[0], "tab:gray") for k in labels]
        errs = tuple(np.array([_err(by.get(k), f"{s}_{quantity}") for k in labels], float)
                     for s in ("p95", "rms"))
        _bars(ax, labels, (("P95 |dev|", p95), ("RMS", rms)), colours, unit, errs=errs)
        ax.set_title(f"{d.upper()} fringes, per pixel (3-D slope conversion)", fontsize=9)
        ax.set_yticklabels([f"{lab}  [{part}]" for part, lab in labels] if ax is axes[0] else [],
                           fontsize=8)
    axes[0].legend(loc="lower right", fontsize=8)
    if nh:
        hl = [f"{r['label']}  [{r['part']}]" for r in height_rows]
        colours = [_COLOURS.get(r["part"], "tab:gray") for r in height_rows]
        ax = fig.add_subplot(gs[1, 0])
        pv = np.array([r["height_pv_nm"] for r in height_rows], float)
        rms = np.array([r["height_rms_nm"] for r in height_rows], float)
        _bars(ax, hl, (("PV", pv), ("RMS", rms)), colours, "height error, nm (log)", log=True,
              errs=tuple(np.array([_err(r, k) for r in height_rows], float)
                         for k in ("height_pv_nm", "height_rms_nm")))
        ax.set_yticklabels(hl, fontsize=8)
        ax.set_title("height error after: " + (settings or {}).get("removed", ""), fontsize=9)
        ax.legend(loc="lower right", fontsize=8)
        ax2 = fig.add_subplot(gs[1, 1])
        sx = np.array([r["slope_rms_x_urad"] for r in height_rows], float)
        sy = np.array([r["slope_rms_y_urad"] for r in height_rows], float)
        _bars(ax2, hl, (("dz/dy RMS", sy), ("dz/dx RMS", sx)), colours,
              "slope error of the reconstruction, urad RMS (log)", log=True,
              errs=tuple(np.array([_err(r, k) for r in height_rows], float)
                         for k in ("slope_rms_y_urad", "slope_rms_x_urad")))
        ax2.set_yticklabels([])
        ax2.set_title("reconstructed slopes (surface frame)", fontsize=9)
        ax2.legend(loc="lower right", fontsize=8)
    est = f"; estimator {settings['estimator']}" if settings and settings.get("estimator") else ""
    fig.suptitle(title + est + "\nlight: P95 or PV; blue: system (mirror decoded minus the exact point), "
                 "orange: surface minus the mirror,\ngreen: calibration (sensitivity x uncertainty), "
                 "grey: numerical error of the surface rows; error bars and ± : numerical error",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.7 / fig.get_size_inches()[1]))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
