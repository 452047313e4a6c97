"""``[sensor]``: the camera sensor (EMVA 1288 linear model)."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from .base import Bool, Float, Int, PositiveFloat, _Model


class SensorConfig(_Model):
    """The camera sensor, EMVA 1288 linear model (:mod:`pmdsim.scene.sensor`).

    Off by default (noise-free camera values). When ``enabled``, camera values become digital
    numbers (DN): the brightest finite value of each captured stack gets ``exposure`` mean
    electrons (give one of ``exposure_electrons``, ``exposure_photons`` (times
    ``quantum_efficiency``) or ``target_fill`` of ``full_well_electrons``; default fill 0.7),
    then PRNU, shot noise (Poisson), dark signal, DSNU and temporal dark noise (electrons),
    clipping at the full well, gain ``gain_dn_per_electron`` (default: the full well fills
    the ADC), offset, rounding and clipping to ``bit_depth`` bits. Fixed patterns (DSNU,
    PRNU) depend on ``seed`` only; temporal noise on ``seed`` and the frame.
    """

    enabled: Bool = False
    quantum_efficiency: Annotated[Float, Field(gt=0, le=1)] = 1.0
    # real pixels hold up to ~1e6 e-; the bounds keep Poisson sampling exact (NumPy's
    # limit is ~9e18) and name the field instead of NumPy's "lam value too large"
    exposure_electrons: Annotated[Float, Field(gt=0, le=1e12)] | None = None
    exposure_photons: Annotated[Float, Field(gt=0, le=1e12)] | None = None
    target_fill: Annotated[Float, Field(gt=0, le=1)] | None = None
    full_well_electrons: Annotated[Float, Field(gt=0, le=1e12)] = 10000.0
    dark_noise_electrons: Annotated[Float, Field(ge=0)] = Field(
        0.0, description="sigma_d, temporal dark noise (std, e-)")
    dark_signal_electrons: Annotated[Float, Field(ge=0)] = Field(
        0.0, description="mu_d, mean dark signal (e-)")
    dsnu_electrons: Annotated[Float, Field(ge=0)] = Field(
        0.0, description="dark signal non-uniformity: std of the per-pixel dark offset (e-)")
    prnu: Annotated[Float, Field(ge=0, lt=1)] = Field(
        0.0, description="photo-response non-uniformity: relative std of the per-pixel gain (1)")
    gain_dn_per_electron: PositiveFloat | None = Field(
        None, description="overall system gain K (DN/e-); default (2^bits - 1 - offset) / full well")
    bit_depth: Annotated[Int, Field(ge=1, le=16)] = 12
    offset_dn: Annotated[Float, Field(ge=0)] = 0.0
    shot_noise: Bool = True
    seed: Annotated[Int, Field(ge=0, lt=2**63)] = 0

    @model_validator(mode="after")
    def _check(self) -> "SensorConfig":
        given = [k for k in ("exposure_electrons", "exposure_photons", "target_fill")
                 if getattr(self, k) is not None]
        if len(given) > 1:
            raise ValueError(f"give one of exposure_electrons, exposure_photons, target_fill (got {given})")
        if self.offset_dn >= 2**self.bit_depth - 1:
            raise ValueError(f"offset_dn must be below the ADC maximum 2^{self.bit_depth} - 1")
        return self
