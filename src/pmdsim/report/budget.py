"""The error budget's bar figure and text table (:mod:`pmdsim.studies.budget`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def budget_text(rows: list[dict], quantity: str = "urad") -> str:
    """A fixed-width table: one line per (effect, direction), RMS and P95 in every unit."""
    head = (f"{'part':8s} {'effect':44s} {'dir':3s} {'RMS mrad':>9s} {'P95 mrad':>9s} "
            f"{'RMS px':>8s} {'P95 px':>8s} {'RMS um':>8s} {'P95 um':>8s} {'RMS urad':>9s} {'P95 urad':>9s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        def f(k, scale=1.0):
            v = r[k]
            return "nan" if v is None or not math.isfinite(v) else f"{v * scale:.3g}"
        lines.append(
            f"{r['part']:8s} {r['label'][:44]:44s} {r['direction'].upper():3s} {f('rms_mrad'):>9s} "
            f"{f('p95_mrad'):>9s} {f('rms_px'):>8s} {f('p95_px'):>8s} {f('rms_mm', 1e3):>8s} "
            f"{f('p95_mm', 1e3):>8s} {f('rms_urad'):>9s} {f('p95_urad'):>9s}")
    return "\n".join(lines) + "\n"


def plot_budget(rows: list[dict], path: Path, title: str = "error budget", quantity: str = "urad") -> Path:
    """Horizontal bars of RMS and P95 (slope, urad) per effect, one panel per direction;
    system effects in blue, the surface in orange."""
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
    fig, axes = plt.subplots(1, len(dirs), figsize=(6.5 * len(dirs), 0.45 * n + 1.8), sharey=True,
                             squeeze=False)
    unit = {"urad": "slope deviation, urad", "px": "monitor px", "mrad": "phase, mrad", "mm": "mm"}[quantity]
    y = np.arange(n)
    for ax, d in zip(axes[0], dirs):
        by = {(r["part"], r["label"]): r for r in rows if r["direction"] == d}
        rms = np.array([by[k][f"rms_{quantity}"] if k in by else np.nan for k in labels], float)
        p95 = np.array([by[k][f"p95_{quantity}"] if k in by else np.nan for k in labels], float)
        colours = ["tab:orange" if k[0] == "surface" else "tab:blue" for k in labels]
        ax.barh(y - 0.2, p95, 0.4, color=colours, alpha=0.45, label="P95 |dev|")
        ax.barh(y + 0.2, rms, 0.4, color=colours, label="RMS")
        for yi, (a, b) in enumerate(zip(rms, p95)):
            for val, off in ((b, -0.2), (a, 0.2)):
                if math.isfinite(val):
                    ax.text(val, yi + off, f" {val:.3g}" if abs(val) >= 0.01 else " < 0.01",
                            va="center", fontsize=7)
        ax.set_xlabel(unit)
        ax.set_title(f"{d.upper()} fringes")
        ax.grid(axis="x", alpha=0.3)
        ax.set_xlim(0, np.nanmax(np.r_[p95, rms, 1e-12]) * 1.25)
    axes[0, 0].set_yticks(y)
    axes[0, 0].set_yticklabels([f"{lab}  [{part}]" for part, lab in labels], fontsize=8)
    axes[0, 0].invert_yaxis()
    axes[0, 0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title + "  (solid: RMS, light: P95; blue: system on the ideal mirror, "
                 "orange: surface minus mirror)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
