"""``[compute]``: how the work is split (tiles on Dask) and the CPU-time limit."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Float, Int, MAX_RESOLUTION_PX, _Model


class ComputeConfig(_Model):
    """How the work is split: camera tiles of ``tile_rows`` rows, run on Dask."""

    tile_rows: Annotated[Int, Field(ge=1, le=MAX_RESOLUTION_PX)] = 32
    scheduler: Literal["threads", "synchronous", "processes", "distributed"] = "threads"
    num_workers: Annotated[Int, Field(ge=1, le=4096)] | None = None
    max_cpu_hours: Annotated[Float, Field(gt=0)] = Field(
        100.0, description="refuse a run whose estimated CPU time (pmdsim.config."
        "estimate_resources) exceeds this; raise it to run anyway")
