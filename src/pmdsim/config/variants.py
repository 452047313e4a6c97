"""``[[variants]]``: members of a comparison that replace some of the run's sections."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, field_validator

from .base import _Model
from .anisotropy import AnisotropyConfig
from .brdf import BrdfConfig
from .sampling import SamplingConfig


#: Files and folders of a run folder: a variant (a sub-folder) cannot take these names.
RESERVED_VARIANT_NAMES = frozenset({
    "run.zarr", "config.json", "pmdsim-run.json", "figures", "fringes", "dots", "images",
    "statistics.json", "summary.txt", "dots.csv", "reference",
})


class VariantConfig(_Model):
    """One member of a comparison (e.g. two surface finishes side by side): the sections it
    gives replace the run's own; everything else is shared."""

    name: Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")]
    description: Annotated[str, Field(max_length=2000)] = ""
    brdf: BrdfConfig | None = None
    anisotropy: AnisotropyConfig | None = None
    sampling: SamplingConfig | None = None

    @field_validator("name")
    @classmethod
    def _folder_name(cls, v: str) -> str:
        # Each variant becomes the sub-folder OUTDIR/<name> of a run: no "..", no names of
        # the run's own files and folders.
        if v.lower() in RESERVED_VARIANT_NAMES or v.endswith("."):
            raise ValueError(
                f"{v!r} cannot name a variant's sub-folder (reserved: "
                f"{sorted(RESERVED_VARIANT_NAMES)}); choose another name"
            )
        return v
