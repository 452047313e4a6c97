"""``[patterns]``: what the monitor shows (fringes, dots, images)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .base import Coord, Float, Int, MAX_RESOLUTION_PX, _Model


class FringeConfig(_Model):
    """Sinusoidal fringes: widths (periods) in monitor px, K equal phase shifts."""

    # a period below 2 monitor pixels cannot be shown (it aliases): the smallest width is 2
    widths_px: Annotated[tuple[Annotated[Float, Field(ge=2, le=1e7)], ...],
                         Field(max_length=16)] = (50.0,)
    shifts: Annotated[Int, Field(ge=3, le=256)] = 4
    directions: tuple[Literal["x", "y"], ...] = ("x", "y")

    @field_validator("widths_px")
    @classmethod
    def _widths(cls, v):
        if len(v) == 0:
            raise ValueError("give at least one fringe width")
        if len(set(v)) != len(v):
            raise ValueError("fringe widths must be distinct")
        return v

    @field_validator("directions")
    @classmethod
    def _dirs(cls, v):
        if len(v) == 0 or len(set(v)) != len(v):
            raise ValueError('directions must be a non-empty subset of ["x", "y"]')
        return v


class DotConfig(_Model):
    """White square dots on black, ``size_px`` monitor pixels wide, at monitor positions
    ``positions_px`` (u, v) and/or on a ``grid`` of (columns, rows) evenly spread over the
    monitor (margin ``margin_px`` from the edges)."""

    size_px: Annotated[Int, Field(ge=1, le=MAX_RESOLUTION_PX)] = 15
    positions_px: Annotated[tuple[tuple[Coord, Coord], ...], Field(max_length=10000)] = ()
    grid: tuple[Annotated[Int, Field(ge=1, le=1000)], Annotated[Int, Field(ge=1, le=1000)]] | None = None
    margin_px: Annotated[Float, Field(ge=0, le=MAX_RESOLUTION_PX)] = 60.0

    @model_validator(mode="after")
    def _check(self) -> "DotConfig":
        if not self.positions_px and self.grid is None:
            raise ValueError("give positions_px or grid")
        return self


class ImageConfig(_Model):
    """Arbitrary monitor images (PNG/TIFF files, paths relative to the config file)."""

    files: Annotated[tuple[Annotated[str, Field(min_length=1, max_length=4096)], ...],
                     Field(max_length=10000)]

    @field_validator("files")
    @classmethod
    def _paths(cls, v):
        # checked here, after the items: pydantic's own length check would also report
        # "at least 1 item ... not 0" for a list whose items are wrong (files = [1])
        if len(v) == 0:
            raise ValueError("give at least one image file")
        if any("\x00" in f for f in v):
            raise ValueError("file names must not contain NUL characters")
        return v


class PatternsConfig(_Model):
    """What the monitor shows. ``fringes = false`` in TOML turns the default fringes off."""

    fringes: FringeConfig | None = FringeConfig()
    dots: DotConfig | None = None
    images: ImageConfig | None = None

    @field_validator("fringes", mode="before")
    @classmethod
    def _no_fringes(cls, v):
        if v is False:
            return None
        if v is True:
            return FringeConfig()
        return v

    @model_validator(mode="after")
    def _something(self) -> "PatternsConfig":
        if self.fringes is None and self.dots is None and self.images is None:
            raise ValueError("nothing to show: give fringes, dots or images")
        return self
