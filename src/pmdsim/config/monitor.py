"""``[monitor]``: the flat monitor's pixel grid, pose and display physics."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from .base import (Bool, Float, Int, Length, ResolutionAxis, Vec3, _Model, _nonzero_vector,
    _unit)

#: Cosine harmonics of a non-linear (gamma != 1) display response that analytic fringes on a
#: continuous monitor are summed with (the render's sums, and their memory in the estimate).
GAMMA_HARMONICS = 16


class MonitorConfig(_Model):
    """Flat monitor: a grid of square pixels. Pixel (v, u) (row, column; centres at integers)
    sits at ``centre_mm + (u - (W-1)/2) pitch e_u + (v - (H-1)/2) pitch e_v``. The screen faces
    ``look_at_mm``; ``up`` is the direction of decreasing row index (top of the screen)."""

    resolution: tuple[ResolutionAxis, ResolutionAxis] = Field(
        description="(width, height) in monitor pixels"
    )
    pixel_pitch_mm: Length
    centre_mm: Vec3
    look_at_mm: Vec3
    up: Vec3 = (0.0, 1.0, 0.0)
    gamma: Annotated[Float, Field(gt=0, le=10)] = Field(
        1.0, description="displayed luminance ~ value**gamma")
    black_level: Annotated[Float, Field(ge=0, le=1e6)] = 0.0
    white_level: Annotated[Float, Field(gt=0, le=1e6)] = 1.0
    pixel_model: Literal["nearest", "continuous"] = Field(
        "nearest",
        description="nearest: each monitor pixel a flat square emitter (the pattern value at "
        "the pixel centre); continuous: analytic fringes evaluated at the exact hit point",
    )
    # --- display physics (scene/display.py, docs/system.md) ---------------------------
    response_lut: str | None = Field(
        None, description="CSV file of (drive in [0, 1], relative luminance) rows replacing "
        "gamma; path relative to the config file")
    bit_depth: Annotated[Int, Field(ge=1, le=16)] | None = Field(
        None, description="quantise the drive value to this many bits before the response "
        "(8 or 10 on real displays); none = unquantised")
    precompensate_gamma: Bool = Field(
        False, description="show the pattern through the inverse response, so that the "
        "luminance (not the drive) is sinusoidal")
    falloff_exponent: Annotated[Float, Field(ge=0)] = Field(
        0.0, description="luminance ~ cos(theta)^m of the emission angle (0 = Lambertian)")
    falloff_table: tuple[tuple[Annotated[Float, Field(ge=0, lt=90)], Annotated[Float, Field(ge=0)]], ...] = Field(
        (), description="(angle_deg, relative luminance) rows, interpolated; multiplies the "
        "cos^m falloff")
    cover_glass_thickness_mm: Annotated[Float, Field(ge=0)] = 0.0
    cover_glass_index: Annotated[Float, Field(ge=1)] = 1.5
    flatness_coefficients_mm: tuple[tuple[Float, ...], ...] = Field(
        (), description="c[i][j]: the emitting surface lies h = sum c[i][j] x^i y^j mm in "
        "front of the nominal plane (towards the viewer), x, y in mm from the centre along "
        "the pixel columns / rows; up to 4 x 4")
    flatness_map: str | None = Field(
        None, description="height map (mm, towards the viewer) of the emitting surface: .npy or "
        "CSV rows, a grid from the centre of pixel (0, 0) to that of (W-1, H-1), interpolated "
        "bilinearly; adds to the polynomial; path relative to the config file")

    _up = field_validator("up")(_nonzero_vector)

    @model_validator(mode="after")
    def _check(self) -> "MonitorConfig":
        if self.white_level <= self.black_level:
            raise ValueError("white_level must be greater than black_level")
        c = self.flatness_coefficients_mm
        if c and (len(c) > 4 or any(len(r) != len(c) for r in c)):
            raise ValueError("flatness_coefficients_mm must be a square matrix of at most 4 x 4")
        if self.response_lut is not None and self.gamma != 1.0:
            raise ValueError("give gamma or response_lut, not both")
        angles = [a for a, _ in self.falloff_table]
        if any(b <= a for a, b in zip(angles, angles[1:])):
            raise ValueError("falloff_table angles must increase")
        n = np.subtract(self.look_at_mm, self.centre_mm)
        if np.linalg.norm(n) < 1e-9:
            raise ValueError("look_at_mm must differ from centre_mm")
        _unit("up", self.up)
        if np.linalg.norm(np.cross(n, self.up)) < 1e-9 * np.linalg.norm(n) * np.linalg.norm(self.up):
            raise ValueError("up must not be parallel to the monitor normal")
        return self
