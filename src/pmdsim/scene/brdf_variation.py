"""Spatially varying BRDF parameters: alpha (per axis) and rho_s as maps over the surface.

A diamond-turned part is not machined the same everywhere: the cutting speed falls towards
the turning centre, so the roughness (alpha along and across the grooves) and the
reflectance change along the radius. :class:`BrdfVariation` turns the configuration
(``[brdf.variation]``, :class:`pmdsim.config.BrdfVariationConfig`) into per-pixel parameter
rows ``(rho_s, alpha_x, alpha_y)`` for the bundle kernels (``brdf_px`` of
:func:`pmdsim.kernels.bundle.render_tile` / ``render_tile_lobe``), evaluated at each
pixel's surface point.

The surface point is recovered from the pixel's geometry row itself (``G_T``, ``G_U0``,
``G_V0`` are the point's coordinates in the monitor's orthonormal frame), so the tracer is
not touched and every camera model (pinhole, lens, sub-pixels) gets its own points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import BrdfVariationConfig, ConfigError, files
from ..kernels import bundle as kb

QUANTITIES = ("alpha_tangential", "alpha_radial", "rho_s_scale")
#: Kernel models that read per-pixel (rho, alpha_x, alpha_y).
SUPPORTED_MODELS = (kb.MODEL_WARD, kb.MODEL_BECKMANN)


def load_variation_map(path, quantity: str | None) -> dict[str, np.ndarray]:
    """{quantity: (H, W) float64 grid} from a .npz (arrays named after the quantities) or a
    .npy/.csv/.txt holding ``quantity``. Raises a ConfigError
    (:class:`~pmdsim.config.files.FileInputError`) naming ``brdf.variation.file``
    (:func:`pmdsim.config.files.read_variation_map`)."""
    return files.read_variation_map(path, quantity, "brdf.variation.file")


@dataclass(frozen=True, eq=False)
class BrdfVariation:
    """Per-pixel BRDF parameters over the surface.

    ``radius`` mode: tables over ``radius_mm`` about the axis through ``centre`` along
    ``axis``; ``map`` mode: grids over the surface's local (x, y) (``origin`` of element
    [0, 0], ``spacing`` (dx, dy)) in the frame ``centre``/``x_axis``/``y_axis``.
    """

    mode: str
    centre: np.ndarray
    axis: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    radius_mm: np.ndarray | None
    values: dict  # quantity -> (R,) table or (H, W) grid
    origin: tuple[float, float] | None = None
    spacing: tuple[float, float] | None = None

    @classmethod
    def from_config(cls, cfg: BrdfVariationConfig, surface, anisotropy) -> "BrdfVariation":
        """The radius is measured from the rotational frame's axis (``anisotropy``), or from
        the surface vertex axis in a fixed frame; map coordinates are the surface's local
        (x, y) about its vertex."""
        if anisotropy.kind == "rotational":
            centre = np.asarray(anisotropy.centre, np.float64)
            axis = surface.normal if anisotropy.axis is None else anisotropy.axis
        else:
            centre = np.asarray(surface.centre, np.float64)
            axis = surface.normal
        axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
        xs = np.asarray(surface.x_axis, np.float64)
        ys = np.asarray(surface.y_axis, np.float64)
        if cfg.radius_mm is not None:
            vals = {k: np.asarray(getattr(cfg, k), np.float64) for k in QUANTITIES
                    if getattr(cfg, k) is not None}
            return cls("radius", centre, axis, xs, ys, np.asarray(cfg.radius_mm, np.float64), vals)
        grids = load_variation_map(cfg.file, cfg.quantity)
        h, w = next(iter(grids.values())).shape
        dx, dy = cfg.spacing_mm
        origin = (cfg.origin_mm if cfg.origin_mm is not None
                  else (-(w - 1) * dx / 2.0, -(h - 1) * dy / 2.0))
        return cls("map", np.asarray(surface.centre, np.float64), axis, xs, ys, None, grids,
                   (float(origin[0]), float(origin[1])), (float(dx), float(dy)))

    # ------------------------------------------------------------------ evaluation
    def radius(self, points: np.ndarray) -> np.ndarray:
        """Distance (...,) of points (..., 3) from the axis, mm."""
        r = np.asarray(points, np.float64) - self.centre
        r = r - (r @ self.axis)[..., None] * self.axis
        return np.sqrt(np.einsum("...k,...k->...", r, r))

    def local_xy(self, points: np.ndarray):
        d = np.asarray(points, np.float64) - self.centre
        return d @ self.x_axis, d @ self.y_axis

    def quantity(self, name: str, points: np.ndarray) -> np.ndarray | None:
        """The quantity ``name`` (...,) at surface points (..., 3); None where not varied."""
        v = self.values.get(name)
        if v is None:
            return None
        if self.mode == "radius":
            return np.interp(self.radius(points), self.radius_mm, v)
        from scipy import ndimage

        x, y = self.local_xy(points)
        col = (x - self.origin[0]) / self.spacing[0]
        row = (y - self.origin[1]) / self.spacing[1]
        shape = np.shape(x)
        coords = np.stack([np.ravel(row), np.ravel(col)])
        out = ndimage.map_coordinates(v, coords, order=1, mode="nearest")
        return out.reshape(shape)

    def pixel_params(self, points: np.ndarray, brdf_vector: np.ndarray) -> np.ndarray:
        """Rows (P, 3) ``(rho_s, alpha_x, alpha_y)`` at points (P, 3) for the kernels'
        ``brdf_px``: the varied quantities at each point, the BRDF's own elsewhere."""
        model = int(brdf_vector[kb.B_MODEL])
        if model not in SUPPORTED_MODELS:
            raise ConfigError("brdf.variation: spatially varying parameters are supported for "
                              "the 'ward' and 'beckmann' models only")
        n = points.shape[0]
        out = np.empty((n, 3))
        out[:, 0] = brdf_vector[kb.B_RHO]
        out[:, 1] = brdf_vector[kb.B_AX]
        out[:, 2] = brdf_vector[kb.B_AY]
        for col, name in ((1, "alpha_tangential"), (2, "alpha_radial")):
            q = self.quantity(name, points)
            if q is not None:
                out[:, col] = q
        s = self.quantity("rho_s_scale", points)
        if s is not None:
            out[:, 0] = brdf_vector[kb.B_RHO] * s
        return out

    def geometry_params(self, geo: np.ndarray, monitor, brdf_vector: np.ndarray) -> np.ndarray:
        """:meth:`pixel_params` of the surface points of bundle geometry rows (P, G_SIZE);
        rows of pixels that miss the surface get the BRDF's own values (never read)."""
        return self.pixel_params(points_from_geometry(geo, monitor), brdf_vector)


