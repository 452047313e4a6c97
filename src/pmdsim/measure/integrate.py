"""Slopes to height: zonal least squares (Southwell), Frankot-Chellappa, modal fits.

Plain functions on arrays; they serve simulated runs and real measurements alike.

Grid convention
---------------
Slope maps are (H, W) arrays on a regular grid: column ``c`` is at
``x = (c - (W - 1) / 2) * dx``, row ``r`` at ``y = (r - (H - 1) / 2) * dy`` (mm, origin at
the array centre unless ``origin_mm`` says otherwise). ``slope_x`` = dz/dx and
``slope_y`` = dz/dy (dimensionless, i.e. rad for small slopes); heights come back in the
unit of ``dx`` (mm). Masks are boolean, ``True`` = measured; heights outside are NaN.

Methods
-------
- :func:`southwell`: zonal least squares on the Southwell grid (slopes and heights at the
  same points). ``order=2`` is the classic scheme (trapezoidal rule between neighbours,
  exact for quadratic surfaces, second-order in the grid step); ``order=4`` adds the
  Euler-Maclaurin end correction ``-h^2/12 (s'_j - s'_i)`` with ``s'`` from finite
  differences of the measured slopes (the higher-order finite-difference scheme of Li et
  al. 2013), fourth-order in the interior and still exact for quadratics. Any mask
  (circles, annuli, islands: piston is set per connected part). Full rectangles are
  solved exactly with a DCT (the normal matrix of the scheme is the Neumann Laplacian);
  masked ones by conjugate gradients preconditioned with that DCT solve on a rectangle
  holding the mask (or, on request, SciPy's sparse LU or PyAMG's algebraic multigrid).
- :func:`frankot_chellappa`: the Fourier projection onto integrable fields for full
  rectangles (periodic FFT, optionally on the mirror-extended field). Documented edge error:
  see ``docs/reconstruction.md``.
- :func:`modal_fit`: least squares of the slopes onto the gradients of Zernike polynomials
  (Noll ordering and normalisation, unit disc) or Legendre products (unit square); returns
  the coefficients and the height.
- :func:`remove_terms` / :func:`height_stats`: piston, tilt, power (and astigmatism)
  removal as metrologists name them, and RMS/PV/P95 over the aperture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..quantiles import percentile
from .poisson import (
    _dct_poisson, _southwell_sparse,
)

__all__ = [
    "grid_coordinates",
    "southwell",
    "frankot_chellappa",
    "modal_fit",
    "ModalFit",
    "zernike_noll_index",
    "zernike",
    "legendre_terms",
    "remove_terms",
    "height_stats",
    "HeightStats",
    "TERM_LEVELS",
]


def _lstsq(a, b):
    """Least squares via the normal equations (Cholesky): our design matrices are tall and
    well conditioned (orthogonal bases, scaled coordinates), and LAPACK's QR/SVD drivers
    are needlessly slow on tall matrices with threaded BLAS. Falls back to lstsq when the
    normal matrix is not positive definite."""
    return _solve_normal(a.T @ a, a.T @ b, lambda: (a, b))


def _solve_normal(ata, atb, full):
    """The least-squares solution from its normal equations ``ata x = atb`` (Cholesky);
    where ``ata`` is not positive definite, ``lstsq`` of the full system ``full()`` ->
    ``(a, b)``, built only then."""
    import scipy.linalg

    try:
        return scipy.linalg.solve(ata, atb, assume_a="pos")
    except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
        a, b = full()
        return np.linalg.lstsq(a, b, rcond=None)[0]


# --------------------------------------------------------------------------------- grid
def grid_coordinates(shape, spacing, origin_mm=None):
    """(x, y) coordinate arrays (H, W) in mm of the grid convention above.

    ``origin_mm``: the (x, y) of pixel (0, 0); default: the array centre is (0, 0).
    """
    h, w = shape
    dx, dy = _spacing(spacing)
    if origin_mm is None:
        x0, y0 = -(w - 1) / 2 * dx, -(h - 1) / 2 * dy
    else:
        x0, y0 = float(origin_mm[0]), float(origin_mm[1])
    x = x0 + np.arange(w) * dx
    y = y0 + np.arange(h) * dy
    return np.meshgrid(x, y)


def _spacing(spacing):
    if np.isscalar(spacing):
        return float(spacing), float(spacing)
    dx, dy = spacing
    return float(dx), float(dy)


def _prepare(slope_x, slope_y, mask):
    sx = np.asarray(slope_x, np.float64)
    sy = np.asarray(slope_y, np.float64)
    if sx.shape != sy.shape or sx.ndim != 2:
        raise ValueError(f"slope_x and slope_y must be (H, W) arrays of one shape, got {sx.shape} and {sy.shape}")
    m = np.isfinite(sx) & np.isfinite(sy)
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != sx.shape:
            raise ValueError(f"mask shape {mask.shape} differs from the slopes' {sx.shape}")
        m &= mask
    return np.where(m, sx, 0.0), np.where(m, sy, 0.0), m


# --------------------------------------------------------------------------- Southwell
def _southwell_rhs(sx, sy, m, dx, dy, order):
    """(H, W) right-hand side A^T b of the Southwell normal equations (one value per node;
    0 outside ``m``): the compiled :func:`pmdsim.kernels.reconstruct.southwell_rhs`."""
    if order not in (2, 4):
        raise ValueError(f"order must be 2 (classic Southwell) or 4 (higher-order), got {order!r}")
    from ..kernels.reconstruct import southwell_rhs

    rhs = np.empty(m.shape)
    southwell_rhs(np.ascontiguousarray(sx), np.ascontiguousarray(sy), np.ascontiguousarray(m),
                  float(dx), float(dy), int(order), rhs)
    return rhs


def southwell(slope_x, slope_y, spacing, mask=None, *, order=4, solver="auto", remove="piston", x0=None,
              rtol=1e-11):
    """Height (H, W) in mm from slopes by zonal least squares (Southwell grid).

    Parameters
    ----------
    slope_x, slope_y : (H, W) ndarray
        dz/dx and dz/dy at the grid points (NaN = not measured).
    spacing : float or (dx, dy)
        Grid step in mm.
    mask : (H, W) bool ndarray, optional
        Measured points (``True``); combined with the finite slopes.
    order : {2, 4}
        2: classic Southwell (trapezoid between neighbours); 4: with the Euler-Maclaurin
        correction from slope derivatives (default; exact for quadratics either way).
    solver : {"auto", "dct", "pcg", "direct", "amg"}
        ``dct`` needs a full rectangle (exact, O(N log N)); ``pcg``: conjugate gradients on
        the masked system preconditioned by the ``dct`` solve on a rectangle holding the
        mask (15-25 iterations on circles, annuli, holes; no set-up); ``direct`` = SciPy's
        sparse LU; ``amg`` = SciPy CG preconditioned by a PyAMG smoothed-aggregation
        V-cycle; ``auto``: ``dct`` on full
        rectangles, ``pcg`` otherwise. The iterative ones stop at a residual of ``rtol``
        times the right-hand side's (the first guess's residual with ``x0``) and fall back
        to ``direct`` when they do not get there. The
        matrix, its LU factors and the AMG hierarchy depend only on the mask: they are kept
        for the next call with the same mask (the iterations of a reconstruction).
    remove : str or sequence
        Terms removed from the result (:func:`remove_terms`); default: piston (mean zero
        per connected part of the aperture). Piston is always undetermined by slopes.
    x0 : (H, W) ndarray, optional
        A first guess of the height (mm) for the iterative solvers (``pcg``, ``amg``), e.g.
        the previous iteration of a reconstruction; the others ignore it.
    rtol : float
        Residual reduction of the iterative solvers (default 1e-11: the exact least-squares
        solution to round-off). A reconstruction passes its previous height as ``x0`` and a
        looser ``rtol``: it only needs the correction to a few digits per iteration.

    Returns
    -------
    height : (H, W) ndarray, mm; NaN outside the mask.
    """
    dx, dy = _spacing(spacing)
    sx, sy, m = _prepare(slope_x, slope_y, mask)
    z = _integrate(sx, sy, m, dx, dy, order, solver, x0, rtol)
    z[~m] = np.nan
    return remove_terms(z, m, *grid_coordinates(m.shape, (dx, dy)), terms=remove, _components=True)


def _integrate(sx, sy, m, dx, dy, order=4, solver="auto", x0=None, rtol=1e-11):
    """:func:`southwell` on prepared input (slopes finite everywhere, 0 outside the bool
    mask ``m``): a height (H, W), no term removed, any value outside ``m``."""
    rhs = _southwell_rhs(sx, sy, m, dx, dy, order)
    if not m.any():
        return np.zeros(m.shape)
    full = bool(m.all())
    if solver == "auto":
        solver = "dct" if full else "pcg"
    if solver == "dct":
        if not full:
            raise ValueError("solver='dct' needs a full rectangle (no mask, all slopes finite); "
                             "use 'pcg', 'direct' or 'amg'")
        z = _dct_poisson(rhs)
    elif solver in ("pcg", "direct", "amg"):
        z = _southwell_sparse(rhs, m, solver, x0, rtol)
    else:
        raise ValueError(f"solver must be 'auto', 'dct', 'pcg', 'direct' or 'amg', got {solver!r}")
    return z


# ------------------------------------------------------------------ Frankot-Chellappa
def frankot_chellappa(slope_x, slope_y, spacing, *, extend="mirror", remove="piston"):
    """Height (H, W) in mm by projecting the slopes onto integrable Fourier fields.

    ``extend="mirror"``: the slopes are extended to a (2H, 2W) field by mirroring (slope_x odd
    across vertical edges, even across horizontal ones; Bon et al. 2012), which removes the
    periodic wrap-around jump; ``"none"``: the classic periodic Frankot-Chellappa. Spectral
    derivatives ``i k``. Needs a full rectangle of finite slopes. The error concentrates at
    the edges (``docs/reconstruction.md`` gives the measured size); for exact least squares
    on a rectangle use :func:`southwell` (its DCT path is as fast).
    """
    dx, dy = _spacing(spacing)
    sx = np.asarray(slope_x, np.float64)
    sy = np.asarray(slope_y, np.float64)
    if not (np.isfinite(sx).all() and np.isfinite(sy).all()):
        raise ValueError("frankot_chellappa needs a full rectangle of finite slopes; use southwell() for masked apertures")
    h, w = sx.shape
    if extend == "mirror":
        sx_e = np.block([[sx, -sx[:, ::-1]], [sx[::-1, :], -sx[::-1, ::-1]]])
        sy_e = np.block([[sy, sy[:, ::-1]], [-sy[::-1, :], -sy[::-1, ::-1]]])
    elif extend == "none":
        sx_e, sy_e = sx, sy
    else:
        raise ValueError(f"extend must be 'mirror' or 'none', got {extend!r}")
    he, we = sx_e.shape
    kx = 2 * np.pi * scipy.fft.fftfreq(we, d=dx)
    ky = 2 * np.pi * scipy.fft.fftfreq(he, d=dy)
    kxx, kyy = np.meshgrid(kx, ky)
    fx = scipy.fft.fft2(sx_e, workers=-1)
    fy = scipy.fft.fft2(sy_e, workers=-1)
    den = kxx**2 + kyy**2
    den[0, 0] = 1.0
    fz = (-1j * kxx * fx - 1j * kyy * fy) / den
    fz[0, 0] = 0.0
    z = scipy.fft.ifft2(fz, workers=-1).real[:h, :w]
    m = np.ones((h, w), bool)
    return remove_terms(z, m, *grid_coordinates(m.shape, (dx, dy)), terms=remove)


# ---------------------------------------------------------------------------- modal
def zernike_noll_index(j: int):
    """(n, m) of Noll's index j >= 1; m > 0 cos, m < 0 sin (even j cos, odd j sin)."""
    if j < 1:
        raise ValueError("Noll indices start at 1")
    n = int((-1 + math.isqrt(8 * (j - 1) + 1)) // 2)
    p = j - n * (n + 1) // 2
    k = n % 2
    m = 2 * ((p + k) // 2) - k
    if m != 0 and j % 2 == 1:
        m = -m
    return n, m


def _radial(n, m, rho):
    """R_n^|m|(rho), dR/drho, R/rho (the last for |m| >= 1, else zeros)."""
    m = abs(m)
    r = np.zeros_like(rho)
    dr = np.zeros_like(rho)
    rr = np.zeros_like(rho)
    for k in range((n - m) // 2 + 1):
        c = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + m) // 2 - k) * math.factorial((n - m) // 2 - k)
        )
        p = n - 2 * k
        r += c * rho**p
        if p >= 1:
            dr += c * p * rho ** (p - 1)
            rr += c * rho ** (p - 1)
    return r, dr, rr


def zernike(j, x, y):
    """Noll-normalised Zernike Z_j on the unit disc at (x, y) and its gradient:
    (Z, dZ/dx, dZ/dy). RMS over the unit disc is 1 for every j."""
    n, m = zernike_noll_index(j)
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    rho = np.hypot(x, y)
    th = np.arctan2(y, x)
    r, dr, rr = _radial(n, m, rho)
    if m == 0:
        norm = math.sqrt(n + 1)
        z = norm * r
        # dZ/dx = R'(rho) x/rho; R' has only odd powers for m = 0 -> R'/rho is a polynomial
        rp_over_rho = np.zeros_like(rho)
        for k in range(n // 2 + 1):
            c = (-1) ** k * math.factorial(n - k) / (math.factorial(k) * math.factorial(n // 2 - k) ** 2)
            p = n - 2 * k
            if p >= 2:
                rp_over_rho += c * p * rho ** (p - 2)
        return z, norm * rp_over_rho * x, norm * rp_over_rho * y
    norm = math.sqrt(2 * (n + 1))
    am = abs(m)
    if m > 0:
        ang, dang = np.cos(am * th), -am * np.sin(am * th)
    else:
        ang, dang = np.sin(am * th), am * np.cos(am * th)
    z = norm * r * ang
    # grad = R' ang rho_hat + (R/rho) dang theta_hat
    c, s = np.cos(th), np.sin(th)
    gx = norm * (dr * ang * c - rr * dang * s)
    gy = norm * (dr * ang * s + rr * dang * c)
    return z, gx, gy


def legendre_terms(n_terms):
    """(i, j) degrees of the first ``n_terms`` Legendre products P_i(x) P_j(y), by total
    degree, then by the y degree j ascending: (0,0), (1,0), (0,1), (2,0), (1,1), (0,2), ..."""
    out = []
    d = 0
    while len(out) < n_terms:
        for j in range(d + 1):
            out.append((d - j, j))
        d += 1
    return out[:n_terms]


def _legendre_table(t, degree):
    """P_k(t) and P_k'(t) for k = 0..degree (Bonnet's recurrence), each (degree + 1, N)."""
    p = np.empty((degree + 1,) + t.shape)
    d = np.zeros_like(p)
    p[0] = 1.0
    if degree >= 1:
        p[1] = t
        d[1] = 1.0
    for k in range(1, degree):
        p[k + 1] = ((2 * k + 1) * t * p[k] - k * p[k - 1]) / (k + 1)
        d[k + 1] = d[k - 1] + (2 * k + 1) * p[k]
    return p, d


def _legendre(i, j, u, v, tables=None):
    """sqrt((2i+1)(2j+1)) P_i(u) P_j(v) (RMS 1 on [-1, 1]^2) and its (u, v) gradient;
    ``tables``: the :func:`_legendre_table` of u and of v, to share between terms."""
    if tables is None:
        tables = (_legendre_table(u, i), _legendre_table(v, j))
    (pu, du), (pv, dv) = tables
    norm = math.sqrt((2 * i + 1) * (2 * j + 1))
    return norm * pu[i] * pv[j], norm * du[i] * pv[j], norm * pu[i] * dv[j]


@dataclass(frozen=True)
class ModalFit:
    """Result of :func:`modal_fit`.

    ``coefficients`` (mm) of the ``names`` terms (index 0 = piston, always 0: slopes do not
    see it); ``height`` (H, W) mm (NaN outside the mask); ``residual_rms`` the RMS slope
    residual (rad); ``radius_mm`` / ``half_size_mm`` the normalisation."""

    basis: str
    names: tuple
    coefficients: np.ndarray
    height: np.ndarray
    residual_rms: float
    centre_mm: tuple
    scale_mm: tuple


def modal_fit(slope_x, slope_y, spacing, mask=None, *, basis="zernike", n_terms=36,
              centre_mm=(0.0, 0.0), radius_mm=None, half_size_mm=None, origin_mm=None):
    """Least-squares fit of slopes onto the gradients of a polynomial basis.

    ``basis="zernike"``: Noll-ordered, Noll-normalised Zernikes Z_1..Z_n on the disc of
    ``radius_mm`` about ``centre_mm`` (default: the smallest disc holding the mask);
    ``"legendre"``: Legendre products on the rectangle ``centre_mm +- half_size_mm`` (default:
    the mask's bounding box). Returns a :class:`ModalFit`.
    """
    dx, dy = _spacing(spacing)
    sx, sy, m = _prepare(slope_x, slope_y, mask)
    x, y = grid_coordinates(m.shape, (dx, dy), origin_mm)
    xm, ym = x[m] - centre_mm[0], y[m] - centre_mm[1]
    if basis == "zernike":
        rad = float(np.max(np.hypot(xm, ym))) if radius_mm is None else float(radius_mm)
        scale = (rad, rad)
        u, v = xm / rad, ym / rad
        terms = list(range(1, n_terms + 1))
        names = tuple(f"Z{j}" for j in terms)
        funcs = [lambda uu, vv, j=j: zernike(j, uu, vv) for j in terms]
    elif basis == "legendre":
        if half_size_mm is None:
            scale = (float(np.max(np.abs(xm))), float(np.max(np.abs(ym))))
        else:
            scale = (float(half_size_mm[0]), float(half_size_mm[1]))
        u, v = xm / scale[0], ym / scale[1]
        terms = legendre_terms(n_terms)
        names = tuple(f"L{i}{j}" for i, j in terms)
        degree = max(max(t) for t in terms)
        tables = (_legendre_table(u, degree), _legendre_table(v, degree))
        funcs = [lambda uu, vv, i=i, j=j: _legendre(i, j, uu, vv, tables) for i, j in terms]
    else:
        raise ValueError(f"basis must be 'zernike' or 'legendre', got {basis!r}")
    # one row per term (rows contiguous): values, d/dx and d/dy at the measured points
    zv = np.empty((len(funcs), len(u)))
    gx = np.empty_like(zv)
    gy = np.empty_like(zv)
    for k, f in enumerate(funcs):
        zv[k], a, b = f(u, v)
        gx[k] = a / scale[0]
        gy[k] = b / scale[1]
    gx, gy = gx[1:], gy[1:]
    bx, by = sx[m], sy[m]
    # least squares of [gx; gy]^T c = [bx; by] by its normal equations, without stacking
    import scipy.linalg

    try:
        coef = scipy.linalg.solve(gx @ gx.T + gy @ gy.T, gx @ bx + gy @ by, assume_a="pos")
    except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
        coef = np.linalg.lstsq(np.hstack([gx, gy]).T, np.concatenate([bx, by]), rcond=None)[0]
    coef = np.concatenate([[0.0], coef])
    res = np.concatenate([coef[1:] @ gx - bx, coef[1:] @ gy - by])
    # height on the grid; piston chosen so the fitted terms have zero mean on the aperture
    zval = coef[1:] @ zv[1:]
    zval -= zval.mean()
    height = np.full(m.shape, np.nan)
    height[m] = zval
    return ModalFit(basis, names, coef, height, float(np.sqrt(np.mean(res**2))), tuple(centre_mm), scale)


# --------------------------------------------------------------------- term removal
TERM_LEVELS = {
    "none": (),
    "piston": ("piston",),
    "tilt": ("piston", "tilt"),
    "power": ("piston", "tilt", "power"),
    "astigmatism": ("piston", "tilt", "power", "astigmatism"),
}


def _term_columns(terms, x, y):
    cols = []
    for t in terms:
        if t == "piston":
            cols.append(np.ones_like(x))
        elif t == "tilt":
            cols += [x, y]
        elif t == "power":
            cols.append(x * x + y * y)
        elif t == "astigmatism":
            cols += [x * x - y * y, 2 * x * y]
        else:
            raise ValueError(f"unknown term {t!r}: use piston, tilt, power, astigmatism")
    return cols


def remove_terms(height, mask, x, y, terms="piston", _components=False):
    """Height minus its least-squares fit of the named low-order terms over ``mask``.

    ``terms``: a level name — ``"none"``, ``"piston"``, ``"tilt"`` (piston and tilt),
    ``"power"`` (piston, tilt and power, i.e. the best-fit sphere's paraxial part x^2+y^2),
    ``"astigmatism"`` (also x^2-y^2 and 2xy) — or a sequence of those term names.
    Returns a new array, NaN outside ``mask``.
    """
    h = np.asarray(height, np.float64)
    m = np.asarray(mask, bool) & np.isfinite(h)
    names = TERM_LEVELS[terms] if isinstance(terms, str) and terms in TERM_LEVELS else tuple(
        [terms] if isinstance(terms, str) else terms
    )
    out = np.where(m, h, np.nan)
    if not names or not m.any():
        return out
    if _components and names == ("piston",):
        # piston per connected part (zonal integration cannot relate separate parts)
        from scipy import ndimage

        lab, n = ndimage.label(m)
        if n > 1:
            means = ndimage.mean(np.where(m, h, 0.0), lab, index=np.arange(1, n + 1))
            out[m] = h[m] - np.asarray(means)[lab[m] - 1]
            return out
    xm, ym = np.asarray(x, np.float64)[m], np.asarray(y, np.float64)[m]
    xc, yc = xm.mean(), ym.mean()
    scale = max(np.abs(xm - xc).max(), np.abs(ym - yc).max(), 1e-300)
    # centred, scaled coordinates keep the normal equations well conditioned (same span)
    cols = _term_columns(names, (xm - xc) / scale, (ym - yc) / scale)
    a = np.stack(cols, axis=1)
    coef = _lstsq(a, h[m])
    out[m] = h[m] - a @ coef
    return out


@dataclass(frozen=True)
class HeightStats:
    """RMS (about the mean), PV (max - min) and P95 (95th percentile of |h - mean|) of a
    height map over its finite points, in the map's unit; ``n`` points."""

    rms: float
    pv: float
    p95: float
    n: int

    def as_dict(self):
        return dict(self.__dict__)


def height_stats(values, mask=None) -> HeightStats:
    v = np.asarray(values, np.float64)
    m = np.isfinite(v) if mask is None else (np.asarray(mask, bool) & np.isfinite(v))
    if not m.any():
        return HeightStats(float("nan"), float("nan"), float("nan"), 0)
    d = v[m] - v[m].mean()
    return HeightStats(float(np.sqrt(np.mean(d * d))), float(np.ptp(v[m])), percentile(np.abs(d), 95, overwrite=True), int(m.sum()))
