"""The measurement chain of a simulation: fringe images -> decode -> deviation -> statistics.

A real PMD system only sees camera images. :func:`run_chain` treats simulated ones the same
way: the fringe images of the surface under test and those of its ideal specular reference
(the same scene with the mirror BRDF, :meth:`pmdsim.scene.Scene.specular`) are decoded per
direction with :func:`pmdsim.decode.decode_sequence` (phase shifting + temporal unwrapping,
with reliability flags), compared with :func:`pmdsim.analysis.compare_direction`, and the
monitor-coordinate deviation is turned into a slope deviation with
:func:`pmdsim.analysis.slope_deviation` (the distance being that from the surface point to
the reference's monitor point). :func:`dot_table` measures the second moments of dot images.

Everything here computes; nothing is written (see :mod:`pmdsim.pipeline`) or drawn (see
:mod:`pmdsim.plot_chain`).

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

from . import analysis
from . import decode as dec

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


def decode_problem(cfg) -> str | None:
    """Why the fringes of a configuration cannot be decoded, or None if they can.

    The message names ``patterns.fringes.widths_px`` and the fix (e.g. the width to add).
    """
    fr = cfg.patterns.fringes
    if fr is None:
        return "no fringes are configured (patterns.fringes = false): nothing to decode"
    method = cfg.decode.method
    try:
        reach = dec.unambiguous_range_px(fr.widths_px, method)
    except ValueError as err:
        return (f"patterns.fringes.widths_px = {list(fr.widths_px)} do not fit "
                f"decode.method = {method!r}: {err}")
    need = max(extent_px(cfg.monitor.resolution, d) for d in fr.directions)
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
def decode_fringes(fringes, monitor_resolution, decode_cfg) -> dict:
    """Decode every direction of a :class:`~pmdsim.render.FringeResult`.

    Returns ``{direction: DecodeResult}``; frames are ``fringes.images[d]`` (n_widths, K,
    H, W), ``extent_px`` the monitor width (x) or height (y).
    """
    out = {}
    for di, d in enumerate(fringes.directions):
        out[d] = dec.decode_sequence(
            fringes.images[di], fringes.widths, fringes.shifts, extent_px(monitor_resolution, d),
            decode_cfg.method, min_relative_amplitude=decode_cfg.min_relative_amplitude,
            max_order_residual=decode_cfg.max_order_residual, dtype=np.float32)
    return out


def surface_to_monitor_mm(sim, geometry, rows_per_chunk: int = 128) -> np.ndarray:
    """(H, W) distance (mm) from each pixel's surface point to the exact monitor point of its
    principal reflection P; NaN where P misses the monitor."""
    from .trace import trace_primary

    scene = sim.scene
    h, w = sim.shape
    out = np.full((h, w), np.nan)
    for r0 in range(0, h, rows_per_chunk):
        r1 = min(h, r0 + rows_per_chunk)
        hits = trace_primary(scene, r0, r1)
        target = scene.monitor.pixel_to_world(geometry.specular_u[r0:r1], geometry.specular_v[r0:r1])
        out[r0:r1] = np.linalg.norm(target - hits.point, axis=-1)
    return out


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


def compare(decoded: dict, reference: dict, geometry, distance_mm: np.ndarray, pitch_mm: float,
            decode_cfg, shifts: int) -> ChainResult:
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
    """
    per = {}
    for d, res in decoded.items():
        ref = reference[d]
        with warnings.catch_warnings():  # pixels off the surface: all-NaN modulation ratios
            warnings.simplefilter("ignore", RuntimeWarning)
            dev = analysis.compare_direction(
                d, res.absolute_phase, res.monitor_coord_px, res.modulation, res.valid,
                ref.absolute_phase, ref.monitor_coord_px, ref.modulation, ref.valid, pitch_mm,
                decode_cfg.min_modulation_ratio)
        slope = analysis.slope_deviation(dev.coord_mm, distance_mm) * 1e6
        considered = np.asarray(ref.valid, bool)
        per[d] = DirectionChain(
            d, res, ref, dev, slope, analysis.deviation_stats(slope, dev.valid, considered),
            geometry.specular_u if d == "x" else geometry.specular_v)
    first = next(iter(decoded.values()))
    return ChainResult(per, distance_mm, first.widths_px, int(shifts), first.method, pitch_mm,
                       decode_cfg.min_modulation_ratio, geometry.surface_mask)


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


