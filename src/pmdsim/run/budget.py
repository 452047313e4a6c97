"""``pmdsim budget``: write the error budget of a configuration (table and figure).

OUT/budget.csv, budget.json (rows and settings) and budget.png; the folder is created
atomically (:func:`pmdsim.run.files.atomic_run_dir`, marker ``pmdsim-budget.json``).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..config import RunConfig, check_resources
from ..studies.budget import TABLE_COLUMNS, budget
from . import files as pio
from .threads import single_blas

MARKER = "pmdsim-budget.json"


@dataclass(frozen=True)
class BudgetResult:
    rows: list
    outdir: Path
    table: Path
    figure: Path | None


@single_blas
def run_budget(cfg: RunConfig, outdir: str | Path, figure: bool = True, overwrite: bool = False,
               progress: Callable[[str], None] | None = None, truth: str = "centre") -> BudgetResult:
    """Compute :func:`pmdsim.studies.budget.budget` and write it into ``outdir``."""
    final = Path(outdir).absolute()
    check_resources(cfg)  # the budget's largest run, before anything is computed
    pio.check_output_dir(final, overwrite, MARKER)
    rows = budget(cfg, progress, truth)
    with pio.atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        with open(tmp / "budget.csv", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=TABLE_COLUMNS, extrasaction="ignore")
            wr.writeheader()
            for r in rows:
                wr.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
        (tmp / "budget.json").write_text(json.dumps(
            {"name": cfg.name, "truth": truth, "rows": rows, "config": cfg.model_dump(mode="json")},
            indent=2) + "\n")
        fig = None
        if figure:
            from ..report.budget import plot_budget

            plot_budget(rows, tmp / "budget.png", title=f"{cfg.name}: error budget")
            fig = final / "budget.png"
        (tmp / MARKER).write_text(json.dumps({"name": cfg.name, "kind": "budget"}) + "\n")
    return BudgetResult(rows, final, final / "budget.csv", fig)
