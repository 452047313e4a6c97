"""Surfaces: anything that can intersect vision rays and report hit points and normals.

A surface implements :class:`Surface`; adding a shape (sphere, asphere, height map) is one
new class here. The scattered bundle only needs the hit point and the normal, so the
rendering kernels never see the surface.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..config import ConfigError, FlatSurfaceConfig, SurfaceConfig
from ..geometry import normalize
from ..topofile import is_instrument_file, read_topography


class Surface(Protocol):
    def intersect(self, origins: np.ndarray, dirs: np.ndarray):
        """Return (t, points, normals, hit) for rays (..., 3); normals are unit vectors on
        the side the ray came from is *not* assumed: callers check ``dot(-dir, n) > 0``."""

    def outline(self) -> np.ndarray:
        """Closed polyline (K, 3) of the surface boundary, for figures."""

    @property
    def default_x_axis(self) -> np.ndarray: ...

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for :mod:`pmdsim.kernels.primary` (layout ``SURF_*``)."""


@dataclass(frozen=True)
class FlatRectangle:
    centre: np.ndarray
    normal: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    size: tuple[float, float]

    @classmethod
    def from_config(cls, cfg: FlatSurfaceConfig) -> "FlatRectangle":
        n = normalize(np.asarray(cfg.normal, np.float64))
        x = np.asarray(cfg.x_axis, np.float64)
        x = normalize(x - (x @ n) * n)
        y = np.cross(n, x)
        return cls(np.asarray(cfg.centre_mm, np.float64), n, x, y, tuple(cfg.size_mm))

    @property
    def default_x_axis(self) -> np.ndarray:
        return self.x_axis

    def intersect(self, origins, dirs):
        dn = dirs @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.centre - origins) @ self.normal) / dn
        p = origins + t[..., None] * dirs
        d = p - self.centre
        hit = (
            (t > 0)
            & (np.abs(d @ self.x_axis) <= self.size[0] / 2)
            & (np.abs(d @ self.y_axis) <= self.size[1] / 2)
        )
        normals = np.broadcast_to(self.normal, p.shape)
        return t, p, normals, hit

    def kernel_params(self) -> np.ndarray:
        from ..kernels import primary as kp

        p = np.zeros(kp.SURF_SIZE)
        p[kp.SURF_TYPE] = kp.SURF_FLAT
        p[kp.SURF_C : kp.SURF_C + 3] = self.centre
        p[kp.SURF_N : kp.SURF_N + 3] = self.normal
        p[kp.SURF_X : kp.SURF_X + 3] = self.x_axis
        p[kp.SURF_Y : kp.SURF_Y + 3] = self.y_axis
        p[kp.SURF_HALF] = self.size[0] / 2
        p[kp.SURF_HALF + 1] = self.size[1] / 2
        return p

    def outline(self) -> np.ndarray:
        hx, hy = self.size[0] / 2, self.size[1] / 2
        corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)]
        return np.array([self.centre + a * self.x_axis + b * self.y_axis for a, b in corners])


def surface_from_config(cfg: SurfaceConfig) -> Surface:
    if cfg.type == "flat":
        return FlatRectangle.from_config(cfg)
    if cfg.type in SAG_TYPES:
        return SagSurface.from_config(cfg)
    raise ValueError(f"surface.type: unknown surface {cfg.type!r}")


# ------------------------------------------------------------------------ sag surfaces
SAG_TYPES = ("sphere", "conic", "asphere", "xy_polynomial", "zernike", "height_map")


