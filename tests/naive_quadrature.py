"""Converged fringe sums of single pixels by SciPy's adaptive cubature (issue 18).

Independent of pmdsim's samplers, rules and kernels: each pixel's geometry comes from the
plain vector algebra of :mod:`naive` (straight from the configuration), the BRDF from
:func:`naive.ward` (or the NumPy model of :mod:`pmdsim.brdf` for Beckmann, itself tested
against Mitsuba), and the integral from :func:`scipy.integrate.cubature` (adaptive
Gauss-Kronrod 21, vectorised), to a relative tolerance far below the rules' errors.

- cone estimators (``paper``): ``S = (1 / |D|) int_D f(i, o) hit(o) exp(i k c(o)) dmu``
  over the cone ``theta <= theta_max`` about P, ``dmu = dtheta dphi`` (``polar``) or
  ``sin theta dtheta dphi`` (``solid_angle``), ``|D|`` the measure of the cone: the limit of
  ``(1/N) sum_p f_p exp(i k c_p)`` over N rays uniform in that measure;
- ``radiometric``: ``S = int f(i, o) cos(theta_o) hit(o) exp(i k c(o)) d omega_o`` over the
  hemisphere, written in the micro-normal's slopes (a, b), ``m = (-a, -b, 1) / |.|``,
  ``o = reflect(i, m)``, ``d omega_o = 4 (i.m) cos^3(theta_m) da db`` (Jacobians of the
  reflection and of the slopes), over a box of +-9 alphas (the lobe's tail beyond is
  < exp(-81)).

``c`` is the monitor coordinate along the fringe direction (u for x, v for y) in monitor px,
continuous (``nearest=True``: the centre of the monitor pixel the ray lands in).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import cubature

import naive


def pixel(cfg, row: int, col: int) -> dict | None:
    """The vision ray of camera pixel (row, col) of a flat plate: surface point ``s``,
    normal ``n``, to-camera ``i``, principal direction ``p``, BRDF frame ``x``, ``y`` and the
    cone basis ``e1``, ``e2`` (as :func:`naive.primary` for one pixel); None off the plate."""
    cam = cfg.camera
    c0, n, sx, sy = naive.surface_axes(cfg.surface)
    half = np.asarray(cfg.surface.size_mm) / 2
    pos = np.asarray(cam.position_mm, np.float64)
    d = naive.vision_ray(cam, row, col)
    t = ((c0 - pos) @ n) / (d @ n)
    s = pos + t * d
    if not (t > 0 and abs((s - c0) @ sx) <= half[0] and abs((s - c0) @ sy) <= half[1]
            and (-d) @ n > 0):
        return None
    p = naive.reflect(d, n)
    x, y = naive.brdf_frame(cfg.anisotropy, s, n)
    e1, e2, _ = naive.cone_basis(n, p, y)
    return dict(s=s, n=n, i=-d, p=p, x=x, y=y, e1=e1, e2=e2)


def _brdf_world(cfg, px, o):
    """f(i, o) for world directions o (..., 3)."""
    b = cfg.brdf
    if b.model == "ward":
        ax, ay = b.alphas
        return naive.ward(px["i"], o, px["n"], px["x"], px["y"], ax, ay, b.rho_s, b.normalization)
    from pmdsim.brdf import brdf_from_config

    model = brdf_from_config(b)
    frame = np.stack([px["x"], px["y"], px["n"]])
    o_loc = o @ frame.T
    i_loc = np.broadcast_to(frame @ px["i"], o_loc.shape)
    return np.where(o_loc[..., 2] > 0, model.evaluate(i_loc, o_loc), 0.0)


def _fringe_terms(cfg, px, o, f, widths, directions, nearest):
    """(n_directions * n_widths, ...) values f hit exp(i k c) for directions o (..., 3)."""
    u, v, hit = naive.monitor_hit(cfg.monitor, px["s"], o)
    fh = np.where(hit, f, 0.0)
    out = []
    for d in directions:
        c = np.where(hit, u if d == "x" else v, 0.0)
        if nearest:
            c = np.floor(c + 0.5)
        for w in widths:
            ph = 2 * math.pi * c / w
            out += [fh * np.cos(ph), fh * np.sin(ph)]
    out.append(fh)
    return np.stack(out)


def cone_sums(cfg, px, widths, directions=("x", "y"), nearest=False, rtol=1e-9):
    """Converged normalised sums of the cone estimator ``paper`` at one pixel.

    Returns (S (n_directions, n_widths) complex, f_hit mean, error estimate of cubature)."""
    s = cfg.sampling
    tm = math.radians(s.theta_max_deg)
    solid = s.scheme == "solid_angle"
    measure = 2 * math.pi * ((1 - math.cos(tm)) if solid else tm)

    def g(x):  # x (npts, 2) -> (npts, nout)
        th, ph = x[:, 0], x[:, 1]
        st, ct = np.sin(th), np.cos(th)
        o = ((st * np.cos(ph))[:, None] * px["e1"] + (st * np.sin(ph))[:, None] * px["e2"]
             + ct[:, None] * px["p"])
        f = _brdf_world(cfg, px, o)
        if solid:
            f = f * st
        return _fringe_terms(cfg, px, o, f, widths, directions, nearest).T / measure

    # pieces in theta so that the narrow lobe's core is resolved from the start
    lo, hi = [0.0, 0.0], [tm, 2 * math.pi]
    atol = rtol * _scale(g, lo, hi)
    res = cubature(g, lo, hi, rtol=rtol, atol=atol, max_subdivisions=20000,
                   points=[np.array([tm * q, math.pi]) for q in (0.1, 0.3)])
    return _pack(res, widths, directions)


def lobe_sums(cfg, px, widths, directions=("x", "y"), nearest=False, rtol=1e-9):
    """Converged sums of the ``radiometric`` estimator at one pixel: the rendering integral
    ``int f cos(theta_o) exp(i k c) d omega`` (module docstring)."""
    b = cfg.brdf
    ax, ay = b.alphas
    frame = np.stack([px["x"], px["y"], px["n"]])

    def g(x):
        a, bb = x[:, 0], x[:, 1]
        m_loc = np.stack([-a, -bb, np.ones_like(a)], -1)
        m_loc /= np.linalg.norm(m_loc, axis=-1, keepdims=True)
        m = m_loc @ frame
        im = m @ px["i"]
        o = 2 * im[:, None] * m - px["i"]
        on = o @ px["n"]
        f = _brdf_world(cfg, px, o)
        jac = 4 * np.maximum(im, 0.0) * m_loc[:, 2] ** 3
        return _fringe_terms(cfg, px, o, f * np.maximum(on, 0.0) * jac, widths, directions,
                             nearest).T

    lim = 9.0
    lo, hi = [-lim * ax, -lim * ay], [lim * ax, lim * ay]
    atol = rtol * _scale(g, lo, hi)
    res = cubature(g, lo, hi, rtol=rtol, atol=atol, max_subdivisions=20000,
                   points=[np.array([0.0, 0.0])])
    return _pack(res, widths, directions)


def _scale(g, lo, hi) -> float:
    """The size of the integral of the weights alone (the last output), to 1e-3: the
    absolute tolerance of a sum is rtol times this (a washed-out fringe's sum is ~ 0)."""
    res = cubature(lambda x: g(x)[:, -1:], lo, hi, rtol=1e-3, max_subdivisions=2000)
    return float(abs(np.asarray(res.estimate)[0]))


def _pack(res, widths, directions):
    est = np.asarray(res.estimate)
    z = est[:-1:2] + 1j * est[1::2]
    return z.reshape(len(directions), len(widths)), float(est[-1]), np.asarray(res.error)
