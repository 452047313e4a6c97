"""Compiled per-node work of slope reconstruction and Southwell integration.

Plain arrays in and out; the validated entry points are
:func:`pmdsim.measure.reconstruct.reconstruct` and :func:`pmdsim.measure.integrate.southwell`.
Slow NumPy references: ``tests/naive_integrate.py`` (the right-hand side) and
:func:`pmdsim.measure.reconstruct.bisector_normals` / ``slopes_in_frame`` (the slopes).

- :func:`southwell_rhs`: the right-hand side ``A^T b`` of the Southwell normal equations on a
  grid, one value per node: every measured neighbour pair (i, j) (j = right or lower
  neighbour) has ``z_j - z_i = b_ij`` with ``b = h (s_i + s_j) / 2`` (order 2, the
  trapezoid rule) ``- h^2 / 12 (s'_j - s'_i)`` (order 4, Euler-Maclaurin end correction,
  ``s'`` by finite differences of the measured slopes along the pair's axis: central where
  both neighbours are measured, one-sided three-point, then two-point, else 0); node i
  receives ``-b``, node j ``+b``.
- :func:`bisector_slopes`: the surface slopes dz/dx, dz/dy in a local frame of the normals
  that bisect the unit directions from the surface points to the camera and to the
  monitor points (the law of reflection); :func:`bisector_slopes_planar` with the monitor
  points of a planar pixel grid computed inline.
- :func:`slope_deviation_3d`: the measurement chain's signed tilt between the bisector
  normals of a reference and a decoded monitor point (NumPy reference:
  :func:`pmdsim.measure.reconstruct.slope_deviation_3d`).
- :func:`node_support`: how the decoded maps serve each projected node: by the cubic spline
  (its 4 x 4 pixel support inside the image and valid), by the rim fit (the pixel the node
  falls in is valid, the spline's support is not), or not at all (that pixel is invalid, or
  outside the image).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._jit import jit, parallel_jit


@jit(inline="always")
def _measured(m, r, c):
    return 0 <= r < m.shape[0] and 0 <= c < m.shape[1] and m[r, c]


@jit(inline="always")
def _slope_derivative(s, m, r, c, dr, dc, h):
    """ds along (dr, dc) at node (r, c) from the measured neighbours (see module doc)."""
    if not m[r, c]:
        return 0.0
    p1 = _measured(m, r + dr, c + dc)
    m1 = _measured(m, r - dr, c - dc)
    if p1 and m1:
        return (s[r + dr, c + dc] - s[r - dr, c - dc]) / (2 * h)
    p2 = _measured(m, r + 2 * dr, c + 2 * dc)
    m2 = _measured(m, r - 2 * dr, c - 2 * dc)
    if p1 and p2:
        return (-3 * s[r, c] + 4 * s[r + dr, c + dc] - s[r + 2 * dr, c + 2 * dc]) / (2 * h)
    if m1 and m2:
        return (3 * s[r, c] - 4 * s[r - dr, c - dc] + s[r - 2 * dr, c - 2 * dc]) / (2 * h)
    if p1:
        return (s[r + dr, c + dc] - s[r, c]) / h
    if m1:
        return (s[r, c] - s[r - dr, c - dc]) / h
    return 0.0


@parallel_jit(fastmath=False)
def southwell_rhs(sx, sy, m, dx, dy, order, rhs):
    """Fill ``rhs`` (H, W) with the Southwell right-hand side of slopes ``sx``, ``sy``
    (H, W; any finite value where ``m`` is False) on the grid of steps ``dx``, ``dy``;
    ``order`` 2 or 4. Each node sums its own pairs, so rows run in parallel without races."""
    nr, nc = m.shape
    cx = dx * dx / 12.0
    cy = dy * dy / 12.0
    dsx = np.zeros((nr, nc))
    dsy = np.zeros((nr, nc))
    if order == 4:
        for r in numba.prange(nr):
            for c in range(nc):
                dsx[r, c] = _slope_derivative(sx, m, r, c, 0, 1, dx)
                dsy[r, c] = _slope_derivative(sy, m, r, c, 1, 0, dy)
    for r in numba.prange(nr):
        for c in range(nc):
            acc = 0.0
            if m[r, c]:
                if c + 1 < nc and m[r, c + 1]:  # pair to the right: this node is i
                    acc -= dx * 0.5 * (sx[r, c] + sx[r, c + 1]) - cx * (dsx[r, c + 1] - dsx[r, c])
                if c >= 1 and m[r, c - 1]:  # pair to the left: this node is j
                    acc += dx * 0.5 * (sx[r, c - 1] + sx[r, c]) - cx * (dsx[r, c] - dsx[r, c - 1])
                if r + 1 < nr and m[r + 1, c]:
                    acc -= dy * 0.5 * (sy[r, c] + sy[r + 1, c]) - cy * (dsy[r + 1, c] - dsy[r, c])
                if r >= 1 and m[r - 1, c]:
                    acc += dy * 0.5 * (sy[r - 1, c] + sy[r, c]) - cy * (dsy[r, c] - dsy[r - 1, c])
            rhs[r, c] = acc


@jit(inline="always")
def _monitor_point(u, v, centre, e_u, e_v, pitch, u_mid, v_mid):
    """World point of monitor coordinates (u, v) px on a planar pixel grid (the arithmetic of
    :meth:`pmdsim.scene.monitor.Monitor.pixel_to_world`)."""
    du = (u - u_mid) * pitch
    dv = (v - v_mid) * pitch
    return (centre[0] + du * e_u[0] + dv * e_v[0], centre[1] + du * e_u[1] + dv * e_v[1],
            centre[2] + du * e_u[2] + dv * e_v[2])


@jit(inline="always")
def _bisector(px, py, pz, camera_position, mx, my, mz):
    """Sum of the unit directions from (px, py, pz) to the camera and to the monitor point
    (mx, my, mz): the reflecting normal, not normalised. ``camera_position``: the camera
    centre (3,), or homogeneous (4,) ``(c, w)``: the direction to the camera is
    ``c - w p`` (w = 0: a telecentric camera's axis direction, the same at every point)."""
    w = camera_position[3] if camera_position.shape[0] > 3 else 1.0
    ax = camera_position[0] - w * px
    ay = camera_position[1] - w * py
    az = camera_position[2] - w * pz
    bx = mx - px
    by = my - py
    bz = mz - pz
    la = 1.0 / math.sqrt(ax * ax + ay * ay + az * az)
    lb = 1.0 / math.sqrt(bx * bx + by * by + bz * bz)
    return ax * la + bx * lb, ay * la + by * lb, az * la + bz * lb


@jit(inline="always")
def _bisector_slope(px, py, pz, camera_position, mx, my, mz, rotation):
    nx, ny, nz = _bisector(px, py, pz, camera_position, mx, my, mz)
    # local components n . (column j of rotation); the scale of n cancels in the ratios
    l0 = nx * rotation[0, 0] + ny * rotation[1, 0] + nz * rotation[2, 0]
    l1 = nx * rotation[0, 1] + ny * rotation[1, 1] + nz * rotation[2, 1]
    l2 = nx * rotation[0, 2] + ny * rotation[1, 2] + nz * rotation[2, 2]
    if l2 == 0.0:
        return math.nan, math.nan
    return -l0 / l2, -l1 / l2


@parallel_jit(fastmath=False)
def bisector_slopes(points, camera_position, monitor_points, rotation, out_sx, out_sy):
    """Slopes (dz/dx, dz/dy) in the frame whose axes are the columns of ``rotation`` of the
    normals bisecting the unit directions from ``points`` (N, 3) to ``camera_position`` (3,)
    and to ``monitor_points`` (N, 3); NaN where the normal lies in the frame's x-y plane."""
    for k in numba.prange(points.shape[0]):
        out_sx[k], out_sy[k] = _bisector_slope(points[k, 0], points[k, 1], points[k, 2], camera_position,
                                               monitor_points[k, 0], monitor_points[k, 1],
                                               monitor_points[k, 2], rotation)


@parallel_jit(fastmath=False)
def bisector_slopes_planar(points, camera_position, u, v, centre, e_u, e_v, pitch, u_mid, v_mid,
                           rotation, out_sx, out_sy):
    """:func:`bisector_slopes` with the monitor points of a planar pixel grid: monitor
    coordinates (u, v) (N,) px -> ``centre + (u - u_mid) pitch e_u + (v - v_mid) pitch e_v``."""
    for k in numba.prange(points.shape[0]):
        mx, my, mz = _monitor_point(u[k], v[k], centre, e_u, e_v, pitch, u_mid, v_mid)
        out_sx[k], out_sy[k] = _bisector_slope(points[k, 0], points[k, 1], points[k, 2], camera_position,
                                               mx, my, mz, rotation)


@jit(inline="always")
def _tilt(nx0, ny0, nz0, sx, sy, sz, camera_position, ur, vr, uu, vv, centre, e_u, e_v, pitch,
          u_mid, v_mid):
    """The signed tilt (rad) from the bisector normal ``n0`` (at the reference monitor point
    ``(ur, vr)``) to the one at ``(uu, vv)``, of the surface point ``s``
    (:func:`slope_deviation_3d`)."""
    mx, my, mz = _monitor_point(uu, vv, centre, e_u, e_v, pitch, u_mid, v_mid)
    nx1, ny1, nz1 = _bisector(sx, sy, sz, camera_position, mx, my, mz)
    # the angle between the normals: atan2(|n0 x n1|, n0 . n1) (their scale cancels)
    cx = ny0 * nz1 - nz0 * ny1
    cy = nz0 * nx1 - nx0 * nz1
    cz = nx0 * ny1 - ny0 * nx1
    ang = math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz),
                     nx0 * nx1 + ny0 * ny1 + nz0 * nz1)
    du, dv = uu - ur, vv - vr
    d = du if abs(du) >= abs(dv) else dv
    return (1.0 if d > 0 else (-1.0 if d < 0 else 0.0)) * ang


