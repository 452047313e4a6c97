"""``[sweep]``: a parameter study over dotted configuration paths."""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .base import Bool, Float, Int, MAX_RESOLUTION_PX, _Model


class SweepRange(_Model):
    """A continuous range of a swept field for ``design = "random"``: values drawn
    uniformly in [min, max] (``scale = "log"``: uniformly in log, min > 0)."""

    min: Float
    max: Float
    scale: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _check(self) -> "SweepRange":
        if not (math.isfinite(self.min) and math.isfinite(self.max)) or self.max <= self.min:
            raise ValueError(f"give finite min < max, got min = {self.min}, max = {self.max}")
        if self.scale == "log" and self.min <= 0:
            raise ValueError("scale = 'log' needs min > 0")
        return self


_RANGE_KEYS = frozenset({"min", "max", "scale"})


def _flatten_parameters(data, prefix: str = "") -> dict:
    """TOML ``[sweep.parameters]`` as {dotted path: values}: quoted keys
    (``"brdf.alpha_y" = [...]``) and dotted keys (``brdf.alpha_y = [...]``, which TOML reads
    as nested tables) give the same path; a table of only min/max/scale is a range."""
    out = {}
    for k, v in data.items():
        path = f"{prefix}{k}"
        if isinstance(v, dict) and v and not set(v) <= _RANGE_KEYS:
            out.update(_flatten_parameters(v, path + "."))
        else:
            out[path] = v
    return out


class SweepConfig(_Model):
    """A parameter study (``pmdsim sweep``): the run's configuration is the base, and
    ``parameters`` names configuration fields by dotted path (``brdf.alpha_y``,
    ``patterns.fringes.widths_px.0`` for an element of a list) with their values.

    ``design``: ``grid`` (every combination; one store dimension per parameter), ``zip``
    (the i-th values of every parameter together; lists of equal length; one ``point``
    dimension), ``random`` (``points`` draws, seeded by ``seed``, from ranges
    ``{min, max, scale}`` or lists of choices; one ``point`` dimension).
    ``decimation``: the deviation and modulation maps are stored at every
    ``decimation``-th camera pixel (0 = no maps). ``common_random_numbers``: every point
    uses ``sampling.seed`` unchanged; by default a point's seed is derived from
    (``sampling.seed``, point index), so each point is independent and recomputes
    bit-identically on its own.
    """

    design: Literal["grid", "zip", "random"] = "grid"
    parameters: dict[str, tuple | SweepRange]
    points: Annotated[Int, Field(ge=1, le=100_000)] | None = Field(
        None, description="number of points of a random design")
    seed: Annotated[Int, Field(ge=0, lt=2**63)] = Field(0, description="seed of a random design")
    decimation: Annotated[Int, Field(ge=0, le=MAX_RESOLUTION_PX)] = Field(
        8, description="maps at every n-th camera pixel (0: statistics only)")
    common_random_numbers: Bool = False

    @field_validator("parameters", mode="before")
    @classmethod
    def _flat(cls, v):
        if isinstance(v, dict):
            v = _flatten_parameters(v)
            return {k: (x if isinstance(x, dict) else
                        tuple(x) if isinstance(x, (list, tuple)) else (x,))
                    for k, x in v.items()}
        return v

    @model_validator(mode="after")
    def _check(self) -> "SweepConfig":
        if not self.parameters:
            raise ValueError("parameters: name at least one field to sweep")
        for k, v in self.parameters.items():
            if isinstance(v, SweepRange) and self.design != "random":
                raise ValueError(f"parameters.{k!r}: a range {{min, max}} needs design = "
                                 "'random'; give a list of values for a grid or zip")
            if isinstance(v, tuple) and len(v) == 0:
                raise ValueError(f"parameters.{k!r}: give at least one value")
        if self.design == "zip":
            n = {k: len(v) for k, v in self.parameters.items()}
            if len(set(n.values())) > 1:
                raise ValueError(f"design = 'zip' needs lists of equal length, got {n}")
        if self.design == "random" and self.points is None:
            raise ValueError("design = 'random' needs points (the number of draws)")
        if self.design != "random" and self.points is not None:
            raise ValueError("points is only for design = 'random'")
        return self
