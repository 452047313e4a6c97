"""Surface reconstruction of a run member: decoded monitor coordinates (x and y fringes)
-> slopes -> height on the surface grid, against the configured (true) surface.

Computation is :mod:`pmdsim.measure.reconstruct`; this module picks the inputs from the
measurement chain, and shapes the dataset variables and the statistics."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..measure.interpolate import (
    EXCLUSION_REASONS,
    NODE_OUTSIDE_APERTURE,
    NODE_RIM_FIT,
    NODE_SPLINE,
)
from ..measure.reconstruct import reconstruct, surface_errors
from .threads import numba_takes_two_threads


def wanted(cfg, directions) -> bool:
    """Reconstruct? ``reconstruct.enabled`` or, when None, whenever x and y are decoded."""
    have = {"x", "y"} <= set(directions)
    if cfg.reconstruct.enabled is False:
        return False
    if cfg.reconstruct.enabled is True and not have:
        raise ValueError("reconstruct.enabled = true needs fringes in both directions: "
                         "set patterns.fringes.directions = ['x', 'y']")
    return have


def reconstruct_coords(cfg, scene, u, v, valid, start=None, tables=True,
                       slope_tolerance=True):
    """:class:`~pmdsim.measure.reconstruct.Reconstruction` and its
    :class:`~pmdsim.measure.reconstruct.SurfaceErrors` (None, message on failure).
    ``start``, ``slope_tolerance``: :func:`~pmdsim.measure.reconstruct.reconstruct`'s;
    ``tables=False``: the errors without their Zernike tables."""
    rc = cfg.reconstruct
    if rc.prior is None:
        prior = scene.surface
    else:
        from ..scene.surfaces import surface_from_config

        prior = surface_from_config(rc.prior)
    try:
        rec = reconstruct(u, v, scene.camera, scene.monitor, prior, valid=valid,
                          spacing_mm=rc.spacing_mm, anchor=rc.anchor, order=rc.order,
                          start=start, slope_tolerance=slope_tolerance)
    except ValueError as err:
        return None, None, str(err)
    return rec, surface_errors(rec, scene.surface, rc.remove, tables=tables), None


def from_chain(cfg, scene, measured, reference_rec=None):
    """(dataset variables, statistics) of a member's reconstruction from its chain result.

    ``reference_rec``: the (Reconstruction, SurfaceErrors) of the specular reference, whose
    height error is the chain's own floor (stored as ``reference_height_error_nm``)."""
    dx, dy = measured.directions["x"], measured.directions["y"]
    u = np.where(dx.deviation.valid, dx.decoded.monitor_coord_px, np.nan)
    v = np.where(dy.deviation.valid, dy.decoded.monitor_coord_px, np.nan)
    valid = np.isfinite(u) & np.isfinite(v)
    rec, err, problem = reconstruct_coords(cfg, scene, u, v, valid)
    if rec is None:
        return {}, {"reconstruction": {"error": problem}}
    stats = statistics(cfg, rec, err, reference_rec)
    moves = patterns = None
    ex, ey = ((dc.numerical or {}).get("coord_px") for dc in (dx, dy))
    if ex is not None and ey is not None:  # the render's numerical error, carried through
        def pattern():
            return pattern_moves(cfg, scene, rec, err, u, v, valid, dx.signed_coord_px,
                                 dy.signed_coord_px)

        # the two repetitions are independent: the pattern's in a second thread where
        # Numba's parallel kernels may run from two threads at once (NumPy, SciPy and the
        # kernels release the GIL for most of a reconstruction: the step took 0.4-0.7 s
        # less on Fig. 3); the same numbers either way
        with ThreadPoolExecutor(1, thread_name_prefix="pmdsim-pattern") as pool:
            later = pool.submit(pattern) if numba_takes_two_threads() else None
            moved = moved_errors(cfg, scene, rec, u, v, ex, ey, valid)
            if moved is not None and moved.height_nm.shape == err.height_nm.shape:
                add_numerical_error(stats, err, moved, rec)
                moves = _changes(moved, err)
                patterns = pattern() if later is None else later.result()
    avars, stats["areal"] = areal_of(rec, err, moves, reference_rec, patterns)
    return {**variables(rec, err, reference_rec), **avars}, {"reconstruction": stats}