@parallel_jit(fastmath=False)
def slope_deviation_3d(points, camera_position, centre, e_u, e_v, pitch, u_mid, v_mid,
                       u_ref, v_ref, u, v, out):
    """Signed surface tilt (rad) per pixel into ``out`` (P,) that moves the decoded monitor
    point from (u_ref, v_ref) to (u, v) on a planar pixel grid (as
    :func:`bisector_slopes_planar`): the angle between the bisector normals at ``points``
    (P, 3), signed by the larger coordinate change; NaN where any input is NaN. The NumPy
    reference is :func:`pmdsim.measure.reconstruct.slope_deviation_3d`."""
    for p in numba.prange(points.shape[0]):
        ur, vr, uu, vv = u_ref[p], v_ref[p], u[p], v[p]
        sx, sy, sz = points[p, 0], points[p, 1], points[p, 2]
        if not (math.isfinite(ur) and math.isfinite(vr) and math.isfinite(uu)
                and math.isfinite(vv) and math.isfinite(sx) and math.isfinite(sy)
                and math.isfinite(sz)):
            out[p] = np.nan
            continue
        mx, my, mz = _monitor_point(ur, vr, centre, e_u, e_v, pitch, u_mid, v_mid)
        nx0, ny0, nz0 = _bisector(sx, sy, sz, camera_position, mx, my, mz)
        out[p] = _tilt(nx0, ny0, nz0, sx, sy, sz, camera_position, ur, vr, uu, vv, centre, e_u,
                       e_v, pitch, u_mid, v_mid)


