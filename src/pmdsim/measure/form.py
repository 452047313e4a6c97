"""Form removal as a metrologist's drawing asks for it, on plain height-error maps.

A height error ``e = z_measured - z_true`` (H, W) on a grid (x, y) in the surface's local
frame (mm) loses what the drawing allows before it is judged:

- ``piston``, ``tilt``, ``power`` (x^2 + y^2), ``astigmatism`` (x^2 - y^2, 2xy): removed
  together by linear least squares over the measured nodes;
- ``sphere``: the best-fit sphere. The measured surface ``z_true + e`` and the true one
  ``z_true`` each get their own best-fit sphere (a geometric sphere, vertical residuals;
  :func:`best_fit_sphere`), and what is left is ``(z_meas - S_meas) - (z_true - S_true)``;
  the radii of both are reported (the change of radius is the "power" a sphere
  interferometer would call a radius error). Includes piston, tilt and power;
- Zernike terms by index (Noll), removed jointly with the terms above.

Then the Zernike content of *what is left* (:func:`zernike_table`): a least-squares fit
of the residual onto the first N Zernike polynomials on the aperture's disc, in Noll
order (Noll normalisation: each coefficient is the term's RMS over the disc) and in Fringe
(University of Arizona) order (unnormalised: each coefficient is the term's amplitude at the
rim), each term marked ``removed`` when the removal took it out. Nodes within a rim band
(``rim_mm`` or ``rim_percent`` of the inscribed radius) are excluded first
(:func:`rim_mask`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from .integrate import _lstsq, _radial, _solve_normal, _term_columns, zernike_noll_index

__all__ = [
    "FormSpec",
    "FormResult",
    "SphereFit",
    "best_fit_sphere",
    "fringe_index",
    "zernike_value",
    "zernike_columns",
    "zernike_table",
    "zernike_tables",
    "rim_mask",
    "remove_form",
    "LINEAR_TERMS",
]

LINEAR_TERMS = ("piston", "tilt", "power", "astigmatism")
TERMS = LINEAR_TERMS + ("sphere",)
LEVELS = {"none": (), "piston": ("piston",), "tilt": ("piston", "tilt"),
          "power": ("piston", "tilt", "power"),
          "astigmatism": ("piston", "tilt", "power", "astigmatism"),
          "sphere": ("sphere",)}
#: Noll indices each named term removes (for the tables' ``removed`` column)
_NOLL_OF = {"piston": (1,), "tilt": (2, 3), "power": (1, 4), "astigmatism": (5, 6),
            "sphere": (1, 2, 3, 4)}


# ---------------------------------------------------------------------------- Zernike
def fringe_index(j: int) -> tuple[int, int]:
    """(n, m) of Fringe (University of Arizona) index j = 1..37; m > 0 cos, m < 0 sin.

    The rule: terms in groups g = (n + |m|) / 2 = 0, 1, 2, ...; within a group |m| falls
    from g to 0 (n = 2g - |m|), cos before sin; Z37 is the 12th-order spherical term (n = 12,
    m = 0), the only term of group 6 in the 37-term set."""
    if not 1 <= j <= 37:
        raise ValueError(f"Fringe indices run from 1 to 37, got {j}")
    if j == 37:
        return 12, 0
    k = 1
    for g in range(7):
        for am in range(g, -1, -1):
            for sgn in ((1, -1) if am else (1,)):
                if k == j:
                    return 2 * g - am, sgn * am
                k += 1
    raise AssertionError("unreachable")


def zernike_value(n: int, m: int, u, v, normalized: bool = True) -> np.ndarray:
    """Z_n^m on the unit disc at (u, v): ``R_n^|m|(rho) cos(m theta)`` (m >= 0) or
    ``sin(|m| theta)`` (m < 0), times Noll's factor sqrt(2 (n + 1)) (sqrt(n + 1) for m = 0)
    when ``normalized`` (RMS 1 over the disc), else 1 (amplitude 1 at the rim)."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    rho = np.hypot(u, v)
    r = _radial(n, m, rho)[0]
    th = np.arctan2(v, u)
    ang = np.ones_like(rho) if m == 0 else (np.cos(m * th) if m > 0 else np.sin(-m * th))
    norm = 1.0
    if normalized:
        norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    return norm * r * ang


