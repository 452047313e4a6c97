"""Shared pieces of every configuration section: the base model (frozen, unknown keys
forbidden, no NaN/inf), the number and vector types with their bounds, and the errors
the command line reports as bad input."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field


def _not_bool(v):
    # pydantic's lax mode reads true/false as 1/0: in a config file that is always a slip.
    if isinstance(v, bool):
        raise ValueError("must be a number, not a boolean (true/false)")
    return v


#: Numbers of a configuration: finite (no NaN/inf: ``allow_inf_nan=False`` on every model),
#: never a boolean.
Float = Annotated[float, BeforeValidator(_not_bool)]
Int = Annotated[int, BeforeValidator(_not_bool)]
Bool = Annotated[bool, Field(strict=True)]
#: Lengths and coordinates (mm) up to 1e7 mm (10 km): beyond that float64 geometry at
#: micrometre scale loses its digits and nothing of a PMD set-up lives there.
MAX_LENGTH_MM = 1e7
Coord = Annotated[Float, Field(ge=-MAX_LENGTH_MM, le=MAX_LENGTH_MM)]
Vec3 = tuple[Coord, Coord, Coord]
PositiveFloat = Annotated[Float, Field(gt=0)]
Length = Annotated[Float, Field(gt=0, le=MAX_LENGTH_MM)]
#: Pixels per image axis (camera and monitor): 65536 (a 64k x 64k image is 4 G pixels).
MAX_RESOLUTION_PX = 65536
ResolutionAxis = Annotated[Int, Field(gt=0, le=MAX_RESOLUTION_PX)]
#: Rays per pixel bundle; the run's memory and time are checked separately
#: (:func:`check_resources`).
MAX_RAYS = 10_000_000


class ConfigError(ValueError):
    """A configuration is invalid; the message names each offending field and the fix."""


class InputError(ValueError):
    """Bad input other than the configuration's values: an input file (a monitor image, a
    camera image, a run folder) or a command-line option; the message names it and the fix.
    With :class:`ConfigError` the only errors the command line reports as bad input (exit
    code 2); anything else is a bug (a traceback, exit code 1)."""


class MissingInputError(InputError, FileNotFoundError):
    """An input file or folder does not exist (also a :class:`FileNotFoundError`)."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _unit(name: str, v: Vec3) -> Vec3:
    n = math.sqrt(sum(x * x for x in v))
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"{name} must be a non-zero, finite 3-vector, got {v}")
    return v


def _nonzero_vector(v, info):
    """Field validator: a direction must be a non-zero, finite 3-vector (error names the field)."""
    if v is not None:
        n = math.sqrt(sum(x * x for x in v))
        if not np.isfinite(n) or n < 1e-12:
            raise ValueError("must be a non-zero, finite 3-vector")
    return v
