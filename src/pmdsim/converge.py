"""Convergence study: decoded phase deviation and modulation versus N, theta_max and estimator.

For the scene of a configuration, on a reduced camera (the configured camera subsampled to
about ``camera_size`` pixels by scaling resolution and focal length in pixels together, so
the field of view and the surface points are the same), :func:`run_convergence` renders
the configured fringes (directions, widths, K shifts)

- with the cone estimators (``paper``, ``weighted_mean``) for every N in ``n_values`` and
  every cone half angle in ``theta_values_deg``, and
- with the ``radiometric`` estimator for every N (it has no cone),

decodes each (``pmdsim.decode.phase_shift``) and compares it with the ideal mirror
(``Scene.specular()``): the wrapped phase difference (rad), its RMS, mean and 95th
percentile of the absolute value over the valid pixels, the median modulation, and the RMS
phase difference from the *converged* answer (the radiometric run with the largest N). The
configured N and theta_max are added to the sweeps, so the paper's N = 100 / 1 deg can be
read off against the converged result.

``paper`` and ``weighted_mean`` differ by a factor per pixel (N / sum f), which cancels in
the decoded phase and in the modulation B / A: one render serves both and their rows are
identical (they are listed for completeness).

With ``diagnostics`` (default) the configured settings are also checked
(:func:`pmdsim.diagnostics.diagnose` and :func:`~pmdsim.diagnostics.check` on the reduced
camera, bounds from ``[diagnostics]``): the warnings name the setting that fixes them.

Outputs (written atomically: into a temporary sibling folder renamed at the end):
``convergence.csv`` (one row per estimator, theta_max, N, direction, width),
``convergence.png`` (log-x figure) and ``convergence.json`` (the settings, the config, the
diagnostics summary and the warnings).
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from . import io as pio
from .analysis import wrap
from .config import RunConfig
from .decode import phase_shift
from .render import Simulation
from .sampling import ConeSampling
from .scene import Scene

DEFAULT_N = (25, 50, 100, 200, 400, 800, 1600)
DEFAULT_THETA_DEG = (0.5, 1.0, 2.0, 4.0, 8.0)
ALL_ESTIMATORS = ("paper", "weighted_mean", "radiometric")
COLUMNS = (
    "estimator", "theta_max_deg", "n_rays", "direction", "width_px", "n_valid",
    "phase_rms_rad", "phase_mean_rad", "phase_p95_rad", "modulation_median",
    "phase_rms_vs_converged_rad", "seconds",
)
#: Marker file of a finished convergence folder (an existing folder is replaced only if it
#: carries it, or is empty).
MARKER = "convergence.json"


def reduced_config(cfg: RunConfig, camera_size: tuple[int, int] = (160, 128)) -> RunConfig:
    """The configuration with its camera subsampled to about ``camera_size`` (width, height).

    Resolution and focal length (in pixels) are scaled by the same factor ``s`` (at most
    1), the principal point accordingly (``(c + 0.5) s - 0.5``): the same field of view
    and surface, seen with fewer, larger pixels.
    """
    w, h = cfg.camera.resolution
    s = min(1.0, camera_size[0] / w, camera_size[1] / h)
    if s >= 1.0:
        return cfg
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    sx, sy = nw / w, nh / h
    cam = cfg.camera
    upd = {"resolution": (nw, nh), "focal_length_px": cam.focal_px * sx,
           "focal_length_mm": None, "pixel_pitch_mm": None}
    if cam.principal_point_px is not None:
        cx, cy = cam.principal_point_px
        upd["principal_point_px"] = ((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5)
    data = cfg.model_dump()
    data["camera"].update(upd)
    data["variants"] = []
    return RunConfig.model_validate(data)


@dataclass(frozen=True)
class ConvergenceResult:
    """Rows of the study (dicts with :data:`COLUMNS`) and the files written."""

    rows: list
    folder: Path
    table: Path
    figure: Path | None
    warnings: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)


def _decode(images: np.ndarray):
    """Phase and modulation (nd, nw, H, W) of images (nd, nw, K, H, W)."""
    nd, nw = images.shape[:2]
    ph = np.empty((nd, nw) + images.shape[3:])
    mod = np.empty_like(ph)
    for d in range(nd):
        for w in range(nw):
            r = phase_shift(images[d, w])
            ph[d, w] = r.wrapped_phase
            mod[d, w] = r.modulation
    return ph, mod


def _stats(dev: np.ndarray, valid: np.ndarray):
    d = dev[valid]
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    return (float(np.sqrt(np.mean(d * d))), float(np.mean(d)),
            float(np.percentile(np.abs(d), 95)))


def run_convergence(
    cfg: RunConfig,
    outdir: str | Path,
    n_values: Sequence[int] = DEFAULT_N,
    theta_values: Sequence[float] = DEFAULT_THETA_DEG,
    estimators: Sequence[str] = ALL_ESTIMATORS,
    camera_size: tuple[int, int] = (160, 128),
    widths: Sequence[float] | None = None,
    directions: Sequence[str] | None = None,
    shifts: int | None = None,
    figure: bool = True,
    overwrite: bool = False,
    progress: Callable[[str], None] | None = None,
    diagnostics: bool = True,
) -> ConvergenceResult:
    """Run the convergence study of ``cfg`` and write table and figure into ``outdir``.

    Parameters
    ----------
    cfg : RunConfig
        Its camera, monitor, surface, anisotropy, BRDF (not the mirror), fringes and
        sampling mode/scheme/seed are used; its own ``n_rays`` and ``theta_max_deg`` are
        added to the sweeps.
    outdir : path
        Output folder (created atomically; an existing one is replaced only with
        ``overwrite`` and only if it is a convergence folder or empty).
    n_values : rays per pixel to try.
    theta_values : cone half angles, deg, for the cone estimators.
    estimators : any of ``paper``, ``weighted_mean``, ``radiometric``.
    camera_size : (width, height) of the reduced camera, px.
    widths, directions, shifts : fringes; default: the configured ones (or 50 px, x and y, 4).
    figure : draw ``convergence.png`` (matplotlib, Agg).
    progress : called with a short text after each render.
    diagnostics : check the configured settings (energy fraction, effective sample size,
        phase standard error) and return/write the warnings.
    """
    estimators = tuple(estimators)
    for e in estimators:
        if e not in ALL_ESTIMATORS:
            raise ValueError(f"estimators: unknown estimator {e!r}; choose from {ALL_ESTIMATORS}")
    if not estimators:
        raise ValueError("estimators: give at least one estimator")
    n_values = sorted({int(n) for n in n_values} | {cfg.sampling.n_rays})
    if n_values[0] < 1:
        raise ValueError(f"n_values: rays per pixel must be >= 1, got {n_values[0]}")
    theta_values = sorted({float(t) for t in theta_values} | {float(cfg.sampling.theta_max_deg)})
    if theta_values[0] <= 0 or theta_values[-1] >= 90:
        raise ValueError(f"theta_values: cone half angles must be in (0, 90) deg, got {theta_values}")
    if cfg.brdf.model == "mirror":
        raise ValueError("brdf: the mirror has nothing to converge (one ray, weight 1)")
    fr = cfg.patterns.fringes
    widths = tuple(float(w) for w in (widths or (fr.widths_px if fr else (50.0,))))
    directions = tuple(directions or (fr.directions if fr else ("x", "y")))
    shifts = int(shifts or (fr.shifts if fr else 4))

    final = Path(outdir).absolute()
    pio.check_output_dir(final, overwrite, MARKER)
    small = reduced_config(cfg, camera_size)
    base = Scene.from_config(small)
    comp = small.compute

    def sim_of(scene):
        return Simulation(scene, comp.tile_rows, comp.scheduler, comp.num_workers)

    def say(msg):
        if progress is not None:
            progress(msg)

    ref_res = sim_of(base.specular()).render_fringes(widths, directions, shifts)
    ref_phase, _ = _decode(ref_res.images)
    geom = sim_of(base).geometry()
    considered = geom.monitor_mask
    samp = base.sampling

    runs = []  # (estimators, theta_deg or None, n, phase, modulation, seconds)
    cone = [e for e in estimators if e != "radiometric"]
    if cone:
        for th in theta_values:
            for n in n_values:
                scene = base.replace(
                    sampling=ConeSampling(n, math.radians(th), samp.scheme, samp.mode, samp.seed),
                    estimator="paper")
                t0 = time.perf_counter()
                ph, mod = _decode(sim_of(scene).render_fringes(widths, directions, shifts).images)
                runs.append((cone, th, n, ph, mod, time.perf_counter() - t0))
                say(f"cone theta_max = {th:g} deg, N = {n}")
    if "radiometric" in estimators:
        for n in n_values:
            scene = base.replace(sampling=ConeSampling(n, samp.theta_max, samp.scheme, samp.mode,
                                                       samp.seed), estimator="radiometric")
            t0 = time.perf_counter()
            ph, mod = _decode(sim_of(scene).render_fringes(widths, directions, shifts).images)
            runs.append((["radiometric"], None, n, ph, mod, time.perf_counter() - t0))
            say(f"radiometric N = {n}")
    converged = next((r[3] for r in reversed(runs) if r[1] is None), None)

    warnings, diag_summary = [], {}
    if diagnostics:
        from . import diagnostics as dg

        diag = dg.diagnose(sim_of(base), widths, directions, grid=small.diagnostics.grid)
        warnings = dg.check(diag, bounds=small.diagnostics)
        diag_summary = diag.summary
        say("diagnostics")

    rows = []
    for ests, th, n, ph, mod, secs in runs:
        for di, d in enumerate(directions):
            for wi, wd in enumerate(widths):
                valid = considered & np.isfinite(ph[di, wi]) & np.isfinite(ref_phase[di, wi])
                dev = wrap(ph[di, wi] - ref_phase[di, wi])
                rms, mean, p95 = _stats(dev, valid)
                m = mod[di, wi][valid]
                vs = float("nan")
                if converged is not None:
                    ok = valid & np.isfinite(converged[di, wi])
                    if ok.any():
                        dc = wrap(ph[di, wi] - converged[di, wi])[ok]
                        vs = float(np.sqrt(np.mean(dc * dc)))
                for e in ests:
                    rows.append({
                        "estimator": e, "theta_max_deg": th if th is not None else float("nan"),
                        "n_rays": n, "direction": d, "width_px": wd, "n_valid": int(valid.sum()),
                        "phase_rms_rad": rms, "phase_mean_rad": mean, "phase_p95_rad": p95,
                        "modulation_median": float(np.median(m)) if m.size else float("nan"),
                        "phase_rms_vs_converged_rad": vs, "seconds": secs,
                    })

    with pio.atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        with open(tmp / "convergence.csv", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=COLUMNS)
            wr.writeheader()
            for r in rows:
                wr.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
        fig_path = None
        if figure:
            plot_convergence(rows, tmp / "convergence.png", cfg.sampling.n_rays,
                             cfg.sampling.theta_max_deg, title=f"{cfg.name}: convergence "
                             f"({small.camera.resolution[0]} x {small.camera.resolution[1]} px camera)")
            fig_path = final / "convergence.png"
        meta = {
            "name": cfg.name, "camera_size": list(small.camera.resolution),
            "n_values": list(n_values), "theta_values_deg": list(theta_values),
            "estimators": list(estimators), "widths_px": list(widths),
            "directions": list(directions), "shifts": shifts,
            "reference": "ideal mirror (Scene.specular())",
            "converged": "radiometric, N = %d" % n_values[-1] if converged is not None else None,
            "diagnostics": diag_summary,
            "warnings": [{"code": w.code, "message": w.message, "setting": w.setting,
                          "suggested": w.suggested} for w in warnings],
            "config": cfg.model_dump(mode="json"),
        }
        (tmp / MARKER).write_text(json.dumps(meta, indent=2) + "\n")
    return ConvergenceResult(rows, final, final / "convergence.csv", fig_path, warnings,
                             diag_summary)


def plot_convergence(rows: list, path: str | Path, n_config: int | None = None,
                     theta_config: float | None = None, title: str = "") -> Path:
    """Figure of the study: per fringe direction (rows of panels), the RMS phase deviation
    from the mirror, the RMS phase difference from the converged radiometric answer and the
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
            ("phase_rms_vs_converged_rad", "RMS phase difference from converged (rad)"),
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
            if key == "phase_rms_vs_converged_rad":
                rr = rr[:-1]  # the converged run itself (0)
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
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