#: The error maps that get areal parameters and PSDs: (SurfaceErrors attribute, dataset
#: name, unit); ``statistics.json`` names them ``<name>_<unit>`` as the RMS/PV/P95.
AREAL_MAPS = (("height_nm", "height_error", "nm"), ("slope_x_urad", "slope_error_x", "urad"),
              ("slope_y_urad", "slope_error_y", "urad"))
#: Coordinates of the PSD variables: 2-D spatial frequencies and the radial bins (1/mm).
PSD_COORDS = ("psd_fx", "psd_fy", "psd_f")


def areal_of(rec, err, moves=None, reference_rec=None, patterns=None) -> tuple[dict, dict]:
    """(dataset variables, statistics) of the areal parameters and PSDs of the surface
    errors (:mod:`pmdsim.measure.areal`): per map its Sq ... Sdq, band RMS and radial PSD
    with their numerical errors, its 2-D and radial PSD as variables; the reference's
    height error too (the chain's floor; exact, no error). The bands are those of the
    height error's measured region, for every map.

    The errors: Sq, Sa and Sz from ``moves``, ``{attribute: (H, W)}``, each node's signed
    change when the decoded coordinates move by their numerical error (its magnitude plus
    the solver's floor, ``Reconstruction.solver_floor``, is the node's error, any signs);
    Ssk, Sku, Sdq and the PSDs from ``patterns`` (:func:`pattern_moves`: the change for the
    error's own signed pattern, times its safety factor) where given, with the solver's
    floor for any signs, else from the nodes' errors for any signs (an error that
    alternated in sign from node to node: a bound 10^3 to 10^5 times the true change of
    Sdq and of the high band on Fig. 3)."""
    from ..measure import areal

    dx, dy = rec.spacing
    stats: dict = {"definitions": dict(areal.DEFINITIONS)}
    out: dict = {}
    valid = np.isfinite(err.height_nm)
    if not valid.any():
        return out, stats
    bands = areal.default_bands(valid, dx, dy)
    # each node's error: the magnitude of its change plus the solver's floor
    maps = [(getattr(err, a), name, unit,
             None if moves is None else np.abs(moves[a]) + rec.solver_floor(a),
             None if patterns is None else (patterns[a], rec.solver_floor(a)))
            for a, name, unit in AREAL_MAPS]
    if reference_rec is not None and reference_rec[1].height_nm.shape == err.height_nm.shape:
        maps.append((reference_rec[1].height_nm, "reference_height_error", "nm", None, None))
    for z, name, unit, dz, pattern in maps:
        # the envelope's moves are no signed pattern (blocks of 8 x 8 pixels, every
        # coordinate moved the same way: their spectrum missed the true change's by up to
        # 6 x): the pattern's change where there is one, else any signs
        kw = {} if pattern is None else {
            "error_maps": [pattern[0], -pattern[0]],
            "floor": np.where(np.isfinite(z), pattern[1], 0.0)}
        st, p = areal.describe(z, dx, dy, unit, error=dz, bands=bands, **kw)
        stats[f"{name}_{unit}"] = st
        if p is None:
            continue
        if not out:
            out["psd_fx"] = (("psd_fx",), p.fx, {"units": "1/mm", "description":
                             "spatial frequency along the surface's local x (cycles per mm)"})
            out["psd_fy"] = (("psd_fy",), p.fy, {"units": "1/mm", "description":
                             "spatial frequency along the surface's local y (cycles per mm)"})
            out["psd_f"] = (("psd_f",), p.frequency, {"units": "1/mm", "description":
                            "radial spatial frequency: centre of each bin (width: psd_f[0])"})
        what = f"{name.replace('_', ' ')} map"
        out[f"{name}_psd"] = (("psd_f",), p.psd_radial, {
            "units": f"{unit}^2 mm", "description": f"1-D radial PSD of the {what}: power of "
            "each annulus of spatial frequency / bin width (pmdsim.measure.areal)"})
        if name == "reference_height_error":
            continue
        out[f"{name}_psd_2d"] = (("psd_fy", "psd_fx"), p.psd_2d, {
            "units": f"{unit}^2 mm^2", "description": f"2-D PSD of the {what}, tapered window "
            "(pmdsim.measure.areal), centred on psd_fx, psd_fy"})
        if p.psd_2d_err is not None:
            out[f"{name}_psd_err"] = (("psd_f",), p.psd_radial_err, {
                "units": f"{unit}^2 mm", "description": f"numerical error of {name}_psd"})
            out[f"{name}_psd_2d_err"] = (("psd_fy", "psd_fx"), p.psd_2d_err, {
                "units": f"{unit}^2 mm^2", "description": f"numerical error of {name}_psd_2d"})
    return out, stats


