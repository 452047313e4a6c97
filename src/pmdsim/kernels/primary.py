"""Vision rays per camera pixel -> surface hit, BRDF frame, P, and the bundle geometry rows.

The compiled twin of :func:`pmdsim.trace.trace_primary` + :func:`pmdsim.trace.bundle_geometry`
(the NumPy versions are the reference the tests compare with). Scene parts arrive as
parameter vectors (layouts ``CAM_*``, ``SURF_*``, ``FRAME_*``, ``MON_*``); a new surface
type adds its parameter layout and one branch in :func:`_intersect`.
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import borrow, fastjit, jit
from .bundle import G_A, G_B, G_C, G_SIZE, G_T, G_U0, G_V0, G_VALID, G_X, G_Y, G_Z
from .surface import SURF_SAG, intersect_sag

# camera: position (3), rotation row-major (9; columns = camera x, y, z), focal px, cx, cy
CAM_POS = 0
CAM_ROT = 3
CAM_F = 12
CAM_CX = 13
CAM_CY = 14
CAM_SIZE = 15

# surface: type, centre (3), normal (3), x axis (3), y axis (3), half sizes (2)
SURF_TYPE = 0
SURF_FLAT = 0
# SURF_SAG = 1 (sphere, conic, asphere, freeforms, height maps): layout SAG_* in kernels/surface.py
SURF_C = 1
SURF_N = 4
SURF_X = 7
SURF_Y = 10
SURF_HALF = 13
SURF_SIZE = 15

# anisotropy frame: type, centre (3), axis (3), has_axis, x direction (3)
FRAME_TYPE = 0
FRAME_FIXED = 0
FRAME_ROTATIONAL = 1
FRAME_C = 1
FRAME_AXIS = 4
FRAME_HAS_AXIS = 7
FRAME_DIR = 8
FRAME_SIZE = 11

# monitor: centre (3), e_u (3), e_v (3), normal (3), pitch, width, height
MON_C = 0
MON_EU = 3
MON_EV = 6
MON_N = 9
MON_PITCH = 12
MON_W = 13
MON_H = 14
MON_SIZE = 15


@fastjit(inline="always")
def _intersect(surf, ox, oy, oz, dx, dy, dz):
    """(hit, t, px, py, pz, nx, ny, nz) of one ray with the surface."""
    if surf[SURF_TYPE] == SURF_SAG:  # curved and measured surfaces: kernels/surface.py
        return intersect_sag(surf, ox, oy, oz, dx, dy, dz)
    cx = surf[SURF_C]
    cy = surf[SURF_C + 1]
    cz = surf[SURF_C + 2]
    nx = surf[SURF_N]
    ny = surf[SURF_N + 1]
    nz = surf[SURF_N + 2]
    dn = dx * nx + dy * ny + dz * nz
    t = ((cx - ox) * nx + (cy - oy) * ny + (cz - oz) * nz) / dn
    px = ox + t * dx
    py = oy + t * dy
    pz = oz + t * dz
    lx = (px - cx) * surf[SURF_X] + (py - cy) * surf[SURF_X + 1] + (pz - cz) * surf[SURF_X + 2]
    ly = (px - cx) * surf[SURF_Y] + (py - cy) * surf[SURF_Y + 1] + (pz - cz) * surf[SURF_Y + 2]
    hit = (t > 0.0) & (abs(lx) <= surf[SURF_HALF]) & (abs(ly) <= surf[SURF_HALF + 1])
    return hit, t, px, py, pz, nx, ny, nz


@fastjit(inline="always")
def _normalize(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    if n > 0.0:
        return x / n, y / n, z / n, n
    return 0.0, 0.0, 0.0, 0.0


@fastjit(inline="always")
def _project_tangent(dx, dy, dz, nx, ny, nz):
    """Unit projection of d onto the tangent plane of n (a perpendicular if d is along n)."""
    k = dx * nx + dy * ny + dz * nz
    x, y, z, m = _normalize(dx - k * nx, dy - k * ny, dz - k * nz)
    if m < 1e-9:
        if abs(dy) < 0.9:  # n x (0, 1, 0)
            x, y, z, m = _normalize(-nz, 0.0, nx)
        else:  # n x (1, 0, 0)
            x, y, z, m = _normalize(0.0, nz, -ny)
    return x, y, z


@fastjit(inline="always")
def _fixed_frame(frame, nx, ny, nz):
    """(x, y) of the fixed BRDF frame: x = the frame's x direction in the tangent plane,
    y = n x x."""
    xx, xy, xz = _project_tangent(
        frame[FRAME_DIR], frame[FRAME_DIR + 1], frame[FRAME_DIR + 2], nx, ny, nz
    )
    return xx, xy, xz, ny * xz - nz * xy, nz * xx - nx * xz, nx * xy - ny * xx


@fastjit(inline="always")
def _fill_row(surf, frame, mon, ox, oy, oz, dx, dy, dz, g, spec_k):
    """Geometry row ``g`` (G_SIZE) and exact monitor hit ``spec_k`` (2) of one vision ray from
    (ox, oy, oz) along the unit direction (dx, dy, dz): zeros / NaN where it misses the
    surface or sees its back."""
    mcx = mon[MON_C]
    mcy = mon[MON_C + 1]
    mcz = mon[MON_C + 2]
    eux = mon[MON_EU]
    euy = mon[MON_EU + 1]
    euz = mon[MON_EU + 2]
    evx = mon[MON_EV]
    evy = mon[MON_EV + 1]
    evz = mon[MON_EV + 2]
    mnx = mon[MON_N]
    mny = mon[MON_N + 1]
    mnz = mon[MON_N + 2]
    pitch = mon[MON_PITCH]
    wm = mon[MON_W]
    hm = mon[MON_H]
    ftype = int(frame[FRAME_TYPE])
    for q in range(G_SIZE):
        g[q] = 0.0
    spec_k[0] = np.nan
    spec_k[1] = np.nan
    hit, t, sx, sy, sz, nx, ny, nz = _intersect(surf, ox, oy, oz, dx, dy, dz)
    ix = -dx
    iy = -dy
    iz = -dz
    cos_i = ix * nx + iy * ny + iz * nz
    if not hit or cos_i <= 0.0:
        return
    # BRDF frame
    if ftype == FRAME_ROTATIONAL:
        rx = sx - frame[FRAME_C]
        ry = sy - frame[FRAME_C + 1]
        rz = sz - frame[FRAME_C + 2]
        if frame[FRAME_HAS_AXIS] != 0.0:
            ax_ = frame[FRAME_AXIS]
            ay_ = frame[FRAME_AXIS + 1]
            az_ = frame[FRAME_AXIS + 2]
        else:
            ax_ = nx
            ay_ = ny
            az_ = nz
        ra = rx * ax_ + ry * ay_ + rz * az_
        rx -= ra * ax_
        ry -= ra * ay_
        rz -= ra * az_
        rn = rx * nx + ry * ny + rz * nz
        yx, yy, yz, m = _normalize(rx - rn * nx, ry - rn * ny, rz - rn * nz)
        if m > 1e-9:
            # x = tangential = radial x n
            xx = yy * nz - yz * ny
            xy = yz * nx - yx * nz
            xz = yx * ny - yy * nx
        else:
            xx, xy, xz, yx, yy, yz = _fixed_frame(frame, nx, ny, nz)
    else:
        xx, xy, xz, yx, yy, yz = _fixed_frame(frame, nx, ny, nz)
    # principal direction and cone basis
    ppx = 2.0 * cos_i * nx - ix
    ppy = 2.0 * cos_i * ny - iy
    ppz = 2.0 * cos_i * nz - iz
    e2x, e2y, e2z, m = _normalize(ny * ppz - nz * ppy, nz * ppx - nx * ppz, nx * ppy - ny * ppx)
    if m < 1e-12:
        e2x, e2y, e2z = yx, yy, yz
    e1x = e2y * ppz - e2z * ppy
    e1y = e2z * ppx - e2x * ppz
    e1z = e2x * ppy - e2y * ppx
    # geometry row
    ddx = sx - mcx
    ddy = sy - mcy
    ddz = sz - mcz
    g[G_T] = -(ddx * mnx + ddy * mny + ddz * mnz)
    g[G_U0] = (ddx * eux + ddy * euy + ddz * euz) / pitch + (wm - 1.0) / 2.0
    g[G_V0] = (ddx * evx + ddy * evy + ddz * evz) / pitch + (hm - 1.0) / 2.0
    bx = (e1x, e2x, ppx)
    by = (e1y, e2y, ppy)
    bz = (e1z, e2z, ppz)
    for q in range(3):
        g[G_A + q] = bx[q] * mnx + by[q] * mny + bz[q] * mnz
        g[G_B + q] = (bx[q] * eux + by[q] * euy + bz[q] * euz) / pitch
        g[G_C + q] = (bx[q] * evx + by[q] * evy + bz[q] * evz) / pitch
        g[G_X + 1 + q] = bx[q] * xx + by[q] * xy + bz[q] * xz
        g[G_Y + 1 + q] = bx[q] * yx + by[q] * yy + bz[q] * yz
        g[G_Z + 1 + q] = bx[q] * nx + by[q] * ny + bz[q] * nz
    g[G_X] = ix * xx + iy * xy + iz * xz
    g[G_Y] = ix * yx + iy * yy + iz * yz
    g[G_Z] = cos_i
    g[G_VALID] = 1.0
    # exact monitor hit of P
    dn = g[G_A + 2]
    tm = g[G_T] / dn
    u = g[G_U0] + tm * g[G_B + 2]
    v = g[G_V0] + tm * g[G_C + 2]
    if (dn < 0.0) & (tm > 0.0) & (u >= -0.5) & (u < wm - 0.5) & (v >= -0.5) & (v < hm - 0.5):
        spec_k[0] = u
        spec_k[1] = v


@fastjit
def geometry_tile(cam, surf, frame, mon, row0, row1, width, geo, spec):
    """Fill ``geo`` ((row1-row0)*width, G_SIZE) and ``spec`` (same rows, 2): the bundle
    geometry rows (cone basis about P) and the exact monitor coordinates (u, v) of P (NaN
    where P misses the monitor or the vision ray misses the surface). One pinhole ray
    through each pixel centre."""
    # reference-count-free views for the pixel loop (the arguments outlive it)
    cam, surf, frame, mon = borrow(cam), borrow(surf), borrow(frame), borrow(mon)
    geo, spec = borrow(geo), borrow(spec)
    px0 = cam[CAM_POS]
    py0 = cam[CAM_POS + 1]
    pz0 = cam[CAM_POS + 2]
    f = cam[CAM_F]
    ccx = cam[CAM_CX]
    ccy = cam[CAM_CY]
    k = 0
    for r in range(row0, row1):
        for c in range(width):
            xc = (c - ccx) / f
            yc = (r - ccy) / f
            dx = cam[CAM_ROT] * xc + cam[CAM_ROT + 1] * yc + cam[CAM_ROT + 2]
            dy = cam[CAM_ROT + 3] * xc + cam[CAM_ROT + 4] * yc + cam[CAM_ROT + 5]
            dz = cam[CAM_ROT + 6] * xc + cam[CAM_ROT + 7] * yc + cam[CAM_ROT + 8]
            dx, dy, dz, _ = _normalize(dx, dy, dz)
            _fill_row(surf, frame, mon, px0, py0, pz0, dx, dy, dz, geo[k], spec[k])
            k += 1


@fastjit
def geometry_rays(origins, dirs, surf, frame, mon, geo, spec):
    """:func:`geometry_tile` for explicit vision rays: ``origins`` and unit ``dirs`` (R, 3)
    (a thin lens's aperture samples, sub-pixel rays) -> ``geo`` (R, G_SIZE), ``spec`` (R, 2)."""
    origins, dirs, surf, frame = borrow(origins), borrow(dirs), borrow(surf), borrow(frame)
    mon, geo, spec = borrow(mon), borrow(geo), borrow(spec)
    for k in range(origins.shape[0]):
        _fill_row(surf, frame, mon, origins[k, 0], origins[k, 1], origins[k, 2],
                  dirs[k, 0], dirs[k, 1], dirs[k, 2], geo[k], spec[k])


@fastjit
def geometry_lens(pos, rot, chief, aperture, focus, surf, frame, mon, geo, spec):
    """Thin-lens vision rays and their geometry rows in one pass.

    ``pos`` (3,) lens centre, ``rot`` (3, 3) camera axes as columns (world), ``chief``
    (P, n2, 3) chief-ray directions (x', y', 1) of every pixel's sub-pixel points in camera
    coordinates, ``aperture`` (P, m, 2) aperture points (mm, camera x, y), ``focus`` the depth
    of the plane in focus (mm; <= 0: pinhole, the chief rays themselves, m must be 1). Ray
    (p, s, a) starts at ``pos + rot (A, 0)`` towards the in-focus point ``focus * chief`` and
    fills row ``(p * n2 + s) * m + a`` of ``geo`` / ``spec``."""
    pos, rot, chief, aperture = borrow(pos), borrow(rot), borrow(chief), borrow(aperture)
    surf, frame, mon, geo, spec = borrow(surf), borrow(frame), borrow(mon), borrow(geo), borrow(spec)
    npix = chief.shape[0]
    n2 = chief.shape[1]
    m = aperture.shape[1]
    k = 0
    for p in range(npix):
        for s in range(n2):
            cx = chief[p, s, 0]
            cy = chief[p, s, 1]
            cz = chief[p, s, 2]
            for a in range(m):
                ax = aperture[p, a, 0]
                ay = aperture[p, a, 1]
                if focus > 0.0:
                    lx = focus * cx - ax
                    ly = focus * cy - ay
                    lz = focus * cz
                else:
                    lx = cx
                    ly = cy
                    lz = cz
                dx = rot[0, 0] * lx + rot[0, 1] * ly + rot[0, 2] * lz
                dy = rot[1, 0] * lx + rot[1, 1] * ly + rot[1, 2] * lz
                dz = rot[2, 0] * lx + rot[2, 1] * ly + rot[2, 2] * lz
                dx, dy, dz, _ = _normalize(dx, dy, dz)
                ox = pos[0] + rot[0, 0] * ax + rot[0, 1] * ay
                oy = pos[1] + rot[1, 0] * ax + rot[1, 1] * ay
                oz = pos[2] + rot[2, 0] * ax + rot[2, 1] * ay
                _fill_row(surf, frame, mon, ox, oy, oz, dx, dy, dz, geo[k], spec[k])
                k += 1


@jit
def orient_rows(geo, ix2, iy2):
    """Turn each row's cone basis (b1, b2) of the geometry rows ``geo`` (P, G_SIZE) about P,
    in place, so that b1 lies on the long axis of the lobe ``exp(-(h_x^2 ix2 + h_y^2 iy2))``
    (``ix2 = 1 / ax^2``, ``iy2 = 1 / ay^2``): the angle ``phi0 = atan2(2 Q12, Q11 - Q22) / 2
    + pi / 2`` of :meth:`pmdsim.scene.sampling.ConeSampling.orient`, whose NumPy passes this
    replaces (strict IEEE arithmetic)."""
    for p in range(geo.shape[0]):
        x1 = geo[p, G_X + 1]
        x2 = geo[p, G_X + 2]
        y1 = geo[p, G_Y + 1]
        y2 = geo[p, G_Y + 2]
        q11 = x1 * x1 * ix2 + y1 * y1 * iy2
        q12 = x1 * x2 * ix2 + y1 * y2 * iy2
        q22 = x2 * x2 * ix2 + y2 * y2 * iy2
        phi0 = 0.5 * math.atan2(2.0 * q12, q11 - q22) + 0.5 * math.pi
        c = math.cos(phi0)
        s = math.sin(phi0)
        for k in (G_A, G_B, G_C, G_X + 1, G_Y + 1, G_Z + 1):
            p1 = geo[p, k]
            p2 = geo[p, k + 1]
            geo[p, k] = c * p1 + s * p2
            geo[p, k + 1] = c * p2 - s * p1
