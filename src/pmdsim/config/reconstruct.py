"""``[reconstruct]``: the monocular reconstruction of slopes and heights."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Bool, PositiveFloat, _Model
from .surface import SurfaceConfig


class ReconstructConfig(_Model):
    """Monocular reconstruction of the surface from the decoded monitor coordinates of both
    fringe directions (docs/reconstruction.md), with the configured surface as the nominal
    shape; height and slope errors against the configured (true) surface.

    ``enabled``: None = whenever the chain decodes both directions x and y; ``spacing_mm``:
    the surface grid; ``remove``: terms removed before the height statistics (``piston``,
    ``tilt`` = piston + tilt, ``power`` = + power, ``astigmatism`` = + astigmatism,
    ``sphere`` = the best-fit sphere, radius reported; docs/reconstruction.md);
    ``order``: 2 = classic Southwell, 4 = higher-order; ``anchor``: where the height is
    tied to the nominal shape (the aperture centre, or the mean over the aperture);
    ``prior``: the nominal shape (a surface table like ``[surface]``, e.g. the design when
    ``[surface]`` is a measured height map); default: the configured surface. The grid is
    in the prior's frame; errors are always against the configured (true) surface."""

    enabled: Bool | None = None
    spacing_mm: PositiveFloat = 0.5
    remove: Literal["none", "piston", "tilt", "power", "astigmatism", "sphere"] = "piston"
    order: Literal[2, 4] = 4
    anchor: Literal["centre", "mean"] = "centre"
    prior: SurfaceConfig | None = Field(
        None, description="nominal shape (a [surface]-like table); default: the configured surface")
