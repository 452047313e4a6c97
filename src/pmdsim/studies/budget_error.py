"""The numerical (quadrature) error of the error budget's rows.

A surface row of :func:`pmdsim.studies.budget.budget` is the scattering surface decoded
minus the ideal mirror decoded through the same system. The mirror's renders trace the
principal ray of every vision ray (no quadrature); the surface's render is a quadrature of
the rendering integral, whose per-pixel error the budget carries to every statistic:

- **per pixel**: the render's own stated phase error of the finest fringe
  (:meth:`pmdsim.render.FringeResult.phase_error`: the pilot's statement of a Gauss rule,
  on linear and non-linear displays alike, or the rqmc replicates) as monitor px,
  ``e = delta phi w / (2 pi)``. Where the render states none, the surface is decoded once
  more through the same chain (same sensor noise) and ``e`` is the decoded
  difference (:func:`difference_error`): for a randomised set (``rqmc``, and the nearest
  monitor's control variate ``rule+rqmc``, :mod:`pmdsim.render.control_variate`) with an
  independent seed at the same order (about sqrt(2) times the random part of either), for
  a deterministic rule with half the nodes (the lower order's error, larger than the
  rendered one's) (:func:`second_estimate`). Through a sensor the same decoded
  difference is taken as well and the larger of the two is the error: the shot noise is
  drawn coupled (:meth:`pmdsim.scene.sensor.Sensor.capture`), but a signal change of a
  fraction of an electron still moves some pixels by one electron or one DN, a discrete
  change of about the square root of the signal change that the render's error, linear in
  it, does not contain;
- **RMS and P95 of a row** (:func:`stat_error`): a statistic ``S`` of ``|d|`` that grows
  with every ``|d_i|`` (RMS, percentiles) lies between ``S(max(|d| - e, 0))`` and
  ``S(|d| + e)`` whatever the errors' signs; the row states the larger distance of ``S(|d|)``
  to those bounds. For the RMS this is at most the RMS of ``e`` (Minkowski). A P95 adds
  the resolution of a percentile of a finite set (:func:`pmdsim.quantiles.one_value_change`:
  what one pixel entering or leaving the valid set moves it by), which no pixel's error
  contains;
- **height rows** (:func:`height_error_bounds`): the decoding is reconstructed again with
  every coordinate moved by ``+e`` and by ``-e`` (x and y together); the larger change of
  each node's slope errors and height error (after removal) is that node's error
  (:func:`node_errors`: the reconstruction is linear in small coordinate errors, and the
  quadrature's errors vary smoothly across pixels), plus the floors of the reconstruction
  solvers whose results the row compares (:func:`solver_floors`: each stops within its own
  tolerance, which no difference shows; the system rows, against the exact truth, state
  their reconstruction's), carried to RMS/P95 by the same interval bound and to the PV by
  the widest range it allows;
- the **numerical error rows** of the budget state the error maps themselves (RMS and P95
  of ``e`` in every unit; heights: RMS, PV and P95 of the nodes' errors).
"""

from __future__ import annotations


import numpy as np

from ..config import RunConfig, with_sampling

#: Statistics of a row that carry an error (the deviation rows: per quantity).
ROW_STATS = ("rms", "p95")


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


def _p95(a: np.ndarray) -> float:
    return float(np.percentile(a, 95)) if a.size else float("nan")


STATS = {"rms": _rms, "p95": _p95}


def stat_error(dev: np.ndarray, err: np.ndarray, valid: np.ndarray, stat: str) -> float:
    """The numerical error of ``stat`` (``"rms"`` or ``"p95"``) of ``|dev|`` over ``valid``
    when every ``dev_i`` is known to within ``err_i`` (>= 0; NaN counts as 0 and is not
    expected where ``dev`` is finite): ``max(S(|d| + e) - S(|d|), S(|d|) - S(max(|d| - e,
    0)))``, exact bounds for a statistic that grows with every ``|d_i|``; for ``"p95"``
    plus :func:`~pmdsim.quantiles.one_value_change` of ``|dev|`` (the percentile of a
    finite set moves by up to that when one pixel enters or leaves it)."""
    f = STATS[stat]
    m = np.asarray(valid, bool) & np.isfinite(dev)
    d = np.abs(np.asarray(dev, np.float64)[m])
    e = np.nan_to_num(np.abs(np.asarray(err, np.float64)[m]), nan=0.0)
    if not d.size:
        return float("nan")
    s = f(d)
    out = max(f(d + e) - s, s - f(np.maximum(d - e, 0.0)))
    if stat == "p95":
        from ..quantiles import one_value_change

        out += one_value_change(d, 95)
    return float(out)


