"""``[sampling]``: the scattered bundle and the estimator."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Float, Int, MAX_RAYS, _Model


class SamplingConfig(_Model):
    """The scattered bundle and the estimator.

    ``n_rays`` counts every ray of the bundle, the principal reflection direction P
    included (as in the paper; the ``radiometric`` estimator draws all ``n_rays`` from the
    lobe and adds no P). ``mode = "stratified"`` uses one deterministic,
    low-discrepancy sample set for every pixel (sampling error becomes a structured,
    repeatable pattern); ``"random"`` rotates that set per pixel by a seeded random
    Cranley-Patterson shift (sampling error becomes noise).
    """

    n_rays: Annotated[Int, Field(ge=1, le=MAX_RAYS)] = 100
    theta_max_deg: Annotated[Float, Field(gt=0, lt=90)] = 1.0
    scheme: Literal["polar", "solid_angle"] = "polar"
    mode: Literal["stratified", "random"] = "stratified"
    seed: Annotated[Int, Field(ge=0, lt=2**63)] = 0
    estimator: Literal["paper", "weighted_mean", "radiometric"] = Field(
        "paper",
        description="paper: (1/N) sum f I over the cone (the paper); weighted_mean: "
        "sum f I / sum f over the cone; radiometric: (1/N) sum f I cos_o / pdf over N "
        "directions importance-sampled from the whole lobe (no cone: theta_max_deg and "
        "scheme are not used, P is not added; see docs/physics.md)",
    )
