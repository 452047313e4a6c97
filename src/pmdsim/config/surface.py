"""``[surface]``: the surface under test, flat or a sag surface (sphere, conic, asphere,
freeform, measured height map) with its aperture; the tagged union :data:`SurfaceConfig`."""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from .base import (Coord, Float, Int, Length, MAX_LENGTH_MM, PositiveFloat, Vec3, _Model,
    _nonzero_vector, _unit)


def _check_axes(surface) -> None:
    """A surface pose's ``normal`` and ``x_axis``: unit-normalisable and not parallel."""
    _unit("normal", surface.normal)
    _unit("x_axis", surface.x_axis)
    n = np.asarray(surface.normal) / np.linalg.norm(surface.normal)
    x = np.asarray(surface.x_axis) / np.linalg.norm(surface.x_axis)
    if abs(n @ x) > 1 - 1e-9:
        raise ValueError("x_axis must not be parallel to normal")


class FlatSurfaceConfig(_Model):
    """A flat rectangle of ``size_mm`` = (along x_axis, along normal x x_axis)."""

    type: Literal["flat"] = "flat"
    size_mm: tuple[Length, Length]
    centre_mm: Vec3 = (0.0, 0.0, 0.0)
    normal: Vec3 = (0.0, 0.0, 1.0)
    x_axis: Vec3 = (1.0, 0.0, 0.0)

    _directions = field_validator("normal", "x_axis")(_nonzero_vector)

    @model_validator(mode="after")
    def _check(self) -> "FlatSurfaceConfig":
        _check_axes(self)
        return self


def _aperture_reach(ap) -> float | None:
    """The largest distance (mm) from the vertex axis that an aperture reaches."""
    if ap is None:
        return None
    cx, cy = ap.centre_mm
    if ap.shape == "rectangular":
        w, h = ap.size_mm
        return math.hypot(abs(cx) + w / 2, abs(cy) + h / 2)
    return math.hypot(cx, cy) + ap.radius_mm


def _aperture_fits(surface) -> None:
    """Refuse an aperture beyond the edge of a closed base conic (a sphere of radius R ends
    at r = |R|; a conic with 1 + k > 0 at |R| / sqrt(1 + k)): the surface has no points there."""
    radius = getattr(surface, "radius_mm", None)
    reach = _aperture_reach(getattr(surface, "aperture", None))
    k = float(getattr(surface, "conic", 0.0))
    if radius is None or reach is None or 1 + k <= 0:
        return
    edge = abs(radius) / math.sqrt(1 + k)
    if reach >= edge:
        what = "sphere" if k == 0 else f"conic (k = {k:g})"
        raise ValueError(
            f"aperture: reaches {reach:g} mm from the axis, but a {what} of radius_mm = "
            f"{radius:g} ends at {edge:g} mm (it has no points beyond); use a smaller "
            "aperture.radius_mm / size_mm (or a larger radius_mm)")


class ApertureConfig(_Model):
    """The clear aperture of a curved surface, in its local (x, y) (mm, about ``centre_mm``).

    ``circular``: ``radius_mm``; ``annular``: ``radius_mm`` and ``inner_radius_mm``;
    ``rectangular``: ``size_mm`` (along local x, along local y). ``centre_mm`` off the
    vertex gives an off-axis segment of the parent surface.
    """

    shape: Literal["circular", "annular", "rectangular"] = "circular"
    radius_mm: PositiveFloat | None = None
    inner_radius_mm: Annotated[Float, Field(ge=0, le=MAX_LENGTH_MM)] = 0.0
    size_mm: tuple[PositiveFloat, PositiveFloat] | None = None
    centre_mm: tuple[Coord, Coord] = (0.0, 0.0)

    @model_validator(mode="after")
    def _check(self) -> "ApertureConfig":
        if self.shape in ("circular", "annular") and self.radius_mm is None:
            raise ValueError(f"aperture.radius_mm is required for shape = {self.shape!r}")
        if self.shape == "annular" and not (0 < self.inner_radius_mm < self.radius_mm):
            raise ValueError("aperture.inner_radius_mm must be > 0 and < radius_mm for an annulus")
        if self.shape == "rectangular" and self.size_mm is None:
            raise ValueError("aperture.size_mm = [width, height] is required for shape = 'rectangular'")
        return self