def error_stats(err: np.ndarray, valid: np.ndarray) -> dict:
    """RMS and P95 of an error map over ``valid`` (the numerical error row)."""
    m = np.asarray(valid, bool) & np.isfinite(err)
    a = np.abs(np.asarray(err, np.float64)[m])
    return {k: f(a) for k, f in STATS.items()}


def difference_error(coord: dict, valid: dict, coord_lo: dict, valid_lo: dict) -> dict:
    """Per direction, ``|c - c_lo|`` (monitor px) where both decodings are valid; where the
    lower order leaves a pixel undecoded its error is unknown: NaN (the rows count it as 0
    and :func:`unknown_share` reports the share)."""
    out = {}
    for d in coord:
        ok = valid[d] & valid_lo[d]
        out[d] = np.where(ok, np.abs(coord[d] - coord_lo[d]), np.nan)
    return out


def unknown_share(err: np.ndarray, valid: np.ndarray) -> float:
    """The share of ``valid`` pixels whose error is unknown (NaN)."""
    v = np.asarray(valid, bool)
    n = int(np.count_nonzero(v))
    return float(np.count_nonzero(v & ~np.isfinite(err)) / n) if n else 0.0


#: Statistics of a height row that carry an error.
HEIGHT_STATS = ("slope_rms_x_urad", "slope_rms_y_urad", "slope_p95_x_urad", "slope_p95_y_urad",
                "height_rms_nm", "height_pv_nm", "height_p95_nm")


#: The maps of a height row that carry per-node errors (HeightError attributes).
NODE_MAPS = ("slope_x_urad", "slope_y_urad", "height_nm")


def node_errors(err, shifted, floors: dict | None = None) -> dict:
    """Per reconstruction node, the numerical error of the slope errors (urad) and of the
    height error after removal (nm): the larger change between ``err`` and the
    :class:`~pmdsim.studies.height_rows.HeightError` of each decoding moved by ``+-e``
    (none: 0 where the map is defined, a mirror's exact render), plus ``floors[key]``
    (the reconstruction solvers' floors, :func:`solver_floors`; None: none)."""
    out = {}
    for key in NODE_MAPS:
        base = getattr(err, key)
        ch = [np.abs(getattr(h, key) - base) for h in shifted]
        if ch:
            e = np.fmax.reduce(ch)
        elif floors is not None:
            e = np.where(np.isfinite(base), 0.0, np.nan)
        else:
            e = np.full_like(base, np.nan)
        out[key] = e + floors[key] if floors is not None else e
    return out


def solver_floors(*recs) -> dict:
    """``{map: floor}`` of a height row: the sum over the reconstructions ``recs`` it is
    the difference of (the surface's and the mirror's; one where the truth is exact) of
    each one's solver floor
    (:meth:`~pmdsim.measure.reconstruct.Reconstruction.solver_floor`)."""
    return {key: float(sum(r.solver_floor(key) for r in recs))
            for key in NODE_MAPS}


