"""Scattered-ray bundles: from per-pixel geometry to weighted monitor hits to pattern sums.

One kernel, :func:`render_tile`, loops over the pixels of a tile. For each pixel it

1. builds the bundle's directions (the shared sample set, or a per-pixel randomly rotated
   copy of it),
2. *phase 1*: intersects every direction with the monitor plane and evaluates its weight,
   writing monitor coordinates and weights into small per-pixel buffers (vectorised over
   the samples),
3. *phase 2*: accumulates the requested pattern sums from those buffers: 1-D profile tables
   gathered at the monitor pixel index (fringes, nearest-pixel monitor), cos/sin of k*u at
   the exact hit (fringes, continuous monitor), gathers from arbitrary monitor images, or
   rectangle indicators (dots); or it stores the rays themselves (transport).

Directions are given as coefficients ``(a, b, c)`` in a per-pixel orthonormal basis
``(b1, b2, b3)``; every dot product the kernel needs is linear in them, so the per-pixel
geometry is a row of precomputed projections (layout ``G_*`` below, built by
``pmdsim.trace.bundle_geometry``). The kernel knows nothing about surfaces or cameras.

Weights ``f`` are the BRDF values of the paper (no sampling density, no cosine); the
estimators' normalisation is applied by the caller from the per-pixel sums returned in
columns ``OUT_FTOTAL`` (sum of f over all rays) and ``OUT_FHIT`` (over rays that hit the
monitor).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import fastjit
from .fastmath import exp_neg, sincos

# --- per-pixel geometry row layout -------------------------------------------------------
G_T = 0  # (M0 - S) . n_m : t = G_T / (o . n_m)
G_A = 1  # b_k . n_m, k = 1..3 (3 entries)
G_U0 = 4  # (S - M0) . e_u / pitch + (W - 1) / 2
G_B = 5  # b_k . e_u / pitch (3)
G_V0 = 8
G_C = 9  # b_k . e_v / pitch (3)
G_X = 12  # i . x, then b_k . x (4): local tangential/x axis
G_Y = 16  # i . y, b_k . y (4)
G_Z = 20  # i . n, b_k . n (4)
G_VALID = 24  # 1.0 where the vision ray hit the surface from the front
G_SIZE = 25

# --- BRDF parameter vector -----------------------------------------------------------------
B_MODEL = 0
B_RHO = 1
B_AX = 2
B_AY = 3
B_NORM = 4
B_SIZE = 5

MODEL_MIRROR = 0
MODEL_WARD = 1

NORM_WARD1992 = 0  # the paper: 1 / (4 pi ax ay sqrt(cos_i cos_o))
NORM_DUER2006 = 1  # 1 / (4 pi ax ay cos_i cos_o)
NORM_GEISLER2010 = 2  # |h|^2 / (pi ax ay (h.n)^4)

# --- sampling ----------------------------------------------------------------------------
SCHEME_POLAR = 0  # theta uniform in [0, theta_max]
SCHEME_SOLID_ANGLE = 1  # cos(theta) uniform in [cos(theta_max), 1]

# --- phase-2 modes -------------------------------------------------------------------------
MODE_TABLES = 0  # out[:, 2 + q] = sum f * table_u[q, iu] (q < nu), then table_v rows
MODE_HARMONIC = 1  # out[:, 2 + 2q (+1)] = sum f * cos (sin)(k_q * coord), u freqs then v
MODE_IMAGES = 2  # out[:, 2 + q] = sum f * images[q, iv, iu]
MODE_DOTS = 3  # out[:, 2 + q] = sum f * [-hu <= iu - u0 < hu and -hv <= iv - v0 < hv]
MODE_TRANSPORT = 4  # out_u/out_v/out_f (npix, nrays): the rays themselves

OUT_FTOTAL = 0
OUT_FHIT = 1
OUT_FIRST = 2

_TWO_PI = 2.0 * math.pi


@fastjit(inline="always")
def _directions(u1, u2, r1, r2, scheme, theta_max, cos_theta_max, include_principal, a, b, c):
    """Fill (a, b, c) with unit directions of the cone sample set, rotated by (r1, r2) mod 1."""
    off = 0
    if include_principal:
        a[0] = 0.0
        b[0] = 0.0
        c[0] = 1.0
        off = 1
    m = u1.shape[0]
    for j in range(m):
        s1 = u1[j] + r1
        s1 = s1 - np.floor(s1)
        s2 = u2[j] + r2
        s2 = s2 - np.floor(s2)
        if scheme == SCHEME_POLAR:
            st, ct = sincos(theta_max * s1)
        else:
            ct = 1.0 - s1 * (1.0 - cos_theta_max)
            st = math.sqrt(max(0.0, 1.0 - ct * ct))
        sp, cp = sincos(_TWO_PI * s2)
        a[off + j] = st * cp
        b[off + j] = st * sp
        c[off + j] = ct


@fastjit(inline="always")
def _phase1(g, a, b, c, n, brdf, wm, hm, ubuf, vbuf, iubuf, ivbuf, fbuf):
    """Monitor hits and weights of one pixel's bundle; returns (sum f, sum f over hits).

    Rays that miss the monitor (behind the surface, parallel, outside the pixel grid) get
    weight 0 in ``fbuf`` and index 0 in ``iubuf``/``ivbuf`` so that gathers stay in range.
    """
    T = g[G_T]
    A1 = g[G_A]
    A2 = g[G_A + 1]
    A3 = g[G_A + 2]
    U0 = g[G_U0]
    B1 = g[G_B]
    B2 = g[G_B + 1]
    B3 = g[G_B + 2]
    V0 = g[G_V0]
    C1 = g[G_C]
    C2 = g[G_C + 1]
    C3 = g[G_C + 2]
    X0 = g[G_X]
    X1 = g[G_X + 1]
    X2 = g[G_X + 2]
    X3 = g[G_X + 3]
    Y0 = g[G_Y]
    Y1 = g[G_Y + 1]
    Y2 = g[G_Y + 2]
    Y3 = g[G_Y + 3]
    Z0 = g[G_Z]
    Z1 = g[G_Z + 1]
    Z2 = g[G_Z + 2]
    Z3 = g[G_Z + 3]
    model = int(brdf[B_MODEL])
    rho = brdf[B_RHO]
    ax = brdf[B_AX]
    ay = brdf[B_AY]
    norm = int(brdf[B_NORM])
    iax2 = 1.0 / (ax * ax) if model == MODEL_WARD else 0.0
    iay2 = 1.0 / (ay * ay) if model == MODEL_WARD else 0.0
    umax = wm - 0.5
    vmax = hm - 0.5
    ftot = 0.0
    fhit = 0.0
    if model == MODEL_WARD:
        if norm == NORM_WARD1992:
            k0 = rho / (4.0 * math.pi * ax * ay * math.sqrt(Z0))
        elif norm == NORM_DUER2006:
            k0 = rho / (4.0 * math.pi * ax * ay * Z0)
        else:
            k0 = rho / (math.pi * ax * ay)
        for j in range(n):
            aj = a[j]
            bj = b[j]
            cj = c[j]
            dn = aj * A1 + bj * A2 + cj * A3
            hx = X0 + aj * X1 + bj * X2 + cj * X3
            hy = Y0 + aj * Y1 + bj * Y2 + cj * Y3
            oz = aj * Z1 + bj * Z2 + cj * Z3
            hz = Z0 + oz
            hz2 = hz * hz
            # one division serves t = T / dn and 1 / hz^2
            inv = 1.0 / (dn * hz2)
            t = T * hz2 * inv
            u = U0 + t * (aj * B1 + bj * B2 + cj * B3)
            v = V0 + t * (aj * C1 + bj * C2 + cj * C3)
            ozp = max(oz, 1e-300)
            e = exp_neg(-(hx * hx * iax2 + hy * hy * iay2) * dn * inv)
            if norm == NORM_WARD1992:
                f = k0 * e / math.sqrt(ozp)
            elif norm == NORM_DUER2006:
                f = k0 * e / ozp
            else:
                hh = hx * hx + hy * hy + hz2
                f = k0 * e * hh * (dn * inv) * (dn * inv)
            f = f if oz > 0.0 else 0.0
            inside = (dn < 0.0) & (t > 0.0) & (u >= -0.5) & (u < umax) & (v >= -0.5) & (v < vmax)
            fh = f if inside else 0.0
            ftot += f
            fhit += fh
            uc = u if inside else 0.0
            vc = v if inside else 0.0
            ubuf[j] = uc
            vbuf[j] = vc
            iubuf[j] = np.int64(np.floor(uc + 0.5))
            ivbuf[j] = np.int64(np.floor(vc + 0.5))
            fbuf[j] = fh
    else:  # ideal mirror: weight 1 per ray (the caller passes the principal ray only)
        for j in range(n):
            aj = a[j]
            bj = b[j]
            cj = c[j]
            dn = aj * A1 + bj * A2 + cj * A3
            t = T / dn
            u = U0 + t * (aj * B1 + bj * B2 + cj * B3)
            v = V0 + t * (aj * C1 + bj * C2 + cj * C3)
            inside = (dn < 0.0) & (t > 0.0) & (u >= -0.5) & (u < umax) & (v >= -0.5) & (v < vmax)
            fh = 1.0 if inside else 0.0
            ftot += 1.0
            fhit += fh
            uc = u if inside else 0.0
            vc = v if inside else 0.0
            ubuf[j] = uc
            vbuf[j] = vc
            iubuf[j] = np.int64(np.floor(uc + 0.5))
            ivbuf[j] = np.int64(np.floor(vc + 0.5))
            fbuf[j] = fh
    return ftot, fhit


@fastjit
def render_tile(
    geo,
    brdf,
    u1,
    u2,
    rotation,
    scheme,
    theta_max,
    include_principal,
    monitor_shape,
    mode,
    table_u,
    table_v,
    k_u,
    k_v,
    images,
    dots,
    out,
    out_u,
    out_v,
    out_f,
):
    """Render one tile of pixels.

    Parameters
    ----------
    geo : (P, G_SIZE) float64
        Per-pixel geometry rows (see ``G_*``); rows with ``G_VALID == 0`` are skipped and
        their outputs set to NaN.
    brdf : (B_SIZE,) float64
        BRDF parameter vector (see ``B_*``).
    u1, u2 : (M,) float64
        Unit-square sample points of the cone (the principal ray not included).
    rotation : (P, 2) float64 or (0, 2)
        Per-pixel Cranley-Patterson offsets added to (u1, u2) mod 1; empty = shared set.
    scheme : int
        ``SCHEME_POLAR`` or ``SCHEME_SOLID_ANGLE``.
    theta_max : float
        Cone half angle, rad.
    include_principal : bool
        Prepend the principal reflection direction P as ray 0.
    monitor_shape : (2,) int64
        (height, width) in monitor pixels.
    mode : int
        ``MODE_*``: what phase 2 accumulates.
    table_u, table_v : (nu, W), (nv, H) float64
        Profiles gathered at the nearest monitor column / row (``MODE_TABLES``).
    k_u, k_v : (nu,), (nv,) float64
        Angular frequencies, rad per monitor px (``MODE_HARMONIC``).
    images : (Q, H, W) float32 or float64
        Monitor images (``MODE_IMAGES``).
    dots : (Q, 4) float64
        Rectangles (u0, v0, half_width, half_height) in monitor px (``MODE_DOTS``).
    out : (P, 2 + n_outputs) float64
        Written: column 0 sum of all weights, column 1 sum over monitor hits, then the sums.
    out_u, out_v, out_f : (P, R) float64
        Written in ``MODE_TRANSPORT``: monitor coordinates and weights of every ray (weight
        0 for rays that miss the monitor).
    """
    npix = geo.shape[0]
    m = u1.shape[0]
    n = m + (1 if include_principal else 0)
    hm = monitor_shape[0]
    wm = monitor_shape[1]
    cos_tm = math.cos(theta_max)
    shared = rotation.shape[0] == 0
    a = np.empty(n)
    b = np.empty(n)
    c = np.empty(n)
    ubuf = np.empty(n)
    vbuf = np.empty(n)
    iubuf = np.empty(n, dtype=np.int64)
    ivbuf = np.empty(n, dtype=np.int64)
    fbuf = np.empty(n)
    if shared:
        _directions(u1, u2, 0.0, 0.0, scheme, theta_max, cos_tm, include_principal, a, b, c)
    nout = out.shape[1] - OUT_FIRST
    for p in range(npix):
        g = geo[p]
        if g[G_VALID] == 0.0:
            for q in range(out.shape[1]):
                out[p, q] = np.nan
            if mode == MODE_TRANSPORT:
                for j in range(n):
                    out_u[p, j] = np.nan
                    out_v[p, j] = np.nan
                    out_f[p, j] = 0.0
            continue
        if not shared:
            _directions(
                u1, u2, rotation[p, 0], rotation[p, 1], scheme, theta_max, cos_tm,
                include_principal, a, b, c,
            )
        ftot, fhit = _phase1(g, a, b, c, n, brdf, wm, hm, ubuf, vbuf, iubuf, ivbuf, fbuf)
        out[p, OUT_FTOTAL] = ftot
        out[p, OUT_FHIT] = fhit
        if mode == MODE_TABLES:
            nu = table_u.shape[0]
            for q in range(nu):
                row = table_u[q]
                acc = 0.0
                for j in range(n):
                    acc += fbuf[j] * row[iubuf[j]]
                out[p, OUT_FIRST + q] = acc
            for q in range(table_v.shape[0]):
                row = table_v[q]
                acc = 0.0
                for j in range(n):
                    acc += fbuf[j] * row[ivbuf[j]]
                out[p, OUT_FIRST + nu + q] = acc
        elif mode == MODE_HARMONIC:
            nu = k_u.shape[0]
            for q in range(nu):
                k = k_u[q]
                acc_c = 0.0
                acc_s = 0.0
                for j in range(n):
                    s_, c_ = sincos(k * ubuf[j])
                    acc_c += fbuf[j] * c_
                    acc_s += fbuf[j] * s_
                out[p, OUT_FIRST + 2 * q] = acc_c
                out[p, OUT_FIRST + 2 * q + 1] = acc_s
            for q in range(k_v.shape[0]):
                k = k_v[q]
                acc_c = 0.0
                acc_s = 0.0
                for j in range(n):
                    s_, c_ = sincos(k * vbuf[j])
                    acc_c += fbuf[j] * c_
                    acc_s += fbuf[j] * s_
                out[p, OUT_FIRST + 2 * nu + 2 * q] = acc_c
                out[p, OUT_FIRST + 2 * nu + 2 * q + 1] = acc_s
        elif mode == MODE_IMAGES:
            for q in range(nout):
                img = images[q]
                acc = 0.0
                for j in range(n):
                    acc += fbuf[j] * img[ivbuf[j], iubuf[j]]
                out[p, OUT_FIRST + q] = acc
        elif mode == MODE_DOTS:
            for q in range(nout):
                u0 = dots[q, 0]
                v0 = dots[q, 1]
                hu = dots[q, 2]
                hv = dots[q, 3]
                acc = 0.0
                for j in range(n):
                    du = iubuf[j] - u0
                    dv = ivbuf[j] - v0
                    inside = (du >= -hu) & (du < hu) & (dv >= -hv) & (dv < hv)
                    acc += fbuf[j] if inside else 0.0
                out[p, OUT_FIRST + q] = acc
        else:
            for j in range(n):
                hit = fbuf[j] > 0.0
                out_u[p, j] = ubuf[j] if hit else np.nan
                out_v[p, j] = vbuf[j] if hit else np.nan
                out_f[p, j] = fbuf[j]
