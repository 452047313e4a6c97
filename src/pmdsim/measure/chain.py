"""The measurement chain of a simulation: fringe images -> decode -> deviation -> statistics.

A real PMD system only sees camera images. :func:`run_chain` treats simulated ones the same
way: the fringe images of the surface under test and those of its ideal specular reference
(the same scene with the mirror BRDF, :meth:`pmdsim.scene.Scene.specular`) are decoded per
direction with :func:`pmdsim.decode.decode_sequence` (phase shifting + temporal unwrapping,
with reliability flags), compared with :func:`pmdsim.measure.deviation.compare_direction`, and the
monitor-coordinate deviation is turned into a slope deviation with the full 3-D geometry,
:func:`pmdsim.measure.reconstruct.slope_deviation_3d` (the tilt of the bisector normal at
the surface point that moves the exact specular monitor point by the deviation), or, without
the surface points, the small-angle :func:`pmdsim.measure.deviation.slope_deviation`
(coord / 2 d: right in the plane of incidence, cos(theta_i) short across it). :func:`dot_table` measures the second moments of dot images.

Everything here computes; nothing is written (see :mod:`pmdsim.store`) or drawn (see
:mod:`pmdsim.report.chain_maps`).

What a deviation means
----------------------
``coord_deviation_px = decoded(surface) - decoded(reference)``, both decoded from camera
images on the same monitor model. On a ``nearest`` monitor (each monitor pixel a flat
emitter) the mirror sees one pixel, so the reference decodes to the *nearest pixel centre*
of the exact specular point, ``floor(u + 0.5)``, while a wide scatter lobe averages many
pixels and decodes close to the exact point: the deviation then contains the reference's
own quantisation, up to +-0.5 monitor px. ``statistics()`` reports it separately
(``reference_vs_exact_px``) and ``coord_vs_exact_px`` (the surface's decoded coordinate
minus the exact specular point) so the two effects can be told apart.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..config import DecodeConfig, FringeConfig
from . import deviation as analysis
from . import decode as dec
from .decode_plan import unambiguous_range_px

#: Background threshold of the dot moments, as a fraction of each dot image's maximum.
DOT_THRESHOLD_FRACTION = 0.05

#: Quantities of the deviation statistics (``deviation_stats`` dataset variable), with units.
QUANTITIES = {
    "phase_mrad": "mrad",
    "coord_px": "monitor px",
    "coord_mm": "mm",
    "slope_urad": "urad",
}
#: Statistics of each quantity.
STATISTICS = ("mean", "rms", "std", "p95", "max", "n_valid", "n_masked", "valid_fraction")


# ----------------------------------------------------------------------------- can we decode?
def extent_px(monitor_resolution, direction: str) -> float:
    """Monitor extent (monitor px) along a fringe direction: width for ``x``, height for ``y``."""
    w, h = monitor_resolution
    return float(w if direction == "x" else h)


def decode_problem(fringes: FringeConfig | None, decode: DecodeConfig,
                   monitor_resolution) -> str | None:
    """Why the fringes (``patterns.fringes``) cannot be decoded with ``decode`` on a monitor
    of ``monitor_resolution`` (width, height), or None if they can.

    The message names ``patterns.fringes.widths_px`` and the fix (e.g. the width to add).
    """
    fr = fringes
    if fr is None:
        return "no fringes are configured (patterns.fringes = false): nothing to decode"
    method = decode.method
    try:
        reach = unambiguous_range_px(fr.widths_px, method)
    except ValueError as err:
        return (f"patterns.fringes.widths_px = {list(fr.widths_px)} do not fit "
                f"decode.method = {method!r}: {err}")
    need = max(extent_px(monitor_resolution, d) for d in fr.directions)
    if reach < need:
        if method == "hierarchical":
            fix = (f"add a width of at least {need:g} monitor px (e.g. widths_px = "
                   f"{sorted(set(fr.widths_px) | {float(_coarse_width(need))})})")
        else:
            fix = "choose widths with a longer unambiguous range, or decode.method = 'hierarchical'"
        return (f"patterns.fringes.widths_px = {list(fr.widths_px)} cannot be unwrapped over the "
                f"monitor: decode.method = {method!r} reaches {reach:g} monitor px, the monitor "
                f"spans {need:g}; {fix}")
    return None


def _coarse_width(extent: float) -> int:
    """A round width >= extent (for the fix in an error message)."""
    step = 10 ** max(0, int(math.log10(extent)) - 1)
    return int(math.ceil(extent / step) * step)


# ----------------------------------------------------------------------------- decoding
def decode_fringes(fringes, monitor_resolution, decode_cfg, saturation_level=None,
                   keep_amplitude: bool = True) -> dict:
    """Decode every direction of a :class:`~pmdsim.render.FringeResult`.

    Returns ``{direction: DecodeResult}``; frames are ``fringes.images[d]`` (n_widths, K,
    H, W), ``extent_px`` the monitor width (x) or height (y). ``keep_amplitude=False``:
    each result's ``amplitude`` and ``offset`` are None (the run's chain uses the
    modulation B/A and stores neither: 63 MB less per decoding at 1.3 MP).
    """
    from dataclasses import replace

    out = {}
    for di, d in enumerate(fringes.directions):
        res = dec.decode_sequence(
            fringes.images[di], fringes.widths, fringes.shifts, extent_px(monitor_resolution, d),
            decode_cfg.method, min_relative_amplitude=decode_cfg.min_relative_amplitude,
            max_order_residual=decode_cfg.max_order_residual, dtype=np.float32,
            saturation_level=saturation_level)
        out[d] = res if keep_amplitude else replace(res, amplitude=None, offset=None)
    return out


def surface_to_monitor_mm(sim, geometry) -> np.ndarray:
    """(H, W) distance (mm) from each pixel's surface point (``geometry.points``) to the
    exact monitor point of its principal reflection P; NaN where P misses the monitor."""
    from .reconstruct import planar_monitor

    planar = planar_monitor(sim.scene.monitor)
    if planar is None:
        target = sim.scene.monitor.pixel_to_world(geometry.specular_u, geometry.specular_v)
        target -= geometry.points
        return np.sqrt(np.einsum("...k,...k->...", target, target))
    from ..kernels.reconstruct import monitor_distance

    shape = np.shape(geometry.specular_u)
    out = np.empty(shape)
    # one compiled pass, the same numbers (no (H, W, 3) temporaries)
    monitor_distance(np.ascontiguousarray(geometry.points, np.float64).reshape(-1, 3),
                     *(np.ascontiguousarray(a, np.float64).reshape(-1)
                       for a in (geometry.specular_u, geometry.specular_v)),
                     *planar, out.reshape(-1))
    return out


@dataclass(frozen=True, eq=False)
class SlopeGeometry:
    """What the 3-D slope conversion needs: the surface point of every pixel (H, W, 3) mm,
    the camera centre (3,) or homogeneous viewpoint (4,) (:attr:`pmdsim.scene.Camera.
    viewpoint`: a telecentric camera's is at infinity) and the monitor (``pixel_to_world``)."""

    points_mm: np.ndarray
    camera_position: np.ndarray
    monitor: object


def slope_deviation_urad(direction, coord_px, geometry, slope_geometry, distance_mm, pitch_mm):
    """Slope deviation (urad) of one direction: 3-D when ``slope_geometry`` is given
    (exact specular point moved by the deviation along the direction's monitor axis), else
    the small-angle coord / (2 d)."""
    if slope_geometry is None:
        return analysis.slope_deviation(coord_px * pitch_mm, distance_mm) * 1e6
    from ..kernels import reconstruct as kr
    from .reconstruct import planar_monitor, slope_deviation_3d

    su, sv = geometry.specular_u, geometry.specular_v
    u1, v1 = (su + coord_px, sv) if direction == "x" else (su, sv + coord_px)
    planar = planar_monitor(slope_geometry.monitor)
    if planar is None:  # another monitor model: its own pixel_to_world, in NumPy
        with np.errstate(invalid="ignore"):
            s = slope_deviation_3d(slope_geometry.points_mm, slope_geometry.camera_position,
                                   slope_geometry.monitor, su, sv, u1, v1)
        return np.where(np.isfinite(coord_px), s * 1e6, np.nan)
    shape = np.shape(coord_px)
    flat = [np.ascontiguousarray(np.broadcast_to(a, shape), np.float64).ravel()
            for a in (su, sv, u1, v1)]
    out = np.empty(flat[0].size)
    # compiled per pixel, the same as the NumPy slope_deviation_3d above
    kr.slope_deviation_3d(np.ascontiguousarray(slope_geometry.points_mm, np.float64).reshape(-1, 3),
                          np.asarray(slope_geometry.camera_position, np.float64), *planar,
                          *flat, out)
    return out.reshape(shape) * 1e6


def slope_and_change_urad(direction, coord_px, delta_px, geometry, slope_geometry,
                          distance_mm, pitch_mm):
    """``(slope, change)`` (urad): :func:`slope_deviation_urad` at ``coord_px``, and the
    change ``|s(c0 + delta_px) - s(coord_px)|`` of a coordinate error ``delta_px``
    (``c0`` the coordinate, 0 where it is not finite; NaN there): the numerical error's
    slope, as :func:`pmdsim.measure.numerical.propagate` takes it. On a planar monitor
    with the 3-D geometry one compiled pass (the reference's normal once); the same
    numbers as the two conversions."""
    from ..kernels import reconstruct as kr
    from .reconstruct import planar_monitor

    planar = None if slope_geometry is None else planar_monitor(slope_geometry.monitor)
    if planar is None:
        slope = slope_deviation_urad(direction, coord_px, geometry, slope_geometry,
                                     distance_mm, pitch_mm)
        c0 = np.where(np.isfinite(coord_px), coord_px, 0.0)
        moved = slope_deviation_urad(direction, c0 + delta_px, geometry, slope_geometry,
                                     distance_mm, pitch_mm)
        return slope, np.abs(moved - slope)
    shape = np.shape(coord_px)
    flat = [np.ascontiguousarray(np.broadcast_to(a, shape), np.float64).ravel()
            for a in (geometry.specular_u, geometry.specular_v, coord_px, delta_px)]
    out, change = np.empty(flat[0].size), np.empty(flat[0].size)
    kr.slope_deviation_pair_3d(
        np.ascontiguousarray(slope_geometry.points_mm, np.float64).reshape(-1, 3),
        np.asarray(slope_geometry.camera_position, np.float64), *planar, *flat,
        direction == "x", 1e6, out, change)
    return out.reshape(shape), change.reshape(shape)


@dataclass(frozen=True, eq=False)
class DirectionChain:
    """Decoded surface and reference of one direction, and their deviation."""

    direction: str
    decoded: dec.DecodeResult
    reference: dec.DecodeResult
    deviation: analysis.DirectionDeviation
    slope_urad: np.ndarray
    stats_slope_urad: analysis.DeviationStats
    exact_px: np.ndarray  # exact monitor coordinate of P (specular_u or specular_v)
    #: numerical error maps {quantity: (H, W)} (:mod:`pmdsim.measure.numerical`); None when
    #: the render stated none
    numerical: dict | None = None
    #: (H, W) monitor px: the estimated signed numerical error of the decoded coordinate
    #: (the render's error pattern, :attr:`pmdsim.render.FringeResult.signed_phase_error`,
    #: carried as the deviation is: ``delta phi w / (2 pi)``; 0 where not valid); not a
    #: bound. None when the render gave none
    signed_coord_px: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ChainResult:
    """The measurement chain of one surface against its specular reference.

    ``directions`` maps a direction to its :class:`DirectionChain`; ``distance_mm`` is the
    (H, W) surface-to-monitor distance used for the slopes.
    """

    directions: dict
    distance_mm: np.ndarray
    widths_px: tuple
    shifts: int
    method: str
    pitch_mm: float
    min_modulation_ratio: float
    surface_mask: np.ndarray
    notes: tuple = field(default=())
    #: (H, W) bool: surface pixels whose bundle puts more than the set share of its weight
    #: off the monitor (``pmdsim.studies.coverage.off_monitor_mask``): never valid, counted
    off_monitor: np.ndarray | None = None


def compare(decoded: dict, reference: dict, geometry, distance_mm: np.ndarray, pitch_mm: float,
            decode_cfg, shifts: int, slope_geometry: SlopeGeometry | None = None,
            off_monitor: np.ndarray | None = None, phase_error: dict | None = None,
            signed_phase_error: dict | None = None) -> ChainResult:
    """Deviation of every decoded direction from the decoded reference.

    Parameters
    ----------
    decoded, reference : dict of direction -> DecodeResult
    geometry : Geometry
        The vision rays (masks and exact specular monitor coordinates).
    distance_mm : (H, W) ndarray
        Surface-to-monitor distance for the slope deviation.
    pitch_mm : float
        Monitor pixel pitch.
    slope_geometry : SlopeGeometry, optional
        Surface points, camera centre and monitor for the 3-D slope conversion (default:
        the small-angle coord / (2 d), wrong by cos(theta_i) across the plane of incidence).
    off_monitor : (H, W) bool ndarray, optional
        Pixels whose bundle hangs off the monitor: excluded from the valid pixels and
        counted (``pixels.lobe_off_monitor`` of the statistics).
    phase_error : dict of direction -> (H, W) rad, optional
        The render's numerical phase error of the finest width
        (:func:`pmdsim.measure.numerical.finest_phase_error`): propagated to every quantity
        (``DirectionChain.numerical``, ``numerical_error`` of the statistics).
    signed_phase_error : dict of direction -> (H, W) rad, optional
        The render's estimate of that error's signed pattern
        (:attr:`pmdsim.render.FringeResult.signed_phase_error`):
        ``DirectionChain.signed_coord_px``.
    """
    from . import numerical
    per = {}
    keep = None if off_monitor is None else ~np.asarray(off_monitor, bool)
    for d, res in decoded.items():
        ref = reference[d]
        with warnings.catch_warnings():  # pixels off the surface: all-NaN modulation ratios
            warnings.simplefilter("ignore", RuntimeWarning)
            dev = analysis.compare_direction(
                d, res.absolute_phase, res.monitor_coord_px, res.modulation,
                res.valid if keep is None else res.valid & keep,
                ref.absolute_phase, ref.monitor_coord_px, ref.modulation, ref.valid, pitch_mm,
                decode_cfg.min_modulation_ratio)
        considered = np.asarray(ref.valid, bool)
        num = None
        if phase_error is not None and phase_error.get(d) is not None:
            # the slope and its numerical error's change in one pass (numerical.propagate
            # with the chain's own slope conversion)
            num = numerical.propagate(phase_error[d], float(min(res.widths_px)), pitch_mm)
            slope, num["slope_urad"] = slope_and_change_urad(
                d, dev.coord_px, num["coord_px"], geometry, slope_geometry, distance_mm,
                pitch_mm)
            num = {k: np.where(dev.valid, v, np.nan) for k, v in num.items()}
        else:
            slope = slope_deviation_urad(d, dev.coord_px, geometry, slope_geometry,
                                         distance_mm, pitch_mm)
        signed = None
        if signed_phase_error is not None and signed_phase_error.get(d) is not None:
            signed = np.where(dev.valid, np.asarray(signed_phase_error[d], np.float64)
                              * float(min(res.widths_px)) / (2 * math.pi), 0.0)
        per[d] = DirectionChain(
            d, res, ref, dev, slope, analysis.deviation_stats(slope, dev.valid, considered),
            geometry.specular_u if d == "x" else geometry.specular_v, num, signed)
    first = next(iter(decoded.values()))
    return ChainResult(per, distance_mm, first.widths_px, int(shifts), first.method, pitch_mm,
                       decode_cfg.min_modulation_ratio, geometry.surface_mask,
                       off_monitor=None if off_monitor is None else np.asarray(off_monitor, bool))


# ----------------------------------------------------------------------------- statistics
def _stats_dict(s: analysis.DeviationStats, scale: float = 1.0) -> dict:
    out = {}
    for k in STATISTICS:
        v = getattr(s, k)
        if k in ("mean", "rms", "std", "p95", "max"):
            v = v * scale
        out[k] = v if isinstance(v, int) else (None if not math.isfinite(v) else float(v))
    return out


def direction_quantity_stats(dc: DirectionChain) -> dict:
    """``{quantity: DeviationStats-as-dict}`` in the units of :data:`QUANTITIES`."""
    dv = dc.deviation
    return {
        "phase_mrad": _stats_dict(dv.stats_phase, 1e3),
        "coord_px": _stats_dict(dv.stats_coord_px),
        "coord_mm": _stats_dict(dv.stats_coord_mm),
        "slope_urad": _stats_dict(dc.stats_slope_urad),
    }


def _flag_counts(flags: np.ndarray, where: np.ndarray) -> dict:
    f = flags[where]
    return {b.name: int(np.count_nonzero(f & int(b))) for b in dec.DecodeFlag}


def statistics(chain: ChainResult, name: str) -> dict:
    """JSON-ready statistics of a chain: per direction the deviation statistics of each
    quantity, the pixel counts (what was masked and why), modulation medians and the
    reference's own quantisation against the exact specular point."""
    out = {
        "name": name,
        "method": chain.method,
        "widths_px": list(chain.widths_px),
        "finest_width_px": float(min(chain.widths_px)),
        "shifts": chain.shifts,
        "monitor_pixel_pitch_mm": chain.pitch_mm,
        "min_modulation_ratio": chain.min_modulation_ratio,
        "units": dict(QUANTITIES),
        "definitions": {
            "deviation": "decoded(surface) - decoded(specular reference), finest width",
            "slope_urad": "tilt of the bisector normal (surface point -> camera, -> monitor point) that moves the exact specular monitor point by the coordinate deviation (full 3-D geometry), in urad",
            "p95, max": "of the absolute deviation",
            "valid_fraction": "valid / considered; considered = pixels whose reference decodes "
                              "without flags (n_masked = considered - valid)",
            "low_modulation": "considered pixels whose modulation B/A of some width is below "
                              "min_modulation_ratio x the reference's (masked, counted)",
            "lobe_off_monitor": "considered pixels whose bundle puts more than "
                                "diagnostics.max_off_monitor_fraction of its weight off the "
                                "monitor (masked, counted; not low_modulation)",
        },
        "directions": {},
    }
    for d, dc in chain.directions.items():
        dv = dc.deviation
        considered = np.asarray(dc.reference.valid, bool)
        off = (np.zeros_like(considered) if chain.off_monitor is None
               else considered & chain.off_monitor & ~dv.low_modulation)
        flagged = considered & ~dc.decoded.valid & ~dv.low_modulation & ~off
        exact = dc.exact_px
        ref_q = np.where(considered, dc.reference.monitor_coord_px - exact, np.nan)
        vs_exact = np.where(dv.valid, dc.decoded.monitor_coord_px - exact, np.nan)
        ratio = dv.modulation_ratio
        out["directions"][d] = dict(
            direction_quantity_stats(dc),
            pixels={
                "surface": int(np.count_nonzero(chain.surface_mask)),
                "considered": int(np.count_nonzero(considered)),
                "valid": int(np.count_nonzero(dv.valid)),
                "low_modulation": int(np.count_nonzero(dv.low_modulation)),
                "decode_flagged": int(np.count_nonzero(flagged)),
                "lobe_off_monitor": int(np.count_nonzero(off)),
                "decode_flags_of_considered": _flag_counts(dc.decoded.flags, considered),
                "reference_flagged_on_surface": int(np.count_nonzero(
                    chain.surface_mask & ~considered)),
            },
            modulation={
                "median_by_width": [analysis.finite_median(m, dc.decoded.valid)
                                    for m in dc.decoded.modulation],
                "reference_median_by_width": [analysis.finite_median(m, considered)
                                              for m in dc.reference.modulation],
                "ratio_median_by_width": [analysis.finite_median(r, considered) for r in ratio],
            },
            reference_vs_exact_px=_stats_dict(analysis.deviation_stats(ref_q, considered)),
            coord_vs_exact_px=_stats_dict(analysis.deviation_stats(vs_exact, dv.valid,
                                                                   considered)),
        )
        if dc.numerical is not None:
            from . import numerical

            out["directions"][d]["numerical_error"] = numerical.summary(dc.numerical, dv.valid)
    if any(dc.numerical is not None for dc in chain.directions.values()):
        out["definitions"]["numerical_error"] = (
            "the rendering's own numerical (quadrature) error of the deviation, propagated "
            "from the stated error of the finest width's fringe sums: RMS, P95 and max over "
            "the valid pixels, same units as the deviation")
    return out






# ----------------------------------------------------------------------------- dataset




# ----------------------------------------------------------------------------- dots
DOT_COLUMNS = ("variant", "dot", "dot_u_px", "dot_v_px", "dot_size_px", "centroid_col",
               "centroid_row",
               "sigma_major_px", "sigma_minor_px", "elongation", "angle_deg", "peak",
               "total", "threshold", "centroid_col_err", "centroid_row_err",
               "sigma_major_px_err", "sigma_minor_px_err", "elongation_err", "angle_deg_err")


def dot_table(dot_images: np.ndarray, dots, variant: str = "",
              threshold_fraction: float = DOT_THRESHOLD_FRACTION,
              dot_errors: np.ndarray | None = None) -> list[dict]:
    """Second moments of every dot image (:func:`pmdsim.measure.deviation.image_moments`)
    and their numerical error (:func:`~pmdsim.measure.deviation.moments_error`, the
    ``*_err`` columns; NaN without ``dot_errors``, the images' numerical error).

    The background threshold is ``threshold_fraction`` x the image's maximum; centroid in
    camera px (col, row), sigmas in camera px, angle of the major axis from +col towards
    +row in degrees. One dict per dot with the keys :data:`DOT_COLUMNS`.
    """
    rows = []
    for q, (img, dot) in enumerate(zip(dot_images, dots)):
        img = np.asarray(img, np.float64)
        peak = float(np.nanmax(img)) if np.isfinite(img).any() else float("nan")
        thr = threshold_fraction * peak if np.isfinite(peak) and peak > 0 else 0.0
        m = analysis.image_moments(img, thr)
        errs = dict.fromkeys(analysis.MOMENT_ERRORS, float("nan"))
        if dot_errors is not None and np.isfinite(peak):
            e = np.asarray(dot_errors[q], np.float64)
            at_peak = e[np.unravel_index(np.nanargmax(img), img.shape)]
            errs = analysis.moments_error(img, e, thr, threshold_fraction * float(at_peak))
        rows.append({
            "variant": variant, "dot": q, "dot_u_px": float(dot.u), "dot_v_px": float(dot.v),
            "dot_size_px": float(dot.size),
            "centroid_col": m.centroid[0], "centroid_row": m.centroid[1],
            "sigma_major_px": m.sigma_major, "sigma_minor_px": m.sigma_minor,
            "elongation": m.elongation, "angle_deg": float(np.degrees(m.angle)),
            "peak": peak, "total": m.total, "threshold": thr,
            "centroid_col_err": errs["centroid_col"], "centroid_row_err": errs["centroid_row"],
            "sigma_major_px_err": errs["sigma_major"], "sigma_minor_px_err": errs["sigma_minor"],
            "elongation_err": errs["elongation"],
            "angle_deg_err": float(np.degrees(errs["angle"])),
        })
    return rows


__all__ = ["DirectionChain", "ChainResult", "decode_problem", "decode_fringes", "compare",
           "surface_to_monitor_mm", "SlopeGeometry", "slope_deviation_urad",
           "slope_and_change_urad", "statistics", "dot_table", "DOT_COLUMNS", "QUANTITIES", "STATISTICS", "DOT_THRESHOLD_FRACTION"]
