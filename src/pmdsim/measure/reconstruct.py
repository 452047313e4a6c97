"""Monocular PMD reconstruction: decoded monitor coordinates -> slopes -> height.

What a real single-camera deflectometer does, from the decoded monitor coordinates (u, v)
of every camera pixel, the calibrated camera and monitor poses and a nominal shape (the
configured surface or a user prior):

1. a regular grid (x, y) in the nominal surface's local frame (its vertex frame, mm);
2. at each grid node the current surface point S = (x, y, z(x, y)) (z starts as the
   nominal sag), projected into the camera: the vision ray C -> S and the camera pixel
   that sees S;
3. the decoded monitor point M at that (fractional) pixel, by cubic-spline interpolation of
   the decoded (u, v) maps in camera pixel space;
4. the normal as the bisector of the unit directions S -> C and S -> M, and the slopes
   dz/dx = -n_x / n_z, dz/dy = -n_y / n_z in the local frame (full 3-D geometry: no
   per-direction scalar);
5. the slopes integrated to z (:func:`pmdsim.measure.integrate.southwell`), anchored to
   the nominal shape at one point (the height-normal ambiguity: slopes fix the shape, the
   anchor fixes the distance; a real system registers the part mechanically);
6. repeat from 2 until z stops changing (each height error changes the normals by about
   height / distance, so the loop contracts).

Plain arrays in, plain arrays out; the camera needs ``position`` and ``project(points)``,
the monitor ``pixel_to_world(u, v)``, the prior ``centre``, ``x_axis``, ``y_axis``,
``normal`` and optionally ``sag(x, y)``, ``in_aperture(x, y)`` and ``bounds()`` (a flat
rectangle with ``size`` works as well).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..kernels.reconstruct import bisector_slopes, bisector_slopes_planar
from .integrate import _integrate
from .interpolate import (
    EXCLUSION_REASONS,
    NODE_OUTSIDE_APERTURE,
    NODE_RIM_FIT,
    maps_at,
    spline_maps,
)

__all__ = [
    "PriorFrame",
    "Reconstruction",
    "SurfaceErrors",
    "bisector_normals",
    "prior_frame",
    "reconstruct",
    "slope_deviation_3d",
    "slopes_in_frame",
    "surface_errors",
]


@dataclass(frozen=True)
class PriorFrame:
    """The nominal shape as reconstruction needs it: local frame (rotation columns = local
    x, y, z), sag, aperture test and local bounds (x_min, x_max, y_min, y_max)."""

    centre: np.ndarray
    rotation: np.ndarray
    sag: object
    in_aperture: object
    bounds: tuple
    aperture_centre: tuple

    def to_world(self, x, y, z):
        return self.centre + np.einsum("...j,kj->...k", np.stack([x, y, z], axis=-1), self.rotation)

    def to_local(self, points):
        return np.einsum("...j,jk->...k", np.asarray(points, np.float64) - self.centre, self.rotation)


def prior_frame(surface) -> PriorFrame:
    """A :class:`PriorFrame` from a scene surface (SagSurface, FlatRectangle or alike)."""
    rot = np.stack([surface.x_axis, surface.y_axis, surface.normal], axis=1).astype(np.float64)
    if hasattr(surface, "sag"):
        def sag(x, y):
            return surface.sag(x, y)[0]
        in_ap = surface.in_aperture
        bounds = tuple(surface.bounds())
        ap = surface.aperture
        ap_centre = (ap[1], ap[2])
    else:  # flat rectangle
        hx, hy = surface.size[0] / 2, surface.size[1] / 2

        def sag(x, y):
            return np.zeros(np.broadcast(x, y).shape)

        def in_ap(x, y):
            return (np.abs(x) <= hx) & (np.abs(y) <= hy)
        bounds = (-hx, hx, -hy, hy)
        ap_centre = (0.0, 0.0)
    return PriorFrame(np.asarray(surface.centre, np.float64), rot, sag, in_ap, bounds, ap_centre)


def bisector_normals(points, camera_position, monitor_points):
    """Unit normals (..., 3): bisector of the directions from ``points`` to the camera and
    to the monitor points (the law of reflection). ``camera_position``: the camera centre
    (3,) or a homogeneous (4,) viewpoint ``(c, w)`` (w = 0: a telecentric camera, the
    direction ``c`` to it at every point; :attr:`pmdsim.scene.Camera.viewpoint`)."""
    cp = np.asarray(camera_position, np.float64)
    a = cp[:3] - cp[3] * points if cp.shape[-1] == 4 else cp - points
    b = np.asarray(monitor_points, np.float64) - points
    n = a / np.linalg.norm(a, axis=-1, keepdims=True) + b / np.linalg.norm(b, axis=-1, keepdims=True)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def slopes_in_frame(normals, rotation):
    """(dz/dx, dz/dy) of the surface with world ``normals`` in the local frame whose axes are
    the columns of ``rotation`` (x, y, z)."""
    nl = np.einsum("...j,jk->...k", np.asarray(normals, np.float64), rotation)
    return -nl[..., 0] / nl[..., 2], -nl[..., 1] / nl[..., 2]


@dataclass(frozen=True)
class Reconstruction:
    """Result of :func:`reconstruct`, on the grid ``x_mm`` (W,) x ``y_mm`` (H,) of the
    prior's local frame. ``height_mm`` and slopes NaN outside ``mask``; ``nominal_mm`` the
    prior's sag on the grid; ``history`` max |change of z| (mm) per iteration;
    ``node_status`` (H, W) int8: how each node was served or why it is not reported
    (:mod:`pmdsim.measure.interpolate`: ``NODE_SPLINE``, ``NODE_RIM_FIT``, the keys of
    ``EXCLUSION_REASONS``; ``NODE_OUTSIDE_APERTURE`` off the nominal aperture);
    ``tolerance_mm`` how far the height may be from the iteration's fixed point
    (:func:`_remaining`) and ``slope_tolerance`` (rad)
    the largest change of a node's slopes that moving it by ``tolerance_mm`` along the
    local z gives (the solver's floor of the stated errors)."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    mask: np.ndarray
    height_mm: np.ndarray
    slope_x: np.ndarray
    slope_y: np.ndarray
    nominal_mm: np.ndarray
    iterations: int
    history: tuple
    converged: bool
    node_status: np.ndarray | None = None
    tolerance_mm: float = 0.0
    slope_tolerance: float = 0.0

    @property
    def spacing(self):
        return (float(self.x_mm[1] - self.x_mm[0]), float(self.y_mm[1] - self.y_mm[0]))

    def solver_floor(self, quantity: str) -> float:
        """The solver's part of a node's error in ``quantity`` (``"height_nm"``,
        ``"slope_x_urad"`` or ``"slope_y_urad"``, the maps of a surface error): how far the
        height-normal iteration stopped from its fixed point (:attr:`tolerance_mm`), twice
        it for the height after removal (the node's own, and the removed piston's change,
        the mean of changes at most that large; the low-order forms removed otherwise are
        fitted to the same smooth field), the slopes' change for it (:attr:`slope_tolerance`)
        in urad. Two reconstructions that are compared node by node (a run's repetition
        with moved coordinates, a budget row's surface and mirror) each stop within their
        own, which their difference does not show: it is added to every stated error."""
        if quantity == "height_nm":
            return 2.0 * self.tolerance_mm * 1e6
        if quantity in ("slope_x_urad", "slope_y_urad"):
            return self.slope_tolerance * 1e6
        raise ValueError(f"solver_floor: unknown quantity {quantity!r}")

    @property
    def excluded(self) -> dict:
        """``{reason: count}`` of the aperture's nodes that are not reported
        (:data:`EXCLUSION_REASONS`; every reason listed, zeros included)."""
        st = self.node_status
        return {name: (0 if st is None else int(np.count_nonzero(st == code)))
                for code, (name, _) in EXCLUSION_REASONS.items()}

    @property
    def rim_fitted(self) -> int:
        """Reported nodes served by the rim fit (:mod:`pmdsim.measure.interpolate`)."""
        return 0 if self.node_status is None else int(np.count_nonzero(self.node_status == NODE_RIM_FIT))


def _anchor(z, nominal, ok, anchor_idx, parts=None):
    """Tie each connected part of the measured grid to the nominal shape: the part holding
    the anchor node (or, when that node is not measured, the measured node nearest to it)
    at that node, every other part (and all with ``anchor_idx`` None) by its mean.
    ``parts``: ``ndimage.label(ok)`` when known."""
    if not ok.any():
        return z
    labels, n = ndimage.label(ok) if parts is None else parts
    out = z.copy()
    if anchor_idx is not None and not ok[anchor_idx]:
        rr, cc = np.nonzero(ok)
        k = np.argmin((rr - anchor_idx[0]) ** 2 + (cc - anchor_idx[1]) ** 2)
        anchor_idx = (int(rr[k]), int(cc[k]))
    anchored = labels[anchor_idx] if anchor_idx is not None else 0
    if n == 1 and anchored == 1:  # one part, holding the anchor: no part masks needed
        out = z - z[anchor_idx] + nominal[anchor_idx]
        out[~ok] = z[~ok]
        return out
    for lab in range(1, n + 1):
        part = labels == lab
        if lab == anchored:
            out[part] = z[part] - z[anchor_idx] + nominal[anchor_idx]
        else:
            out[part] = z[part] - z[part].mean() + nominal[part].mean()
    return out


#: residual reduction asked of an iterative Southwell solver in each iteration (see reconstruct)
SOLVE_RTOL = 1e-3


def reconstruct(u, v, camera, monitor, prior, *, valid=None, spacing_mm=0.5, grid=None,
                anchor="centre", order=4, max_iter=30, tol_mm=1e-8, solver="auto",
                start=None, slope_tolerance=True) -> Reconstruction:
    """Surface height and slopes from decoded monitor coordinates (monocular PMD).

    Parameters
    ----------
    u, v : (H, W) ndarray, monitor px
        Decoded monitor coordinates of every camera pixel (NaN = not decoded).
    camera : object with ``position`` (3,) mm (or a homogeneous ``viewpoint`` (4,), which
        wins) and ``project(points) -> (..., 2)`` (col, row)
    monitor : object with ``pixel_to_world(u, v) -> (..., 3)`` mm
    prior : the nominal surface (:func:`prior_frame` input) or a :class:`PriorFrame`
    valid : (H, W) bool ndarray, optional — pixels to use (default: finite u and v)
    spacing_mm : float — grid step (mm) when ``grid`` is not given
    grid : (x_mm, y_mm), optional — 1-D local coordinates of the grid columns / rows
    anchor : "centre" | "mean" | (x, y)
        Where the height is tied to the prior: the grid node nearest the aperture centre
        (default) or (x, y) (the nearest measured node when that one is not measured), or
        the mean over the aperture. Separate measured parts are each tied by their mean.
    order, solver : passed to :func:`~pmdsim.measure.integrate.southwell`
    max_iter, tol_mm : the height-normal iteration stops when the height is within
        ``tol_mm`` of its fixed point: max |dz| of the last iteration below ``tol_mm``, or,
        while the iteration contracts, the geometric estimate of the changes still to come
        (:func:`_settled`). Default 1e-8 mm = 0.01 nm: a hundredth of the 1 nm RMS that the
        noise-free accuracy tests allow, far below any chain's floor.
    start : (H, W) ndarray, optional
        The first height on the grid (mm; NaN nodes start from the nominal sag), e.g. the
        height of a reconstruction from nearly the same coordinates: the iteration then
        starts next to its fixed point (same ``tol_mm``, fewer iterations).
    slope_tolerance : bool
        Compute :attr:`Reconstruction.slope_tolerance` (the slopes' change for the
        height's tolerance: two bisector-normal passes over the nodes); False: NaN, for a
        repetition whose solver floor is not asked (a run's numerical-error repeats).
    """
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    ok_pix = np.isfinite(u) & np.isfinite(v)
    if valid is not None:
        ok_pix &= np.asarray(valid, bool)
    pf = prior if isinstance(prior, PriorFrame) else prior_frame(prior)
    if grid is None:
        x0, x1, y0, y1 = pf.bounds
        cx, cy = pf.aperture_centre
        nxl, nxr = int(np.floor((cx - x0) / spacing_mm + 1e-9)), int(np.floor((x1 - cx) / spacing_mm + 1e-9))
        nyl, nyr = int(np.floor((cy - y0) / spacing_mm + 1e-9)), int(np.floor((y1 - cy) / spacing_mm + 1e-9))
        xs = cx + spacing_mm * np.arange(-nxl, nxr + 1)
        ys = cy + spacing_mm * np.arange(-nyl, nyr + 1)
    else:
        xs, ys = (np.asarray(g, np.float64) for g in grid)
    dx, dy = float(xs[1] - xs[0]), float(ys[1] - ys[0])
    x, y = np.meshgrid(xs, ys)
    nominal = np.asarray(pf.sag(x, y), np.float64)
    mask = np.asarray(pf.in_aperture(x, y), bool) & np.isfinite(nominal)
    cu, cv = spline_maps(u, v, ok_pix)
    # homogeneous viewpoint (a telecentric camera's is at infinity), else the centre
    cam_pos = np.asarray(getattr(camera, "viewpoint", camera.position), np.float64)

    if anchor == "centre":
        ax, ay = pf.aperture_centre
        anchor_idx = (int(np.argmin(np.abs(ys - ay))), int(np.argmin(np.abs(xs - ax))))
    elif anchor == "mean":
        anchor_idx = None
    else:
        anchor_idx = (int(np.argmin(np.abs(ys - anchor[1]))), int(np.argmin(np.abs(xs - anchor[0]))))

    z = np.where(mask, nominal, 0.0)
    outside = z  # the height of nodes not measured (never changed in place)
    if start is not None:
        start = np.asarray(start, np.float64)
        if start.shape != z.shape:
            raise ValueError(f"start: shape {start.shape} is not the grid's {z.shape}")
        z = np.where(mask & np.isfinite(start), start, z)
    history = []
    converged = False
    node_ok = mask
    sx = sy = None
    it = 0
    rot = np.ascontiguousarray(pf.rotation)
    planar = planar_monitor(monitor)
    # the aperture's nodes: their (x, y) part of the world point is fixed, z moves
    base = pf.centre + x[mask][:, None] * rot[:, 0] + y[mask][:, None] * rot[:, 1]
    status = np.empty(len(base), np.int8)  # how each aperture node is served (node_status)
    left_out = np.zeros(len(base), bool)  # nodes left out so far
    first_reason = np.empty_like(status)  # why (where left_out)
    ok_pix = np.ascontiguousarray(ok_pix)
    parts = None  # (node mask, its connected parts)
    for it in range(1, max_iter + 1):
        s = base + z[mask][:, None] * rot[:, 2]
        pix = camera.project(s)
        col, row = np.ascontiguousarray(pix[..., 0]), np.ascontiguousarray(pix[..., 1])
        # the decoded maps at the nodes' pixels: by the spline, by the rim fit, or not
        # (status says which, and why)
        mu, mv = maps_at(u, v, ok_pix, cu, cv, col, row, status)
        # a node left out once stays out, for the reason it was: one whose pixel sits at a
        # threshold would otherwise come and go with the height, and the loop never settle
        status[left_out] = first_reason[left_out]
        new = (status > NODE_RIM_FIT) & ~left_out
        first_reason[new] = status[new]
        left_out |= new
        ok_m = status <= NODE_RIM_FIT
        node_ok = np.zeros(mask.shape, bool)
        node_ok[mask] = ok_m
        k = int(ok_m.sum())
        mu = np.ascontiguousarray(mu[ok_m])
        mv = np.ascontiguousarray(mv[ok_m])
        a = np.empty(k)
        b = np.empty(k)
        # = slopes_in_frame(bisector_normals(s, camera, monitor.pixel_to_world(mu, mv)), rotation)
        if planar is not None:
            bisector_slopes_planar(s[ok_m], cam_pos, mu, mv, *planar, rot, a, b)
        else:
            m3 = np.ascontiguousarray(monitor.pixel_to_world(mu, mv), np.float64)
            bisector_slopes(s[ok_m], cam_pos, m3, rot, a, b)
        sx = np.zeros(x.shape)
        sy = np.zeros(x.shape)
        sx[node_ok] = a
        sy[node_ok] = b
        # = southwell(sx, sy, (dx, dy), node_ok, ..., remove="none"), on the prepared slopes.
        # The previous height as first guess; iterative solvers only refine the correction
        # to SOLVE_RTOL: the next iteration continues from there, and the last corrections
        # are below tol_mm, so the solver's error is below tol_mm * SOLVE_RTOL
        zi = _integrate(sx, sy, node_ok, dx, dy, order=order, solver=solver, x0=z, rtol=SOLVE_RTOL)
        if parts is None or not np.array_equal(node_ok, parts[0]):
            parts = (node_ok, ndimage.label(node_ok))
        zi = _anchor(zi, nominal, node_ok, anchor_idx, parts[1])
        change = float(np.max(np.abs(zi - z)[node_ok])) if k else 0.0
        history.append(change)
        z = np.where(node_ok, zi, outside)
        if _settled(history, tol_mm):
            converged = True
            break
    if sx is not None:
        sx[~node_ok] = np.nan
        sy[~node_ok] = np.nan
    height = np.where(node_ok, z, np.nan)
    node_status = np.full(mask.shape, NODE_OUTSIDE_APERTURE, np.int8)
    node_status[mask] = status
    tolerance = _remaining(history)
    slope_tol = 0.0 if slope_tolerance else math.nan
    if slope_tolerance and sx is not None and ok_m.any():  # the slopes' change for the height's tolerance
        pts = s[ok_m]
        m3 = np.asarray(monitor.pixel_to_world(mu, mv), np.float64)
        moved = [slopes_in_frame(bisector_normals(p, cam_pos, m3), rot)
                 for p in (pts, pts + tolerance * rot[:, 2])]
        slope_tol = float(np.nanmax(np.abs(np.subtract(moved[1], moved[0]))))
    return Reconstruction(xs, ys, node_ok, height, sx, sy, np.where(mask, nominal, np.nan), it,
                          tuple(history), converged, node_status, tolerance, slope_tol)


def planar_monitor(monitor):
    """The plane parameters of a :class:`~pmdsim.scene.monitor.Monitor` (whose
    ``pixel_to_world`` the compiled :func:`~pmdsim.kernels.reconstruct.bisector_slopes_planar`
    repeats, as does the chain's slope_deviation_3d), None for any other monitor model (its own
    ``pixel_to_world`` is called)."""
    from ..scene.monitor import Monitor

    if getattr(type(monitor), "pixel_to_world", None) is not Monitor.pixel_to_world:
        return None
    f = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
    return (f(monitor.centre), f(monitor.e_u), f(monitor.e_v), float(monitor.pitch),
            (monitor.width - 1) / 2.0, (monitor.height - 1) / 2.0)


def _remaining(history) -> float:
    """How far the height-normal iteration's last height may be from its fixed point (mm):
    the geometric tail ``last q / (1 - q)`` of the changes still to come where the last two
    contract (``q`` their ratio; the estimate :func:`_settled` stops on), else the last
    change itself, plus the iterative solver's part (it refines each correction to
    :data:`SOLVE_RTOL` of its size). 0 without an iteration."""
    if not history:
        return 0.0
    last = float(history[-1])
    tail = last
    if len(history) >= 2 and history[-2] > 0 and last / history[-2] < 1.0:
        q = last / history[-2]
        tail = last * q / (1.0 - q)
    return tail + last * SOLVE_RTOL


def _settled(history, tol_mm):
    """Has the height-normal iteration reached its fixed point within ``tol_mm``? Yes when
    the last change is below it, or when the iteration contracts (ratio q of the last two
    changes below 1/2) and the geometric tail of the remaining changes, last * q / (1 - q),
    is below it."""
    last = history[-1]
    if last < tol_mm:
        return True
    if len(history) < 2 or not history[-2] > 0:
        return False
    q = last / history[-2]
    return q < 0.5 and last * q / (1.0 - q) < tol_mm


def slope_deviation_3d(points, camera_position, monitor, u_ref, v_ref, u, v):
    """Signed surface tilt (rad) that moves the decoded monitor point from the reference
    (u_ref, v_ref) to (u, v), from the full 3-D geometry at the surface ``points`` (..., 3).

    The angle between the bisector normals of S -> camera with S -> M_ref and with S -> M,
    signed by the larger monitor-coordinate change. Replaces the scalar coord / (2 d), which
    holds in the plane of incidence but is cos(theta_i) too small across it (a tilt delta
    across the plane turns the reflected ray by 2 delta cos(theta_i)). For one fringe
    direction pass the other coordinate unchanged (``v = v_ref`` for X fringes).
    """
    m_ref = monitor.pixel_to_world(u_ref, v_ref)
    m = monitor.pixel_to_world(u, v)
    n0 = bisector_normals(points, camera_position, m_ref)
    n1 = bisector_normals(points, camera_position, m)
    ang = np.arctan2(np.linalg.norm(np.cross(n0, n1), axis=-1), np.sum(n0 * n1, axis=-1))
    du = np.asarray(u, np.float64) - u_ref
    dv = np.asarray(v, np.float64) - v_ref
    sign = np.where(np.abs(du) >= np.abs(dv), np.sign(du), np.sign(dv))
    return sign * ang


@dataclass(frozen=True)
class SurfaceErrors:
    """Reconstructed minus true surface on the reconstruction grid.

    ``height_nm`` after removing ``removed`` (see :func:`~pmdsim.measure.integrate.remove_terms`),
    ``slope_x_urad`` / ``slope_y_urad`` the slope errors dz/dx, dz/dy in the surface's local
    frame; ``stats``: RMS/PV/P95 of each (:func:`~pmdsim.measure.integrate.height_stats`)."""

    height_nm: np.ndarray
    slope_x_urad: np.ndarray
    slope_y_urad: np.ndarray
    removed: str
    stats: dict


def surface_errors(rec: Reconstruction, truth, remove="piston", form=None,
                   tables: bool = True) -> SurfaceErrors:
    """Errors of a :class:`Reconstruction` against the true surface (a scene surface or a
    :class:`PriorFrame`; its sag and gradient are evaluated on the grid).

    ``remove``: a removal level or term names (:data:`pmdsim.measure.form.LEVELS`, e.g.
    ``"power"`` or ``"sphere"``); ``form``: a :class:`~pmdsim.measure.form.FormSpec`
    instead (Zernike terms, rim band). ``stats["terms_nm"]`` holds the Noll Zernike terms
    Z2..Z15 of the height error *after* the removal (nm RMS each, fitted to the residual on
    the aperture's disc), ``stats["zernike_noll_nm"]``/``["zernike_fringe_nm"]`` the full
    tables with their ``removed`` column, ``stats["removal"]`` what was removed."""
    from .form import FormSpec, remove_form
    from .integrate import height_stats

    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    if hasattr(truth, "sag") and not isinstance(truth, PriorFrame):
        z, gx, gy, _ = truth.sag(x, y)
    else:  # flat rectangle / prior frame: numerical gradient of its sag is zero for a plane
        pf = truth if isinstance(truth, PriorFrame) else prior_frame(truth)
        z = np.asarray(pf.sag(x, y), np.float64)
        gx = np.zeros_like(z)
        gy = np.zeros_like(z)
    spec = form if form is not None else FormSpec.of(remove)
    ap = getattr(truth, "aperture", None)
    disc = ((ap[1], ap[2]), ap[3]) if isinstance(ap, tuple) and ap[0] in ("circular", "annular") else (None, None)
    m0 = rec.mask & np.isfinite(rec.height_mm)
    res = remove_form(np.where(m0, rec.height_mm - z, np.nan), m0, x, y, spec,
                      true_height=np.where(m0, z, 0.0), disc=disc, tables=tables)
    m = res.mask
    dh = res.residual * 1e6
    ex = np.where(m, rec.slope_x - gx, np.nan) * 1e6
    ey = np.where(m, rec.slope_y - gy, np.nan) * 1e6
    stats = {"height_error_nm": height_stats(dh).as_dict(),
             "slope_error_x_urad": height_stats(ex).as_dict(),
             "slope_error_y_urad": height_stats(ey).as_dict()}
    # slope statistics are about zero, not the mean: report the RMS about zero too
    for k, a in (("slope_error_x_urad", ex), ("slope_error_y_urad", ey)):
        stats[k]["rms_about_zero"] = float(np.sqrt(np.nanmean(a**2))) if np.isfinite(a).any() else float("nan")
    stats["removal"] = res.removed
    stats["rim_excluded"] = res.excluded_rim
    if res.sphere is not None:
        stats["sphere"] = res.sphere
    stats["zernike_noll_nm"] = [dict(t, coefficient=t["coefficient"] * 1e6) for t in res.noll]
    stats["zernike_fringe_nm"] = [dict(t, coefficient=t["coefficient"] * 1e6) for t in res.fringe]
    stats["terms_nm"] = ({"basis": "zernike", **{f"Z{t['index']}": t["coefficient"]
                                                 for t in stats["zernike_noll_nm"] if 2 <= t["index"] <= 15}}
                         if res.noll else {})
    removed = remove if isinstance(remove, str) else "+".join(remove)
    if form is not None:
        removed = "+".join(form.terms) or "none"
    return SurfaceErrors(dh, ex, ey, removed, stats)