def zernike_columns(order: str, n_terms: int, u, v, basis=None) -> tuple[list, np.ndarray]:
    """([(j, n, m), ...], (points, n_terms) matrix) of the first ``n_terms`` Zernikes in
    ``order`` "noll" (normalised) or "fringe" (unnormalised) at unit-disc points (u, v).
    ``basis``: the :class:`_Basis` of (u, v) when the caller has one (its radial and
    angular factors are shared with other tables of the same points)."""
    idx = _term_indices(order, n_terms)
    basis = _Basis(u, v) if basis is None else basis
    cols = np.empty((basis.rho.size, len(idx)))
    for k, (_, n, m) in enumerate(idx):
        cols[:, k] = basis.value(n, m, normalized=order == "noll").ravel()
    return idx, cols.reshape(basis.rho.shape + (len(idx),))


class _Basis:
    """Zernike terms at fixed unit-disc points (u, v), sharing rho, theta, the powers of rho
    and the angular factors between terms: term by term the same arithmetic as
    :func:`zernike_value` (so the same numbers, bit for bit), without recomputing them."""

    def __init__(self, u, v):
        self.u = np.asarray(u, np.float64)
        self.v = np.asarray(v, np.float64)
        self.rho = np.hypot(self.u, self.v)
        self._theta = None
        self._powers: dict = {}
        self._angular: dict = {}
        self._radial: dict = {}

    def _power(self, p: int) -> np.ndarray:
        if p not in self._powers:
            self._powers[p] = self.rho**p
        return self._powers[p]

    def radial(self, n: int, m: int) -> np.ndarray:
        """R_n^|m|(rho), summed as :func:`pmdsim.measure.integrate._radial` sums it."""
        m = abs(m)
        if (n, m) in self._radial:
            return self._radial[n, m]
        r = np.zeros_like(self.rho)
        for k in range((n - m) // 2 + 1):
            c = (-1) ** k * math.factorial(n - k) / (
                math.factorial(k) * math.factorial((n + m) // 2 - k)
                * math.factorial((n - m) // 2 - k))
            r += c * self._power(n - 2 * k)
        self._radial[n, m] = r
        return r

    def angular(self, m: int) -> np.ndarray | None:
        """cos(m theta) (m > 0), sin(|m| theta) (m < 0); None for m = 0 (a factor 1)."""
        if m == 0:
            return None
        if m not in self._angular:
            if self._theta is None:
                self._theta = np.arctan2(self.v, self.u)
            th = self._theta
            self._angular[m] = np.cos(m * th) if m > 0 else np.sin(-m * th)
        return self._angular[m]

    def value(self, n: int, m: int, normalized: bool = True) -> np.ndarray:
        norm = 1.0
        if normalized:
            norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
        ang = self.angular(m)
        return norm * self.radial(n, m) if ang is None else norm * self.radial(n, m) * ang


def disc_of(mask, x, y, centre=None, radius=None) -> tuple[tuple[float, float], float]:
    """The Zernike disc: ``centre`` (default: the centre of the mask's bounding box) and
    ``radius`` (default: the distance of the farthest measured node from it)."""
    m = np.asarray(mask, bool)
    if centre is None:
        centre = (0.5 * (x[m].min() + x[m].max()), 0.5 * (y[m].min() + y[m].max()))
    if radius is None:
        radius = float(np.max(np.hypot(x[m] - centre[0], y[m] - centre[1])))
    return (float(centre[0]), float(centre[1])), float(radius)


def zernike_table(residual, mask, x, y, *, order="noll", n_terms=37, centre=None, radius=None,
                  removed=()) -> list[dict]:
    """Least-squares Zernike coefficients (in the unit of ``residual``) of ``residual`` over
    ``mask`` on the disc (:func:`disc_of`): one dict per term with ``index``, ``n``, ``m``,
    ``coefficient`` and ``removed`` (its (n, m) is among the Noll indices ``removed``)."""
    m = np.asarray(mask, bool) & np.isfinite(residual)
    if m.sum() < n_terms:
        return []
    c, r = disc_of(m, x, y, centre, radius)
    return zernike_tables(np.asarray(residual, np.float64)[m], (x[m] - c[0]) / r,
                          (y[m] - c[1]) / r, ((order, n_terms),), removed)[0]


#: Points per block of :func:`zernike_tables` (37 columns of 16384 points: 4.6 MB).
TABLE_BLOCK = 16384


def _term_indices(order: str, n_terms: int) -> list:
    if order == "noll":
        return [(j, *zernike_noll_index(j)) for j in range(1, n_terms + 1)]
    if order == "fringe":
        return [(j, *fringe_index(j)) for j in range(1, n_terms + 1)]
    raise ValueError(f"order must be 'noll' or 'fringe', got {order!r}")


def zernike_tables(values, u, v, tables, removed=(), block: int = TABLE_BLOCK) -> list[list]:
    """The Zernike tables ``tables`` (a sequence of ``(order, n_terms)``) of the point values
    ``values`` at unit-disc points (u, v) (1-D): for each, the least-squares coefficients as
    :func:`zernike_table` gives them.

    One pass over the points in blocks of ``block``: each block's columns of every table
    are built from one :class:`_Basis` of the block and added into that table's normal
    equations (``A^T A``, ``A^T b``: n_terms^2 numbers), so no (points, n_terms) matrix
    exists (on a 1.3 MP map two 37-term matrices were 0.77 GB). Solved as
    :func:`pmdsim.measure.integrate._lstsq` solves (:func:`~pmdsim.measure.integrate.
    _solve_normal`: Cholesky of the normal matrix; where it is not positive definite, fewer
    distinct points than terms, the full matrix is built and solved by ``lstsq``). Fewer
    points than a table's terms: that table is empty."""
    b = np.asarray(values, np.float64).ravel()
    u = np.asarray(u, np.float64).ravel()
    v = np.asarray(v, np.float64).ravel()
    gone = {zernike_noll_index(j) for j in removed}
    specs = [(order, _term_indices(order, n_terms)) for order, n_terms in tables]
    gram = [np.zeros((len(idx), len(idx))) for _, idx in specs]
    rhs = [np.zeros(len(idx)) for _, idx in specs]
    bufs = [np.empty((len(idx), min(block, b.size))) for _, idx in specs]  # rows: terms
    for s0 in range(0, b.size, block):
        s1 = min(s0 + block, b.size)
        basis = _Basis(u[s0:s1], v[s0:s1])
        for (order, idx), g, r, buf in zip(specs, gram, rhs, bufs):
            a = buf[:, : s1 - s0]
            for k, (_, n, mm) in enumerate(idx):
                a[k] = basis.value(n, mm, normalized=order == "noll")
            g += a @ a.T
            r += a @ b[s0:s1]
    out = []
    for (order, idx), g, r in zip(specs, gram, rhs):
        if b.size < len(idx):  # fewer points than terms: no table
            out.append([])
            continue
        coef = _solve_normal(g, r, lambda: (zernike_columns(order, len(idx), u, v)[1], b))
        out.append([{"index": j, "n": n, "m": mm, "coefficient": float(k),
                     "removed": (n, mm) in gone} for (j, n, mm), k in zip(idx, coef)])
    return out


# ------------------------------------------------------------------------ sphere
@dataclass(frozen=True)
class SphereFit:
    """A best-fit sphere: ``radius_mm`` (signed: > 0 concave towards +z, inf for a plane),
    its height ``z0_mm`` and slopes ``(p, q)`` at ``origin`` (x, y), ``rms_mm`` of the
    vertical residual."""

    radius_mm: float
    curvature: float
    z0_mm: float
    slopes: tuple
    origin: tuple
    rms_mm: float

    def sag(self, x, y):
        return _sphere_z((self.z0_mm, *self.slopes, self.curvature), np.asarray(x) - self.origin[0],
                         np.asarray(y) - self.origin[1])


def _sphere_z(p, x, y):
    """Height of the sphere through (0, 0, z0) with slopes (p, q) there and curvature k:
    the root of k (x^2 + y^2 + w^2) = 2 n . (x, y, w) nearest the vertex, w = z - z0, written
    so that k -> 0 is the plane z0 + p x + q y (no cancellation)."""
    z0, sp, sq, k = p
    s = math.sqrt(1.0 + sp * sp + sq * sq)
    nx, ny, nz = -sp / s, -sq / s, 1.0 / s
    a = k * (x * x + y * y) - 2.0 * (nx * x + ny * y)
    disc = np.maximum(nz * nz - k * a, 0.0)
    return z0 + a / (nz + np.sqrt(disc))


def best_fit_sphere(x, y, z, mask=None, origin=None) -> SphereFit:
    """Least-squares sphere (vertical residuals) through the points (x, y, z) (mm): a
    parabola fit starts Levenberg-Marquardt on (z0, p, q, k) at ``origin`` (default: the
    centroid of the points). Exact for points on a sphere (to rounding); a plane gives
    k = 0 (radius inf)."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    z = np.asarray(z, np.float64)
    m = np.isfinite(z) if mask is None else (np.asarray(mask, bool) & np.isfinite(z))
    if m.sum() < 4:
        raise ValueError("best_fit_sphere: fewer than 4 measured points")
    xm, ym, zm = x[m], y[m], z[m]
    if origin is None:
        origin = (float(xm.mean()), float(ym.mean()))
    xm = xm - origin[0]
    ym = ym - origin[1]
    a = np.stack([np.ones_like(xm), xm, ym, 0.5 * (xm * xm + ym * ym)], axis=1)
    p0 = _lstsq(a, zm)
    from scipy.optimize import least_squares

    scale = max(float(np.max(np.hypot(xm, ym))), 1e-9)

    def res(p):
        return _sphere_z((p[0], p[1], p[2], p[3] / scale**2), xm, ym) - zm

    sol = least_squares(res, np.array([p0[0], p0[1], p0[2], p0[3] * scale**2]), method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    z0, sp, sq, ks = sol.x
    k = float(ks / scale**2)
    rms = float(np.sqrt(np.mean(sol.fun**2)))
    return SphereFit(1.0 / k if k != 0 else math.inf, k, float(z0), (float(sp), float(sq)),
                     (float(origin[0]), float(origin[1])), rms)


# --------------------------------------------------------------------------- rim
def rim_mask(mask, spacing, rim_mm: float = 0.0, rim_percent: float = 0.0) -> np.ndarray:
    """``mask`` without the nodes within the rim band of its edge: ``rim_mm`` (mm), or
    ``rim_percent`` of the largest such distance (the inscribed radius: the aperture radius
    of a full disc); the wider of the two. ``spacing`` (dx, dy) mm. A node's distance to the
    edge is its distance to the nearest node outside minus half the larger grid step (the
    edge lies between the last node in and the first out): right to within half a step."""
    m = np.asarray(mask, bool)
    if rim_mm <= 0 and rim_percent <= 0:
        return m.copy()
    dx, dy = spacing
    dist = ndimage.distance_transform_edt(np.pad(m, 1), sampling=(dy, dx))[1:-1, 1:-1] - 0.5 * max(dx, dy)
    band = max(rim_mm, rim_percent / 100.0 * float(dist.max(initial=0.0)))
    return m & (dist > band)


# ---------------------------------------------------------------------- removal
@dataclass(frozen=True)
class FormSpec:
    """What to remove: named ``terms`` (a level of :data:`LEVELS` or term names of
    :data:`TERMS`), Noll indices ``zernike``, the rim band and the table size."""

    terms: tuple = ("piston",)
    zernike: tuple = ()
    rim_mm: float = 0.0
    rim_percent: float = 0.0
    n_zernike: int = 37

    @classmethod
    def of(cls, terms="piston", zernike=(), rim_mm=0.0, rim_percent=0.0, n_zernike=37) -> "FormSpec":
        if isinstance(terms, str):
            if terms not in LEVELS:
                raise ValueError(f"unknown removal {terms!r}: use one of {sorted(LEVELS)}")
            names = LEVELS[terms]
        else:
            names = tuple(terms)
        bad = [t for t in names if t not in TERMS]
        if bad:
            raise ValueError(f"unknown removal term(s) {bad}: use {list(TERMS)}")
        return cls(names, tuple(int(j) for j in zernike), float(rim_mm), float(rim_percent), int(n_zernike))

    @property
    def removed_noll(self) -> tuple:
        out = set(self.zernike)
        for t in self.terms:
            out |= set(_NOLL_OF[t])
        return tuple(sorted(out))

    def describe(self) -> str:
        parts = list(self.terms) or ["nothing"]
        if "sphere" in parts:
            parts[parts.index("sphere")] = "best-fit sphere"
        if self.zernike:
            parts.append("Zernike (Noll) " + ",".join(f"Z{j}" for j in self.zernike))
        s = " + ".join(parts) + " removed"
        if self.rim_mm > 0 or self.rim_percent > 0:
            band = [f"{self.rim_mm:g} mm"] if self.rim_mm > 0 else []
            band += [f"{self.rim_percent:g} % of the radius"] if self.rim_percent > 0 else []
            s += ", rim band " + " / ".join(band) + " excluded"
        return s


@dataclass(frozen=True)
class FormResult:
    """Residual (NaN outside ``mask``) after :func:`remove_form`; ``sphere``: radii of the
    best-fit spheres (measured, true, change, mm) when removed; ``noll``/``fringe``: the
    Zernike tables of the residual (:func:`zernike_table`)."""

    residual: np.ndarray
    mask: np.ndarray
    removed: str
    sphere: dict | None = None
    noll: list = field(default_factory=list)
    fringe: list = field(default_factory=list)
    excluded_rim: int = 0


def remove_form(error, mask, x, y, spec: FormSpec, *, true_height=None, disc=(None, None),
                spacing=None, tables: bool = True) -> FormResult:
    """Apply ``spec`` to the height error ``error`` (H, W) over ``mask`` on the grid
    (x, y) (each (H, W), mm); ``true_height``: the true sag on the grid (needed for the
    best-fit sphere; zeros when None); ``disc``: (centre, radius) of the Zernike disc
    (default :func:`disc_of` of the rim-trimmed mask); ``spacing``: (dx, dy) for the rim band
    (default from x, y); ``tables=False``: no Zernike tables (empty lists), for a caller
    that needs only the residual. Units: those of ``error`` and ``true_height`` (must agree:
    mm)."""
    e = np.asarray(error, np.float64)
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    m0 = np.asarray(mask, bool) & np.isfinite(e)
    if spacing is None:
        spacing = (float(abs(x[0, 1] - x[0, 0])) if x.shape[1] > 1 else 1.0,
                   float(abs(y[1, 0] - y[0, 0])) if y.shape[0] > 1 else 1.0)
    m = rim_mask(m0, spacing, spec.rim_mm, spec.rim_percent)
    out = np.full(e.shape, np.nan)
    sphere = None
    if not m.any():
        return FormResult(out, m, spec.describe(), None, [], [], int(m0.sum()))
    r = e[m].copy()
    if "sphere" in spec.terms:
        zt = np.zeros_like(e) if true_height is None else np.asarray(true_height, np.float64)
        origin = (float(x[m].mean()), float(y[m].mean()))
        fm = best_fit_sphere(x[m], y[m], zt[m] + r, origin=origin)
        ft = best_fit_sphere(x[m], y[m], zt[m], origin=origin)
        r = (zt[m] + r - fm.sag(x[m], y[m])) - (zt[m] - ft.sag(x[m], y[m]))
        sphere = {"radius_measured_mm": fm.radius_mm, "radius_true_mm": ft.radius_mm,
                  "radius_change_mm": (fm.radius_mm - ft.radius_mm
                                       if math.isfinite(fm.radius_mm) and math.isfinite(ft.radius_mm)
                                       else (math.inf if fm.curvature != ft.curvature else 0.0)),
                  "curvature_change_per_mm": fm.curvature - ft.curvature}
    (c, rad) = disc_of(m, x, y, *disc)
    xm, ym = x[m], y[m]
    cols = []
    lin = [t for t in spec.terms if t != "sphere"]
    if lin:
        xc, yc = xm.mean(), ym.mean()
        scale = max(np.abs(xm - xc).max(), np.abs(ym - yc).max(), 1e-300)
        cols += _term_columns(lin, (xm - xc) / scale, (ym - yc) / scale)
    if spec.zernike:
        basis = _Basis((xm - c[0]) / rad, (ym - c[1]) / rad)
        cols += [basis.value(*zernike_noll_index(j)) for j in spec.zernike]
        del basis
    if cols:
        a = np.stack(cols, axis=1)
        r = r - a @ _lstsq(a, r)
        del a, cols
    out[m] = r
    if not tables:
        return FormResult(out, m, spec.describe(), sphere, [], [], int(m0.sum() - m.sum()))
    noll, fringe = zernike_tables(r, (xm - c[0]) / rad, (ym - c[1]) / rad,
                                  (("noll", spec.n_zernike), ("fringe", min(spec.n_zernike, 37))),
                                  spec.removed_noll)
    return FormResult(out, m, spec.describe(), sphere, noll, fringe, int(m0.sum() - m.sum()))
