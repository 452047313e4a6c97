"""``pmdsim budget``: write the error budget of a configuration (table and figure).

OUT/budget.csv (per effect and fringe direction), heights.csv (per effect: slope errors
X/Y and height error after the removal, the calibration rows among them), zernike.csv (the
Noll and Fringe tables of every height row, after removal), areal.csv (per height row and
map: ISO 25178 areal parameters and band-limited RMS, :mod:`pmdsim.studies.budget_areal`),
budget.json (all rows with their radial PSDs, the settings, the configuration), budget.png
and budget_psd.png (the height rows' radial PSDs); the folder is created atomically (:func:`pmdsim.store.folder.atomic_run_dir`, marker ``pmdsim-budget.json``).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..config import ConfigError, RunConfig, check_resources
from .simulate import resolve_roi
from ..studies.budget_error import HEIGHT_COLUMNS, TABLE_COLUMNS
from ..studies.budget import budget
from ..studies.valid_pixels import check_rows
from .threads import single_blas
from ..store.folder import atomic_run_dir, check_output_dir
from ..store.tables import write_json

MARKER = "pmdsim-budget.json"


@dataclass(frozen=True)
class BudgetResult:
    rows: list
    outdir: Path
    table: Path
    figure: Path | None
    height_rows: list = ()
    settings: dict | None = None
    notes: tuple = ()


def _csv(path: Path, rows, columns) -> None:
    with open(path, "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        wr.writeheader()
        for r in rows:
            wr.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def zernike_rows(height_rows) -> list[dict]:
    """One CSV row per (height row, ordering, term): the tables after removal."""
    out = []
    for r in height_rows:
        for order in ("noll", "fringe"):
            for t in r.get(f"zernike_{order}_nm", ()):
                out.append({"effect": r["effect"], "part": r["part"], "order": order, **t})
    return out


def _check_height_rows(cfg: RunConfig, rows) -> list[str]:
    """Refuse height rows without a node (every statistic NaN: not a result), naming what
    removed the nodes: the rim band (``budget.rim_exclusion_mm`` / ``_percent``) or the
    view; a note instead with ``diagnostics.allow_no_valid_pixels``."""
    empty = [r for r in rows or () if int(r.get("n_nodes", 1)) == 0]
    if not empty:
        return []
    b = cfg.budget
    labels = [r.get("label", r.get("effect", "?")) for r in empty]
    names = "; ".join(labels[:3]) + (f"; and {len(labels) - 3} more" if len(labels) > 3 else "")
    rim = max(int(r.get("rim_excluded") or 0) for r in empty)
    if rim:
        field = ("budget.rim_exclusion_mm = " f"{b.rim_exclusion_mm:g}" if b.rim_exclusion_mm
                 else f"budget.rim_exclusion_percent = {b.rim_exclusion_percent:g}")
        text = (f"{field}: the rim band takes every one of the {rim} nodes of the measured area "
                f"in {len(empty)} of {len(rows)} height rows ({names}), so their height and "
                "slope statistics are undefined; lower it below the measured area's inscribed "
                "radius (or use budget.rim_exclusion_percent)")
    else:
        field = (f"camera.roi = {list(cfg.camera.roi)}" if isinstance(cfg.camera.roi, tuple)
                 else "reconstruct")
        text = (f"{field}: no reconstructed node in {len(empty)} of {len(rows)} height rows "
                f"({names}); the camera sees too little of the part to reconstruct it")
    if cfg.diagnostics.allow_no_valid_pixels:
        return [f"budget: {text} (kept because diagnostics.allow_no_valid_pixels = true)"]
    raise ConfigError(f"invalid set-up:\n  {text}; nothing was written")


def _inscribed_radius_mm(surface) -> float | None:
    """The radius of the largest disc inside the surface's outline (mm): the half of the
    shorter side of a flat plate or a rectangular aperture, a circular aperture's radius,
    half an annulus's width; None where the configuration does not say (a height map's
    own extent)."""
    if getattr(surface, "type", None) == "flat":
        return 0.5 * min(surface.size_mm)
    ap = getattr(surface, "aperture", None)
    if ap is None:
        return None
    if ap.shape == "circular":
        return ap.radius_mm
    if ap.shape == "annular":
        return 0.5 * (ap.radius_mm - ap.inner_radius_mm)
    return 0.5 * min(ap.size_mm)


def _check_rim_band(cfg: RunConfig) -> None:
    """Refuse, before any work, a rim band at least as wide as the part's inscribed radius:
    the measured area lies inside the part, so the band would take every node
    (:func:`_check_height_rows` catches, after the work, a band that takes the nodes of a
    smaller view)."""
    b = cfg.budget
    inner = _inscribed_radius_mm(cfg.surface)
    if b.rim_exclusion_mm > 0 and inner is not None and b.rim_exclusion_mm >= inner:
        raise ConfigError(
            f"invalid set-up:\n  budget.rim_exclusion_mm = {b.rim_exclusion_mm:g}: the rim band "
            f"takes every node, since the part's inscribed radius is {inner:g} mm (the measured "
            "area lies inside it); lower it below the measured area's inscribed radius (or use "
            "budget.rim_exclusion_percent); nothing was written")


@single_blas
def run_budget(cfg: RunConfig, outdir: str | Path, figure: bool = True, overwrite: bool = False,
               progress: Callable[[str], None] | None = None, truth: str = "centre") -> BudgetResult:
    """Compute :func:`pmdsim.studies.budget.budget` and write it into ``outdir``."""
    from ..config import physical_estimator

    final = Path(outdir).absolute()
    cfg = resolve_roi(physical_estimator(cfg))  # the rendering integral unless cfg names one; camera.roi = "auto": the window that sees the part
    check_resources(cfg)  # the budget's largest run, before anything is computed
    _check_rim_band(cfg)
    check_output_dir(final, overwrite, MARKER)
    from ..scene import Scene
    from ..studies.physics_checks import check_physics

    check_physics(cfg, Scene.from_config(cfg))  # a sensor/display that leaves no signal
    try:
        result = budget(cfg, progress, truth)
    except ValueError as err:
        if isinstance(cfg.camera.roi, tuple) and "no valid decoded pixel" in str(err):
            raise ConfigError(f"invalid set-up:\n  camera.roi = {list(cfg.camera.roi)}: {err}: "
                              "the window (col0, row0, width, height) sees no decodable part "
                              "of the surface; widen it or set camera.roi = 'auto'") from None
        raise
    rows = result.rows
    notes = check_rows(rows, cfg.diagnostics.allow_no_valid_pixels, "budget",
                       lambda r: f"{r['effect']} {r['direction']}")  # 0 valid: not a result
    notes += _check_height_rows(cfg, result.height_rows)
    with atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        _csv(tmp / "budget.csv", rows, TABLE_COLUMNS)
        if result.height_rows:
            _csv(tmp / "heights.csv", result.height_rows, HEIGHT_COLUMNS)
            _csv(tmp / "zernike.csv", zernike_rows(result.height_rows),
                 ("effect", "part", "order", "index", "n", "m", "coefficient", "removed"))
            from ..studies.budget_areal import AREAL_COLUMNS, areal_rows

            _csv(tmp / "areal.csv", areal_rows(result.height_rows), AREAL_COLUMNS)
        write_json(tmp / "budget.json", {
            "name": cfg.name, "truth": truth, "settings": result.settings,
            "units": "every statistic X has its numerical error X_err (null: not stated)",
            "rows": rows, "height_rows": result.height_rows,
            "config": cfg.model_dump(mode="json")})
        fig = None
        if figure:
            from ..report.budget import plot_budget

            plot_budget(rows, tmp / "budget.png", title=f"{cfg.name}: error budget",
                        height_rows=result.height_rows, settings=result.settings)
            fig = final / "budget.png"
            if result.height_rows:
                from ..report.psd import plot_budget_psd

                plot_budget_psd(result.height_rows, tmp / "budget_psd.png",
                                title=f"{cfg.name}: error budget")
        (tmp / MARKER).write_text(json.dumps({"name": cfg.name, "kind": "budget"}) + "\n")
    return BudgetResult(rows, final, final / "budget.csv", fig, result.height_rows, result.settings,
                        tuple(notes))