def zernike_noll(j: int) -> tuple[int, int]:
    """(n, m) of Noll's index j (m > 0: cos(m theta), m < 0: sin(|m| theta))."""
    n = int((math.isqrt(8 * (j - 1) + 1) - 1) // 2)
    p = j - n * (n + 1) // 2
    m = 2 * ((p + n % 2) // 2) - n % 2
    return n, (-m if (m != 0 and j % 2 == 1) else m)


def _poly_mul(a, b):
    out = np.zeros((a.shape[0] + b.shape[0] - 1, a.shape[1] + b.shape[1] - 1))
    for i, j in zip(*np.nonzero(a)):
        out[i : i + b.shape[0], j : j + b.shape[1]] += a[i, j] * b
    return out


def zernike_monomials(j: int) -> np.ndarray:
    """Coefficients C[i, k] of u^i v^k of Noll's Z_j (Noll normalisation), degree n."""
    n, m = zernike_noll(j)
    am = abs(m)
    # Re / Im of (u + i v)^|m|
    trig = np.zeros((am + 1, am + 1))
    for p in range(am + 1):
        if (m >= 0 and p % 2 == 0) or (m < 0 and p % 2 == 1):
            sign = (-1) ** (p // 2)
            trig[am - p, p] = sign * math.comb(am, p)
    rho2 = np.zeros((3, 3))
    rho2[2, 0] = rho2[0, 2] = 1.0
    out = np.zeros((n + 1, n + 1))
    for k in range((n - am) // 2 + 1):
        c = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + am) // 2 - k) * math.factorial((n - am) // 2 - k)
        )
        term = trig.copy()
        for _ in range((n - 2 * k - am) // 2):
            term = _poly_mul(term, rho2)
        out[: term.shape[0], : term.shape[1]] += c * term
    norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    return norm * out


def load_height_map(path, field: str = "surface.file", spacing_mm=(1.0, 1.0), height_unit="mm",
                    **options):
    """A (H, W) float64 height grid in mm and its spacing (dx, dy) in mm from an instrument
    file (X3P, .sur, .sdf, ...: units and spacing from the file) or a plain array (.npy,
    .csv/.txt, 32/64-bit float .tif/.tiff: ``spacing_mm``, ``height_unit``;
    :func:`pmdsim.config.files.read_height_map`) through
    :func:`pmdsim.topofile.read_topography` (``options``: ``level``, ``fill``,
    ``outlier_sigma``). Raises :class:`~pmdsim.config.files.FileInputError` (a
    ConfigError) naming ``field``."""
    t = read_topography(path, field, spacing_mm=spacing_mm, height_unit=height_unit, **options)
    return t.heights, (t.dx, t.dy)


def bspline_coefficients(z: np.ndarray) -> np.ndarray:
    """Cubic B-spline coefficients of a height grid, padded by 2 on each side, so that the
    kernel's spline equals ``scipy.ndimage.map_coordinates(z, order=3, mode='mirror')``."""
    from scipy import ndimage

    coef = ndimage.spline_filter(np.asarray(z, np.float64), order=3, mode="mirror")
    return np.pad(coef, 2, mode="reflect")


@dataclass(frozen=True, eq=False)
class SagSurface:
    """A surface z = sag(x, y) in its local frame (vertex ``centre``, local z ``normal``):
    base conic (``curvature`` 1/mm, ``conic`` k) + even asphere (``asphere`` = A4, A6, ...)
    + XY polynomial (``poly[i, j]`` of (x/s)^i (y/s)^j, s = ``poly_norm``) + bicubic height
    map (``height_map`` grid, ``map_origin`` local (x, y) of [0, 0], ``map_spacing``), inside
    ``aperture`` = (kind, centre x, centre y, a, b): rectangular (a, b half widths),
    circular (a radius) or annular (a outer, b inner radius). Intersections by
    :mod:`pmdsim.kernels.surface` (closed form for conics, safeguarded Newton otherwise)."""

    kind: str
    centre: np.ndarray
    normal: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    aperture: tuple
    curvature: float = 0.0
    conic: float = 0.0
    asphere: tuple = ()
    poly: np.ndarray | None = None
    poly_norm: float = 1.0
    height_map: np.ndarray | None = None
    map_origin: tuple = (0.0, 0.0)
    map_spacing: tuple = (1.0, 1.0)
    _params: np.ndarray = field(default=None, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "_params", self._build_params())

    @classmethod
    def from_config(cls, cfg: SurfaceConfig) -> "SagSurface":
        n = normalize(np.asarray(cfg.normal, np.float64))
        x = np.asarray(cfg.x_axis, np.float64)
        x = normalize(x - (x @ n) * n)
        y = np.cross(n, x)
        radius = getattr(cfg, "radius_mm", None)
        kw = dict(
            kind=cfg.type, centre=np.asarray(cfg.centre_mm, np.float64), normal=n, x_axis=x, y_axis=y,
            curvature=0.0 if radius is None else 1.0 / radius, conic=float(getattr(cfg, "conic", 0.0)),
        )
        if cfg.type == "asphere":
            kw["asphere"] = tuple(float(a) for a in cfg.coefficients)
        elif cfg.type == "xy_polynomial" and cfg.terms:
            deg = max(max(i, j) for i, j, _ in cfg.terms)
            poly = np.zeros((deg + 1, deg + 1))
            for i, j, c in cfg.terms:
                poly[i, j] += c
            kw.update(poly=poly, poly_norm=float(cfg.norm_radius_mm))
        elif cfg.type == "zernike" and cfg.coefficients:
            deg = max(zernike_noll(j)[0] for j, _ in cfg.coefficients)
            poly = np.zeros((deg + 1, deg + 1))
            for j, c in cfg.coefficients:
                mono = zernike_monomials(j)
                poly[: mono.shape[0], : mono.shape[1]] += c * mono
            kw.update(poly=poly, poly_norm=float(cfg.norm_radius_mm))
        elif cfg.type == "height_map":
            if cfg.spacing_mm is None and not is_instrument_file(cfg.file):
                raise ConfigError(f"surface.spacing_mm: {cfg.file} holds no sample spacing; "
                                  "give spacing_mm = [dx, dy] (mm)")
            z, (dx, dy) = load_height_map(cfg.file, "surface.file", cfg.spacing_mm, cfg.height_unit,
                                          level=cfg.level,
                                          fill=cfg.fill, outlier_sigma=cfg.outlier_sigma)
            h, w = z.shape
            origin = (-(w - 1) / 2 * dx, -(h - 1) / 2 * dy) if cfg.origin_mm is None else tuple(cfg.origin_mm)
            kw.update(height_map=z, map_origin=origin, map_spacing=(dx, dy))
        ap = cfg.aperture
        if ap is None:  # height map: its grid
            (x0, y0), (dx, dy) = kw["map_origin"], kw["map_spacing"]
            h, w = kw["height_map"].shape
            kw["aperture"] = ("rectangular", x0 + (w - 1) * dx / 2, y0 + (h - 1) * dy / 2,
                              (w - 1) * dx / 2, (h - 1) * dy / 2)
        elif ap.shape == "rectangular":
            kw["aperture"] = ("rectangular", *ap.centre_mm, ap.size_mm[0] / 2, ap.size_mm[1] / 2)
        elif ap.shape == "circular":
            kw["aperture"] = ("circular", *ap.centre_mm, ap.radius_mm, 0.0)
        else:
            kw["aperture"] = ("annular", *ap.centre_mm, ap.radius_mm, ap.inner_radius_mm)
        return cls(**kw)

    # -- the Surface interface -------------------------------------------------------
    @property
    def default_x_axis(self) -> np.ndarray:
        return self.x_axis

    def kernel_params(self) -> np.ndarray:
        return self._params

    def intersect(self, origins, dirs):
        from ..kernels import surface as ks

        o = np.ascontiguousarray(np.broadcast_to(origins, np.broadcast_shapes(np.shape(origins), np.shape(dirs))), np.float64)
        d = np.ascontiguousarray(np.broadcast_to(dirs, o.shape), np.float64)
        shape = o.shape[:-1]
        o2, d2 = o.reshape(-1, 3), d.reshape(-1, 3)
        t = np.empty(len(o2))
        p = np.empty((len(o2), 3))
        nrm = np.empty((len(o2), 3))
        hit = np.empty(len(o2), bool)
        ks.intersect_many(self._params, o2, d2, t, p, nrm, hit)
        return t.reshape(shape), p.reshape(shape + (3,)), nrm.reshape(shape + (3,)), hit.reshape(shape)

    def outline(self, n: int = 181) -> np.ndarray:
        kind, cx, cy, a, b = self.aperture
        if kind == "rectangular":
            s = np.linspace(-1, 1, n // 4 + 1)
            o = np.ones_like(s)
            xs = np.concatenate([s * a, o * a, -s * a, -o * a]) + cx
            ys = np.concatenate([-o * b, s * b, o * b, -s * b]) + cy
        else:
            th = np.linspace(0, 2 * np.pi, n)
            xs, ys = cx + a * np.cos(th), cy + a * np.sin(th)
        z, *_ = self.sag(xs, ys)
        return self.to_world(xs, ys, np.nan_to_num(z))

    # -- local frame helpers -----------------------------------------------------------
    def sag(self, x, y):
        """(z, dz/dx, dz/dy, ok) at local (x, y) mm (any shape); NaN where undefined."""
        from ..kernels import surface as ks

        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        x, y = np.broadcast_arrays(x, y)
        xf, yf = np.ascontiguousarray(x).ravel(), np.ascontiguousarray(y).ravel()
        z, zx, zy = (np.empty(len(xf)) for _ in range(3))
        ok = np.empty(len(xf), bool)
        ks.sag_many(self._params, xf, yf, z, zx, zy, ok)
        return z.reshape(x.shape), zx.reshape(x.shape), zy.reshape(x.shape), ok.reshape(x.shape)

    def in_aperture(self, x, y):
        kind, cx, cy, a, b = self.aperture
        ax, ay = np.asarray(x) - cx, np.asarray(y) - cy
        if kind == "rectangular":
            return (np.abs(ax) <= a) & (np.abs(ay) <= b)
        r2 = ax * ax + ay * ay
        return (r2 <= a * a) & ((r2 >= b * b) if kind == "annular" else True)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) local -> world rotation (columns: local x, y, z)."""
        return np.stack([self.x_axis, self.y_axis, self.normal], axis=1)

    def to_local(self, points):
        return (np.asarray(points, np.float64) - self.centre) @ self.rotation

    def to_world(self, x, y, z):
        return self.centre + np.stack([x, y, z], axis=-1) @ self.rotation.T

    def bounds(self):
        """(x_min, x_max, y_min, y_max) of the aperture in local mm."""
        kind, cx, cy, a, b = self.aperture
        if kind == "rectangular":
            return cx - a, cx + a, cy - b, cy + b
        return cx - a, cx + a, cy - a, cy + a

    def _build_params(self) -> np.ndarray:
        from ..kernels import surface as ks

        head = np.zeros(ks.SAG_HEADER)
        head[0] = ks.SURF_SAG
        head[ks.SAG_C : ks.SAG_C + 3] = self.centre
        head[ks.SAG_N : ks.SAG_N + 3] = self.normal
        head[ks.SAG_X : ks.SAG_X + 3] = self.x_axis
        head[ks.SAG_Y : ks.SAG_Y + 3] = self.y_axis
        kind, cx, cy, a, b = self.aperture
        head[ks.SAG_AP_TYPE] = {"rectangular": ks.AP_RECT, "circular": ks.AP_CIRC, "annular": ks.AP_ANNULUS}[kind]
        head[ks.SAG_AP_CX], head[ks.SAG_AP_CY], head[ks.SAG_AP_A], head[ks.SAG_AP_B] = cx, cy, a, b
        head[ks.SAG_CURV] = self.curvature
        head[ks.SAG_CONIC] = self.conic
        head[ks.SAG_SCALE] = max(a, b, 1e-3) + math.hypot(cx, cy)
        tail = []
        off = ks.SAG_HEADER
        head[ks.SAG_N_ASPH] = len(self.asphere)
        head[ks.SAG_OFF_ASPH] = off
        tail.append(np.asarray(self.asphere, np.float64))
        off += len(self.asphere)
        head[ks.SAG_POLY_DEG] = -1
        if self.poly is not None:
            head[ks.SAG_POLY_DEG] = self.poly.shape[0] - 1
            head[ks.SAG_POLY_NORM] = self.poly_norm
            head[ks.SAG_OFF_POLY] = off
            tail.append(np.asarray(self.poly, np.float64).ravel())
            off += self.poly.size
        if self.height_map is not None:
            coef = bspline_coefficients(self.height_map)
            ny, nx = self.height_map.shape
            head[ks.SAG_MAP] = 1.0
            head[ks.SAG_MAP_NX], head[ks.SAG_MAP_NY] = nx, ny
            head[ks.SAG_MAP_X0], head[ks.SAG_MAP_Y0] = self.map_origin
            head[ks.SAG_MAP_DX], head[ks.SAG_MAP_DY] = self.map_spacing
            head[ks.SAG_OFF_MAP] = off
            tail.append(coef.ravel())
        return np.concatenate([head, *tail])
