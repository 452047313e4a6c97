"""``[brdf]`` models from measured topographies and smooth finishes (issue 20):
``model = "topography"`` (a measured height map: slope density or specular peak plus
Rayleigh-Rice halo, by the Rayleigh parameter) and ``model = "rayleigh_rice"`` (a specular
peak plus the halo of an anisotropic K-correlation PSD). Physics in
``pmdsim.brdf.topography`` and ``pmdsim.brdf.rayleigh_rice``; docs/texture.md."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .base import Float, PositiveFloat, _Model

Wavelength = Annotated[Float, Field(gt=1.0, le=1e5)]
Incidence = Annotated[Float, Field(ge=0, lt=89)]


class _SmoothFields(_Model):
    """What the halo needs besides the PSD: wavelength, incidence and substrate."""

    wavelength_nm: Wavelength = 545.0
    incidence_deg: Incidence | None = Field(
        None, description="incidence the halo table is built for and the Rayleigh parameter "
                          "is taken at; default: the set-up's at the surface centre")
    refractive_index: tuple[PositiveFloat, Annotated[Float, Field(ge=0)]] | None = Field(
        None, description="substrate (n, k) for the polarisation factor Q and the reflectance; "
                          "default: Q = rho_s")
    rho_s: Annotated[Float, Field(gt=0, le=1)] = 0.9
    halo_bins: Annotated[int, Field(ge=16, le=2048)] = 512


class RayleighRiceConfig(_SmoothFields):
    """An optically smooth finish: the specular peak (share exp(-(4 pi sigma cos / lambda)^2),
    rendered as the mirror) plus the first-order Rayleigh-Rice halo of an anisotropic
    K-correlation PSD: RMS height ``sigma_nm``, correlation lengths (B / 2 pi) along the
    local x (tangential) and y (radial) axes, exponent ``exponent_c`` > 1 (2: exponential
    autocorrelation). Needs ``sampling.estimator = "radiometric"`` or ``"weighted_mean"``."""

    model: Literal["rayleigh_rice"] = "rayleigh_rice"
    sigma_nm: Annotated[Float, Field(gt=0, le=1000)]
    correlation_length_tangential_um: Annotated[Float, Field(gt=0, le=1e5)]
    correlation_length_radial_um: Annotated[Float, Field(gt=0, le=1e5)]
    exponent_c: Annotated[Float, Field(gt=1, le=20)] = 2.0


class TopographyConfig(_SmoothFields):
    """A measured roughness patch (``file``: X3P, .sur, .sdf, .vk4, .plu, .datx, ... with units and
    spacing inside, or .npy/.csv/.tif with ``spacing_mm`` and ``height_unit``), levelled
    (``level``), outliers and non-measured points handled (``outlier_sigma``, ``fill``);
    ``radial_axis``: the map axis across the turning grooves (local y). ``regime``:
    ``auto`` (by the Rayleigh parameter 4 pi Sq cos / lambda: the specular peak plus the
    Rayleigh-Rice halo of the map's PSD below 1, the slope density above), ``smooth`` or
    ``geometric``. ``psd``: the halo from the ``tabulated`` periodogram or its
    ``k_correlation`` fit."""

    model: Literal["topography"] = "topography"
    file: str
    spacing_mm: tuple[PositiveFloat, PositiveFloat] | None = None
    height_unit: Literal["mm", "um", "nm"] = "um"
    level: Literal["none", "mean", "plane"] = "plane"
    fill: Literal["error", "nearest", "mean"] = "nearest"
    outlier_sigma: PositiveFloat | None = None
    radial_axis: Literal["x", "y"] = "y"
    regime: Literal["auto", "smooth", "geometric"] = "auto"
    psd: Literal["tabulated", "k_correlation"] = "tabulated"
    bins: Annotated[int, Field(ge=4, le=4096)] = 128
    shadowing: Literal["smith", "none"] = "smith"

    @model_validator(mode="after")
    def _check(self) -> "TopographyConfig":
        if not self.file:
            raise ValueError("file: give the topography file (X3P, .sur, .sdf, ...)")
        return self
