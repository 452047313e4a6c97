"""The decoded monitor-coordinate maps at fractional camera pixels, honest to the rim.

A reconstruction needs the decoded maps (u, v) (H, W) at the fractional pixel of every
grid node (:func:`pmdsim.measure.reconstruct.reconstruct`). :func:`maps_at` serves each
node one of three ways and says which (``status``, the codes below):

- by the cubic spline of the maps (:func:`spline_maps`) where its 4 x 4 support and
  :data:`SPLINE_MARGIN` pixels around it are valid: the spline's prefilter couples every
  coefficient to the filled pixels by 0.268^distance, so nodes next to the edge of the
  valid pixels (the aperture's rim in the image, the image's own edge, holes) would carry
  the fill's kink;
- by the rim fit (:func:`rim_fit`) at any other node inside the image: a cubic in (col,
  row) least-squares fitted to the valid pixels around the node, one-sided at the rim,
  where it reaches the node with at most one pixel's noise (:data:`RIM_MAX_GAIN`);
- not at all, with the reason (:data:`EXCLUSION_REASONS`).

docs/reconstruction.md ("The rim") gives the measured accuracy of each.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..kernels.reconstruct import (
    SUPPORT_OUTSIDE,
    SUPPORT_PIXEL_INVALID,
    SUPPORT_RIM,
    SUPPORT_SPLINE,
    node_support,
    rim_fit_nodes,
)
from ..kernels.surface import bspline_eval_pair
from .integrate import _lstsq

__all__ = ["EXCLUSION_REASONS", "NODE_OUTSIDE_APERTURE", "NODE_RIM_FIT", "NODE_SPLINE",
           "NODE_TOO_FEW_PIXELS", "maps_at", "rim_fit", "spline_maps"]

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


def spline_maps(u, v, valid):
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


def rim_fit(u, v, valid, cols, rows, window=RIM_WINDOWS[0]):
    """(u, v, gain) at the fractional pixels (cols, rows) (K,) by the rim fit on the
    ``window`` x ``window`` block (see :data:`RIM_WINDOWS`); gain inf (and u, v NaN) where
    the valid pixels of the block do not determine the cubic (compiled:
    :func:`pmdsim.kernels.reconstruct.rim_fit_nodes`)."""
    ti = np.array([i for i, _ in _RIM_TERMS], np.int64)
    tj = np.array([j for _, j in _RIM_TERMS], np.int64)
    cols = np.ascontiguousarray(cols, np.float64)
    rows = np.ascontiguousarray(rows, np.float64)
    out_u, out_v, gain = np.empty(cols.shape), np.empty(cols.shape), np.empty(cols.shape)
    rim_fit_nodes(np.ascontiguousarray(u, np.float64), np.ascontiguousarray(v, np.float64),
                  np.ascontiguousarray(valid, np.bool_), cols, rows, int(window), ti, tj,
                  out_u, out_v, gain)
    return out_u, out_v, gain


def maps_at(u, v, valid, cu, cv, cols, rows, status):
    """(u, v) at the fractional pixels (cols, rows) (K,) (integers = pixel centres) and, in
    ``status`` (K,) int8, how each was served: :data:`NODE_SPLINE` (the coefficients
    ``cu``, ``cv`` of :func:`spline_maps`), :data:`NODE_RIM_FIT` (:func:`rim_fit` of the
    valid pixels of ``u``, ``v``), or why not (:data:`EXCLUSION_REASONS`; u, v NaN there).
    ``valid``: the valid decoded pixels (H, W)."""
    node_support(valid, cols, rows, SPLINE_MARGIN, status)
    spl = status == SUPPORT_SPLINE
    rim = np.nonzero((status == SUPPORT_RIM) | (status == SUPPORT_PIXEL_INVALID))[0]
    mu = np.full(len(cols), np.nan)
    mv = np.full(len(cols), np.nan)
    ks = int(spl.sum())
    su, sv = np.empty(ks), np.empty(ks)
    # = ndimage.map_coordinates(..., order=3, mode="mirror") of u and v, in one pass
    bspline_eval_pair(cu, cv, np.ascontiguousarray(rows[spl]) + SPLINE_PAD,
                      np.ascontiguousarray(cols[spl]) + SPLINE_PAD, su, sv)
    mu[spl], mv[spl] = su, sv
    for window in RIM_WINDOWS:  # the smallest block that reaches the node
        if not rim.size:
            break
        ru, rv, gain = rim_fit(u, v, valid, cols[rim], rows[rim], window)
        near = gain <= RIM_MAX_GAIN
        mu[rim[near]], mv[rim[near]] = ru[near], rv[near]
        status[rim[near]] = NODE_RIM_FIT
        rim = rim[~near]
    # not reached: their own pixel invalid (stays SUPPORT_PIXEL_INVALID), or too few valid
    # pixels around a valid one
    status[rim[status[rim] == SUPPORT_RIM]] = NODE_TOO_FEW_PIXELS
    return mu, mv
