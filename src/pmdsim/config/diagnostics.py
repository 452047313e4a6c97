"""``[diagnostics]``: bounds of the convergence warnings."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Bool, Float, Int, PositiveFloat, _Model


class DiagnosticsConfig(_Model):
    """Bounds for the convergence warnings of :func:`pmdsim.studies.diagnostic_warnings.check`, and
    the explicit overrides of the checks before and after the work (``allow_*``)."""

    min_energy_fraction: Annotated[Float, Field(gt=0, le=1)] = Field(
        0.95, description="warn when the cone (theta_max) holds less of the lobe's energy"
    )
    max_phase_error_mrad: PositiveFloat = Field(
        1.0, description="warn when the Monte-Carlo standard error of the phase exceeds this"
    )
    min_ess_fraction: Annotated[Float, Field(gt=0, le=1)] = Field(
        0.1, description="warn when the effective sample size is below this fraction of N"
    )
    grid: tuple[Annotated[Int, Field(ge=2, le=1000)], Annotated[Int, Field(ge=2, le=1000)]] = Field(
        (24, 20), description="(columns, rows) of the coarse camera-pixel grid of the maps"
    )
    min_view_fraction: Annotated[Float, Field(ge=0, le=1)] = Field(
        0.01, description="stop before rendering when fewer camera pixels than this fraction "
        "see the surface and, by their principal reflection, the monitor (a warning with the "
        "fraction below 50 %)")
    max_off_monitor_fraction: Annotated[Float, Field(gt=0, le=1)] = Field(
        0.05, description="flag (and exclude from the valid pixels) a pixel when more than "
        "this fraction of its bundle's weight misses the monitor")
    phase_method: Literal["seeds", "delta"] = Field(
        "seeds",
        description="phase standard error from independent sample sets (seeds: measures the "
        "error the sampling actually makes) or from the per-ray variance (delta: cheaper, an "
        "upper bound that ignores the stratification, ~5x pessimistic on Fig. 3)",
    )
    allow_no_valid_pixels: Bool = Field(
        False, description="keep a decoded run in which some fringe direction has no valid "
        "pixel (by default an error naming the stage that removed them and its share)")
    allow_albedo_above_one: Bool = Field(
        False, description="accept a BRDF whose rho_s (times the largest [brdf.variation] "
        "rho_s_scale) exceeds 1, a surface that reflects more light than falls on it (by "
        "default refused before the work); the run says so in a note")
