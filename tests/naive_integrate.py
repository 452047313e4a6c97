"""Slow, obvious NumPy reference of the Southwell right-hand side
(:func:`pmdsim.kernels.reconstruct.southwell_rhs`): the neighbour equations' right-hand
sides as whole shifted arrays, then A^T b by adding each pair's value to its two nodes."""

from __future__ import annotations

import numpy as np


def derivative_along(s, m, axis, h):
    """ds/d(axis) from valid neighbours: central where both exist, one-sided 3-point
    (2nd order) where two on one side exist, 2-point otherwise, 0 for isolated points."""
    s = np.moveaxis(s, axis, -1)
    m = np.moveaxis(m, axis, -1)
    d = np.zeros_like(s)
    if s.shape[-1] < 2:
        return np.moveaxis(d, -1, axis)

    def sh(a, k, fill):  # value at index i + k (fill outside)
        out = np.full_like(a, fill)
        if k > 0:
            out[..., :-k] = a[..., k:]
        else:
            out[..., -k:] = a[..., :k]
        return out

    mp1, mm1, mp2, mm2 = sh(m, 1, False), sh(m, -1, False), sh(m, 2, False), sh(m, -2, False)
    sp1, sm1, sp2, sm2 = sh(s, 1, 0.0), sh(s, -1, 0.0), sh(s, 2, 0.0), sh(s, -2, 0.0)
    central = m & mp1 & mm1
    fwd3 = m & ~central & mp1 & mp2
    bwd3 = m & ~central & ~fwd3 & mm1 & mm2
    fwd2 = m & ~central & ~fwd3 & ~bwd3 & mp1
    bwd2 = m & ~central & ~fwd3 & ~bwd3 & ~fwd2 & mm1
    d = np.where(central, (sp1 - sm1) / (2 * h), d)
    d = np.where(fwd3, (-3 * s + 4 * sp1 - sp2) / (2 * h), d)
    d = np.where(bwd3, (3 * s - 4 * sm1 + sm2) / (2 * h), d)
    d = np.where(fwd2, (sp1 - s) / h, d)
    d = np.where(bwd2, (s - sm1) / h, d)
    return np.moveaxis(d, -1, axis)


def southwell_rhs(sx, sy, m, dx, dy, order):
    """(H, W) A^T b of the Southwell equations z_j - z_i = b (slopes 0 outside ``m``)."""
    sx = np.where(m, sx, 0.0)
    sy = np.where(m, sy, 0.0)
    px = m[:, :-1] & m[:, 1:]
    py = m[:-1, :] & m[1:, :]
    bx = dx * 0.5 * (sx[:, :-1] + sx[:, 1:])
    by = dy * 0.5 * (sy[:-1, :] + sy[1:, :])
    if order == 4:
        dsx = derivative_along(sx, m, 1, dx)
        dsy = derivative_along(sy, m, 0, dy)
        bx = bx - dx * dx / 12.0 * (dsx[:, 1:] - dsx[:, :-1])
        by = by - dy * dy / 12.0 * (dsy[1:, :] - dsy[:-1, :])
    bx = np.where(px, bx, 0.0)
    by = np.where(py, by, 0.0)
    rhs = np.zeros(m.shape)
    rhs[:, :-1] -= bx
    rhs[:, 1:] += bx
    rhs[:-1, :] -= by
    rhs[1:, :] += by
    return rhs