@parallel_jit(fastmath=False)
def slope_deviation_pair_3d(points, camera_position, centre, e_u, e_v, pitch, u_mid, v_mid,
                            u_ref, v_ref, coord, delta, along_u, scale, out, change):
    """:func:`slope_deviation_3d` of one fringe direction at two coordinate deviations, with
    the reference's normal once: ``out[p] = scale s(c)`` and ``change[p] = |scale s(c0 +
    delta) - scale s(c)|`` (``c = coord[p]``, ``c0`` = c or 0 where c is not finite: the
    numerical error's slope change, :func:`pmdsim.measure.numerical.propagate`), the
    deviation along u (``along_u``, x fringes) or v; NaN where an input is not finite."""
    for p in numba.prange(points.shape[0]):
        ur, vr, c = u_ref[p], v_ref[p], coord[p]
        sx, sy, sz = points[p, 0], points[p, 1], points[p, 2]
        s1 = np.nan
        s2 = np.nan
        if (math.isfinite(ur) and math.isfinite(vr) and math.isfinite(sx)
                and math.isfinite(sy) and math.isfinite(sz)):
            mx, my, mz = _monitor_point(ur, vr, centre, e_u, e_v, pitch, u_mid, v_mid)
            nx0, ny0, nz0 = _bisector(sx, sy, sz, camera_position, mx, my, mz)
            uu, vv = (ur + c, vr) if along_u else (ur, vr + c)
            if math.isfinite(uu) and math.isfinite(vv):
                s1 = _tilt(nx0, ny0, nz0, sx, sy, sz, camera_position, ur, vr, uu, vv, centre,
                           e_u, e_v, pitch, u_mid, v_mid)
            cm = (c if math.isfinite(c) else 0.0) + delta[p]
            uu, vv = (ur + cm, vr) if along_u else (ur, vr + cm)
            if math.isfinite(uu) and math.isfinite(vv):
                s2 = _tilt(nx0, ny0, nz0, sx, sy, sz, camera_position, ur, vr, uu, vv, centre,
                           e_u, e_v, pitch, u_mid, v_mid)
        v1 = s1 * scale
        out[p] = v1
        change[p] = abs(s2 * scale - v1)


