"""``[decode]``: the measurement chain (phase shifting, unwrapping, comparison)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Bool, Float, _Model


class DecodeConfig(_Model):
    """The measurement chain of ``pmdsim simulate``: decode the fringe images (phase
    shifting + temporal unwrapping, :mod:`pmdsim.decode`) of the surface and of its ideal
    specular reference, and compare them (:mod:`pmdsim.measure.chain`).

    ``enabled``: ``"auto"`` (default) decodes whenever the fringes allow it (K >= 3 shifts,
    widths that fit ``method`` over the monitor extent) and otherwise skips decoding with a
    note; ``true`` requires decoding (an error names ``patterns.fringes.widths_px`` when the
    widths do not fit); ``false`` turns the chain off.
    """

    enabled: Bool | Literal["auto"] = "auto"
    method: Literal["hierarchical", "heterodyne", "number_theoretic"] = Field(
        "hierarchical", description="temporal unwrapping method (see pmdsim.decode)"
    )
    min_relative_amplitude: Annotated[Float, Field(ge=0, le=1)] = Field(
        0.1, description="flag LOW_AMPLITUDE below this fraction of the median fringe "
        "amplitude of each width"
    )
    max_order_residual: Annotated[Float, Field(gt=0, le=0.5)] = Field(
        0.25, description="flag ORDER_RESIDUAL above this fringe-order residual"
    )
    min_modulation_ratio: Annotated[Float, Field(ge=0, le=1)] = Field(
        0.1, description="mask (low_modulation) pixels whose modulation B/A of any width is "
        "below this fraction of the specular reference's; they are counted, not hidden"
    )
