"""The numerical error of a reconstruction, carried linearly from the decoded coordinates.

A run states the numerical (quadrature) error of every decoded monitor coordinate
(:mod:`pmdsim.measure.numerical`). Its effect on the reconstructed surface is the change of
the reconstruction when every coordinate moves by its error. The reconstruction
(:func:`pmdsim.measure.reconstruct.reconstruct`) is a fixed point of "slopes from the
monitor points at the current height, then the height from the slopes"; for coordinate
changes of a thousandth of a pixel it is linear in them:

1. at every measured node the surface point S of the reconstructed height and the camera
   pixel that sees it (as the reconstruction's last iteration);
2. the monitor point M the reconstruction used there, reflected back from S with the
   reconstructed normal (the law of reflection the bisector inverts), and its change, the
   coordinate errors (``ex``, ``ey``) interpolated bilinearly at the pixel;
3. the slope change of every node: the reconstruction's own compiled bisector slopes at
   M + dM minus at M (exact for the node's geometry, not a derivative formula), plus the
   slope change per unit height change (a node moved by dz along the local z axis is seen
   by another pixel, which decodes another coordinate, and its bisector turns: a finite
   difference of 1 um through the same slopes, with the bilinear gradient of the decoded
   maps) times the height change;
4. the height change: those slope changes integrated by the reconstruction's Southwell
   solver on the same nodes (linear; the mask's operator is kept from the reconstruction)
   and tied at the same anchor, repeated from step 3 until the height change settles (the
   linearised height-normal loop contracts as the reconstruction's does: 3-4 solves).

It replaces repeating the whole reconstruction with moved coordinates (cubic spline
coefficients of both maps and 3-4 nonlinear iterations from the reconstructed height: half
the reconstruction step of a run) at about 60 % of its CPU time on Fig. 3 (0.55-0.64
against 0.94-1.03 CPU-s with the removal and statistics, 2026-12-06, loaded machine). What
it leaves out is quadratic in the coordinate change (each node's direct slope change is
exact, the coupling through the height linear). The two differ where the repeated
reconstruction's cubic spline reads what the bilinear carry does not: between pixels (a
few per mil where nodes are denser than pixels) and, within a few nodes of the measured
area's edge, the smoothly filled invalid pixels around it (there up to 2.5 % of the
largest node error on Fig. 3's geometry, 18 % on a 64 x 48 camera of a sphere at 12 px of
coordinate error). The carry reads only valid pixels at a node (its bilinear cell is
valid), so at the edge it is the one that does not depend on how the maps were filled.
The statements the run makes from it, RMS, P95 and PV of the height and slope errors,
agree with the repeated reconstruction's to 1 % on Fig. 3 (at 64 nodes, 1280 x 1024) and
on a 96 x 80 Fig. 3 camera, to 3 % on the sphere (``tests/test_reconstruct_error.py``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from .integrate import _integrate
from .reconstruct import (
    PriorFrame,
    Reconstruction,
    _anchor,
    planar_monitor,
    prior_frame,
)

__all__ = ["anchor_index", "moved_reconstruction"]

#: Residual reduction asked of each Southwell solve of the height change (of its first
#: guess's residual, as the reconstruction's own ``SOLVE_RTOL``); the loop stops when the
#: height change settles to ``rtol`` of itself.
RTOL = 1e-3


def anchor_index(anchor, xs, ys, pf: PriorFrame):
    """The grid index (row, col) the reconstruction ties its height at (None: the mean), as
    :func:`~pmdsim.measure.reconstruct.reconstruct` picks it."""
    if anchor == "centre":
        ax, ay = pf.aperture_centre
        return int(np.argmin(np.abs(ys - ay))), int(np.argmin(np.abs(xs - ax)))
    if anchor == "mean":
        return None
    return int(np.argmin(np.abs(ys - anchor[1]))), int(np.argmin(np.abs(xs - anchor[0])))


def _reflected_monitor_points(s, cam_pos, normals, planar):
    """Monitor coordinates (u, v) (monitor px) where the rays from the camera to the points
    ``s`` (N, 3), reflected by the unit ``normals`` (N, 3), meet the plane of the planar
    monitor ``planar`` (:func:`~pmdsim.measure.reconstruct.planar_monitor`; beyond its
    pixel grid too: the grid's formula continued)."""
    centre, e_u, e_v, pitch, u_mid, v_mid = planar
    c = cam_pos - s
    c /= np.sqrt(np.einsum("ij,ij->i", c, c))[:, None]
    r = 2.0 * np.einsum("ij,ij->i", normals, c)[:, None] * normals - c
    w = np.cross(e_u, e_v)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((centre - s) @ w) / (r @ w)
    p = s + t[:, None] * r - centre
    return p @ e_u / pitch + u_mid, p @ e_v / pitch + v_mid


def _cell_gradient(a, row, col):
    """(d a / d row, d a / d col) of the bilinear interpolant of the map ``a`` (H, W) at the
    fractional pixels (row, col), in the pixel cell that holds each (NaN where a corner is
    NaN)."""
    h, w = a.shape
    r0 = np.clip(np.floor(row).astype(np.intp), 0, h - 2)
    c0 = np.clip(np.floor(col).astype(np.intp), 0, w - 2)
    fr, fc = row - r0, col - c0
    a00, a01 = a[r0, c0], a[r0, c0 + 1]
    a10, a11 = a[r0 + 1, c0], a[r0 + 1, c0 + 1]
    return ((1.0 - fc) * (a10 - a00) + fc * (a11 - a01),
            (1.0 - fr) * (a01 - a00) + fr * (a11 - a10))


def moved_reconstruction(rec: Reconstruction, camera, monitor, prior, u, v, ex, ey, *,
                         order=4, anchor="centre", solver="auto", rtol=1e-3,
                         max_iter=20) -> Reconstruction | None:
    """The reconstruction ``rec`` of the decoded coordinates (``u``, ``v``) (H, W) monitor
    px as it would be with every coordinate moved by (``ex``, ``ey``) (NaN counts as 0),
    carried linearly (the module's steps); None where this needs what only a full
    reconstruction gives (a monitor model other than the planar pixel grid). The same
    grid, mask and iterations as ``rec``; slopes NaN at nodes whose change is unknown.

    The height change is the fixed point of the linearised height-normal loop: slopes
    changed by the moved coordinates directly and by the height change itself (a node
    moved by dz is seen by another camera pixel, which decodes another coordinate, and
    its bisector moves), integrated and anchored, until the last change of the height
    change is below ``rtol`` of it (the loop contracts as the reconstruction's does)."""
    planar = planar_monitor(monitor)
    if planar is None or not rec.mask.any():
        return None
    from ..kernels.reconstruct import bisector_slopes_planar

    pf = prior if isinstance(prior, PriorFrame) else prior_frame(prior)
    rot = np.ascontiguousarray(pf.rotation)
    m = rec.mask
    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    s = np.ascontiguousarray(pf.centre + x[m][:, None] * rot[:, 0] + y[m][:, None] * rot[:, 1]
                             + rec.height_mm[m][:, None] * rot[:, 2])
    cam_pos = np.asarray(camera.position, np.float64)
    # the monitor point of each node: reflected with the reconstructed normal
    a, b = rec.slope_x[m], rec.slope_y[m]
    inv = 1.0 / np.sqrt(1.0 + a * a + b * b)
    nl = np.stack([-a * inv, -b * inv, inv], axis=1)
    mu, mv = _reflected_monitor_points(s, cam_pos, np.einsum("ij,kj->ik", nl, rot), planar)
    pix = camera.project(s)
    row, col = pix[:, 1], pix[:, 0]
    # the coordinate errors where the reconstruction reads the coordinates, interpolated
    # bilinearly (a node's cell holds valid pixels only: the reconstruction's support test)
    du, dv = (ndimage.map_coordinates(np.nan_to_num(np.asarray(e, np.float64)), [row, col],
                                      order=1, mode="nearest") for e in (ex, ey))
    k = len(s)

    def slopes(points, uu, vv):
        sa, sb = np.empty(k), np.empty(k)
        bisector_slopes_planar(np.ascontiguousarray(points), cam_pos, uu, vv, *planar, rot,
                               sa, sb)
        return sa, sb

    a0, b0 = slopes(s, mu, mv)
    a1, b1 = slopes(s, mu + du, mv + dv)
    da0, db0 = a1 - a0, b1 - b0  # the direct change, exact for each node's geometry
    # the change per unit height change (finite difference of 1 um): the node's point and
    # the coordinate its new pixel decodes (the bilinear gradient of u and v there)
    step = 1e-3
    dpix = (camera.project(s + step * rot[:, 2]) - pix) / step
    gu = _cell_gradient(np.asarray(u, np.float64), row, col)
    gv = _cell_gradient(np.asarray(v, np.float64), row, col)
    dmu = gu[0] * dpix[:, 1] + gu[1] * dpix[:, 0]
    dmv = gv[0] * dpix[:, 1] + gv[1] * dpix[:, 0]
    dmu, dmv = np.nan_to_num(dmu), np.nan_to_num(dmv)  # a NaN corner: the bisector's part
    a2, b2 = slopes(s + step * rot[:, 2], mu + step * dmu, mv + step * dmv)
    ca, cb = (a2 - a0) / step, (b2 - b0) / step
    known = np.isfinite(da0) & np.isfinite(db0) & np.isfinite(ca) & np.isfinite(cb)
    da0, db0, ca, cb = (np.where(known, q, 0.0) for q in (da0, db0, ca, cb))
    dx, dy = rec.spacing
    idx = anchor_index(anchor, rec.x_mm, rec.y_mm, pf)
    zero = np.zeros(m.shape)
    parts = ndimage.label(m)
    sx, sy = np.zeros(m.shape), np.zeros(m.shape)
    dz = zero
    dzm = np.zeros(k)
    for _ in range(max_iter):
        sx[m] = da0 + ca * dzm
        sy[m] = db0 + cb * dzm
        new = _integrate(sx, sy, m, dx, dy, order=order, solver=solver, x0=dz, rtol=RTOL)
        new = _anchor(new, zero, m, idx, parts)
        change = float(np.max(np.abs(new - dz)[m]))
        dz = np.where(m, new, 0.0)
        dzm = dz[m]
        if change <= rtol * float(np.max(np.abs(dzm))):
            break
    sx[m] = np.where(known, da0 + ca * dzm, np.nan)
    sy[m] = np.where(known, db0 + cb * dzm, np.nan)
    height = np.where(m, rec.height_mm + dz, np.nan)
    return replace(rec, height_mm=height, slope_x=rec.slope_x + sx, slope_y=rec.slope_y + sy)