def with_params(brdf, rho_s: float, alpha_x: float, alpha_y: float):
    """The Ward or Beckmann model ``brdf`` with one pixel's parameters (a row of
    :meth:`BrdfVariation.pixel_params`): the NumPy twin of the kernels' ``brdf_px``."""
    import dataclasses

    if hasattr(brdf, "alpha_u"):
        return dataclasses.replace(brdf, rho_s=float(rho_s), alpha_u=float(alpha_x),
                                   alpha_v=float(alpha_y))
    return dataclasses.replace(brdf, rho_s=float(rho_s), alpha_x=float(alpha_x),
                               alpha_y=float(alpha_y))


def points_from_geometry(geo: np.ndarray, monitor) -> np.ndarray:
    """Surface points (P, 3) of geometry rows: S = M0 + (U0 - (W-1)/2) p e_u +
    (V0 - (H-1)/2) p e_v - T n_m (the rows' ``G_U0``, ``G_V0``, ``G_T``; orthonormal
    monitor frame). Rows of misses give the monitor side of garbage; mask with ``G_VALID``."""
    p = monitor.pitch
    a = (geo[:, kb.G_U0] - (monitor.width - 1) / 2.0) * p
    b = (geo[:, kb.G_V0] - (monitor.height - 1) / 2.0) * p
    t = geo[:, kb.G_T]
    return (monitor.centre + a[:, None] * monitor.e_u + b[:, None] * monitor.e_v
            - t[:, None] * monitor.normal)
