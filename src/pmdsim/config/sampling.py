"""``[sampling]``: the scattered bundle and the estimator."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .base import Float, Int, MAX_RAYS, _Model


class SamplingConfig(_Model):
    """The scattered bundle and the estimator.

    ``n_rays`` counts the rays (quadrature nodes) of a pixel's bundle. ``mode = "rule"``
    (default) uses a deterministic Gauss rule of at most ``n_rays`` nodes (cone:
    Gauss-Legendre theta x trapezoid phi; radiometric: Gauss-Hermite in slope space) and
    estimates every sum's numerical error from the embedded rules of about 3/4 and 1/2 the
    order (docs/physics.md); where the integrand is not smooth (``nearest`` monitor, dots,
    images, tabulated slope densities) it uses ``"rqmc"``: ``replicates`` scrambled Sobol
    sets of ``n_rays / replicates`` points, error from their spread.
    ``"stratified"`` (the earlier default) is P plus a Fibonacci lattice, the same for
    every pixel (a structured error, not estimated); ``"random"`` rotates it per pixel by
    a seeded Cranley-Patterson shift (noise). ``target_error_mrad``: raise the rule's
    order until the phase error (P95 over pixels, each fringe) is below it.
    """

    n_rays: Annotated[Int, Field(ge=1, le=MAX_RAYS)] = 100
    theta_max_deg: Annotated[Float, Field(gt=0, lt=90)] = 1.0
    scheme: Literal["polar", "solid_angle"] = "polar"
    mode: Literal["rule", "rqmc", "stratified", "random"] = "rule"
    seed: Annotated[Int, Field(ge=0, lt=2**63)] = 0
    replicates: Annotated[Int, Field(ge=2, le=1024)] = 8
    error_estimate: bool = Field(
        True, description="render the two embedded rules (mode 'rule') to state every sum's "
        "numerical error; false saves those passes (about 81 % more rays, 58 % on large "
        "cameras) and states none")
    target_error_mrad: Annotated[Float, Field(gt=0)] | None = Field(
        None, description="raise the rule's order (n_rays) until the stated phase error "
        "(P95 over pixels, every fringe) is below this; None: render n_rays as given")
    max_rays: Annotated[Int, Field(ge=1, le=MAX_RAYS)] = 65536
    estimator: Literal["paper", "weighted_mean", "radiometric"] = Field(
        "paper",
        description="unset: paper for simulate, radiometric for budget, sweep and fit "
        "(pmdsim.config.physical_estimator). paper: (1/N) sum f I over the cone (the paper); weighted_mean: "
        "sum f I / sum f over the cone; radiometric: (1/N) sum f I cos_o / pdf over N "
        "directions importance-sampled from the whole lobe (no cone: theta_max_deg and "
        "scheme are not used, P is not added; see docs/physics.md)",
    )

    @model_validator(mode="after")
    def _check(self) -> "SamplingConfig":
        if self.mode == "rqmc" and self.n_rays < 2 * self.replicates:
            raise ValueError(
                f"n_rays = {self.n_rays} gives fewer than 2 points to each of the "
                f"{self.replicates} rqmc replicates: raise n_rays to >= {2 * self.replicates} "
                "or lower replicates")
        if self.target_error_mrad is not None and self.mode not in ("rule", "rqmc"):
            raise ValueError(
                f"target_error_mrad needs an error estimate: mode = {self.mode!r} has none; "
                "use mode = 'rule' (or 'rqmc')")
        if self.target_error_mrad is not None and not self.error_estimate:
            raise ValueError("target_error_mrad needs error_estimate = true")
        if self.max_rays < self.n_rays:
            raise ValueError(f"max_rays = {self.max_rays} is below n_rays = {self.n_rays}: "
                             "raise max_rays (the cap of target_error_mrad)")
        return self