def _median(a) -> float | None:
    a = np.asarray(a, np.float64)
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else None


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
            "slope_urad": "coord_mm / (2 d), d = surface point to monitor point (mm), in urad",
            "p95, max": "of the absolute deviation",
            "valid_fraction": "valid / considered; considered = pixels whose reference decodes "
                              "without flags (n_masked = considered - valid)",
            "low_modulation": "considered pixels whose modulation B/A of some width is below "
                              "min_modulation_ratio x the reference's (masked, counted)",
        },
        "directions": {},
    }
    for d, dc in chain.directions.items():
        dv = dc.deviation
        considered = np.asarray(dc.reference.valid, bool)
        flagged = considered & ~dc.decoded.valid & ~dv.low_modulation
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
                "decode_flags_of_considered": _flag_counts(dc.decoded.flags, considered),
                "reference_flagged_on_surface": int(np.count_nonzero(
                    chain.surface_mask & ~considered)),
            },
            modulation={
                "median_by_width": [_median(m[dc.decoded.valid]) for m in dc.decoded.modulation],
                "reference_median_by_width": [_median(m[considered])
                                              for m in dc.reference.modulation],
                "ratio_median_by_width": [_median(r[considered]) for r in ratio],
            },
            reference_vs_exact_px=_stats_dict(analysis.deviation_stats(ref_q, considered)),
            coord_vs_exact_px=_stats_dict(analysis.deviation_stats(vs_exact, dv.valid,
                                                                   considered)),
        )
    return out


def _fmt(v, digits=4) -> str:
    if v is None:
        return "nan"
    if isinstance(v, int):
        return str(v)
    return f"{v:.{digits}g}"


