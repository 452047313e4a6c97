"""The figure of a convergence study (``convergence.png``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def plot_convergence(rows: list, path: str | Path, n_config: int | None = None,
                     theta_config: float | None = None, title: str = "") -> Path:
    """Figure of the study: per fringe direction (rows of panels), the RMS phase deviation
    from the mirror, the RMS phase difference from the reference (radiometric, largest N;
    a dashed line at its own stated numerical error: differences below it are not resolved) and the
    median modulation versus N (log x), for the finest fringe width whose converged
    modulation is at least 0.1 (finer fringes are washed out by the lobe: their phase is
    noise at any N; the table has them all); one line per cone half angle (cone
    estimators; paper and weighted_mean coincide) and one for radiometric.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    directions = list(dict.fromkeys(r["direction"] for r in rows))
    widths = sorted({r["width_px"] for r in rows})
    n_max = max(r["n_rays"] for r in rows)

    def shown_width(d):
        # the finest width whose converged modulation is measurable (>= 0.1)
        for wd in widths:
            conv = [r for r in rows if r["direction"] == d and r["width_px"] == wd
                    and r["estimator"] == "radiometric" and r["n_rays"] == n_max]
            if not conv or conv[0]["modulation_median"] >= 0.1:
                return wd
        return widths[-1]

    chosen = {d: shown_width(d) for d in directions}
    sel = [r for r in rows if r["width_px"] == chosen[r["direction"]]
           and r["estimator"] in ("paper", "radiometric")]
    if not any(r["estimator"] == "paper" for r in sel):  # weighted_mean only: same numbers
        sel += [dict(r, estimator="paper") for r in rows if r["estimator"] == "weighted_mean"
                and r["width_px"] == chosen[r["direction"]]]
    thetas = sorted({r["theta_max_deg"] for r in sel if r["estimator"] == "paper"})
    cmap = plt.get_cmap("viridis")
    fig, axes = plt.subplots(len(directions), 3, figsize=(14, 3.6 * len(directions)), squeeze=False)
    cols = (("phase_rms_rad", "RMS phase deviation from mirror (rad)"),
            ("phase_rms_vs_reference_rad", "RMS phase difference from reference (rad)"),
            ("modulation_median", "median modulation"))
    for di, d in enumerate(directions):
        for ci, (key, label) in enumerate(cols):
            ax = axes[di, ci]
            for ti, th in enumerate(thetas):
                rr = sorted((r for r in sel if r["direction"] == d and r["estimator"] == "paper"
                             and r["theta_max_deg"] == th), key=lambda r: r["n_rays"])
                ax.plot([r["n_rays"] for r in rr], [r[key] for r in rr], "o-", ms=3,
                        color=cmap(ti / max(1, len(thetas) - 1)),
                        label=f"cone {th:g} deg")
                if n_config is not None and theta_config is not None and math.isclose(th, theta_config):
                    star = [r for r in rr if r["n_rays"] == n_config]
                    if star:
                        ax.plot([n_config], [star[0][key]], "*", ms=14, color="tab:red",
                                label=f"config (N = {n_config}, {th:g} deg)")
            rr = sorted((r for r in sel if r["direction"] == d and r["estimator"] == "radiometric"),
                        key=lambda r: r["n_rays"])
            if key == "phase_rms_vs_reference_rad":
                ref_err = [r["reference_error_rms_rad"] for r in rr[-1:]]
                rr = rr[:-1]  # the reference run itself (0)
                if ref_err and np.isfinite(ref_err[0]) and ref_err[0] > 0:
                    ax.axhline(ref_err[0], color="tab:red", ls="--", lw=1,
                               label="reference's own error: below it, not resolved")
            if rr:
                ax.plot([r["n_rays"] for r in rr], [r[key] for r in rr], "s-", ms=3, lw=2.5,
                        color="black", label="radiometric")
            ax.set_xscale("log")
            if key != "modulation_median":
                vals = [r[key] for r in sel if r["direction"] == d and np.isfinite(r[key]) and r[key] > 0]
                if vals:
                    ax.set_yscale("log")
            ax.set_xlabel("rays per pixel N")
            ax.set_ylabel(label)
            ax.set_title(f"{d} fringes, width {chosen[d]:g} monitor px", fontsize=10)
            ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="best")
    for ax in axes[:, 1]:
        if any(line.get_linestyle() == "--" for line in ax.get_lines()):
            ax.legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
