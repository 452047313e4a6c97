"""Gaussian micro-facet slopes: the sampler and density shared by Ward and Beckmann.

Both models describe the surface by micro-facet slopes ``(a, b)`` (along the local x and
y axes) with the anisotropic Gaussian density

    p_slope(a, b) = exp(-(a^2 / ax^2 + b^2 / ay^2)) / (pi ax ay),

so the RMS slope along x is ``ax / sqrt(2)`` (``ax`` = sqrt(2) x RMS slope per axis, the
Beckmann convention; for an isotropic surface ``alpha`` is the RMS of the slope vector's
length). A slope ``(a, b)`` is the micro-normal ``m = (-a, -b, 1) / sqrt(1 + a^2 + b^2)``.

Sampling (Walter 2005, "Notes on the Ward BRDF", for Ward; the same for Beckmann's ``D
cos(theta_m)``): from unit-square points ``(u1, u2)``

    a = ax sqrt(-ln u1) cos(2 pi u2),  b = ay sqrt(-ln u1) sin(2 pi u2),  o = 2 (i.m) m - i.

Densities per solid angle: ``pdf(m) = p_slope / cos^3(theta_m)`` (the slope plane -> sphere
Jacobian) and ``pdf(o) = pdf(m) / (4 (i.m))`` (the reflection Jacobian), with ``m`` the
normalised half vector of ``i`` and ``o``. A sample whose ``o`` falls below the surface
(possible at oblique incidence) carries weight 0; its probability is simply missing from
the upper hemisphere, so ``pdf`` integrates to at most 1 there.

All functions take local unit vectors (..., 3) in the BRDF frame (x, y, z = normal) with
``i`` towards the camera and ``o`` towards the monitor, and broadcast.
"""

from __future__ import annotations

import numpy as np

from ..geometry import dot3


def sample_slopes(u1, u2, alpha_x: float, alpha_y: float):
    """Gaussian slopes (a, b) of unit-square points (u1 in (0, 1], u2 in [0, 1))."""
    u1 = np.asarray(u1, np.float64)
    u2 = np.asarray(u2, np.float64)
    r = np.sqrt(-np.log(np.maximum(u1, 1e-300)))
    return alpha_x * r * np.cos(2 * np.pi * u2), alpha_y * r * np.sin(2 * np.pi * u2)


def slope_density(a, b, alpha_x: float, alpha_y: float):
    """p_slope(a, b), per unit slope area."""
    return np.exp(-((a / alpha_x) ** 2 + (b / alpha_y) ** 2)) / (np.pi * alpha_x * alpha_y)


def micronormal(a, b) -> np.ndarray:
    """Unit micro-normals (..., 3) of slopes (a, b)."""
    a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
    m = np.stack([-a, -b, np.ones_like(a)], axis=-1)
    return m / np.sqrt(dot3(m, m))[..., None]


def reflect(i_local, m) -> np.ndarray:
    """o = 2 (i.m) m - i."""
    i_local = np.asarray(i_local, np.float64)
    return 2.0 * dot3(i_local, m)[..., None] * m - i_local


def sample_reflection(u1, u2, i_local, alpha_x: float, alpha_y: float) -> np.ndarray:
    """Outgoing directions (..., 3) reflected about Walter-sampled micro-normals."""
    a, b = sample_slopes(u1, u2, alpha_x, alpha_y)
    return reflect(i_local, micronormal(a, b))


def half_vector(i_local, o_local):
    """Normalised half vector h = (i + o) / |i + o| (..., 3)."""
    h = np.asarray(i_local, np.float64) + np.asarray(o_local, np.float64)
    n = np.sqrt(dot3(h, h))[..., None]
    return np.divide(h, n, out=np.zeros_like(h), where=n > 0)


def reflection_pdf(i_local, o_local, alpha_x: float, alpha_y: float) -> np.ndarray:
    """Density per solid angle (...,) of ``o`` under :func:`sample_reflection`; 0 where i or
    o is below the surface."""
    i_local = np.asarray(i_local, np.float64)
    o_local = np.asarray(o_local, np.float64)
    h = half_vector(i_local, o_local)
    ok = (i_local[..., 2] > 0) & (o_local[..., 2] > 0)
    hz = np.where(ok, h[..., 2], 1.0)
    ih = np.where(ok, dot3(i_local, h), 1.0)
    p = slope_density(-h[..., 0] / hz, -h[..., 1] / hz, alpha_x, alpha_y) / (hz**3 * 4.0 * ih)
    return np.where(ok, p, 0.0)
