"""Micro-facet BRDF with any anisotropic slope density (the generalisation of Beckmann).

    f(i, o) = F W(i) D(h) G(i, o) / (4 cos_i cos_o),   D(h) = p(s_x, s_y) / cos^4(theta_h),

with ``h`` the normalised half vector of ``i`` and ``o``, ``(s_x, s_y) = -(h_x, h_y) / h_z``
its slopes along the local x and y axes (tangential and radial in a rotational frame) and
``p`` a slope density per unit slope area. Parameters:

- ``density``: one of

  - :class:`GaussianSlopes` (``alpha_x``, ``alpha_y``): ``p = exp(-(s_x^2/ax^2 +
    s_y^2/ay^2)) / (pi ax ay)``; the BRDF is then exactly :class:`~pmdsim.brdf.Beckmann`
    (its compiled case is Beckmann's);
  - :class:`TabulatedSlopes`: ``p`` piecewise constant on a uniform slope grid, separable
    (``p = p_x(s_x) p_y(s_y)``) or joint; built from a slope histogram, a measured height
    map or a file (:func:`tabulated_from_file`), or by :func:`kinematic_slopes` (the
    diamond-turning profile, see :mod:`pmdsim.brdf.turning`);
  - :class:`GratingOrders`: a mixture of Gaussian lobes centred on the grating orders of a
    turned surface, ``p = sum_k w_k G(s - s_k(i)) / W(i)``, whose centres depend on the
    incident direction (the diffractive regime of :mod:`pmdsim.brdf.turning`); ``W(i)`` is
    the share of the orders that propagate (1 for the other densities).
- ``rho_s``: the Fresnel factor ``F``, a constant.
- ``smith``: Smith-type shadowing-masking ``G = G1(i) G1(o)`` with Beckmann's ``Lambda``
  evaluated with the density's *equivalent* alphas (sqrt(2) x RMS slope per axis; exact for
  the Gaussian density, an approximation otherwise, below 1e-3 for the slopes of turned
  parts at PMD angles); ``False``: ``G = 1``.

Sampling draws slopes from ``p`` (closed form for the Gaussian and the orders, the
piecewise-constant table exactly by its cumulative tables otherwise), makes the
micro-normal ``m = (-s_x, -s_y, 1) / |.|`` and reflects ``i`` about it, so
``pdf(o) = p / (cos^3(theta_h) 4 (i.h))`` and the radiometric weight is
``f cos_o / pdf = F W G (i.h) / (cos_i cos(theta_h))``, the same closed form as Beckmann's:
the radiometric and both cone estimators work unchanged. The compiled kernels
(``pmdsim.kernels.bundle``, ``MODEL_SLOPE_TABLE`` and ``MODEL_SLOPE_ORDERS``) use the same
formulas; this module is their NumPy reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from ..kernels import bundle as kb
from . import microfacet
from .beckmann import Beckmann, smith_g1


# =========================================================================== densities
@dataclass(frozen=True)
class GaussianSlopes:
    """Anisotropic Gaussian slopes: ``alpha`` = sqrt(2) x RMS slope per axis (Beckmann)."""

    alpha_x: float
    alpha_y: float
    kind: str = "gaussian"

    def __post_init__(self):
        if not (self.alpha_x > 0 and self.alpha_y > 0):
            raise ValueError(f"alpha_x, alpha_y must be > 0, got {self.alpha_x}, {self.alpha_y}")

    @property
    def equivalent_alphas(self) -> tuple[float, float]:
        return float(self.alpha_x), float(self.alpha_y)

    def density(self, sx, sy, i_local=None):
        return microfacet.slope_density(sx, sy, self.alpha_x, self.alpha_y)

    def share(self, i_local):
        return np.ones(np.shape(i_local)[:-1])

    def sample(self, u1, u2, i_local=None):
        return microfacet.sample_slopes(u1, u2, self.alpha_x, self.alpha_y)


@dataclass(frozen=True, eq=False)
class TabulatedSlopes:
    """A slope density, piecewise constant on a uniform grid of cells.

    Cell ``(i, j)`` covers ``s_x`` in ``[x0 + i dx, x0 + (i+1) dx)`` and ``s_y`` in
    ``[y0 + j dy, ...)``. ``mass`` is (nx, ny), the probability of each cell (sums to 1);
    for a separable density ``mass_x`` (nx,) and ``mass_y`` (ny,) instead (``mass`` None).
    """

    x0: float
    dx: float
    y0: float
    dy: float
    mass: np.ndarray | None = None
    mass_x: np.ndarray | None = None
    mass_y: np.ndarray | None = None
    kind: str = "tabulated"
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if not (self.dx > 0 and self.dy > 0):
            raise ValueError(f"slope table cells must have dx, dy > 0, got {self.dx}, {self.dy}")
        if self.mass is None:
            if self.mass_x is None or self.mass_y is None:
                raise ValueError("give a joint mass (nx, ny) or both mass_x and mass_y")
            mx = _normalised(self.mass_x, "mass_x")
            my = _normalised(self.mass_y, "mass_y")
            object.__setattr__(self, "mass_x", mx)
            object.__setattr__(self, "mass_y", my)
        else:
            m = _normalised(self.mass, "mass")
            if m.ndim != 2:
                raise ValueError(f"a joint slope table must be 2-D, got shape {m.shape}")
            object.__setattr__(self, "mass", m)

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_histogram(cls, counts, edges_x, edges_y) -> "TabulatedSlopes":
        """From a 2-D slope histogram (nx, ny) on uniform edges (nx + 1,), (ny + 1,)."""
        counts = np.asarray(counts, np.float64)
        ex, ey = np.asarray(edges_x, np.float64), np.asarray(edges_y, np.float64)
        if counts.shape != (ex.size - 1, ey.size - 1):
            raise ValueError(f"histogram shape {counts.shape} does not match edges "
                             f"({ex.size - 1}, {ey.size - 1})")
        for name, e in (("edges_x", ex), ("edges_y", ey)):
            d = np.diff(e)
            if np.any(d <= 0) or np.ptp(d) > 1e-9 * d.mean():
                raise ValueError(f"{name}: slope histogram edges must be uniform and increasing")
        return cls(float(ex[0]), float(ex[1] - ex[0]), float(ey[0]), float(ey[1] - ey[0]), counts)

    @classmethod
    def from_height_map(cls, heights, pitch_x: float, pitch_y: float, bins: int = 128,
                        max_slope: float | None = None) -> "TabulatedSlopes":
        """Slope histogram of a measured height map (rows along y, columns along x; heights
        and pitches in the same unit): central-difference slopes, ``bins`` x ``bins`` cells
        over +- ``max_slope`` (default: the largest |slope| found, or 6 RMS if smaller)."""
        h = np.asarray(heights, np.float64)
        if h.ndim != 2 or min(h.shape) < 3:
            raise ValueError(f"a height map must be 2-D with at least 3 x 3 points, got {h.shape}")
        gy, gx = np.gradient(h, pitch_y, pitch_x)
        ok = np.isfinite(gx) & np.isfinite(gy)
        gx, gy = gx[ok], gy[ok]
        if max_slope is None:
            max_slope = float(min(max(np.abs(gx).max(), np.abs(gy).max()),
                                  6 * max(gx.std(), gy.std())) * 1.0001 + 1e-12)
        edges = np.linspace(-max_slope, max_slope, bins + 1)
        counts, _, _ = np.histogram2d(gx, gy, bins=[edges, edges])
        return cls.from_histogram(counts, edges, edges)

    # ---------------------------------------------------------------- properties
    @property
    def separable(self) -> bool:
        return self.mass is None

    @property
    def shape(self) -> tuple[int, int]:
        return (self.mass_x.size, self.mass_y.size) if self.separable else self.mass.shape

    def _marginals(self):
        if self.separable:
            return self.mass_x, self.mass_y
        return self.mass.sum(1), self.mass.sum(0)

    @property
    def equivalent_alphas(self) -> tuple[float, float]:
        """sqrt(2) x RMS slope per axis (about zero) of the piecewise-constant density."""
        nx, ny = self.shape
        mx, my = self._marginals()
        out = []
        for m, x0, d, n in ((mx, self.x0, self.dx, nx), (my, self.y0, self.dy, ny)):
            lo = x0 + np.arange(n) * d
            second = (lo**2 + lo * d + d * d / 3.0)  # mean of s^2 over the cell
            out.append(math.sqrt(2.0 * float(np.sum(m * second))))
        return out[0], out[1]

    def _tables(self):
        if "t" not in self._cache:
            nx, ny = self.shape
            mx, my = self._marginals()
            cdf_x = _cdf(mx)
            if self.separable:
                cdf_y = _cdf(my)[None]
                dens = (self.mass_x / self.dx, self.mass_y / self.dy)
            else:
                cond = self.mass / np.where(mx > 0, mx, 1.0)[:, None]
                cdf_y = np.stack([_cdf(row) if row.sum() > 0 else np.linspace(0, 1, ny + 1)
                                  for row in cond])
                dens = self.mass / (self.dx * self.dy)
            self._cache["t"] = (cdf_x, cdf_y, dens)
        return self._cache["t"]

    def density(self, sx, sy, i_local=None):
        """p(s_x, s_y) per unit slope area (0 off the grid)."""
        sx = np.asarray(sx, np.float64)
        sy = np.asarray(sy, np.float64)
        nx, ny = self.shape
        fx = (sx - self.x0) / self.dx
        fy = (sy - self.y0) / self.dy
        ok = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)
        i = np.where(ok, fx, 0).astype(np.int64)
        j = np.where(ok, fy, 0).astype(np.int64)
        _, _, dens = self._tables()
        if self.separable:
            p = dens[0][i] * dens[1][j]
        else:
            p = dens[i, j]
        return np.where(ok, p, 0.0)

    def share(self, i_local):
        return np.ones(np.shape(i_local)[:-1])

    def sample(self, u1, u2, i_local=None):
        """Slopes of unit-square points: u1 picks the x cell by the marginal cdf and its
        remainder places the slope in the cell; u2 the same for y (conditional on x)."""
        u1 = np.asarray(u1, np.float64)
        u2 = np.asarray(u2, np.float64)
        nx, ny = self.shape
        cdf_x, cdf_y, _ = self._tables()
        i, tx = _cdf_pick(cdf_x, u1)
        if self.separable:
            j, ty = _cdf_pick(cdf_y[0], u2)
        else:
            rows = cdf_y[i]  # (..., ny + 1): the conditional cdf of each sample's x cell
            u2b = np.broadcast_to(u2, rows.shape[:-1])
            j = np.clip(np.sum(rows <= u2b[..., None], -1) - 1, 0, ny - 1)
            c0 = np.take_along_axis(rows, j[..., None], -1)[..., 0]
            dc = np.take_along_axis(rows, j[..., None] + 1, -1)[..., 0] - c0
            with np.errstate(divide="ignore", invalid="ignore"):
                ty = np.where(dc > 0, (u2b - c0) / np.where(dc > 0, dc, 1.0), 0.5)
            ty = np.clip(ty, 0.0, 1.0)
        return self.x0 + (i + tx) * self.dx, self.y0 + (j + ty) * self.dy

    def kernel_data(self) -> np.ndarray:
        nx, ny = self.shape
        cdf_x, cdf_y, dens = self._tables()
        head = [self.x0, self.dx, nx, self.y0, self.dy, ny, 1.0 if self.separable else 0.0]
        if self.separable:
            parts = [head, cdf_x, cdf_y[0], dens[0], dens[1]]
        else:
            parts = [head, cdf_x, cdf_y.ravel(), dens.ravel()]
        return np.concatenate([np.asarray(p, np.float64).ravel() for p in parts])


@dataclass(frozen=True, eq=False)
class GratingOrders:
    """Gaussian lobes (``alpha_x``, ``alpha_y``: sqrt(2) x RMS slope of the random
    roughness) about the grating orders of a groove grating along local y.

    Order ``k`` leaves along the direction cosines ``(-i_x, -i_y + q_k)`` (``q_k = m
    lambda / f``: the grating equation ``sin(theta_m) = sin(theta_i) + m lambda / f`` in
    the radial plane, conical diffraction otherwise) with weight ``w_k`` (efficiency x
    spectral weight, summing to 1 over all orders); its lobe is centred on the slope of the
    half vector of ``i`` and that direction. Orders that do not propagate are dropped:
    ``share(i)`` is the weight that does.
    """

    q: np.ndarray
    w: np.ndarray
    alpha_x: float
    alpha_y: float
    kind: str = "orders"

    def __post_init__(self):
        q = np.asarray(self.q, np.float64).ravel()
        w = np.asarray(self.w, np.float64).ravel()
        if q.shape != w.shape or q.size == 0:
            raise ValueError("grating orders need matching, non-empty q and w")
        if np.any(w < 0):
            raise ValueError("order weights must be >= 0")
        if not (self.alpha_x > 0 and self.alpha_y > 0):
            raise ValueError("the orders' random-roughness alphas must be > 0")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "w", w / w.sum())

    @property
    def equivalent_alphas(self) -> tuple[float, float]:
        """For Smith: sqrt(2) x RMS slope at normal incidence (order centres ~ q / 2)."""
        sy2 = float(np.sum(self.w * (np.arcsin(np.clip(self.q, -1, 1)) / 2) ** 2))
        return float(self.alpha_x), math.sqrt(self.alpha_y**2 + 2 * sy2)

    def centres(self, i_local):
        """Order centres (..., K) s_x, s_y and weights (..., K) (0 if evanescent)."""
        i = np.asarray(i_local, np.float64)[..., None, :]
        ox = -i[..., 0]
        oy = -i[..., 1] + self.q
        oz2 = 1.0 - ox * ox - oy * oy
        ok = oz2 > 0
        hz = i[..., 2] + np.sqrt(np.where(ok, oz2, 0.0))
        sx = np.where(ok, -(i[..., 0] + ox) / hz, 0.0)
        sy = np.where(ok, -(i[..., 1] + oy) / hz, 0.0)
        return sx, sy, np.where(ok, self.w, 0.0)

    def share(self, i_local):
        return self.centres(i_local)[2].sum(-1)

    def density(self, sx, sy, i_local):
        cx, cy, w = self.centres(i_local)
        sx = np.asarray(sx, np.float64)[..., None]
        sy = np.asarray(sy, np.float64)[..., None]
        e = np.exp(-(((sx - cx) / self.alpha_x) ** 2 + ((sy - cy) / self.alpha_y) ** 2))
        wsum = w.sum(-1)
        return np.sum(w * e, -1) / (np.pi * self.alpha_x * self.alpha_y * np.where(wsum > 0, wsum, 1.0))

    def sample(self, u1, u2, i_local):
        cx, cy, w = self.centres(i_local)
        u1 = np.asarray(u1, np.float64)
        u2 = np.asarray(u2, np.float64)
        shape = np.broadcast_shapes(u1.shape, u2.shape, cx.shape[:-1])
        cx, cy, w = (np.broadcast_to(a, shape + a.shape[-1:]) for a in (cx, cy, w))
        cum = np.cumsum(w, -1)
        wsum = cum[..., -1]
        target = u1 * wsum
        k = np.sum(cum <= target[..., None], -1)
        last = w.shape[-1] - 1 - np.argmax((w > 0)[..., ::-1], -1)
        k = np.minimum(k, last)
        acc = np.where(k > 0, np.take_along_axis(cum, np.maximum(k - 1, 0)[..., None], -1)[..., 0], 0.0)
        wk = np.take_along_axis(w, k[..., None], -1)[..., 0]
        t = np.clip(np.where(wk > 0, (target - acc) / np.where(wk > 0, wk, 1.0), 0.0), 0.0, 1.0)
        r = np.sqrt(-np.log(np.maximum(1.0 - t, 1e-300)))
        sx = np.take_along_axis(cx, k[..., None], -1)[..., 0] + self.alpha_x * r * np.cos(2 * np.pi * u2)
        sy = np.take_along_axis(cy, k[..., None], -1)[..., 0] + self.alpha_y * r * np.sin(2 * np.pi * u2)
        return sx, sy

    def kernel_data(self) -> np.ndarray:
        pairs = np.stack([self.q, self.w], -1).ravel()
        return np.concatenate([[self.alpha_x, self.alpha_y, float(self.q.size)], pairs])


def _normalised(m, name):
    m = np.asarray(m, np.float64)
    if m.size == 0 or np.any(~np.isfinite(m)) or np.any(m < 0) or not m.sum() > 0:
        raise ValueError(f"{name}: a slope table needs finite, non-negative cells with a positive sum")
    return m / m.sum()


def _cdf(m):
    c = np.concatenate([[0.0], np.cumsum(m)])
    c /= c[-1]
    c[-1] = 1.0
    return c


def _cdf_pick(cdf, u):
    """Cell index and position in the cell of u under a cumulative table (as the kernel)."""
    n = cdf.size - 1
    i = np.clip(np.searchsorted(cdf, u, "right") - 1, 0, n - 1)
    c0 = cdf[i]
    dc = cdf[i + 1] - c0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dc > 0, (u - c0) / np.where(dc > 0, dc, 1.0), 0.5)
    return i, np.clip(t, 0.0, 1.0)


# =========================================================================== builders
def gaussian_cell_masses(edges, sigma: float) -> np.ndarray:
    """Probabilities of N(0, sigma^2) in the cells between ``edges``."""
    return np.diff(ndtr(np.asarray(edges, np.float64) / sigma))


def arc_slope_cdf(s, feed: float, radius: float) -> np.ndarray:
    """P(slope <= s) for the circular-arc profile h = r - sqrt(r^2 - x^2), x uniform over
    one feed period [-f/2, f/2]: slope(x) = x / sqrt(r^2 - x^2), so x(s) = r s / sqrt(1+s^2)."""
    s = np.asarray(s, np.float64)
    x = radius * s / np.sqrt(1.0 + s * s)
    return (np.clip(x, -feed / 2, feed / 2) + feed / 2) / feed


def arc_max_slope(feed: float, radius: float) -> float:
    """Largest slope of the arc profile: (f/2) / sqrt(r^2 - f^2/4)."""
    if not feed < 2 * radius:
        raise ValueError(f"feed ({feed}) must be below twice the tool nose radius ({radius})")
    return (feed / 2) / math.sqrt(radius**2 - feed**2 / 4)


def kinematic_slopes(feed: float, radius: float, sigma_radial: float, sigma_tangential: float,
                     n_radial: int = 2048, n_tangential: int = 256,
                     radial_axis: str = "y") -> TabulatedSlopes:
    """Slope table of a diamond-turned surface (separable).

    Radial slopes: the exact slopes of circular arcs of radius ``radius`` cut every ``feed``
    (same length unit), x uniform over one period (small-slope limit: uniform over
    +-f/(2r)), convolved with Gaussian random-roughness slopes of RMS ``sigma_radial``
    (0: none). Tangential slopes: Gaussian of RMS ``sigma_tangential`` (> 0). ``radial_axis``
    is the local axis across the grooves (``"y"`` in a rotational frame).
    """
    if not sigma_tangential > 0:
        raise ValueError("the tangential RMS slope must be > 0 (give Rq and a correlation "
                         "length, or rms_slope_tangential)")
    if sigma_radial < 0:
        raise ValueError("the radial random RMS slope must be >= 0")
    amax = arc_max_slope(feed, radius)
    half = amax + 6.5 * sigma_radial
    edges = np.linspace(-half, half, n_radial + 1)
    if sigma_radial == 0:
        m_rad = np.diff(arc_slope_cdf(edges, feed, radius))
    else:
        # P(a + e <= edge) = int p_arc(a) Phi((edge - a) / sigma) da: Gauss-Legendre in x
        # (x uniform over the period), panels of at most sigma in slope so the integrand is
        # resolved, 16 nodes each.
        n_pan = int(min(4000, max(16, math.ceil(2 * amax / sigma_radial) * 2)))
        xg, wg = np.polynomial.legendre.leggauss(16)
        xb = np.linspace(-feed / 2, feed / 2, n_pan + 1)
        xs = (0.5 * (xb[1:] - xb[:-1])[:, None] * xg + 0.5 * (xb[1:] + xb[:-1])[:, None]).ravel()
        ws = (0.5 * (xb[1:] - xb[:-1])[:, None] * wg).ravel() / feed
        a = xs / np.sqrt(radius**2 - xs**2)
        cdf = np.empty(edges.size)
        for c0 in range(0, edges.size, 256):
            e = edges[c0:c0 + 256, None]
            cdf[c0:c0 + 256] = ndtr((e - a) / sigma_radial) @ ws
        m_rad = np.diff(cdf)
    m_rad = np.maximum(m_rad, 0.0)
    t_half = 6.5 * sigma_tangential
    t_edges = np.linspace(-t_half, t_half, n_tangential + 1)
    m_tan = gaussian_cell_masses(t_edges, sigma_tangential)
    if radial_axis == "y":
        return TabulatedSlopes(-t_half, t_edges[1] - t_edges[0], -half, edges[1] - edges[0],
                               mass_x=m_tan, mass_y=m_rad, kind="kinematic")
    if radial_axis == "x":
        return TabulatedSlopes(-half, edges[1] - edges[0], -t_half, t_edges[1] - t_edges[0],
                               mass_x=m_rad, mass_y=m_tan, kind="kinematic")
    raise ValueError(f"radial_axis must be 'x' or 'y', got {radial_axis!r}")


def tabulated_from_file(path, pitch_mm: tuple[float, float] | None = None,
                        bins: int = 128, field: str = "brdf.file") -> TabulatedSlopes:
    """A slope table from a file.

    - ``.npz`` with ``counts`` (nx, ny) and ``edges_x`` (nx + 1,), ``edges_y`` (ny + 1,):
      a slope histogram (x = tangential, y = radial in a rotational frame);
    - ``.npz`` with ``heights`` (rows along y) or a ``.npy`` height map: a measured height
      map; ``pitch_mm`` (x, y) is the sample spacing (heights in mm too).
    """
    from ..config.files import read_slope_table

    data = read_slope_table(path, field)
    if "counts" in data:
        return TabulatedSlopes.from_histogram(data["counts"], data["edges_x"], data["edges_y"])
    if pitch_mm is None:  # read_slope_table returns a histogram or heights
        from ..config.files import FileInputError

        raise FileInputError(f"brdf.pitch_mm: {path} is a height map: give pitch_mm (x, y), "
                             "the sample spacing")
    return TabulatedSlopes.from_height_map(data["heights"], pitch_mm[0], pitch_mm[1], bins)


# =========================================================================== the BRDF
@dataclass(frozen=True, eq=False)
class SlopeDensityBRDF:
    density: GaussianSlopes | TabulatedSlopes | GratingOrders
    rho_s: float = 1.0
    smith: bool = True
    name: str = "slope_density"
    is_delta: bool = False

    def __post_init__(self):
        if not self.rho_s > 0:
            raise ValueError(f"rho_s must be > 0, got {self.rho_s}")

    @property
    def smith_alphas(self) -> tuple[float, float]:
        return self.density.equivalent_alphas

    def slope_pdf(self, h_local, i_local):
        h = np.asarray(h_local, np.float64)
        hz = h[..., 2]
        ok = hz > 0
        hz_ = np.where(ok, hz, 1.0)
        p = self.density.density(-h[..., 0] / hz_, -h[..., 1] / hz_, i_local)
        return np.where(ok, p, 0.0), hz_

    def distribution(self, h_local, i_local) -> np.ndarray:
        """D(h) = p(slopes of h) / cos^4(theta_h) (...,) (without the share W)."""
        p, hz = self.slope_pdf(h_local, i_local)
        return p / hz**4

    def evaluate(self, i_local, o_local):
        i_local = np.asarray(i_local, np.float64)
        o_local = np.asarray(o_local, np.float64)
        ci, co = i_local[..., 2], o_local[..., 2]
        ok = (ci > 0) & (co > 0)
        h = microfacet.half_vector(i_local, o_local)
        d = self.distribution(h, i_local) * self.density.share(i_local)
        f = self.rho_s * d / (4.0 * np.where(ok, ci * co, 1.0))
        if self.smith:
            ax, ay = self.smith_alphas
            f = f * smith_g1(i_local, ax, ay) * smith_g1(o_local, ax, ay)
        return np.where(ok, f, 0.0)

    def sample(self, u1, u2, i_local):
        """Directions (..., 3) reflected about micro-normals of slopes drawn from p."""
        sx, sy = self.density.sample(u1, u2, i_local)
        return microfacet.reflect(i_local, microfacet.micronormal(sx, sy))

    def pdf(self, i_local, o_local):
        """p / (cos^3(theta_h) 4 (i.h)) (...,); 0 below the surface."""
        i_local = np.asarray(i_local, np.float64)
        o_local = np.asarray(o_local, np.float64)
        h = microfacet.half_vector(i_local, o_local)
        ok = (i_local[..., 2] > 0) & (o_local[..., 2] > 0)
        p, hz = self.slope_pdf(h, i_local)
        ih = np.where(ok, np.sum(i_local * h, axis=-1), 1.0)
        return np.where(ok, p / (hz**3 * 4.0 * ih), 0.0)

    def kernel_params(self):
        if isinstance(self.density, GaussianSlopes):
            return Beckmann(self.density.alpha_x, self.density.alpha_y, self.rho_s,
                            self.smith).kernel_params()
        head = np.zeros(kb.B_TAB)
        head[kb.B_MODEL] = (kb.MODEL_SLOPE_ORDERS if isinstance(self.density, GratingOrders)
                            else kb.MODEL_SLOPE_TABLE)
        head[kb.B_RHO] = self.rho_s
        head[kb.B_AX], head[kb.B_AY] = self.smith_alphas
        head[kb.B_SMITH] = 1.0 if self.smith else 0.0
        return np.concatenate([head, self.density.kernel_data()])