def moved_errors(cfg, scene, rec, u, v, ex, ey, valid):
    """The :class:`~pmdsim.measure.reconstruct.SurfaceErrors` of the reconstruction ``rec``
    of (``u``, ``v``) with every coordinate moved by its numerical error (``ex``, ``ey``):
    the reconstruction repeated with the moved coordinates from the reconstructed height
    (their fixed point is next to it). A linear carry through the reconstruction's
    linearisation was measured 40 % cheaper but disagreed with this repetition at the rim
    fit's nodes by more than the change itself (docs/performance.md)."""
    _, err, _ = reconstruct_coords(cfg, scene, u + np.nan_to_num(ex), v + np.nan_to_num(ey),
                                   valid, start=rec.height_mm, tables=False,
                                   slope_tolerance=False)  # its solver floor: rec's
    return err


def pattern_moves(cfg, scene, rec, err, u, v, valid, sx, sy) -> dict | None:
    """``{attribute: (H, W)}``: :data:`~pmdsim.render.pilot.PATTERN_SAFETY` times each
    node's signed change of the surface errors ``err`` (of the reconstruction ``rec`` of
    ``u``, ``v``) when the decoded coordinates move by the render's estimated signed error
    ``sx``, ``sy`` (monitor px, :attr:`pmdsim.measure.chain.DirectionChain.signed_coord_px`):
    the error's pattern carried through the reconstruction (repeated, as
    :func:`moved_errors`). None without both patterns, or where the repetition fails."""
    from ..render.pilot import PATTERN_SAFETY

    if sx is None or sy is None:
        return None
    moved = moved_errors(cfg, scene, rec, u, v, sx, sy, valid)
    if moved is None or moved.height_nm.shape != err.height_nm.shape:
        return None
    return _changes(moved, err, PATTERN_SAFETY)


def _changes(moved, err, scale: float = 1.0) -> dict:
    """``{attribute: (H, W)}``: ``scale`` times each node's signed change from the surface
    errors ``err`` to ``moved`` for every map of :data:`AREAL_MAPS` (0 where either is
    undefined)."""
    return {a: scale * np.nan_to_num(getattr(moved, a) - getattr(err, a), nan=0.0)
            for a, _, _ in AREAL_MAPS}


#: The statistics of each surface error that get a numerical error, with what they are of:
#: deviations about the mean (RMS, P95 of |d|), about zero (slopes' RMS) and the PV.
_ERROR_STATS = {"height_error_nm": "height_nm", "slope_error_x_urad": "slope_x_urad",
                "slope_error_y_urad": "slope_y_urad"}


def add_numerical_error(stats: dict, err, moved, rec) -> None:
    """Add ``<stat>_err`` to the RMS / PV / P95 of each surface error in ``stats``: the
    reconstruction with every decoded coordinate moved by its numerical error (x and y
    together; the reconstruction is linear in small coordinate changes: :func:`moved_errors`), each
    node's change is its error, carried to the statistics as the budget's height rows are
    (:func:`pmdsim.studies.budget_error.stat_error`: exact intervals for RMS and P95; the
    PV by the widest range the nodes' errors allow), plus the solver's floor
    (:meth:`~pmdsim.measure.reconstruct.Reconstruction.solver_floor`)."""
    from ..studies.budget_error import stat_error

    for key, attr in _ERROR_STATS.items():
        st = stats.get(key)
        a = np.asarray(getattr(err, attr), np.float64)
        e = np.abs(np.asarray(getattr(moved, attr), np.float64) - a) + rec.solver_floor(attr)
        m = np.isfinite(a)
        if not st or not m.any():
            continue
        ok = m & np.isfinite(e)
        e = np.where(ok, e, 0.0)
        d = np.where(m, a - np.mean(a[m]), np.nan)
        st["rms_err"] = stat_error(d, e, m, "rms")
        st["p95_err"] = stat_error(d, e, m, "p95")
        st["pv_err"] = float(np.max(a[m] + e[m]) - np.min(a[m] - e[m]) - np.ptp(a[m]))
        if "rms_about_zero" in st:
            st["rms_about_zero_err"] = stat_error(a, e, m, "rms")
        st["unknown_share"] = float(np.count_nonzero(m & ~ok) / np.count_nonzero(m))


