"""The manifest ``pmdsim-run.json`` of a run folder (written last: it marks the folder complete)."""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

from ..config import RunConfig
from .folder import MANIFEST
from .schema import CONFIG_NAME, DATASET_NAME, _version
from .tables import write_json


def write_run_manifest(folder: Path, cfg: RunConfig, result, timings: dict) -> None:
    rel = lambda ps: [str(Path(p).relative_to(folder)) for p in ps]  # noqa: E731
    write_manifest(folder, {
        "format": "pmdsim-run/1",
        "name": cfg.name,
        "pmdsim_version": _version(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "dataset": DATASET_NAME,
        "config": CONFIG_NAME,
        "images": rel(result.image_paths),
        "figures": rel(result.figure_paths),
        "exposure": result.exposure,
        "image_scaling": "pixel = round(clip(value * exposure, 0, 2**bit_depth - 1)); "
                         "NaN (no surface) -> 0",
        "bit_depth": cfg.output.bit_depth,
        "camera_shape": list(result.shape),
        "surface_pixels": result.surface_pixels,
        "rays_per_pixel": result.rays_per_pixel,
        "rays_traced": result.rays_traced,
        "notes": list(result.notes),
        "warnings": [w.message for w in result.warnings],
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
        "sizes_bytes": dict(result.sizes),
    })



def write_variants_manifest(folder: Path, cfg: RunConfig, top) -> None:
    """The manifest of the top level of a run with variants (written after the variants')."""
    figure_paths = [p for p in top.figure_paths if Path(p).parent == folder / "figures"]
    names = [r.config.name for r in top.variants]
    write_manifest(folder, {
        "format": "pmdsim-run/1",
        "name": cfg.name,
        "pmdsim_version": _version(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "config": CONFIG_NAME,
        "variants": names,
        "figures": [str(p.relative_to(folder)) for p in figure_paths],
        "rays_traced": top.rays_traced,
        "notes": list(top.notes),
        "warnings": {r.config.name: [w.message for w in r.warnings] for r in top.variants},
        "timings_s": {k: round(v, 4) for k, v in top.timings.items()},
        "sizes_bytes": dict(top.sizes),
    })


def write_manifest(folder: str | Path, content: dict) -> Path:
    """Write the run manifest (JSON) into ``folder``; call it last."""
    return write_json(Path(folder) / MANIFEST, content)
