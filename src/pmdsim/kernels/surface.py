"""Compiled sag surfaces: conic + even asphere + XY polynomial + bicubic height map.

One parameter vector (float64) describes a surface in its local frame (vertex at the
origin, local z = the configured normal, sag z(x, y) along it). The header layout is
``SAG_*``; variable-length parts (asphere coefficients, XY polynomial matrix, height-map
B-spline coefficients) follow the header at the offsets the header stores. Built by
:class:`pmdsim.scene.surfaces.SagSurface`; the first 13 entries (type, vertex, normal, x, y)
share the layout of the flat surface (``kernels.primary.SURF_*``).

sag(x, y) = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2))          base conic, r^2 = x^2 + y^2
          + sum_i A_i r^(2i + 4)                              even asphere A4, A6, ...
          + sum_ij C_ij (x / s)^i (y / s)^j                   XY polynomial (s: norm radius)
          + sum_ij b_ij B3((x - x0) / dx - j) B3((y - y0) / dy - i)   height map (cubic B-spline)

Intersection: the base conic's closed form (the whole answer for plane, sphere and conic),
then safeguarded Newton on F(t) = o_z + t d_z - sag(o_x + t d_x, o_y + t d_y) (bracketing
with bisection once a sign change is seen, step limit and backtracking while the sag is
undefined); no convergence, grazing (|F'| tiny) or outside the aperture = miss.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._jit import fastjit, parallel_jit

SURF_SAG = 1

SAG_C = 1  # vertex (3)
SAG_N = 4  # local z (3)
SAG_X = 7  # local x (3)
SAG_Y = 10  # local y (3)
SAG_AP_TYPE = 13  # 0 rectangular, 1 circular, 2 annular
SAG_AP_CX = 14  # aperture centre in local x, y (off-axis segments)
SAG_AP_CY = 15
SAG_AP_A = 16  # half width x | outer radius
SAG_AP_B = 17  # half width y | inner radius
SAG_CURV = 18  # c = 1 / R (1/mm), 0 = plane
SAG_CONIC = 19  # k
SAG_N_ASPH = 20  # number of asphere coefficients (A4, A6, ...)
SAG_POLY_DEG = 21  # XY polynomial degree P per variable; -1 = none
SAG_POLY_NORM = 22  # s (mm)
SAG_MAP = 23  # 1 = height map present
SAG_MAP_NX = 24
SAG_MAP_NY = 25
SAG_MAP_X0 = 26  # local x of map column 0 (mm)
SAG_MAP_Y0 = 27  # local y of map row 0 (mm)
SAG_MAP_DX = 28
SAG_MAP_DY = 29
SAG_OFF_ASPH = 30
SAG_OFF_POLY = 31
SAG_OFF_MAP = 32
SAG_SCALE = 33  # a length of the aperture's size (mm): Newton step limit and tolerance
SAG_HEADER = 34

AP_RECT = 0
AP_CIRC = 1
AP_ANNULUS = 2


@fastjit(inline="always")
def _bspline3(t):
    """Cubic B-spline weights and derivatives at fraction t in [0, 1]."""
    t2 = t * t
    t3 = t2 * t
    u = 1.0 - t
    w0 = u * u * u / 6.0
    w1 = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    w2 = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    w3 = t3 / 6.0
    d0 = -0.5 * u * u
    d1 = 1.5 * t2 - 2.0 * t
    d2 = -1.5 * t2 + t + 0.5
    d3 = 0.5 * t2
    return w0, w1, w2, w3, d0, d1, d2, d3


@fastjit
def sag(surf, x, y):
    """(ok, z, dz/dx, dz/dy) at local (x, y) mm; ok = False outside the conic's domain or
    the height map."""
    c = surf[SAG_CURV]
    k = surf[SAG_CONIC]
    r2 = x * x + y * y
    arg = 1.0 - (1.0 + k) * c * c * r2
    if arg <= 0.0:
        return False, 0.0, 0.0, 0.0
    s = math.sqrt(arg)
    z = c * r2 / (1.0 + s)
    zx = c * x / s
    zy = c * y / s
    na = int(surf[SAG_N_ASPH])
    if na > 0:
        off = int(surf[SAG_OFF_ASPH])
        p = r2  # r^(2i + 2)
        for i in range(na):
            a = surf[off + i]
            z += a * p * r2
            g = a * (2.0 * i + 4.0) * p  # d(r^(2i+4))/dr / r
            zx += g * x
            zy += g * y
            p *= r2
    deg = int(surf[SAG_POLY_DEG])
    if deg >= 0:
        off = int(surf[SAG_OFF_POLY])
        sn = surf[SAG_POLY_NORM]
        u = x / sn
        v = y / sn
        n1 = deg + 1
        pz = 0.0
        pu = 0.0
        pv = 0.0
        ui = 1.0  # u^i
        ui1 = 0.0  # i u^(i-1)
        for i in range(n1):
            q = 0.0
            dq = 0.0
            vj = 1.0
            jv = 0.0
            for j in range(n1):
                cij = surf[off + i * n1 + j]
                q += cij * vj
                dq += cij * jv
                jv = (j + 1) * vj
                vj *= v
            pz += ui * q
            pu += ui1 * q
            pv += ui * dq
            ui1 = (i + 1) * ui
            ui *= u
        z += pz
        zx += pu / sn
        zy += pv / sn
    if surf[SAG_MAP] != 0.0:
        nx = int(surf[SAG_MAP_NX])
        ny = int(surf[SAG_MAP_NY])
        ddx = surf[SAG_MAP_DX]
        ddy = surf[SAG_MAP_DY]
        fx = (x - surf[SAG_MAP_X0]) / ddx
        fy = (y - surf[SAG_MAP_Y0]) / ddy
        if not ((fx >= 0.0) & (fx <= nx - 1.0) & (fy >= 0.0) & (fy <= ny - 1.0)):
            return False, 0.0, 0.0, 0.0
        ix = min(int(math.floor(fx)), nx - 2)
        iy = min(int(math.floor(fy)), ny - 2)
        tx = fx - ix
        ty = fy - iy
        wx0, wx1, wx2, wx3, dx0, dx1, dx2, dx3 = _bspline3(tx)
        wy0, wy1, wy2, wy3, dy0, dy1, dy2, dy3 = _bspline3(ty)
        wx = (wx0, wx1, wx2, wx3)
        dwx = (dx0, dx1, dx2, dx3)
        wy = (wy0, wy1, wy2, wy3)
        dwy = (dy0, dy1, dy2, dy3)
        off = int(surf[SAG_OFF_MAP])
        stride = nx + 4
        mz = 0.0
        mx = 0.0
        my = 0.0
        for a in range(4):
            row = off + (iy + 1 + a) * stride + ix + 1  # padded by 2: index - 1 + 2
            rz = 0.0
            rx = 0.0
            for b in range(4):
                cb = surf[row + b]
                rz += wx[b] * cb
                rx += dwx[b] * cb
            mz += wy[a] * rz
            mx += wy[a] * rx
            my += dwy[a] * rz
        z += mz
        zx += mx / ddx
        zy += my / ddy
    return True, z, zx, zy


@fastjit(inline="always")
def _conic_root(c, k, ox, oy, oz, dx, dy, dz):
    """Smallest t > 0 where the ray meets the base conic's vertex branch; -1 if none.
    c (x^2 + y^2 + (1 + k) z^2) - 2 z = 0 with (1 + k) c z < 1 on the branch."""
    kk = 1.0 + k
    a = c * (dx * dx + dy * dy + kk * dz * dz)
    b = 2.0 * c * (ox * dx + oy * dy + kk * oz * dz) - 2.0 * dz
    e = c * (ox * ox + oy * oy + kk * oz * oz) - 2.0 * oz
    best = -1.0
    if abs(a) < 1e-300:
        if b != 0.0:
            t = -e / b
            if t > 0.0:
                best = t
        return best
    disc = b * b - 4.0 * a * e
    if disc < 0.0:
        return best
    sq = math.sqrt(disc)
    q = -0.5 * (b + sq) if b >= 0.0 else -0.5 * (b - sq)
    t1 = q / a
    t2 = e / q if q != 0.0 else t1
    for t in (t1, t2):
        if t > 0.0:
            z = oz + t * dz
            if kk * c * z < 1.0 and (best < 0.0 or t < best):
                best = t
    return best


@fastjit(inline="always")
def _in_aperture(surf, x, y):
    ax = x - surf[SAG_AP_CX]
    ay = y - surf[SAG_AP_CY]
    kind = int(surf[SAG_AP_TYPE])
    if kind == AP_RECT:
        return (abs(ax) <= surf[SAG_AP_A]) & (abs(ay) <= surf[SAG_AP_B])
    r2 = ax * ax + ay * ay
    if kind == AP_CIRC:
        return r2 <= surf[SAG_AP_A] * surf[SAG_AP_A]
    return (r2 <= surf[SAG_AP_A] * surf[SAG_AP_A]) & (r2 >= surf[SAG_AP_B] * surf[SAG_AP_B])


@fastjit
def intersect_sag(surf, ox, oy, oz, dx, dy, dz):
    """(hit, t, px, py, pz, nx, ny, nz) of one world ray with a sag surface (world normal
    on the local +z side)."""
    cx = ox - surf[SAG_C]
    cy = oy - surf[SAG_C + 1]
    cz = oz - surf[SAG_C + 2]
    # to the local frame (rows of R^T = local axes)
    lox = cx * surf[SAG_X] + cy * surf[SAG_X + 1] + cz * surf[SAG_X + 2]
    loy = cx * surf[SAG_Y] + cy * surf[SAG_Y + 1] + cz * surf[SAG_Y + 2]
    loz = cx * surf[SAG_N] + cy * surf[SAG_N + 1] + cz * surf[SAG_N + 2]
    ldx = dx * surf[SAG_X] + dy * surf[SAG_X + 1] + dz * surf[SAG_X + 2]
    ldy = dx * surf[SAG_Y] + dy * surf[SAG_Y + 1] + dz * surf[SAG_Y + 2]
    ldz = dx * surf[SAG_N] + dy * surf[SAG_N + 1] + dz * surf[SAG_N + 2]
    c = surf[SAG_CURV]
    pure = (surf[SAG_N_ASPH] == 0.0) & (surf[SAG_POLY_DEG] < 0.0) & (surf[SAG_MAP] == 0.0)
    t = _conic_root(c, surf[SAG_CONIC], lox, loy, loz, ldx, ldy, ldz)
    fail = (False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if t < 0.0:
        if pure or ldz == 0.0:
            return fail
        t = -loz / ldz  # the vertex plane as a start
        if t <= 0.0:
            return fail
    ok, z, zx, zy = sag(surf, lox + t * ldx, loy + t * ldy)
    if not pure:
        scale = surf[SAG_SCALE]
        tol = 1e-13 * (abs(t) + scale)
        has_br = False
        ta = 0.0
        tb = 0.0
        fa = 0.0
        converged = False
        for _ in range(80):
            if not ok:
                return fail
            f = loz + t * ldz - z
            df = ldz - zx * ldx - zy * ldy
            if f == 0.0:
                converged = True
                break
            # keep / update a bracket [ta, tb] with sign change (fa = F(ta))
            if has_br:
                if (f > 0.0) == (fa > 0.0):
                    ta = t
                    fa = f
                else:
                    tb = t
            if abs(df) < 1e-12:
                return fail  # grazing
            tn = t - f / df
            if has_br:
                lo = min(ta, tb)
                hi = max(ta, tb)
                if not ((tn > lo) & (tn < hi)):
                    tn = 0.5 * (ta + tb)
            else:
                step = tn - t
                if abs(step) > scale:
                    tn = t + math.copysign(scale, step)
            # backtrack while the sag is undefined at the new point
            okn, zn, zxn, zyn = sag(surf, lox + tn * ldx, loy + tn * ldy)
            nb = 0
            while (not okn) and nb < 40:
                tn = 0.5 * (t + tn)
                okn, zn, zxn, zyn = sag(surf, lox + tn * ldx, loy + tn * ldy)
                nb += 1
            if not okn:
                return fail
            fn = loz + tn * ldz - zn
            if (not has_br) and ((fn > 0.0) != (f > 0.0)):
                has_br = True
                ta = t
                fa = f
                tb = tn
            dt = tn - t
            t = tn
            ok, z, zx, zy = okn, zn, zxn, zyn
            if abs(dt) < tol:
                converged = True
                break
        if not converged or t <= 0.0:
            return fail
    if not ok:
        return fail
    x = lox + t * ldx
    y = loy + t * ldy
    if not _in_aperture(surf, x, y):
        return fail
    inv = 1.0 / math.sqrt(1.0 + zx * zx + zy * zy)
    lnx = -zx * inv
    lny = -zy * inv
    lnz = inv
    nx = lnx * surf[SAG_X] + lny * surf[SAG_Y] + lnz * surf[SAG_N]
    ny = lnx * surf[SAG_X + 1] + lny * surf[SAG_Y + 1] + lnz * surf[SAG_N + 1]
    nz = lnx * surf[SAG_X + 2] + lny * surf[SAG_Y + 2] + lnz * surf[SAG_N + 2]
    return True, t, ox + t * dx, oy + t * dy, oz + t * dz, nx, ny, nz


@fastjit
def intersect_many(surf, origins, dirs, t_out, p_out, n_out, hit_out):
    """Loop of :func:`intersect_sag` over (M, 3) rays (NaN t/points/normals on misses)."""
    for q in range(origins.shape[0]):
        hit, t, px, py, pz, nx, ny, nz = intersect_sag(
            surf, origins[q, 0], origins[q, 1], origins[q, 2], dirs[q, 0], dirs[q, 1], dirs[q, 2]
        )
        hit_out[q] = hit
        if hit:
            t_out[q] = t
            p_out[q, 0] = px
            p_out[q, 1] = py
            p_out[q, 2] = pz
            n_out[q, 0] = nx
            n_out[q, 1] = ny
            n_out[q, 2] = nz
        else:
            t_out[q] = np.nan
            for a in range(3):
                p_out[q, a] = np.nan
                n_out[q, a] = np.nan


@fastjit
def sag_many(surf, x, y, z_out, zx_out, zy_out, ok_out):
    """Loop of :func:`sag` over (M,) local coordinates."""
    for q in range(x.shape[0]):
        ok, z, zx, zy = sag(surf, x[q], y[q])
        ok_out[q] = ok
        z_out[q] = z if ok else np.nan
        zx_out[q] = zx if ok else np.nan
        zy_out[q] = zy if ok else np.nan


@parallel_jit
def bspline_eval_pair(cu, cv, rows, cols, out_u, out_v):
    """Cubic B-spline of two coefficient grids (each padded by 2 on every side, as from
    :func:`pmdsim.scene.surfaces.bspline_coefficients`) at fractional (rows, cols) of the
    unpadded grid, clamped to it; shares the weights between the two grids."""
    ny = cu.shape[0] - 4
    nx = cu.shape[1] - 4
    for q in numba.prange(rows.shape[0]):
        fy = min(max(rows[q], 0.0), ny - 1.0)
        fx = min(max(cols[q], 0.0), nx - 1.0)
        iy = min(int(math.floor(fy)), ny - 2)
        ix = min(int(math.floor(fx)), nx - 2)
        wx0, wx1, wx2, wx3, _, _, _, _ = _bspline3(fx - ix)
        wy0, wy1, wy2, wy3, _, _, _, _ = _bspline3(fy - iy)
        wx = (wx0, wx1, wx2, wx3)
        wy = (wy0, wy1, wy2, wy3)
        su = 0.0
        sv = 0.0
        for a in range(4):
            ru = 0.0
            rv = 0.0
            r = iy + 1 + a
            for b in range(4):
                c = ix + 1 + b
                ru += wx[b] * cu[r, c]
                rv += wx[b] * cv[r, c]
            su += wy[a] * ru
            sv += wy[a] * rv
        out_u[q] = su
        out_v[q] = sv
