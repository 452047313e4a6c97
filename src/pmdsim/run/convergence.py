"""A convergence study written as a folder: ``convergence.csv``, ``convergence.png`` and
``convergence.json`` (atomically, like a run folder; see :mod:`pmdsim.studies.convergence`
for what is computed)."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from ..config import RunConfig
from ..studies.physics_checks import check_physics
from ..studies.valid_pixels import check_rows
from ..studies.convergence import (ALL_ESTIMATORS, COLUMNS, DEFAULT_N, DEFAULT_THETA_DEG,
                                   convergence_study)
from .threads import single_blas
from ..store.folder import atomic_run_dir, check_output_dir
from ..store.tables import write_json

#: Marker file of a finished convergence folder (an existing folder is replaced only if it
#: carries it, or is empty).
MARKER = "convergence.json"


#: Marker file of a finished convergence folder (an existing folder is replaced only if it
#: carries it, or is empty).
MARKER = "convergence.json"



@dataclass(frozen=True)
class ConvergenceResult:
    """Rows of the study (dicts with :data:`COLUMNS`) and the files written."""

    rows: list
    folder: Path
    table: Path
    figure: Path | None
    warnings: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)
    notes: tuple = ()
    reference: dict | None = None



def _row_name(r: dict) -> str:
    theta = "" if r["theta_max_deg"] != r["theta_max_deg"] else f" theta_max {r['theta_max_deg']:g} deg"
    return f"{r['estimator']} N = {r['n_rays']}{theta} {r['direction']} {r['width_px']:g} px"


@single_blas
def run_convergence(
    cfg: RunConfig,
    outdir: str | Path,
    n_values: Sequence[int] = DEFAULT_N,
    theta_values: Sequence[float] = DEFAULT_THETA_DEG,
    estimators: Sequence[str] = ALL_ESTIMATORS,
    camera_size: tuple[int, int] = (160, 128),
    widths: Sequence[float] | None = None,
    directions: Sequence[str] | None = None,
    shifts: int | None = None,
    figure: bool = True,
    overwrite: bool = False,
    progress: Callable[[str], None] | None = None,
    diagnostics: bool = True,
) -> ConvergenceResult:
    """Run :func:`pmdsim.studies.convergence.convergence_study` and write its table, figure
    and settings into ``outdir`` (created atomically; an existing one is replaced only with
    ``overwrite`` and only if it is a convergence folder or empty). ``figure``: draw
    ``convergence.png``; the other parameters are the study's."""
    final = Path(outdir).absolute()
    check_output_dir(final, overwrite, MARKER)
    notes = check_physics(cfg)  # a sensor/display/BRDF that leaves no signal, before the work
    study = convergence_study(cfg, n_values, theta_values, estimators, camera_size, widths,
                              directions, shifts, progress, diagnostics)
    notes += check_rows(study.rows, cfg.diagnostics.allow_no_valid_pixels, "converge",
                        _row_name)
    with atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        with open(tmp / "convergence.csv", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=COLUMNS)
            wr.writeheader()
            for r in study.rows:
                wr.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
        fig_path = None
        if figure:
            from ..report.convergence import plot_convergence

            w, h = study.meta["camera_size"]
            plot_convergence(study.rows, tmp / "convergence.png", cfg.sampling.n_rays,
                             cfg.sampling.theta_max_deg,
                             title=f"{cfg.name}: convergence ({w} x {h} px camera)")
            fig_path = final / "convergence.png"
        write_json(tmp / MARKER, study.meta)
    return ConvergenceResult(study.rows, final, final / "convergence.csv", fig_path,
                             study.warnings, study.diagnostics, tuple(notes),
                             study.meta.get("reference"))