def summary_text(stats: dict, timings: dict | None = None) -> str:
    """A short human-readable summary of :func:`statistics` (for ``summary.txt``)."""
    lines = [f"pmdsim measurement chain: {stats['name']}",
             f"decoding: {stats['method']} unwrapping, widths {stats['widths_px']} monitor px, "
             f"K = {stats['shifts']} shifts; deviation of the finest width "
             f"({stats['finest_width_px']:g} px) from the ideal specular reference",
             f"pixels masked when the modulation ratio < {stats['min_modulation_ratio']:g} "
             "(counted below, never hidden)", ""]
    head = f"{'dir':<4}{'deviation':<20}{'mean':>11}{'RMS':>11}{'P95':>11}{'max':>11}"
    lines.append(head)
    lines.append("-" * len(head))
    for d, s in stats["directions"].items():
        for q, unit in stats["units"].items():
            r = s[q]
            label = q.rsplit("_", 1)[0] + f" ({unit})"
            lines.append(f"{d.upper():<4}{label:<20}" + "".join(
                f"{_fmt(r[k]):>11}" for k in ("mean", "rms", "p95", "max")))
        p = s["pixels"]
        frac = s["phase_mrad"]["valid_fraction"]
        lines.append(f"    valid {p['valid']} of {p['considered']} considered pixels "
                     f"({100 * frac:.2f} %); masked: low modulation {p['low_modulation']}, "
                     f"decode flags {p['decode_flagged']}")
        mr = ", ".join(_fmt(x, 3) for x in s["modulation"]["ratio_median_by_width"])
        lines.append(f"    median modulation ratio by width {stats['widths_px']}: {mr}")
        rq = s["reference_vs_exact_px"]
        lines.append(f"    reference vs exact specular point: RMS {_fmt(rq['rms'])} px "
                     f"(monitor pixel quantisation of the reference)")
        lines.append("")
    if timings:
        lines.append("timings (s): " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return "\n".join(lines).rstrip() + "\n"


# ----------------------------------------------------------------------------- dataset
def dataset_variables(chain: ChainResult) -> dict:
    """xarray variables ``{name: (dims, data, attrs)}`` of a chain (to assign to a run
    dataset with ``direction``, ``width``, ``row``, ``col`` coordinates)."""
    dirs = list(chain.directions)
    dcs = [chain.directions[d] for d in dirs]
    pitch = chain.pitch_mm

    def per(fn, dtype=None):
        a = np.stack([fn(dc) for dc in dcs])
        return a.astype(dtype) if dtype is not None else a

    D, DW = ("direction", "row", "col"), ("direction", "width", "row", "col")
    v = {}
    for prefix, get in (("", lambda dc: dc.decoded), ("reference_", lambda dc: dc.reference)):
        who = "surface" if not prefix else "ideal specular reference (mirror BRDF)"
        v[prefix + "wrapped_phase"] = (DW, per(lambda dc: get(dc).wrapped_phase, np.float32), {
            "units": "rad", "description": f"wrapped phase of each width, (-pi, pi], {who}"})
        v[prefix + "absolute_phase"] = (D, per(lambda dc: get(dc).absolute_phase), {
            "units": "rad", "description": f"absolute phase of the finest width, {who}"})
        v[prefix + "modulation"] = (DW, per(lambda dc: get(dc).modulation, np.float32), {
            "units": "1", "description": f"fringe modulation B/A of each width, {who}"})
        v[prefix + "decode_flags"] = (D, per(lambda dc: get(dc).flags, np.uint8), {
            "description": f"decode reliability flags, {who}: 1 NAN_INPUT, 2 LOW_AMPLITUDE, "
                           "4 ORDER_RESIDUAL, 8 OUT_OF_RANGE; 0 = valid"})
        v[prefix + "order_residual"] = (D, per(lambda dc: get(dc).order_residual, np.float32), {
            "units": "1", "description": f"largest fringe-order residual of the unwrapping, {who}"})
        v[prefix + "monitor_coord_px"] = (D, per(lambda dc: get(dc).monitor_coord_px), {
            "units": "monitor px", "description": f"decoded monitor coordinate (u for x, v for "
                                                  f"y; 0-based, centres at integers), {who}"})
        v[prefix + "monitor_coord_mm"] = (D, per(lambda dc: get(dc).monitor_coord_px) * pitch, {
            "units": "mm", "description": f"decoded monitor coordinate from the centre of "
                                          f"monitor pixel 0 (coord_px x pitch), {who}"})
    v["phase_deviation"] = (D, per(lambda dc: dc.deviation.phase), {
        "units": "rad", "description": "absolute phase (finest width) minus the reference's; "
                                       "NaN where not valid"})
    v["coord_deviation_px"] = (D, per(lambda dc: dc.deviation.coord_px), {
        "units": "monitor px", "description": "decoded monitor coordinate minus the reference's"})
    v["coord_deviation_mm"] = (D, per(lambda dc: dc.deviation.coord_mm), {
        "units": "mm", "description": "coord_deviation_px x monitor pixel pitch"})
    v["slope_deviation_urad"] = (D, per(lambda dc: dc.slope_urad), {
        "units": "urad", "description": "slope deviation coord_deviation_mm / (2 d), d = "
                                        "surface_to_monitor_mm (small angles)"})
    v["modulation_ratio"] = (DW, per(lambda dc: dc.deviation.modulation_ratio, np.float32), {
        "units": "1", "description": "modulation / reference modulation, per width"})
    v["valid"] = (D, per(lambda dc: dc.deviation.valid), {
        "description": "True where surface and reference decode without flags and the "
                       "modulation ratio reaches min_modulation_ratio: the deviation pixels"})
    v["low_modulation"] = (D, per(lambda dc: dc.deviation.low_modulation), {
        "description": "True where the reference is valid but the modulation ratio of some "
                       "width is below min_modulation_ratio (masked and counted)"})
    v["surface_to_monitor_mm"] = (("row", "col"), chain.distance_mm, {
        "units": "mm", "description": "distance from the surface point to the monitor point of "
                                      "the principal reflection P"})
    qs = list(QUANTITIES)
    table = np.array([[[float("nan") if (x := direction_quantity_stats(dc)[q][s]) is None
                        else x for s in STATISTICS] for q in qs] for dc in dcs])
    v["deviation_stats"] = (("direction", "quantity", "statistic"), table, {
        "description": "deviation statistics over the valid pixels; units per quantity: "
                       + ", ".join(f"{q}: {u}" for q, u in QUANTITIES.items())})
    return v


def assign_to_dataset(ds, chain: ChainResult, stats: dict):
    """Return ``ds`` with the chain's variables, coordinates ``quantity``/``statistic`` and
    attrs ``decode_method``, ``statistics_json``."""
    import json

    ds = ds.assign_coords(quantity=("quantity", np.array(list(QUANTITIES), dtype=object)),
                          statistic=("statistic", np.array(STATISTICS, dtype=object)))
    for name, (dims, data, attrs) in dataset_variables(chain).items():
        ds[name] = (dims, data, attrs)
    ds.attrs["decode_method"] = chain.method
    ds.attrs["min_modulation_ratio"] = chain.min_modulation_ratio
    ds.attrs["statistics_json"] = json.dumps(stats)
    return ds


# ----------------------------------------------------------------------------- dots
DOT_COLUMNS = ("variant", "dot", "dot_u_px", "dot_v_px", "dot_size_px", "centroid_col",
               "centroid_row",
               "sigma_major_px", "sigma_minor_px", "elongation", "angle_deg", "peak",
               "total", "threshold")


def dot_table(dot_images: np.ndarray, dots, variant: str = "",
              threshold_fraction: float = DOT_THRESHOLD_FRACTION) -> list[dict]:
    """Second moments of every dot image (:func:`pmdsim.analysis.image_moments`).

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
        rows.append({
            "variant": variant, "dot": q, "dot_u_px": float(dot.u), "dot_v_px": float(dot.v),
            "dot_size_px": float(dot.size),
            "centroid_col": m.centroid[0], "centroid_row": m.centroid[1],
            "sigma_major_px": m.sigma_major, "sigma_minor_px": m.sigma_minor,
            "elongation": m.elongation, "angle_deg": float(np.degrees(m.angle)),
            "peak": peak, "total": m.total, "threshold": thr,
        })
    return rows


def dot_dataset_variables(table: list[dict]) -> dict:
    """xarray variables ``{name: (dims, data, attrs)}`` along ``dot`` from :func:`dot_table`."""
    def col(k):
        return np.array([r[k] for r in table], np.float64)

    thr = f"moments above {DOT_THRESHOLD_FRACTION:g} x the dot image's maximum"
    return {
        "dot_centroid_col": (("dot",), col("centroid_col"), {
            "units": "camera px", "description": f"dot image centroid column ({thr})"}),
        "dot_centroid_row": (("dot",), col("centroid_row"), {
            "units": "camera px", "description": f"dot image centroid row ({thr})"}),
        "dot_sigma_major": (("dot",), col("sigma_major_px"), {
            "units": "camera px", "description": f"standard deviation along the major axis ({thr})"}),
        "dot_sigma_minor": (("dot",), col("sigma_minor_px"), {
            "units": "camera px", "description": f"standard deviation along the minor axis ({thr})"}),
        "dot_elongation": (("dot",), col("elongation"), {
            "units": "1", "description": "sigma_major / sigma_minor"}),
        "dot_angle": (("dot",), col("angle_deg"), {
            "units": "deg", "description": "major axis angle from +col towards +row, (-90, 90]"}),
        "dot_peak": (("dot",), col("peak"), {"description": "maximum camera value of the dot image"}),
    }


def write_dot_csv(path, table: list[dict]) -> None:
    """Write :func:`dot_table` rows as CSV (header :data:`DOT_COLUMNS`)."""
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(DOT_COLUMNS))
        w.writeheader()
        for r in table:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k])
                        for k in DOT_COLUMNS})


__all__ = ["DirectionChain", "ChainResult", "decode_problem", "decode_fringes", "compare",
           "surface_to_monitor_mm", "statistics", "summary_text", "dataset_variables",
           "assign_to_dataset", "dot_table", "dot_dataset_variables", "write_dot_csv",
           "QUANTITIES", "STATISTICS", "DOT_THRESHOLD_FRACTION"]