@parallel_jit(fastmath=False)
def monitor_distance(points, u, v, centre, e_u, e_v, pitch, u_mid, v_mid, out):
    """Distance (mm) from each point (P, 3) to the monitor point of its coordinates (u, v)
    (P,) px on a planar pixel grid (:func:`_monitor_point`), into ``out`` (P,): NumPy's
    ``pixel_to_world`` and difference, the squares summed as NumPy's einsum sums three
    (x and z first); NaN where an input is NaN."""
    for p in numba.prange(points.shape[0]):
        mx, my, mz = _monitor_point(u[p], v[p], centre, e_u, e_v, pitch, u_mid, v_mid)
        dx = mx - points[p, 0]
        dy = my - points[p, 1]
        dz = mz - points[p, 2]
        out[p] = math.sqrt((dx * dx + dz * dz) + dy * dy)


#: :func:`node_support` codes: served by the spline, by the rim fit, not served (the pixel the
#: node falls in is invalid; it falls outside the image, or its coordinates are not finite)
SUPPORT_SPLINE, SUPPORT_RIM, SUPPORT_PIXEL_INVALID, SUPPORT_OUTSIDE = 0, 1, 2, 3


@parallel_jit(fastmath=False)
def node_support(valid, cols, rows, margin, status):
    """``status[k]`` (int8) of the fractional pixel (cols[k], rows[k]) (integers = pixel
    centres) in the decoded maps' validity ``valid`` (H, W): SUPPORT_SPLINE when the cubic
    spline's 4 x 4 support grown by ``margin`` pixels on every side (floor - 1 - margin ..
    floor + 2 + margin on each axis) lies inside the image and is valid; else SUPPORT_RIM
    when the pixel it falls in (the nearest, ``floor(x + 0.5)``) is inside and valid;
    SUPPORT_PIXEL_INVALID when that pixel is inside and invalid; SUPPORT_OUTSIDE when it is
    outside the image (or a coordinate is NaN or inf)."""
    h, w = valid.shape
    n = 4 + 2 * margin
    for k in numba.prange(status.shape[0]):
        c = cols[k]
        r = rows[k]
        if not (c >= -0.5 and r >= -0.5 and c < w - 0.5 and r < h - 0.5):  # also NaN, inf
            status[k] = SUPPORT_OUTSIDE
            continue
        cn = math.floor(c + 0.5)
        rn = math.floor(r + 0.5)
        if not valid[rn, cn]:
            status[k] = SUPPORT_PIXEL_INVALID
            continue
        c0 = math.floor(c) - 1 - margin
        r0 = math.floor(r) - 1 - margin
        full = c0 >= 0 and r0 >= 0 and c0 + n <= w and r0 + n <= h
        if full:
            for a in range(n):
                for b in range(n):
                    if not valid[r0 + a, c0 + b]:
                        full = False
        status[k] = SUPPORT_SPLINE if full else SUPPORT_RIM


#: The smallest Cholesky pivot (of the normal matrix scaled to a unit diagonal) that
#: :func:`rim_fit_nodes` takes as determined: a block whose valid pixels do not fix the cubic
#: (too few, or all on a line) has a pivot of the order of the rounding, 1e-16.
RIM_MIN_PIVOT = 1e-10


