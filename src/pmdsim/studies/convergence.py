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
percentile of the absolute value over the valid pixels, the median modulation, the row's own
numerical phase error (the rule's statement, :meth:`pmdsim.render.FringeResult.phase_error`,
RMS over the valid pixels, capped at pi per pixel: a phase cannot be wronger; NaN for a mode
without an error estimate) and the RMS phase difference from the *reference*: the
radiometric run with the largest N. The reference carries its own stated numerical error
(``reference_error_rms_rad``, RMS over the same pixels); a difference at or below it cannot
be told from the reference's own error and the row is ``resolved = False`` ("not resolved").
A reference whose error exceeds :data:`REFERENCE_CONVERGED_RAD` for a fringe is not
converged there (``meta["reference"]["fringes"]``), and nothing calls it converged. The
configured N and theta_max are added to the sweeps, so the paper's N = 100 / 1 deg can be
read off against the reference.

``paper`` and ``weighted_mean`` differ by a factor per pixel (N / sum f), which cancels in
the decoded phase and in the modulation B / A: one render serves both and their rows are
identical (they are listed for completeness).

With ``diagnostics`` (default) the configured settings are also checked
(:func:`pmdsim.studies.diagnostics.diagnose` and :func:`~pmdsim.studies.diagnostic_warnings.check` on the reduced
camera, bounds from ``[diagnostics]``): the warnings name the setting that fixes them.

Outputs (written atomically: into a temporary sibling folder renamed at the end):
``convergence.csv`` (one row per estimator, theta_max, N, direction, width),
``convergence.png`` (log-x figure) and ``convergence.json`` (the settings, the config, the
diagnostics summary and the warnings).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from typing import Callable, Sequence

import numpy as np

from ..config import InputError, RunConfig
from ..measure.decode import phase_shift
from ..measure.deviation import wrap
from ..quantiles import percentile
from ..render import Simulation
from ..scene import Scene

DEFAULT_N = (25, 50, 100, 200, 400, 800, 1600)
DEFAULT_THETA_DEG = (0.5, 1.0, 2.0, 4.0, 8.0)
ALL_ESTIMATORS = ("paper", "weighted_mean", "radiometric")
COLUMNS = (
    "estimator", "theta_max_deg", "n_rays", "direction", "width_px", "n_valid",
    "phase_rms_rad", "phase_mean_rad", "phase_p95_rad", "modulation_median",
    "phase_error_rms_rad", "phase_rms_vs_reference_rad", "reference_error_rms_rad",
    "resolved", "seconds",
)

#: A fringe's reference counts as converged when its stated numerical phase error (RMS over
#: the valid pixels) is at most this (rad): 1 mrad, ten times the sampling's default target
#: (0.1 mrad); above it the table calls it "not converged" and says by how much.
REFERENCE_CONVERGED_RAD = 1e-3


def reduced_config(cfg: RunConfig, camera_size: tuple[int, int] = (160, 128)) -> RunConfig:
    """The configuration with its camera subsampled to about ``camera_size`` (width, height).

    Resolution and focal length (in pixels) are scaled by the same factor ``s`` (at most
    1), the principal point accordingly (``(c + 0.5) s - 0.5``): the same field of view
    and surface, seen with fewer, larger pixels.
    """
    if isinstance(cfg.camera.roi, tuple):  # the window as the sensor
        cfg = cfg.model_copy(update={"camera": cfg.camera.cropped()})
    w, h = cfg.camera.resolution
    s = min(1.0, camera_size[0] / w, camera_size[1] / h)
    if s >= 1.0:
        return cfg
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    sx, sy = nw / w, nh / h
    cam = cfg.camera
    if cam.projection == "telecentric" and cam.camera_matrix is None:
        # the same field on the part: larger pixels at the same magnification
        upd = {"resolution": (nw, nh), "pixel_pitch_mm": cam.pixel_pitch_mm / sx}
    elif cam.f_number is not None:  # a thin lens keeps its focal length: larger pixels instead
        upd = {"resolution": (nw, nh), "focal_length_px": None,
               "pixel_pitch_mm": cam.focal_length_mm / (cam.focal_px * sx)}
    else:
        upd = {"resolution": (nw, nh), "focal_length_px": cam.focal_px * sx,
               "focal_length_mm": None, "pixel_pitch_mm": None}
    if cam.principal_point_px is not None:
        cx, cy = cam.principal_point_px
        upd["principal_point_px"] = ((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5)
    data = cfg.model_dump()
    data["camera"].update(upd)
    data["variants"] = []
    return RunConfig.model_validate(data)




def _phase_error(fr) -> np.ndarray | None:
    """(nd, nw, H, W) stated numerical phase error (rad) of a render, capped at pi (a phase
    is never wronger than that); None without an estimate."""
    pe = fr.phase_error()
    return None if pe is None else np.minimum(pe, np.pi)


def _rms_over(a: np.ndarray | None, ok: np.ndarray) -> float:
    if a is None or not ok.any():
        return float("nan")
    v = a[ok]
    if not np.all(np.isfinite(v)):
        return float("inf")
    return float(np.sqrt(np.mean(v * v)))


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
            percentile(np.abs(d), 95, overwrite=True))


