"""Validated, frozen run configuration, read from TOML or built in Python.

Every model forbids unknown keys, so a typo in a config file is an error that names the
field. Lengths are in mm, angles in degrees where the name says ``_deg``. The resolved
configuration of a run is stored with its results (``RunConfig.model_dump``), so a run can
be reproduced from its own output.

One module per section of a configuration file (``camera``, ``monitor``, ``surface``,
``anisotropy``, ``brdf``, ``sampling``, ``patterns``, ``diagnostics``, ``compute``,
``output``, ``reconstruct``, ``decode``, ``sensor``, ``budget``, ``sweep``, ``variants``), the shared
base types and errors (``base``), :class:`RunConfig` composing them (``run``), reading
and validating (``loading``) and the memory and time estimate (``resources``). Every
public name is re-exported here: ``from pmdsim.config import X``.

Example
-------
>>> from pmdsim.config import RunConfig
>>> cfg = RunConfig.model_validate({"camera": {...}, ...})       # doctest: +SKIP
>>> cfg = load_config("examples/paper_fig3.toml")                 # doctest: +SKIP
"""

from .base import (Bool, ConfigError, Coord, Float, InputError, Int, Length, MAX_LENGTH_MM,
    MAX_RAYS, MAX_RESOLUTION_PX, MissingInputError, PositiveFloat, ResolutionAxis, Vec3)
from .camera import CameraConfig
from .monitor import MonitorConfig
from .surface import (ApertureConfig, AsphereSurfaceConfig, ConicSurfaceConfig,
    FlatSurfaceConfig, HeightMapSurfaceConfig, SphereSurfaceConfig, SurfaceConfig,
    XYPolynomialSurfaceConfig, ZernikeSurfaceConfig)
from .anisotropy import AnisotropyConfig
from .brdf import (Albedo, Alpha, BeckmannConfig, BrdfConfig, BrdfVariationConfig,
    MirrorConfig, SlopeDensityConfig, TurnedConfig, WardConfig)
from .topography import RayleighRiceConfig, TopographyConfig
from .sampling import SamplingConfig
from .patterns import DotConfig, FringeConfig, ImageConfig, PatternsConfig
from .diagnostics import DiagnosticsConfig
from .compute import ComputeConfig
from .output import OutputConfig
from .reconstruct import ReconstructConfig
from .decode import DecodeConfig
from .sensor import SensorConfig
from .budget import BudgetConfig, CalibrationUncertainty
from .sweep import SweepConfig, SweepRange
from .variants import RESERVED_VARIANT_NAMES, VariantConfig
from .run import (PHYSICAL_ESTIMATOR, RunConfig, SceneSections, SimulationSections, physical_estimator,
                  with_sampling, with_target_error)
from .loading import load_config, parse_config
from .resources import (BASE_MEMORY_BYTES, RAYS_PER_CPU_SECOND, ResourceEstimate,
                        available_memory_bytes, check_resources, estimate_resources)

#: Every public name of the sections (one module per section of a configuration file), the
#: loading and the resource estimate.
__all__ = [
    "Bool", "ConfigError", "Coord", "Float", "InputError", "Int", "Length",
    "MAX_LENGTH_MM", "MAX_RAYS", "MAX_RESOLUTION_PX", "MissingInputError", "PositiveFloat",
    "ResolutionAxis", "Vec3", "CameraConfig", "MonitorConfig", "ApertureConfig",
    "AsphereSurfaceConfig", "ConicSurfaceConfig", "FlatSurfaceConfig",
    "HeightMapSurfaceConfig", "SphereSurfaceConfig", "SurfaceConfig",
    "XYPolynomialSurfaceConfig", "ZernikeSurfaceConfig", "AnisotropyConfig", "Albedo",
    "Alpha", "BeckmannConfig", "BrdfConfig", "BrdfVariationConfig", "MirrorConfig",
    "SlopeDensityConfig", "TurnedConfig", "WardConfig", "RayleighRiceConfig", "TopographyConfig", "SamplingConfig", "DotConfig",
    "FringeConfig", "ImageConfig", "PatternsConfig", "DiagnosticsConfig", "ComputeConfig",
    "OutputConfig", "ReconstructConfig", "DecodeConfig", "SensorConfig", "BudgetConfig", "CalibrationUncertainty", "SweepConfig",
    "SweepRange", "RESERVED_VARIANT_NAMES", "VariantConfig", "RunConfig", "SceneSections", "SimulationSections", "PHYSICAL_ESTIMATOR",
    "physical_estimator", "with_sampling", "with_target_error", "load_config",
    "parse_config", "BASE_MEMORY_BYTES", "RAYS_PER_CPU_SECOND", "ResourceEstimate",
    "available_memory_bytes", "check_resources", "estimate_resources",
]