@parallel_jit(fastmath=False)
def rim_fit_nodes(u, v, valid, cols, rows, window, ti, tj, out_u, out_v, gain):
    """The rim fit at the fractional pixels (cols[k], rows[k]): the polynomial
    ``sum_t c_t dc^ti[t] dr^tj[t]`` (dc, dr: the pixel's offset from the node / (window //
    2)) fitted by least squares to the valid pixels of ``u`` and ``v`` in the ``window`` x
    ``window`` block floor - window/2 + 1 .. floor + window/2 about the node, evaluated at
    the node (``c_0``: the term ti = tj = 0 comes first): ``out_u``, ``out_v``; ``gain`` =
    sqrt(e0^T G^-1 e0) (G the normal matrix: the value's standard deviation per unit noise
    of each pixel). NaN / inf where the block holds fewer valid pixels than terms or G's
    unit-diagonal Cholesky pivot falls below :data:`RIM_MIN_PIVOT`. NumPy reference:
    ``numpy.linalg.lstsq`` of the same block (tests/measure)."""
    h, w = valid.shape
    half = window // 2
    nt = ti.shape[0]
    for k in numba.prange(cols.shape[0]):
        g = np.zeros((nt, nt))
        bu = np.zeros(nt)
        bv = np.zeros(nt)
        a = np.empty(nt)
        pc = np.empty(4)
        pr = np.empty(4)
        c = cols[k]
        r = rows[k]
        c0 = math.floor(c) - (half - 1)
        r0 = math.floor(r) - (half - 1)
        count = 0
        for jr in range(window):
            rr = r0 + jr
            if rr < 0 or rr >= h:
                continue
            dr = (rr - r) / half
            for jc in range(window):
                cc = c0 + jc
                if cc < 0 or cc >= w or not valid[rr, cc]:
                    continue
                dc = (cc - c) / half
                pc[0] = 1.0
                pr[0] = 1.0
                for p in range(1, 4):
                    pc[p] = pc[p - 1] * dc
                    pr[p] = pr[p - 1] * dr
                for t in range(nt):
                    a[t] = pc[ti[t]] * pr[tj[t]]
                fu = u[rr, cc]
                fv = v[rr, cc]
                for t in range(nt):
                    bu[t] += a[t] * fu
                    bv[t] += a[t] * fv
                    for s in range(t + 1):
                        g[t, s] += a[t] * a[s]
                count += 1
        out_u[k] = np.nan
        out_v[k] = np.nan
        gain[k] = np.inf
        if count < nt:
            continue
        # Cholesky of D^-1/2 G D^-1/2 (lower triangle of g, unit diagonal), in place
        d = np.empty(nt)
        ok = True
        for t in range(nt):
            if not g[t, t] > 0.0:
                ok = False
                break
            d[t] = 1.0 / math.sqrt(g[t, t])
        if not ok:
            continue
        for t in range(nt):
            for s in range(t + 1):
                g[t, s] *= d[t] * d[s]
        for j in range(nt):
            x = g[j, j]
            for p in range(j):
                x -= g[j, p] * g[j, p]
            if not x > RIM_MIN_PIVOT:
                ok = False
                break
            g[j, j] = math.sqrt(x)
            for i in range(j + 1, nt):
                y = g[i, j]
                for p in range(j):
                    y -= g[i, p] * g[j, p]
                g[i, j] = y / g[j, j]
        if not ok:
            continue
        # z = G^-1 e0 = D (L L^T)^-1 D e0: forward then back substitution
        z = np.zeros(nt)
        z[0] = d[0]
        for i in range(nt):
            y = z[i]
            for p in range(i):
                y -= g[i, p] * z[p]
            z[i] = y / g[i, i]
        for i in range(nt - 1, -1, -1):
            y = z[i]
            for p in range(i + 1, nt):
                y -= g[p, i] * z[p]
            z[i] = y / g[i, i]
        su = 0.0
        sv = 0.0
        for t in range(nt):
            z[t] *= d[t]
            su += z[t] * bu[t]
            sv += z[t] * bv[t]
        out_u[k] = su
        out_v[k] = sv
        gain[k] = math.sqrt(abs(z[0]))