class _SagSurfaceBase(_Model):
    """Pose and aperture of a sag surface: vertex at ``centre_mm``, local z = ``normal``
    (the side the camera looks from), local x = ``x_axis`` (projected). ``radius_mm`` > 0
    puts the centre of curvature on the +normal side (concave towards the camera);
    None = flat base. See docs/surfaces.md."""

    centre_mm: Vec3 = (0.0, 0.0, 0.0)
    normal: Vec3 = (0.0, 0.0, 1.0)
    x_axis: Vec3 = (1.0, 0.0, 0.0)
    aperture: ApertureConfig

    _directions = field_validator("normal", "x_axis")(_nonzero_vector)

    @field_validator("radius_mm", check_fields=False)
    @classmethod
    def _radius(cls, v):
        if v is not None and (not np.isfinite(v) or v == 0):
            raise ValueError("must be a non-zero finite radius of curvature in mm (None or omit for a flat base)")
        return v

    @model_validator(mode="after")
    def _check_pose(self):
        _check_axes(self)
        _aperture_fits(self)
        return self


class SphereSurfaceConfig(_SagSurfaceBase):
    """A sphere of radius of curvature ``radius_mm``."""

    type: Literal["sphere"]
    radius_mm: Coord


class ConicSurfaceConfig(_SagSurfaceBase):
    """A conic: radius of curvature at the vertex and conic constant k (0 sphere, -1
    paraboloid, < -1 hyperboloid, (-1, 0) prolate and > 0 oblate ellipsoid)."""

    type: Literal["conic"]
    radius_mm: Coord | None = None
    conic: Annotated[Float, Field(ge=-1e6, le=1e6)] = 0.0


class AsphereSurfaceConfig(_SagSurfaceBase):
    """Even asphere: the conic plus ``coefficients`` A4, A6, A8, ... of r^4, r^6, r^8, ...
    (mm^-3, mm^-5, ...)."""

    type: Literal["asphere"]
    radius_mm: Coord | None = None
    conic: Annotated[Float, Field(ge=-1e6, le=1e6)] = 0.0
    coefficients: Annotated[tuple[Float, ...], Field(max_length=64)] = ()


class XYPolynomialSurfaceConfig(_SagSurfaceBase):
    """Freeform: the base conic plus sum c (x/s)^i (y/s)^j over ``terms`` = [[i, j, c_mm], ...],
    s = ``norm_radius_mm``."""

    type: Literal["xy_polynomial"]
    radius_mm: Coord | None = None
    conic: Annotated[Float, Field(ge=-1e6, le=1e6)] = 0.0
    norm_radius_mm: PositiveFloat = 1.0
    terms: tuple[tuple[Annotated[Int, Field(ge=0, le=20)], Annotated[Int, Field(ge=0, le=20)], Float], ...] = ()


class ZernikeSurfaceConfig(_SagSurfaceBase):
    """Freeform: the base conic plus sum c_j Z_j(x/s, y/s) with Noll's ordering and
    normalisation (RMS 1 on the unit disc), ``coefficients`` = [[j, c_mm], ...],
    s = ``norm_radius_mm``."""

    type: Literal["zernike"]
    radius_mm: Coord | None = None
    conic: Annotated[Float, Field(ge=-1e6, le=1e6)] = 0.0
    norm_radius_mm: PositiveFloat
    coefficients: tuple[tuple[Annotated[Int, Field(ge=1, le=231)], Float], ...] = ()


class HeightMapSurfaceConfig(_SagSurfaceBase):
    """A measured topography: heights on a regular grid from ``file``, rows along local y,
    columns along local x: an instrument file (X3P, Digital Surf .sur, ISO 25178-71 .sdf,
    Alicona .al3d, ...: units and spacing from the file; ``pmdsim.topofile``) or a plain
    array (.npy, .csv, 32-bit float .tif/.tiff) with ``spacing_mm`` = (dx, dy) and heights
    in ``height_unit``. ``level`` ("none", "mean", "plane"), ``outlier_sigma`` and ``fill``
    ("error", "nearest", "mean": for non-measured points and outliers) prepare it.
    ``origin_mm`` = local (x, y) of element [0, 0] (default: the grid centred on the
    vertex); the heights are added to the base conic, interpolated with a bicubic B-spline
    (continuous normals). The aperture defaults to the grid."""

    type: Literal["height_map"]
    file: str
    spacing_mm: tuple[PositiveFloat, PositiveFloat] | None = None
    level: Literal["none", "mean", "plane"] = "none"
    fill: Literal["error", "nearest", "mean"] = "error"
    outlier_sigma: PositiveFloat | None = None
    origin_mm: tuple[Coord, Coord] | None = None
    height_unit: Literal["mm", "um", "nm"] = "mm"
    radius_mm: Coord | None = None
    conic: Annotated[Float, Field(ge=-1e6, le=1e6)] = 0.0
    aperture: ApertureConfig | None = None


SurfaceConfig = Annotated[
    FlatSurfaceConfig | SphereSurfaceConfig | ConicSurfaceConfig | AsphereSurfaceConfig
    | XYPolynomialSurfaceConfig | ZernikeSurfaceConfig | HeightMapSurfaceConfig,
    Field(discriminator="type"),
]
