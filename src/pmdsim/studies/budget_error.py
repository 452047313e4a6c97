"""The numerical (quadrature) error of the error budget's rows.

A surface row of :func:`pmdsim.studies.budget.budget` is the scattering surface decoded
minus the ideal mirror decoded through the same system. The mirror's renders trace the
principal ray of every vision ray (no quadrature); the surface's render is a quadrature of
the rendering integral, whose per-pixel error the budget carries to every statistic:

- **per pixel**: the render's own stated phase error of the finest fringe
  (:meth:`pmdsim.render.FringeResult.phase_error`: the embedded rule or the rqmc replicates)
  as monitor px, ``e = delta phi w / (2 pi)``. Where the render states none (a display with
  gamma != 1 or a LUT: its images are not linear in the fringe sums), the surface is
  decoded once more through the same chain (same sensor noise) and ``e`` is the decoded
  difference (:func:`difference_error`): for a randomised set (``rqmc``: the nearest-pixel
  monitor) with an independent seed at the same order (about sqrt(2) times the error of
  either), for a deterministic rule with half the nodes (the lower order's error, larger
  than the rendered one's) (:func:`pmdsim.studies.budget.second_estimate`);
- **RMS and P95 of a row** (:func:`stat_error`): a statistic ``S`` of ``|d|`` that grows
  with every ``|d_i|`` (RMS, percentiles) lies between ``S(max(|d| - e, 0))`` and
  ``S(|d| + e)`` whatever the errors' signs; the row states the larger distance of ``S(|d|)``
  to those bounds. For the RMS this is at most the RMS of ``e`` (Minkowski);
- **height rows** (:func:`height_error_bounds`): the decoding is reconstructed again with
  every coordinate moved by ``+e`` and by ``-e`` (x and y together), and each statistic
  states the larger change (the reconstruction is linear in small coordinate errors, and a
  coherent shift is the one that integrates to the largest height);
- the **numerical error row** of the budget states the error maps themselves (RMS and P95 of
  ``e`` in every unit; heights: the larger of the two shifted reconstructions' differences).
"""

from __future__ import annotations

import math

import numpy as np

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
    0)))``, exact bounds for a statistic that grows with every ``|d_i|``."""
    f = STATS[stat]
    m = np.asarray(valid, bool) & np.isfinite(dev)
    d = np.abs(np.asarray(dev, np.float64)[m])
    e = np.nan_to_num(np.abs(np.asarray(err, np.float64)[m]), nan=0.0)
    if not d.size:
        return float("nan")
    s = f(d)
    return float(max(f(d + e) - s, s - f(np.maximum(d - e, 0.0))))


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


def height_error_bounds(row: dict, shifted_rows) -> dict:
    """{statistic + "_err"}: the larger change of each of :data:`HEIGHT_STATS` between
    ``row`` and the rows of the decodings moved by ``+e`` and ``-e``."""
    out = {}
    for k in HEIGHT_STATS:
        v = row.get(k)
        ch = [abs(r[k] - v) for r in shifted_rows
              if v is not None and math.isfinite(v) and math.isfinite(r.get(k, math.nan))]
        out[f"{k}_err"] = max(ch) if ch else float("nan")
    return out