def height_error_bounds(err, shifted, floors: dict | None = None) -> dict:
    """{statistic + "_err"} of :data:`HEIGHT_STATS`: the per-node errors of
    :func:`node_errors` (with the solvers' ``floors``) carried to each statistic by
    :func:`stat_error` (RMS and P95 about zero for the slopes, about the mean for the
    height, as the row's statistics are), the PV's by the widest range the per-node
    errors allow; with ``floors`` also the floors themselves (``solver_floor_nm``, the
    larger slope floor ``solver_floor_urad``)."""
    e = node_errors(err, shifted, floors)
    out = {} if floors is None else {
        "solver_floor_nm": floors["height_nm"],
        "solver_floor_urad": max(floors["slope_x_urad"], floors["slope_y_urad"])}
    for k in ("x", "y"):
        a, ea = getattr(err, f"slope_{k}_urad"), e[f"slope_{k}_urad"]
        m = np.isfinite(a)
        out[f"slope_rms_{k}_urad_err"] = stat_error(a, ea, m, "rms")
        out[f"slope_p95_{k}_urad_err"] = stat_error(a, ea, m, "p95")
    h, eh = err.height_nm, e["height_nm"]
    m = np.isfinite(h)
    if not m.any():
        return out | {"height_rms_nm_err": float("nan"), "height_p95_nm_err": float("nan"),
                      "height_pv_nm_err": float("nan")}
    d = np.where(m, h - np.mean(h[m]), np.nan)
    out["height_rms_nm_err"] = stat_error(d, eh, m, "rms")
    out["height_p95_nm_err"] = stat_error(d, eh, m, "p95")
    ehm = np.nan_to_num(eh[m], nan=0.0)
    out["height_pv_nm_err"] = float(np.max(h[m] + ehm) - np.min(h[m] - ehm) - np.ptp(h[m]))
    return out


def second_estimate(cfg: RunConfig, n_rays: int, mode: str | None) -> tuple[RunConfig, str]:
    """The render whose decoded difference states the numerical error of ``cfg``'s at
    ``n_rays`` where the render states none: a randomised set (``rqmc``, ``random``) again
    with an independent seed (the difference is about sqrt(2) times the error), a
    deterministic one with half the nodes (the lower order's error, larger than the
    rendered one's)."""
    if mode in ("rqmc", "random", "rule+rqmc"):
        c = at_order(cfg, n_rays)
        seed = (cfg.sampling.seed + 7919) % 2**63
        return with_sampling(c, seed=seed), f"decoded difference to an independent seed ({seed})"
    lo = max(n_rays // 2, 1)
    return at_order(cfg, lo), f"decoded difference to {lo} nodes"


def at_order(cfg: RunConfig, n_rays: int) -> RunConfig:
    """``cfg`` rendered with ``n_rays`` nodes and no target error (the order is given)."""
    s = cfg.sampling
    n = max(int(n_rays), 2 * s.replicates) if s.mode == "rqmc" else int(n_rays)
    return with_sampling(cfg, n_rays=n, target_error_mrad=None, max_rays=max(n, s.max_rays))


# ------------------------------------------------------- the budget's tables (budget.py)
def estimator_label(sampling) -> str:
    """The estimator as tables and figures name it; the cone (``theta_max_deg``) only for
    the cone estimators, which use it."""
    if sampling.estimator == "radiometric":
        return "radiometric (the rendering integral over the whole lobe)"
    return f"{sampling.estimator} (cone {sampling.theta_max_deg:g} deg)"


TABLE_COLUMNS = ("effect", "part", "direction", "rms_mrad", "rms_mrad_err", "p95_mrad",
                 "p95_mrad_err", "rms_px", "rms_px_err", "p95_px", "p95_px_err", "rms_mm",
                 "rms_mm_err", "p95_mm", "p95_mm_err", "rms_urad", "rms_urad_err", "p95_urad",
                 "p95_urad_err", "mean_px", "n_valid", "seconds", "label")
HEIGHT_COLUMNS = ("effect", "part", "slope_rms_x_urad", "slope_rms_x_urad_err", "slope_rms_y_urad",
                  "slope_rms_y_urad_err", "slope_p95_x_urad", "slope_p95_x_urad_err",
                  "slope_p95_y_urad", "slope_p95_y_urad_err", "height_rms_nm", "height_rms_nm_err",
                  "height_pv_nm", "height_pv_nm_err", "height_p95_nm", "height_p95_nm_err",
                  "n_nodes", "rim_excluded", "removed", "seconds", "label", "how")
