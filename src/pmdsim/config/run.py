"""The whole configuration (:class:`RunConfig`) composed of the sections, and the checks
across sections."""

from __future__ import annotations

from typing import Annotated, Protocol

from pydantic import Field, model_validator

from .base import ConfigError, _Model
from .camera import CameraConfig
from .monitor import MonitorConfig
from .surface import SurfaceConfig
from .anisotropy import AnisotropyConfig
from .brdf import BeckmannConfig, BrdfConfig, SlopeDensityConfig, WardConfig
from .sampling import SamplingConfig
from .patterns import PatternsConfig
from .diagnostics import DiagnosticsConfig
from .compute import ComputeConfig
from .output import OutputConfig
from .reconstruct import ReconstructConfig
from .decode import DecodeConfig
from .sensor import SensorConfig
from .budget import BudgetConfig
from .sweep import SweepConfig
from .variants import VariantConfig


class SceneSections(Protocol):
    """The sections a scene is built from (:meth:`pmdsim.scene.Scene.from_config`): what a
    :class:`RunConfig` has, and all the scene may read of it."""

    camera: CameraConfig
    monitor: MonitorConfig
    surface: SurfaceConfig
    anisotropy: AnisotropyConfig
    brdf: BrdfConfig
    sampling: SamplingConfig


class SimulationSections(SceneSections, Protocol):
    """The sections a simulation is built from (:meth:`pmdsim.render.Simulation.from_config`):
    the scene's and ``compute`` (tiles, scheduler, workers)."""

    compute: ComputeConfig


class RunConfig(_Model):
    """Everything a simulation needs.

    With ``variants`` the run simulates each variant (same camera, monitor, surface shape
    and patterns; its own BRDF/anisotropy/sampling); :meth:`expand` lists them.
    """

    name: Annotated[str, Field(max_length=200)] = "pmdsim-run"
    camera: CameraConfig
    monitor: MonitorConfig
    surface: SurfaceConfig
    anisotropy: AnisotropyConfig = AnisotropyConfig()
    brdf: BrdfConfig
    sampling: SamplingConfig = SamplingConfig()
    patterns: PatternsConfig = PatternsConfig()
    compute: ComputeConfig = ComputeConfig()
    output: OutputConfig = OutputConfig()
    decode: DecodeConfig = DecodeConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    diagnostics: DiagnosticsConfig = DiagnosticsConfig()
    sensor: SensorConfig = SensorConfig()
    budget: BudgetConfig = BudgetConfig()
    variants: Annotated[tuple[VariantConfig, ...], Field(max_length=64)] = ()
    sweep: SweepConfig | None = None

    @model_validator(mode="before")
    @classmethod
    def _default_surface_type(cls, data):
        # ``surface.type`` defaults to "flat" (as documented); the tagged union needs the tag.
        if isinstance(data, dict) and isinstance(data.get("surface"), dict) and "type" not in data["surface"]:
            data = dict(data, surface=dict(data["surface"], type="flat"))
        return data

    @model_validator(mode="before")
    @classmethod
    def _variation_models(cls, data):
        # brdf.variation exists for Ward and Beckmann only: name the field, not the union
        if isinstance(data, dict):
            _check_variation_model(data.get("brdf"), "brdf")
            if isinstance(data.get("variants"), (list, tuple)):
                for k, v in enumerate(data["variants"]):
                    if isinstance(v, dict):
                        _check_variation_model(v.get("brdf"), f"variants.{k}.brdf")
        return data

    @model_validator(mode="after")
    def _check(self) -> "RunConfig":
        _check_alpha_frame(self.brdf, self.anisotropy, "brdf")
        names = [v.name for v in self.variants]
        if len(set(names)) != len(names):
            raise ValueError(f"variants: names must be unique, got {names}")
        for k, v in enumerate(self.variants):
            _check_alpha_frame(v.brdf or self.brdf, v.anisotropy or self.anisotropy,
                               f"variants.{k}.brdf")
        return self

    def expand(self) -> list[tuple[str, "RunConfig"]]:
        """(name, config) of every variant with its sections applied; the run itself when
        there are no variants."""
        if not self.variants:
            return [(self.name, self)]
        out = []
        for v in self.variants:
            changes = {k: getattr(v, k) for k in ("brdf", "anisotropy", "sampling")
                       if getattr(v, k) is not None}
            out.append((v.name, self.model_copy(update=dict(changes, variants=(), name=v.name))))
        return out