def reference_reconstruction(cfg, scene, decoded):
    """(Reconstruction, SurfaceErrors) of the decoded specular reference, or None. Its
    errors come without Zernike tables: a run reports the reference's height error map and
    statistics (the chain's floor), not its Zernike content."""
    if not wanted(cfg, decoded):
        return None
    u = np.where(decoded["x"].valid, decoded["x"].monitor_coord_px, np.nan)
    v = np.where(decoded["y"].valid, decoded["y"].monitor_coord_px, np.nan)
    rec, err, _ = reconstruct_coords(cfg, scene, u, v, np.isfinite(u) & np.isfinite(v),
                                     tables=False)
    return None if rec is None else (rec, err)


def variables(rec, err, reference_rec=None) -> dict:
    """xarray variables ``{name: (dims, data, attrs)}`` on (surface_y, surface_x)."""
    dims = ("surface_y", "surface_x")
    out = {
        "surface_x_mm": (("surface_x",), rec.x_mm, {"units": "mm", "description": "local x of the surface grid (the surface's vertex frame)"}),
        "surface_y_mm": (("surface_y",), rec.y_mm, {"units": "mm", "description": "local y of the surface grid"}),
        "reconstructed_height_mm": (dims, rec.height_mm, {
            "units": "mm", "description": "monocular reconstruction: sag along the local z axis"}),
        "height_error_nm": (dims, err.height_nm, {
            "units": "nm", "description": f"reconstructed minus true height, {err.removed} removed"}),
        "slope_error_x_urad": (dims, err.slope_x_urad, {
            "units": "urad", "description": "reconstructed minus true dz/dx (local frame)"}),
        "slope_error_y_urad": (dims, err.slope_y_urad, {
            "units": "urad", "description": "reconstructed minus true dz/dy (local frame)"}),
    }
    if rec.node_status is not None:
        codes = {NODE_OUTSIDE_APERTURE: "outside_aperture", NODE_SPLINE: "reported_spline",
                 NODE_RIM_FIT: "reported_rim_fit",
                 **{c: f"excluded_{name}" for c, (name, _) in EXCLUSION_REASONS.items()}}
        out["reconstruction_node_status"] = (dims, rec.node_status, {
            "description": "how each grid node of the reconstruction is served, or why it is "
                           "not reported (docs/reconstruction.md)",
            "flag_values": list(codes), "flag_meanings": " ".join(codes.values())})
    if reference_rec is not None and reference_rec[0].height_mm.shape == rec.height_mm.shape:
        out["reference_height_error_nm"] = (dims, reference_rec[1].height_nm, {
            "units": "nm", "description": "the specular reference's reconstruction minus the true "
                                          f"height, {err.removed} removed (the chain's own floor)"})
    return out


def excluded_nodes(rec) -> dict:
    """The aperture's nodes that are not reported, by reason, and those the rim fit serves
    (statistics.json's ``excluded_nodes`` and ``rim_fit_nodes``)."""
    ex = rec.excluded
    aperture = int(np.isfinite(rec.nominal_mm).sum())
    total = sum(ex.values())
    return {"excluded_nodes": {"total": total, "fraction_of_aperture": total / max(aperture, 1),
                               "aperture_nodes": aperture, **ex},
            "rim_fit_nodes": rec.rim_fitted,
            "excluded_definitions": {name: text for name, text in EXCLUSION_REASONS.values()}}


def statistics(cfg, rec, err, reference_rec=None) -> dict:
    out = {
        "removed": err.removed,
        "spacing_mm": cfg.reconstruct.spacing_mm,
        "order": cfg.reconstruct.order,
        "anchor": cfg.reconstruct.anchor,
        "iterations": rec.iterations,
        "converged": rec.converged,
        # the iteration's stop, in every stated height and slope error (rec.solver_floor)
        "solver_tolerance_nm": rec.tolerance_mm * 1e6,
        "solver_slope_tolerance_urad": rec.slope_tolerance * 1e6,
        "grid_points": int(rec.mask.sum()),
        "aperture_fraction": float(rec.mask.sum() / max(np.isfinite(rec.nominal_mm).sum(), 1)),
        **excluded_nodes(rec),
        **err.stats,
    }
    if reference_rec is not None:
        out["reference_height_error_nm"] = reference_rec[1].stats["height_error_nm"]
    return out