@dataclass(frozen=True)
class ConvergenceStudy:
    """Rows of the study (dicts with :data:`COLUMNS`), its settings and the diagnostics of
    the configured settings (summary and :func:`~pmdsim.studies.diagnostic_warnings.check` warnings)."""

    rows: list
    meta: dict
    warnings: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)


def convergence_study(
    cfg: RunConfig,
    n_values: Sequence[int] = DEFAULT_N,
    theta_values: Sequence[float] = DEFAULT_THETA_DEG,
    estimators: Sequence[str] = ALL_ESTIMATORS,
    camera_size: tuple[int, int] = (160, 128),
    widths: Sequence[float] | None = None,
    directions: Sequence[str] | None = None,
    shifts: int | None = None,
    progress: Callable[[str], None] | None = None,
    diagnostics: bool = True,
) -> ConvergenceStudy:
    """Run the convergence study of ``cfg`` (nothing is written; see
    :func:`pmdsim.run.convergence.run_convergence`).

    Parameters
    ----------
    cfg : RunConfig
        Its camera, monitor, surface, anisotropy, BRDF (not the mirror), fringes and
        sampling mode/scheme/seed are used; its own ``n_rays`` and ``theta_max_deg`` are
        added to the sweeps.
    n_values : rays per pixel to try.
    theta_values : cone half angles, deg, for the cone estimators.
    estimators : any of ``paper``, ``weighted_mean``, ``radiometric``.
    camera_size : (width, height) of the reduced camera, px.
    widths, directions, shifts : fringes; default: the configured ones (or 50 px, x and y, 4).
    progress : called with a short text after each render.
    diagnostics : check the configured settings (energy fraction, effective sample size,
        phase standard error) and return/write the warnings.
    """
    estimators = tuple(estimators)
    for e in estimators:
        if e not in ALL_ESTIMATORS:
            raise InputError(f"estimators: unknown estimator {e!r}; choose from {ALL_ESTIMATORS}")
    if not estimators:
        raise InputError("estimators: give at least one estimator")
    n_values = sorted({int(n) for n in n_values} | {cfg.sampling.n_rays})
    if n_values[0] < 1:
        raise InputError(f"n_values: rays per pixel must be >= 1, got {n_values[0]}")
    theta_values = sorted({float(t) for t in theta_values} | {float(cfg.sampling.theta_max_deg)})
    if theta_values[0] <= 0 or theta_values[-1] >= 90:
        raise InputError(f"theta_values: cone half angles must be in (0, 90) deg, got {theta_values}")
    if cfg.brdf.model == "mirror":
        raise InputError("brdf: the mirror has nothing to converge (one ray, weight 1)")
    fr = cfg.patterns.fringes
    widths = tuple(float(w) for w in (widths or (fr.widths_px if fr else (50.0,))))
    directions = tuple(directions or (fr.directions if fr else ("x", "y")))
    shifts = int(shifts or (fr.shifts if fr else 4))

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

    runs = []  # (estimators, theta_deg or None, n, phase, modulation, seconds, phase error)
    ref_sampling: dict = {}
    cone = [e for e in estimators if e != "radiometric"]
    if cone:
        for th in theta_values:
            for n in n_values:
                scene = base.replace(
                    sampling=dc_replace(samp, n_rays=n, theta_max=math.radians(th),
                                        target_error=None),
                    estimator="paper")
                t0 = time.perf_counter()
                fr = sim_of(scene).render_fringes(widths, directions, shifts)
                ph, mod = _decode(fr.images)
                runs.append((cone, th, n, ph, mod, time.perf_counter() - t0, _phase_error(fr)))
                say(f"cone theta_max = {th:g} deg, N = {n}")
    if "radiometric" in estimators:
        for n in n_values:
            scene = base.replace(sampling=dc_replace(samp, n_rays=n, target_error=None),
                                 estimator="radiometric")
            t0 = time.perf_counter()
            fr = sim_of(scene).render_fringes(widths, directions, shifts)
            ph, mod = _decode(fr.images)
            runs.append((["radiometric"], None, n, ph, mod, time.perf_counter() - t0,
                         _phase_error(fr)))
            ref_sampling = dict(fr.sampling or {})
            say(f"radiometric N = {n}")
    ref_run = next((r for r in reversed(runs) if r[1] is None), None)
    reference = ref_run[3] if ref_run is not None else None
    reference_err = ref_run[6] if ref_run is not None else None

    warnings, diag_summary = [], {}
    if diagnostics:
        from . import diagnostics as dg
        from .diagnostic_warnings import check as warnings_of

        diag = dg.diagnose(sim_of(base), widths, directions, grid=small.diagnostics.grid,
                           phase_method=small.diagnostics.phase_method)
        warnings = warnings_of(diag, bounds=small.diagnostics)
        diag_summary = diag.summary
        say("diagnostics")

    rows = []
    for ests, th, n, ph, mod, secs, perr in runs:
        for di, d in enumerate(directions):
            for wi, wd in enumerate(widths):
                valid = considered & np.isfinite(ph[di, wi]) & np.isfinite(ref_phase[di, wi])
                dev = wrap(ph[di, wi] - ref_phase[di, wi])
                rms, mean, p95 = _stats(dev, valid)
                m = mod[di, wi][valid]
                own = _rms_over(None if perr is None else perr[di, wi], valid)
                vs = ref_err = float("nan")
                if reference is not None:
                    ok = valid & np.isfinite(reference[di, wi])
                    if ok.any():
                        dc = wrap(ph[di, wi] - reference[di, wi])[ok]
                        vs = float(np.sqrt(np.mean(dc * dc)))
                    ref_err = _rms_over(None if reference_err is None else reference_err[di, wi], ok)
                # a difference within the reference's own error (or against a reference
                # whose error is unknown) says nothing about this row
                resolved = bool(np.isfinite(vs) and np.isfinite(ref_err) and vs > ref_err)
                for e in ests:
                    rows.append({
                        "estimator": e, "theta_max_deg": th if th is not None else float("nan"),
                        "n_rays": n, "direction": d, "width_px": wd, "n_valid": int(valid.sum()),
                        "phase_rms_rad": rms, "phase_mean_rad": mean, "phase_p95_rad": p95,
                        "modulation_median": float(np.median(m)) if m.size else float("nan"),
                        "phase_error_rms_rad": own, "phase_rms_vs_reference_rad": vs,
                        "reference_error_rms_rad": ref_err, "resolved": resolved,
                        "seconds": secs,
                    })
    ref_fringes = []
    if ref_run is not None:
        for r in rows:
            if r["estimator"] == "radiometric" and r["n_rays"] == n_values[-1]:
                e = r["phase_error_rms_rad"]
                ref_fringes.append({
                    "direction": r["direction"], "width_px": r["width_px"],
                    "error_rms_rad": e if np.isfinite(e) else None,
                    "converged": bool(np.isfinite(e) and e <= REFERENCE_CONVERGED_RAD)})

    meta = {
        "name": cfg.name, "camera_size": list(small.camera.resolution),
        "n_values": list(n_values), "theta_values_deg": list(theta_values),
        "estimators": list(estimators), "widths_px": list(widths),
        "directions": list(directions), "shifts": shifts,
        "mirror": "ideal mirror (Scene.specular())",
        "reference": None if ref_run is None else {
            "run": "radiometric, N = %d" % n_values[-1],
            "sampling": {k: ref_sampling.get(k) for k in ("mode", "rule", "nodes", "error")},
            "converged_below_rad": REFERENCE_CONVERGED_RAD,
            "fringes": ref_fringes},
        "diagnostics": diag_summary,
        "warnings": [{"code": w.code, "message": w.message, "setting": w.setting,
                      "suggested": w.suggested} for w in warnings],
        "config": cfg.model_dump(mode="json"),
    }
    return ConvergenceStudy(rows, meta, warnings, diag_summary)
