"""``[output]``: what a run writes (image format, figures)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Bool, Int, _Model


class OutputConfig(_Model):
    image_format: Literal["tiff", "png"] = "tiff"
    bit_depth: Literal[8, 16] = 16
    write_images: Bool = True
    figures: Bool = True
    figure_set: Literal["summary", "all"] = Field(
        "summary", description="summary: setup.png and overview.png (without decoding: "
        "setup, fringes, modulation); all: every figure (pmdsim report RUN --all draws them "
        "later from the run folder)")
    figure_workers: Annotated[Int, Field(ge=1, le=4096)] | None = Field(
        None, description="processes drawing a run's figures (forked on Linux, drawing "
        "from the run's data while it computes and writes); default: one per 2 CPU-s of "
        "drawing of the figures started together (pmdsim.run.figures.PROCESS_COST), at most "
        "one per core and per figure")
