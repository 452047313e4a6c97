"""``[sampling]``: the scattered bundle and the estimator."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .base import Float, Int, MAX_RAYS, _Model


#: The target of the stated phase error (mrad, P95 over pixels, every fringe) where mode
#: ``rule`` is given neither ``n_rays`` nor ``target_error_mrad``, and the rule it starts from.
DEFAULT_TARGET_MRAD = 0.1
DEFAULT_TARGET_START = 16


class SamplingConfig(_Model):
    """The scattered bundle and the estimator.

    ``n_rays`` counts the rays (quadrature nodes) of a pixel's bundle. ``mode = "rule"``
    (default) uses a deterministic Gauss rule of at most ``n_rays`` nodes (cone:
    Gauss-Legendre theta x trapezoid phi; radiometric: Gauss-Hermite in slope space); on a
    continuous monitor its phase error is measured against a rule 4 x finer on a grid of
    1/64 of the pixels and carried to every pixel (:mod:`pmdsim.render.pilot`), elsewhere
    estimated from the embedded rules of about 3/4 and 1/2 the order (docs/physics.md); where the integrand is not smooth (``nearest`` monitor, dots,
    images, tabulated slope densities) it uses ``"rqmc"``: ``replicates`` scrambled Sobol
    sets of ``n_rays / replicates`` points, error from their spread.
    ``"stratified"`` (the earlier default) is P plus a Fibonacci lattice, the same for
    every pixel (a structured error, not estimated); ``"random"`` rotates it per pixel by
    a seeded Cranley-Patterson shift (noise). ``target_error_mrad``: the cheapest rule
    ``n_rays 2^k`` (or a step of 9/8 ... 3/2 of one that missed by at most 4 x) whose
    stated phase error (P95 over pixels, each fringe) is below it (picked by the pilot,
    then the camera rendered once; :func:`pmdsim.render.order.choose_order`). Neither
    ``n_rays`` nor ``target_error_mrad`` given (mode ``rule``): the target
    :data:`DEFAULT_TARGET_MRAD` from :data:`DEFAULT_TARGET_START` nodes; ``n_rays`` alone
    renders exactly that rule.
    ``max_rays`` caps a target only.
    """

    n_rays: Annotated[Int, Field(ge=1, le=MAX_RAYS)] = 100
    theta_max_deg: Annotated[Float, Field(gt=0, lt=90)] = 1.0
    scheme: Literal["polar", "solid_angle"] = "polar"
    mode: Literal["rule", "rqmc", "stratified", "random"] = "rule"
    seed: Annotated[Int, Field(ge=0, lt=2**63)] = 0
    replicates: Annotated[Int, Field(ge=2, le=1024)] = 8
    error_estimate: bool = Field(
        True, description="state the numerical error (mode 'rule'): by the pilot's rules on "
        "1/64 of the pixels where it applies (fringes on a smooth integrand), else by "
        "rendering the two embedded rules (about 81 % more rays, 58 % on large cameras); "
        "false states none")
    target_error_mrad: Annotated[Float, Field(gt=0)] | None = Field(
        None, description="the cheapest rule n_rays 2^k (or a step of 9/8 ... 3/2 of "
        "one that missed by at most 4 x) whose stated phase error (P95 over pixels, every "
        "fringe) is below this, picked by a pilot on a sparse grid of pixels; "
        "None: render n_rays as given (neither given in mode 'rule': 0.1 from 16 nodes)")
    max_rays: Annotated[Int, Field(ge=1, le=MAX_RAYS)] = 65536
    estimator: Literal["paper", "weighted_mean", "radiometric"] = Field(
        "paper",
        description="unset: paper for simulate, radiometric for budget, sweep and fit "
        "(pmdsim.config.physical_estimator). paper: (1/N) sum f I over the cone (the paper); weighted_mean: "
        "sum f I / sum f over the cone; radiometric: (1/N) sum f I cos_o / pdf over N "
        "directions importance-sampled from the whole lobe (no cone: theta_max_deg and "
        "scheme are not used, P is not added; see docs/physics.md)",
    )

    @model_validator(mode="before")
    @classmethod
    def _default_target(cls, data):
        """Mode ``rule`` with neither ``n_rays`` nor ``target_error_mrad`` given: the
        default target; a target without ``n_rays``: from :data:`DEFAULT_TARGET_START`
        nodes."""
        if not isinstance(data, dict) or "n_rays" in data:
            return data
        if data.get("target_error_mrad") is not None:  # a target alone: from 16 nodes
            return {**data, "n_rays": DEFAULT_TARGET_START}
        if data.get("mode", "rule") == "rule" and data.get("error_estimate", True) is not False:
            return {**data, "n_rays": DEFAULT_TARGET_START,
                    "target_error_mrad": DEFAULT_TARGET_MRAD}
        return data

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
        if self.target_error_mrad is not None and self.max_rays < self.n_rays:
            raise ValueError(f"max_rays = {self.max_rays} is below n_rays = {self.n_rays}, "
                             f"where target_error_mrad = {self.target_error_mrad:g} starts: "
                             "raise max_rays (the cap of the target) or lower n_rays")
        return self
