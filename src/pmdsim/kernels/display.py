"""The display's geometry and falloff, applied to the phase-1 buffers of the bundle
kernels (``mon_corr``): flatness (polynomial and height map), cover glass refraction and
angular falloff (docs/system.md)."""

from __future__ import annotations

import math

import numpy as np

from ._jit import fastjit
from .layout import (G_T, G_U0, G_V0, MC_COEF, MC_FALL_M, MC_FALL_N, MC_FLAT_N, MC_GLASS_N,
                     MC_GLASS_T, MC_MAP_C, MC_MAP_R, MC_PITCH, MC_UC, MC_VC)


@fastjit(inline="always")
def _flat_height(mc, n, x, y, map0, mr, mcols, gu, gv):
    """h(x, y) (mm) of the display's emitting surface: the polynomial sum_ij c[i, j] x^i y^j
    plus the bilinearly interpolated height map at grid coordinates (gu, gv) (clamped)."""
    h = 0.0
    xi = 1.0
    for i in range(n):
        yj = 1.0
        for j in range(n):
            h += mc[MC_COEF + i * n + j] * xi * yj
            yj *= y
        xi *= x
    if mr > 0:
        gu = min(max(gu, 0.0), mcols - 1.0)
        gv = min(max(gv, 0.0), mr - 1.0)
        i0 = min(int(gv), mr - 2) if mr > 1 else 0
        j0 = min(int(gu), mcols - 2) if mcols > 1 else 0
        fv = gv - i0
        fu = gu - j0
        i1 = min(i0 + 1, mr - 1)
        j1 = min(j0 + 1, mcols - 1)
        h00 = mc[map0 + i0 * mcols + j0]
        h01 = mc[map0 + i0 * mcols + j1]
        h10 = mc[map0 + i1 * mcols + j0]
        h11 = mc[map0 + i1 * mcols + j1]
        h += (1.0 - fv) * ((1.0 - fu) * h00 + fu * h01) + fv * ((1.0 - fu) * h10 + fu * h11)
    return h


@fastjit
def monitor_correction(g, mc, n, wm, hm, ubuf, vbuf, iubuf, ivbuf, fbuf):
    """Move the phase-1 monitor hits of one pixel's ``n`` rays from the nominal (flat, bare)
    monitor plane to the display's pixels, and weight them by its angular falloff; returns
    the new sum of weights over monitor hits.

    The ray direction follows from its plane hit: with ``T = G_T`` (minus the distance of
    the surface point from the plane), ``o = (du pitch, dv pitch, T) / |.|`` in (e_u, e_v,
    n_m), ``du = u - G_U0``. Then, per ray, with ``c = -o.n_m = cos(theta)``:

    - flatness: the emitting surface lies at height ``h(x, y)`` (mm, towards the viewer)
      over the plane point (x, y) (polynomial plus bilinear height map); the ray meets it at
      ``(x, y) - h (o_u, o_v) / c`` (fixed-point iteration, converged for slopes << 1);
    - cover glass of thickness ``t_g`` and index ``n_g`` in front of the pixels: the ray
      refracts (``sin theta_r = sin theta / n_g``) and reaches the pixels
      ``t_g (tan theta - tan theta_r)`` closer to the point below its entry, i.e. shifted
      by ``-t_g (o_u, o_v) (1/c - 1/sqrt(n_g^2 - sin^2 theta))``;
    - falloff: the weight is multiplied by ``cos(theta)^m`` and/or the tabulated factor.

    Rays that leave the pixel grid get weight 0 (rays moved onto the grid from outside are
    not recovered: an edge band of ``t_g tan(theta)`` px).
    """
    T = g[G_T]
    U0 = g[G_U0]
    V0 = g[G_V0]
    tg = mc[MC_GLASS_T]
    ng = mc[MC_GLASS_N]
    pitch = mc[MC_PITCH]
    uc = mc[MC_UC]
    vc = mc[MC_VC]
    nflat = int(mc[MC_FLAT_N])
    fall_m = mc[MC_FALL_M]
    nfall = int(mc[MC_FALL_N])
    tab0 = MC_COEF + nflat * nflat
    mr = int(mc[MC_MAP_R])
    mcols = int(mc[MC_MAP_C])
    map0 = tab0 + 2 * nfall
    su = (mcols - 1.0) / max(wm - 1.0, 1.0)  # height-map nodes per monitor px
    sv = (mr - 1.0) / max(hm - 1.0, 1.0)
    umax = wm - 0.5
    vmax = hm - 0.5
    fhit = 0.0
    for j in range(n):
        w = fbuf[j]
        if w == 0.0:
            continue
        ou = (ubuf[j] - U0) * pitch
        ov = (vbuf[j] - V0) * pitch
        norm = math.sqrt(ou * ou + ov * ov + T * T)
        ou /= norm
        ov /= norm
        c = -T / norm
        x = (ubuf[j] - uc) * pitch
        y = (vbuf[j] - vc) * pitch
        if nflat > 0 or mr > 0:
            x0 = x
            y0 = y
            for _ in range(8):
                h = _flat_height(mc, nflat, x, y, map0, mr, mcols,
                                 (x / pitch + uc) * su, (y / pitch + vc) * sv)
                x = x0 - h * ou / c
                y = y0 - h * ov / c
        if tg > 0.0:
            s2 = ou * ou + ov * ov
            k = tg * (1.0 / c - 1.0 / math.sqrt(ng * ng - s2))
            x -= k * ou
            y -= k * ov
        u = x / pitch + uc
        v = y / pitch + vc
        if fall_m != 0.0:
            w *= c**fall_m
        if nfall > 0:
            ang = math.degrees(math.acos(min(c, 1.0)))
            w *= np.interp(ang, mc[tab0 : tab0 + nfall], mc[tab0 + nfall : tab0 + 2 * nfall])
        inside = (u >= -0.5) & (u < umax) & (v >= -0.5) & (v < vmax)
        if not inside:
            w = 0.0
            u = 0.0
            v = 0.0
        ubuf[j] = u
        vbuf[j] = v
        iubuf[j] = np.int64(np.floor(u + 0.5))
        ivbuf[j] = np.int64(np.floor(v + 0.5))
        fbuf[j] = w
        fhit += w
    return fhit