#: The estimator of ``budget``, ``sweep`` and ``fit`` when the configuration names none: the
#: rendering integral (the physical answer); ``simulate`` keeps ``SamplingConfig``'s default
#: (the paper's cone estimator, to reproduce the paper).
PHYSICAL_ESTIMATOR = "radiometric"


def physical_estimator(cfg: "RunConfig") -> "RunConfig":
    """``cfg`` with ``sampling.estimator = "radiometric"`` unless its file (or its caller)
    set ``sampling.estimator`` explicitly: the default of ``budget``, ``sweep`` and ``fit``.
    Idempotent (the result names its estimator)."""
    if "estimator" in cfg.sampling.model_fields_set:
        return cfg
    return with_sampling(cfg, estimator=PHYSICAL_ESTIMATOR)


def with_sampling(cfg: "RunConfig", **changes) -> "RunConfig":
    """``cfg`` with ``changes`` to ``[sampling]``, validated; the fields the configuration
    set explicitly stay marked as set (:func:`physical_estimator` reads them)."""
    from .sampling import DEFAULT_TARGET_MRAD, DEFAULT_TARGET_START

    s = cfg.sampling
    if ("n_rays" in changes and "target_error_mrad" not in changes
            and s.n_rays == DEFAULT_TARGET_START and s.target_error_mrad == DEFAULT_TARGET_MRAD):
        changes = {**changes, "target_error_mrad": None}  # the default target: n_rays alone
    given = set(cfg.sampling.model_fields_set) | set(changes)
    full = type(cfg).model_validate({**cfg.model_dump(), "sampling": {**cfg.sampling.model_dump(),
                                                                      **changes}})
    samp = full.sampling.model_construct(_fields_set=given, **full.sampling.model_dump())
    return full.model_copy(update={"sampling": samp})


def with_target_error(cfg: "RunConfig", target_error_mrad: float | None) -> "RunConfig":
    """``cfg`` with ``sampling.target_error_mrad`` (the ``--target-error-mrad`` option; None
    leaves it); a field-named error when the target is not positive or the sampling mode
    has no error estimate."""
    if target_error_mrad is None:
        return cfg
    if not target_error_mrad > 0:
        raise ConfigError(f"--target-error-mrad must be > 0 mrad, got {target_error_mrad}")
    try:
        return with_sampling(cfg, target_error_mrad=float(target_error_mrad))
    except ValueError as err:
        why = ("; ".join(e["msg"].removeprefix("Value error, ") for e in err.errors())
               if hasattr(err, "errors") else str(err))
        raise ConfigError(f"--target-error-mrad: {why}") from None

def _check_variation_model(brdf, where: str) -> None:
    if isinstance(brdf, dict) and "variation" in brdf and brdf.get("model") not in ("ward", "beckmann"):
        raise ValueError(
            f"{where}.variation: spatially varying BRDF parameters are supported for "
            f"model 'ward' and 'beckmann' only, got {where}.model = {brdf.get('model')!r}; "
            f"remove {where}.variation or change the model")


def _check_alpha_frame(brdf, anisotropy, where: str) -> None:
    if (isinstance(brdf, (WardConfig, BeckmannConfig, SlopeDensityConfig))
            and brdf.alpha_tangential is not None):
        if anisotropy.frame != "rotational":
            raise ValueError(
                f"{where}.alpha_tangential/alpha_radial need anisotropy.frame = 'rotational'; "
                "with a fixed frame use "
                + ("alpha_u/alpha_v" if isinstance(brdf, BeckmannConfig) else "alpha_x/alpha_y")
            )
