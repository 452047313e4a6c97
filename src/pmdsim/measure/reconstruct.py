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

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..kernels.reconstruct import (
    SUPPORT_OUTSIDE,
    SUPPORT_PIXEL_INVALID,
    SUPPORT_RIM,
    SUPPORT_SPLINE,
    bisector_slopes,
    bisector_slopes_planar,
    node_support,
)
from ..kernels.surface import bspline_eval_pair
from .integrate import _integrate, _lstsq

__all__ = [
    "EXCLUSION_REASONS",
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
    ``node_status`` (H, W) int8: how each node was served (:data:`NODE_SPLINE`,
    :data:`NODE_RIM_FIT`) or why it is not reported (the keys of :data:`EXCLUSION_REASONS`;
    :data:`NODE_OUTSIDE_APERTURE` off the nominal aperture)."""

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

    @property
    def spacing(self):
        return (float(self.x_mm[1] - self.x_mm[0]), float(self.y_mm[1] - self.y_mm[0]))

    @property
    def excluded(self) -> dict:
        """``{reason: count}`` of the aperture's nodes that are not reported
        (:data:`EXCLUSION_REASONS`; every reason listed, zeros included)."""
        st = self.node_status
        return {name: (0 if st is None else int(np.count_nonzero(st == code)))
                for code, (name, _) in EXCLUSION_REASONS.items()}

    @property
    def rim_fitted(self) -> int:
        """Reported nodes served by the rim fit (:func:`_rim_fit`)."""
        return 0 if self.node_status is None else int(np.count_nonzero(self.node_status == NODE_RIM_FIT))


#: ``Reconstruction.node_status`` codes: reported, by the cubic spline of the decoded maps or
#: by the rim fit; off the nominal aperture (not a node of the surface)
NODE_SPLINE, NODE_RIM_FIT, NODE_OUTSIDE_APERTURE = SUPPORT_SPLINE, SUPPORT_RIM, -1
#: a rim node whose fit has too few valid pixels around it (its noise gain above
#: RIM_MAX_GAIN, or too few to fit at all)
NODE_TOO_FEW_PIXELS = 4
#: Why an aperture node is not reported: ``{node_status code: (name, what it means)}``.
EXCLUSION_REASONS = {
    SUPPORT_OUTSIDE: ("outside_camera_view", "the node projects outside the camera image"),
    SUPPORT_PIXEL_INVALID: ("pixel_invalid", (
        "the camera pixel the node falls in has no valid decoded coordinates (off the surface "
        "in the image, masked or flagged by decoding), and the rim fit of the valid pixels "
        "around it does not reach it with at most one pixel's noise")),
    NODE_TOO_FEW_PIXELS: ("too_few_valid_pixels", (
        "the node's pixel is valid, but too few pixels around it are for the rim fit to "
        "reach it with at most one pixel's noise")),
}


def _smooth_fill(maps, valid, near, degree=6, max_samples=50_000):
    """The maps (each (H, W)) with invalid pixels filled smoothly: a 2-D polynomial fitted to
    the valid pixels plus the nearest valid pixel's residual (continuous at the boundary, so
    the spline's prefilter does not ring into the valid region). ``near``: the (rows, cols)
    of the nearest valid pixel of each invalid one, in ``np.nonzero(~valid)`` order."""
    h, w = valid.shape
    rows, cols = np.nonzero(valid)
    step = max(1, len(rows) // max_samples)
    rs, cs = rows[::step], cols[::step]

    terms = [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]

    def vander(r, c):
        vx = np.polynomial.legendre.legvander(2.0 * c / max(w - 1, 1) - 1.0, degree)
        vy = np.polynomial.legendre.legvander(2.0 * r / max(h - 1, 1) - 1.0, degree)
        return vx, vy

    vx, vy = vander(rs, cs)
    a_mat = np.stack([vx[:, i] * vy[:, j] for i, j in terms], axis=1)
    coefs = _lstsq(a_mat, np.stack([a[rs, cs] for a in maps], axis=1))
    gx, _ = vander(np.zeros(w), np.arange(w))
    _, gy = vander(np.arange(h), np.zeros(h))
    bad = ~valid
    out = []
    for a, coef in zip(maps, coefs.T):
        cmat = np.zeros((degree + 1, degree + 1))
        for (i, j), c in zip(terms, coef):
            cmat[i, j] = c
        # the fit on the whole grid, separably: fit[r, c] = sum_ij C_ij Px_i(c) Py_j(r)
        fit = gy @ cmat.T @ gx.T
        f = a.copy()
        f[bad] = fit[bad] + (a[near] - fit[near])
        out.append(f)
    return out


def _nearest_valid(valid):
    """(rows, cols) of the nearest valid pixel (Euclidean) of each invalid one, in
    ``np.nonzero(~valid)`` order. The nearest valid pixel always has an invalid 4-neighbour
    (a step from any other valid pixel towards the invalid one comes closer), so a k-d tree
    of those edge pixels answers when few pixels are invalid; the exact distance transform
    of the whole image otherwise."""
    bad = ~valid
    if bad.sum() > 0.05 * bad.size:
        idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
        return tuple(i[bad] for i in idx)
    from scipy.spatial import cKDTree

    edge = np.argwhere(valid & ~ndimage.binary_erosion(valid, border_value=1))
    k = cKDTree(edge).query(np.argwhere(bad))[1]
    return edge[k, 0], edge[k, 1]


#: invalid pixels added on every side of the decoded maps before the smooth fill and the
#: spline prefilter: the prefilter's mirror boundary then lies beyond the smooth fill, not at
#: the image's edge (a mirror of a ramp is a kink, which the prefilter spreads into the image)
SPLINE_PAD = 4


def _spline_maps(u, v, valid):
    """Cubic-spline coefficients of u and v with the invalid pixels and a border of
    :data:`SPLINE_PAD` pixels filled smoothly (evaluate at pixel + SPLINE_PAD)."""
    if not valid.any():
        raise ValueError("no valid decoded pixel: nothing to reconstruct")
    pad = SPLINE_PAD
    valid = np.pad(valid, pad, constant_values=False)
    u = np.pad(u, pad)
    v = np.pad(v, pad)
    uf, vf = _smooth_fill((u, v), valid, _nearest_valid(valid))
    cu = np.pad(ndimage.spline_filter(uf, order=3, mode="mirror"), 2, mode="reflect")
    cv = np.pad(ndimage.spline_filter(vf, order=3, mode="mirror"), 2, mode="reflect")
    return cu, cv


#: Valid pixels required around the spline's 4 x 4 support for the spline to serve a node:
#: the spline's prefilter couples every coefficient to the filled pixels by 0.268^distance
#: (px), so the fill's kink at the edge of the valid pixels reaches the nodes next to it;
#: those go to the rim fit. Measured on the 140 mm sphere cut by the image's edge
#: (tests/test_rim.py): max slope error of the spline's nodes 0.43, 0.11, 0.030, 0.0079 urad
#: at margins 0, 1, 2, 3 (83 urad at margin 0 without SPLINE_PAD); the rim fit's 0.0004.
SPLINE_MARGIN = 3


#: The rim fit (nodes whose spline support holds an invalid pixel or leaves the image): a
#: cubic polynomial in (col, row) fitted by least squares to the valid pixels of the n x n
#: block about the node (floor - n/2 + 1 .. floor + n/2), evaluated at the node; the first
#: of these block sizes whose fit reaches the node within RIM_MAX_GAIN. Exact for a cubic
#: map, one-sided where the block is cut by the rim, and it never reads a filled pixel.
RIM_WINDOWS = (6, 8)
RIM_DEGREE = 3
#: The largest noise gain sqrt(e0^T (A^T A)^-1 e0) of the rim fit at a node (the standard
#: deviation of its value per unit standard deviation of independent pixel noise): a node
#: that the valid pixels around it reach only with more than one pixel's noise is not
#: reported. An interpolating cubic spline's gain in the interior is about 0.8.
RIM_MAX_GAIN = 1.0
_RIM_TERMS = tuple((i, j) for d in range(RIM_DEGREE + 1) for j in range(d + 1) for i in (d - j,))


def _rim_fit(u, v, valid, cols, rows, window=RIM_WINDOWS[0], block=20_000):
    """(u, v, gain) at the fractional pixels (cols, rows) (K,) by the rim fit on the
    ``window`` x ``window`` block (see :data:`RIM_WINDOWS`); gain inf (and u, v NaN) where
    the valid pixels of the block do not determine the cubic."""
    h, w = valid.shape
    n = int(window)
    half = n // 2
    off = np.arange(n)
    out_u = np.full(cols.shape, np.nan)
    out_v = np.full(cols.shape, np.nan)
    gain = np.full(cols.shape, np.inf)
    nt = len(_RIM_TERMS)
    for s0 in range(0, cols.size, block):
        c = cols[s0:s0 + block]
        r = rows[s0:s0 + block]
        cc = (np.floor(c).astype(np.int64) - (half - 1))[:, None, None] + off[None, None, :]
        rr = (np.floor(r).astype(np.int64) - (half - 1))[:, None, None] + off[None, :, None]
        inside = (cc >= 0) & (cc < w) & (rr >= 0) & (rr < h)
        ci = np.clip(cc, 0, w - 1)
        ri = np.clip(rr, 0, h - 1)
        wgt = (inside & valid[ri, ci]).reshape(len(c), -1)
        # local coordinates about the node, scaled to about [-1, 1]
        dc = np.broadcast_to((cc - c[:, None, None]) / half, (len(c), n, n)).reshape(len(c), -1)
        dr = np.broadcast_to((rr - r[:, None, None]) / half, (len(c), n, n)).reshape(len(c), -1)
        a = np.stack([dc**i * dr**j for i, j in _RIM_TERMS], axis=-1) * wgt[..., None]
        g = np.einsum("kpt,kps->kts", a, a)
        fu = np.where(wgt, u[ri, ci].reshape(len(c), -1), 0.0)
        fv = np.where(wgt, v[ri, ci].reshape(len(c), -1), 0.0)
        bu = np.einsum("kpt,kp->kt", a, fu)
        bv = np.einsum("kpt,kp->kt", a, fv)
        lam, vec = np.linalg.eigh(g)
        ok = (wgt.sum(axis=1) >= nt) & (lam[:, 0] > 1e-10 * lam[:, -1])
        inv0 = np.where(ok[:, None], vec[:, 0, :] / np.where(ok[:, None], lam, 1.0), 0.0)
        # (G^-1 b)[0] = sum_t V[0, t] (V[:, t] . b) / lam_t; (G^-1)[0, 0] = sum_t V[0, t]^2 / lam_t
        out_u[s0:s0 + block] = np.where(ok, np.einsum("kt,kst,ks->k", inv0, vec, bu), np.nan)
        out_v[s0:s0 + block] = np.where(ok, np.einsum("kt,kst,ks->k", inv0, vec, bv), np.nan)
        gain[s0:s0 + block] = np.where(ok, np.sqrt(np.abs(np.einsum("kt,kt->k", inv0, vec[:, 0, :]))), np.inf)
    return out_u, out_v, gain


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
                start=None) -> Reconstruction:
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
    cu, cv = _spline_maps(u, v, ok_pix)
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
    ok_pix = np.ascontiguousarray(ok_pix)
    parts = None  # (node mask, its connected parts)
    for it in range(1, max_iter + 1):
        s = base + z[mask][:, None] * rot[:, 2]
        pix = camera.project(s)
        col, row = np.ascontiguousarray(pix[..., 0]), np.ascontiguousarray(pix[..., 1])
        # nodes whose spline support (4 x 4 pixels) is valid: the spline of the maps; nodes
        # in the image whose support is not all valid (their own pixel included): the rim
        # fit (valid pixels only), reported where it reaches the node with at most one
        # pixel's noise
        node_support(ok_pix, col, row, SPLINE_MARGIN, status)
        spl = status == SUPPORT_SPLINE
        rim = np.nonzero((status == SUPPORT_RIM) | (status == SUPPORT_PIXEL_INVALID))[0]
        mu = np.full(len(base), np.nan)
        mv = np.full(len(base), np.nan)
        ks = int(spl.sum())
        su, sv = np.empty(ks), np.empty(ks)
        # = ndimage.map_coordinates(..., order=3, mode="mirror") of u and v, in one pass
        bspline_eval_pair(cu, cv, np.ascontiguousarray(row[spl]) + SPLINE_PAD,
                          np.ascontiguousarray(col[spl]) + SPLINE_PAD, su, sv)
        mu[spl], mv[spl] = su, sv
        for window in RIM_WINDOWS:  # the smallest block that reaches the node
            if not rim.size:
                break
            ru, rv, gain = _rim_fit(u, v, ok_pix, col[rim], row[rim], window)
            near = gain <= RIM_MAX_GAIN
            mu[rim[near]], mv[rim[near]] = ru[near], rv[near]
            status[rim[near]] = NODE_RIM_FIT
            rim = rim[~near]
        # not reached: their own pixel invalid (SUPPORT_PIXEL_INVALID), or too few valid
        # pixels around a valid one
        status[rim[status[rim] == SUPPORT_RIM]] = NODE_TOO_FEW_PIXELS
        ok_m = status <= SUPPORT_RIM
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
    return Reconstruction(xs, ys, node_ok, height, sx, sy, np.where(mask, nominal, np.nan), it,
                          tuple(history), converged, node_status)


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
