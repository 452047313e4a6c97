"""Calibration and geometry errors as budget rows: sensitivity x uncertainty.

A PMD system reconstructs with its *calibrated* camera, monitor and nominal surface
position, not the true ones. Each row here takes the ideal mirror's decoding through the
ideal system (the true scene's monitor coordinates) and reconstructs it with one
calibrated quantity off by its standard uncertainty (``[budget.calibration]``), against the
reconstruction with the true calibration: one run per component, +1 sigma, so each row is
the first-order sensitivity times the uncertainty (the errors are linear in these small
perturbations). Components of a group (the three axes of a position, the three rotation
axes of an orientation, the two coordinates of the principal point) are independent: the
group row adds their statistics in quadrature (RMS exactly for independent errors; PV and
P95 the same way, as a typical rather than worst value), and the last row adds all groups.

Perturbations: camera position along world x, y, z; camera rotation about its own x, y, z
axes; focal length fx and fy by the relative uncertainty; principal point along col and
row; OpenCV's k1; monitor position along world x, y, z; monitor rotation about its column
(e_u), row (e_v) and normal axes, about its centre; pixel pitch by the relative
uncertainty; the nominal surface (the reconstruction's prior) moved along its normal (the
height-slope ambiguity of monocular PMD).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..measure.reconstruct import prior_frame

__all__ = ["GROUPS", "perturbations", "calibration_rows", "rotation_about"]

#: (uncertainty field, row label, unit shown)
GROUPS = (
    ("camera_position_mm", "camera position", "mm"),
    ("camera_orientation_deg", "camera orientation", "deg"),
    ("focal_length_rel", "camera focal length", "relative"),
    ("principal_point_px", "camera principal point", "px"),
    ("distortion_k1", "camera distortion k1", ""),
    ("monitor_position_mm", "monitor position", "mm"),
    ("monitor_orientation_deg", "monitor orientation", "deg"),
    ("monitor_pitch_rel", "monitor pixel pitch", "relative"),
    ("surface_distance_mm", "nominal surface distance", "mm"),
)


def rotation_about(axis, angle_rad: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle_rad`` about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * k @ k


def perturbations(group: str, sigma: float, camera, monitor, prior):
    """[(component name, camera, monitor, prior frame, height shift mm)] of one group, each
    off by ``sigma`` (the unit of the group's field) in one component."""
    out = []
    cam, mon, pf = camera, monitor, prior
    if group == "camera_position_mm":
        for k, ax in enumerate("xyz"):
            out.append((ax, replace(cam, position=cam.position + sigma * np.eye(3)[k]), mon, pf, 0.0))
    elif group == "camera_orientation_deg":
        for k, ax in enumerate("xyz"):
            r = rotation_about(cam.rotation[:, k], math.radians(sigma))
            out.append((f"about camera {ax}", replace(cam, rotation=r @ cam.rotation), mon, pf, 0.0))
    elif group == "focal_length_rel":
        fy = None if cam.focal_px_y is None else cam.focal_px_y * (1 + sigma)
        out.append(("fx, fy", replace(cam, focal_px=cam.focal_px * (1 + sigma), focal_px_y=fy), mon, pf, 0.0))
    elif group == "principal_point_px":
        c0, r0 = cam.principal_point
        out.append(("col", replace(cam, principal_point=(c0 + sigma, r0)), mon, pf, 0.0))
        out.append(("row", replace(cam, principal_point=(c0, r0 + sigma)), mon, pf, 0.0))
    elif group == "distortion_k1":
        d = list(cam.distortion)
        d[0] += sigma
        out.append(("k1", replace(cam, distortion=tuple(d)), mon, pf, 0.0))
    elif group == "monitor_position_mm":
        for k, ax in enumerate("xyz"):
            out.append((ax, cam, replace(mon, centre=mon.centre + sigma * np.eye(3)[k]), pf, 0.0))
    elif group == "monitor_orientation_deg":
        for name, axis in (("about its columns (e_u)", mon.e_u), ("about its rows (e_v)", mon.e_v),
                           ("about its normal", mon.normal)):
            r = rotation_about(axis, math.radians(sigma))
            out.append((name, cam, replace(mon, e_u=r @ mon.e_u, e_v=r @ mon.e_v, normal=r @ mon.normal),
                        pf, 0.0))
    elif group == "monitor_pitch_rel":
        out.append(("pitch", cam, replace(mon, pitch=mon.pitch * (1 + sigma)), pf, 0.0))
    elif group == "surface_distance_mm":
        # the prior (its frame) sits sigma along its normal: heights in its frame are sigma
        # lower than in the true frame
        n = pf.rotation[:, 2]
        out.append(("along the normal", cam, mon, replace(pf, centre=pf.centre + sigma * n), sigma))
    else:
        raise ValueError(f"unknown calibration group {group!r}")
    return out


_QUAD = ("slope_rms_x_urad", "slope_rms_y_urad", "slope_p95_x_urad", "slope_p95_y_urad",
         "height_rms_nm", "height_pv_nm", "height_p95_nm")


def _quadrature(rows):
    """The quadrature sum of each statistic of ``rows`` and its error: the norm
    ``sqrt(sum r_k^2)`` moves by at most ``sqrt(sum e_k^2)`` when every ``r_k`` moves by up
    to ``e_k`` (Minkowski)."""
    out = {}
    for k in _QUAD:
        ok = [r for r in rows if math.isfinite(r[k])]
        out[k] = float(math.sqrt(sum(r[k] ** 2 for r in ok)))
        out[f"{k}_err"] = float(math.sqrt(sum(r.get(f"{k}_err", 0.0) ** 2 for r in ok)))
    return out


def calibration_rows(cfg, scene, decoded, rec0, spec, disc) -> list[dict]:
    """Height rows (``part = "calibration"``) of every group of ``cfg.budget.calibration``
    with a non-zero uncertainty, and their quadrature sum; ``decoded``/``rec0``: the ideal
    mirror's decoding through the ideal system and its reconstruction."""
    from .height_rows import SurfaceMaps, height_error, height_row, prior_of, reconstruct_decoded
    from .budget_areal import areal_of
    from .budget_error import height_error_bounds, solver_floors

    unc = cfg.budget.calibration
    base = SurfaceMaps.of(rec0)
    pf = prior_frame(prior_of(cfg, scene))
    out = []
    for field_name, label, unit in GROUPS:
        sigma = float(getattr(unc, field_name))
        if sigma <= 0:
            continue
        comps = []
        for name, cam, mon, prior, shift in perturbations(field_name, sigma, scene.camera, scene.monitor, pf):
            rec = reconstruct_decoded(cfg, scene, decoded, camera=cam, monitor=mon, prior=prior)
            err = height_error(SurfaceMaps.of(rec), base, spec, disc, shift_mm=shift)
            r = height_row(field_name, name, "calibration", err)
            # the mirror's render is exact: the two reconstructions' solver floors alone
            floors = solver_floors(rec, rec0)
            r.update(height_error_bounds(err, [], floors))
            r["areal"] = areal_of(err, rec.spacing, floors=floors)
            for k in ("zernike_noll_nm", "zernike_fringe_nm"):
                r.pop(k)
            comps.append(r)
        row = {"effect": field_name, "label": f"{label} ({sigma:g} {unit})".replace(" )", ")"),
               "note": ("the monocular height-slope ambiguity" if field_name == "surface_distance_mm" else ""),
               "part": "calibration", **_quadrature(comps), "n_nodes": min(c["n_nodes"] for c in comps),
               "removed": spec.describe(), "rim_excluded": comps[0]["rim_excluded"], "seconds": 0.0,
               "how": (f"sensitivity x uncertainty: reconstructed with {label} off by {sigma:g} {unit} "
                       f"(+1 sigma) minus the true calibration's reconstruction; "
                       f"{len(comps)} component(s) in quadrature"),
               "uncertainty": sigma, "components": comps, "zernike_noll_nm": [], "zernike_fringe_nm": []}
        out.append(row)
    if out:
        out.append({"effect": "calibration_total", "label": "all calibration errors (quadrature sum)",
                    "part": "calibration", **_quadrature(out),
                    "n_nodes": min(r["n_nodes"] for r in out), "removed": spec.describe(),
                    "rim_excluded": out[0]["rim_excluded"], "seconds": 0.0,
                    "how": "quadrature sum of the calibration rows (independent errors)",
                    "zernike_noll_nm": [], "zernike_fringe_nm": []})
    return out
