"""Deviation of a measurement from the ideal specular reference, and dot-shape moments.

Plain functions on arrays: they serve simulated runs and real camera data alike.

- :func:`wrap` and :func:`deviation_stats` for any deviation map;
- :func:`compare_direction`: phase, monitor-coordinate and modulation deviation of one
  fringe direction against the reference, with masks that are counted, not hidden;
- :func:`slope_deviation`: the slope error a monitor-coordinate deviation implies;
- :func:`image_moments`: centroid, size and elongation of a spot (second moments);
  :func:`moments_error`: their numerical error from the image's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..quantiles import percentile


def finite_values(values: np.ndarray, where: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """``(values[where & isfinite(values)] as float64, count_nonzero(where |
    isfinite(values)))`` in one compiled pass (:func:`pmdsim.kernels.images.gather_finite`;
    ``where`` None: everywhere)."""
    from ..kernels.images import gather_finite

    values = np.asarray(values)
    flat = np.ascontiguousarray(values).reshape(-1)
    if values.dtype.kind != "f":
        flat = flat.astype(np.float64)
    if where is None:
        mask = np.empty(0, np.bool_)
    else:
        mask = np.ascontiguousarray(np.broadcast_to(np.asarray(where, bool), values.shape)).reshape(-1)
    out = np.empty(flat.size)
    n, either = gather_finite(flat, mask, out)
    return out[:n], int(either)


def finite_median(values: np.ndarray, where: np.ndarray | None = None) -> float | None:
    """The median of the finite values of ``values`` where ``where`` holds
    (:func:`finite_values`), None if there is none."""
    from ..quantiles import median

    a, _ = finite_values(values, where)
    return median(a, overwrite=True) if a.size else None


def wrap(phase: np.ndarray) -> np.ndarray:
    """Wrap phases (rad) to (-pi, pi]."""
    w = np.mod(np.asarray(phase, np.float64) + np.pi, 2 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


@dataclass(frozen=True)
class DeviationStats:
    """Statistics of a deviation map over the valid pixels.

    ``p95`` and ``max`` are of the absolute deviation. ``valid_fraction`` is relative to the
    pixels that *could* be measured (``considered``), ``n_masked`` counts those excluded.
    """

    mean: float
    rms: float
    std: float
    p95: float
    max: float
    n_valid: int
    n_masked: int
    valid_fraction: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def deviation_stats(deviation: np.ndarray, valid: np.ndarray, considered: np.ndarray | None = None) -> DeviationStats:
    """Mean, RMS, standard deviation, P95 |dev|, max |dev| over ``valid`` pixels.

    Parameters
    ----------
    deviation : (H, W) ndarray
    valid : (H, W) bool ndarray
        Pixels that enter the statistics.
    considered : (H, W) bool ndarray, optional
        Pixels that could have been valid (e.g. those seeing the monitor); default: all
        finite pixels of ``deviation`` or ``valid``.
    """
    d, n_either = finite_values(deviation, valid)  # deviation[valid & isfinite(deviation)]
    # a pixel marked valid whose deviation is NaN is masked, not hidden (default considered)
    n_cons = n_either if considered is None else int(np.count_nonzero(considered))
    n = d.size
    if n == 0:
        nan = float("nan")
        return DeviationStats(nan, nan, nan, nan, nan, 0, n_cons, 0.0)
    a = np.abs(d)
    return DeviationStats(
        mean=float(d.mean()),
        rms=float(np.sqrt(np.mean(d**2))),
        std=float(d.std()),
        p95=percentile(a, 95, overwrite=True),
        max=float(a.max()),
        n_valid=n,
        n_masked=max(n_cons - n, 0),
        valid_fraction=float(n / n_cons) if n_cons else 0.0,
    )


@dataclass(frozen=True)
class DirectionDeviation:
    """Deviation of one fringe direction from the specular reference.

    Maps are (H, W); NaN outside ``valid``. ``phase`` is the absolute-phase deviation of
    the finest fringe width (rad), ``coord_px``/``coord_mm`` the decoded monitor
    coordinate minus the reference's, ``modulation_ratio`` the modulation (B/A) relative to
    the reference's (per fringe width: (n_widths, H, W)).
    """

    direction: str
    phase: np.ndarray
    coord_px: np.ndarray
    coord_mm: np.ndarray
    modulation_ratio: np.ndarray
    valid: np.ndarray
    low_modulation: np.ndarray
    stats_phase: DeviationStats
    stats_coord_px: DeviationStats
    stats_coord_mm: DeviationStats


def compare_direction(
    direction: str,
    absolute_phase: np.ndarray,
    coord_px: np.ndarray,
    modulation: np.ndarray,
    valid: np.ndarray,
    ref_absolute_phase: np.ndarray,
    ref_coord_px: np.ndarray,
    ref_modulation: np.ndarray,
    ref_valid: np.ndarray,
    pitch_mm: float,
    min_modulation_ratio: float = 0.1,
) -> DirectionDeviation:
    """Compare a decoded direction with its specular reference.

    Pixels enter the statistics where both decodings are valid and the modulation of the
    finest width is at least ``min_modulation_ratio`` times the reference's; pixels that
    fail only the modulation threshold are reported in ``low_modulation`` and counted in
    ``n_masked``.

    Parameters
    ----------
    absolute_phase, coord_px : (H, W) ndarray, rad / monitor px
    modulation : (n_widths, H, W) ndarray
        Fringe modulation (contrast B/A) per width, finest first or in the run's order (the
        ratio is taken element-wise; the threshold uses the width of smallest ratio).
    valid : (H, W) bool ndarray
    ref_* : the same for the specular reference.
    pitch_mm : float
        Monitor pixel pitch, mm.
    min_modulation_ratio : float
    """
    # float32 modulations (the decoder's) give a float32 ratio: it is stored in float32, and
    # float64 copies of the (n_widths, H, W) stacks would hold ~1 GB at 5 MP
    dtype = np.result_type(np.asarray(modulation).dtype, np.asarray(ref_modulation).dtype,
                           np.float32)
    modulation = np.asarray(modulation, dtype)
    ref_modulation = np.asarray(ref_modulation, dtype)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = modulation / ref_modulation
    considered = np.asarray(ref_valid, bool)
    # the smallest finite ratio over the widths (NaN where none is finite, without a warning)
    worst = np.fmin.reduce(np.where(np.isfinite(ratio), ratio, np.nan), axis=0) if ratio.ndim == 3 else ratio
    low = considered & ~(worst >= min_modulation_ratio)
    ok = considered & np.asarray(valid, bool) & ~low
    dphi = np.where(ok, np.asarray(absolute_phase) - np.asarray(ref_absolute_phase), np.nan)
    dc = np.where(ok, np.asarray(coord_px) - np.asarray(ref_coord_px), np.nan)
    ratio = np.where(considered, ratio, np.nan)
    return DirectionDeviation(
        direction=direction,
        phase=dphi,
        coord_px=dc,
        coord_mm=dc * pitch_mm,
        modulation_ratio=ratio,
        valid=ok,
        low_modulation=low,
        stats_phase=deviation_stats(dphi, ok, considered),
        stats_coord_px=deviation_stats(dc, ok, considered),
        stats_coord_mm=deviation_stats(dc * pitch_mm, ok, considered),
    )


def slope_deviation(coord_mm: np.ndarray, distance_mm: np.ndarray) -> np.ndarray:
    """Surface slope error (rad) implied by a monitor-coordinate deviation (mm).

    A surface tilt delta_s turns the reflected ray by 2 delta_s, which moves its monitor
    hit by 2 delta_s d (small angles, monitor roughly normal to the ray, d = distance from
    the surface point to the monitor hit): delta_s = delta_c / (2 d). This is the
    sensitivity PMD works with (PHYSICS.md: delta_s = p delta_phi / (4 pi d)).

    Only right in the plane of incidence: across it a tilt delta turns the ray by
    2 delta cos(theta_i), so this is cos(theta_i) too small there (0.906 at 25 deg, 0.707
    at 45 deg). The measurement chain uses the full 3-D conversion
    :func:`pmdsim.measure.reconstruct.slope_deviation_3d` when it knows the geometry.
    """
    return np.asarray(coord_mm, np.float64) / (2.0 * np.asarray(distance_mm, np.float64))


@dataclass(frozen=True)
class Moments:
    """Second moments of a spot image.

    ``centroid`` (col, row) in camera px; ``sigma_major``/``sigma_minor`` the standard
    deviations along the principal axes (camera px); ``elongation`` = major/minor;
    ``angle`` of the major axis from the +col axis towards +row (rad, in (-pi/2, pi/2]);
    ``total`` the summed intensity.
    """

    centroid: tuple[float, float]
    sigma_major: float
    sigma_minor: float
    elongation: float
    angle: float
    total: float


def image_moments(image: np.ndarray, threshold: float = 0.0) -> Moments:
    """Second moments of a (H, W) spot image; NaN pixels and values <= threshold ignored.

    ``threshold`` (absolute) suppresses background before the moments are taken.
    """
    img = np.asarray(image, np.float64)
    w = np.where(np.isfinite(img) & (img > threshold), img - threshold, 0.0)
    total = w.sum()
    if total <= 0:
        nan = float("nan")
        return Moments((nan, nan), nan, nan, nan, nan, 0.0)
    rows, cols = np.indices(img.shape)
    cc = (w * cols).sum() / total
    rc = (w * rows).sum() / total
    scc = (w * (cols - cc) ** 2).sum() / total
    srr = (w * (rows - rc) ** 2).sum() / total
    src = (w * (cols - cc) * (rows - rc)).sum() / total
    evals, evecs = np.linalg.eigh(np.array([[scc, src], [src, srr]]))
    minor, major = np.sqrt(np.maximum(evals, 0.0))
    vx, vy = evecs[:, 1]
    angle = float(np.arctan2(vy, vx))
    if angle <= -np.pi / 2:
        angle += np.pi
    elif angle > np.pi / 2:
        angle -= np.pi
    elong = float(major / minor) if minor > 0 else float("inf")
    return Moments((float(cc), float(rc)), float(major), float(minor), elong, angle, float(total))


#: The quantities :func:`moments_error` states, named as :class:`Moments`' fields.
MOMENT_ERRORS = ("centroid_col", "centroid_row", "sigma_major", "sigma_minor", "elongation",
                 "angle")


def moments_error(image: np.ndarray, error: np.ndarray, threshold: float = 0.0,
                  threshold_error: float = 0.0) -> dict:
    """Numerical error of :func:`image_moments` (same ``threshold``) from the image values'
    error ``error`` (H, W; e.g. the rqmc replicates' 95 % half-widths): a first-order bound,
    ``sum_i |d m / d I_i| e_i`` for each moment ``m`` (the pixels' errors added in magnitude,
    so correlated errors are covered too). Derivatives: the centroid ``(x_i - c) / T``, the
    second moments ``((x_i - c_x)(y_i - c_y) - s) / T`` (``T`` the summed weight), carried
    through the principal axes of the 2 x 2 moment matrix (eigenvalue derivatives
    ``v^T dS v``, the angle's ``v_major^T dS v_minor / (l_major - l_minor)``). Returns
    {name in :data:`MOMENT_ERRORS`: error} (angle in rad); NaN where the moments are, inf
    where a pixel that enters them has no stated error. ``threshold_error``: the error of
    ``threshold`` (a share of the peak value inherits the peak's), which shifts every
    weight at once: ``|sum_i d m / d I_i| e_t`` is added."""
    img = np.asarray(image, np.float64)
    err = np.where(np.isfinite(error), np.abs(np.asarray(error, np.float64)), np.inf)
    above = np.isfinite(img) & (img > threshold)
    w = np.where(above, img - threshold, 0.0)
    total = w.sum()
    nan = {k: float("nan") for k in MOMENT_ERRORS}
    if total <= 0:
        return nan
    rows, cols = np.indices(img.shape)
    x, y, e = cols[above].astype(np.float64), rows[above].astype(np.float64), err[above]
    wa = w[above]
    cx, cy = (wa * x).sum() / total, (wa * y).sum() / total
    dx, dy = x - cx, y - cy
    sxx, syy, sxy = (wa * dx * dx).sum() / total, (wa * dy * dy).sum() / total, (wa * dx * dy).sum() / total
    # per pixel, d(moment) / d(I_i): rows of (n_pixels, 5) for cx, cy, sxx, syy, sxy
    d_sxx, d_syy, d_sxy = (dx * dx - sxx) / total, (dy * dy - syy) / total, (dx * dy - sxy) / total
    evals, evecs = np.linalg.eigh(np.array([[sxx, sxy], [sxy, syy]]))
    lmin, lmaj = np.maximum(evals, 0.0)
    vmin, vmaj = evecs[:, 0], evecs[:, 1]

    def quad(a, b):  # a^T dS b for every pixel's dS
        return a[0] * b[0] * d_sxx + a[1] * b[1] * d_syy + (a[0] * b[1] + a[1] * b[0]) * d_sxy

    d_lmaj, d_lmin = quad(vmaj, vmaj), quad(vmin, vmin)
    smaj, smin = np.sqrt(lmaj), np.sqrt(lmin)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_smaj = d_lmaj / (2 * smaj)
        d_smin = d_lmin / (2 * smin)
        d_elong = (d_smaj * smin - smaj * d_smin) / (smin * smin)
        d_angle = quad(vmaj, vmin) / (lmaj - lmin)
    out = {"centroid_col": dx / total, "centroid_row": dy / total, "sigma_major": d_smaj,
           "sigma_minor": d_smin, "elongation": d_elong, "angle": d_angle}
    if not np.all(np.isfinite(e)):
        return {k: float("inf") for k in MOMENT_ERRORS}
    return {k: float(np.sum(np.abs(v) * e) + abs(np.sum(v)) * threshold_error)
            for k, v in out.items()}
