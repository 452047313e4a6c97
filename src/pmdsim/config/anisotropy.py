"""``[anisotropy]``: the local frame of the anisotropic BRDF at each hit point."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from .base import Vec3, _Model, _nonzero_vector, _unit


class AnisotropyConfig(_Model):
    """The local frame of the anisotropic BRDF at each hit point (z = surface normal).

    ``rotational``: x = tangential, y = radial about a diamond-turning centre and axis (the
    paper's convention). ``fixed``: x = ``x_direction`` projected onto the tangent plane.
    """

    frame: Literal["rotational", "fixed"] = "fixed"
    centre_mm: Vec3 = (0.0, 0.0, 0.0)
    axis: Vec3 | None = Field(None, description="turning axis; default: the surface normal")
    x_direction: Vec3 = (1.0, 0.0, 0.0)

    _directions = field_validator("axis", "x_direction")(_nonzero_vector)

    @model_validator(mode="after")
    def _check(self) -> "AnisotropyConfig":
        if self.axis is not None:
            _unit("axis", self.axis)
        _unit("x_direction", self.x_direction)
        return self
