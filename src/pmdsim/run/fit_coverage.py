"""Write the fit's coverage study (:mod:`pmdsim.studies.fit_coverage`) to a folder:
coverage.json (every case and result) and coverage.png (normalised errors), atomically.

``python -m pmdsim.run.fit_coverage OUTDIR [N [SEED]]`` (20 cases, seed 0: a few minutes on
two cores)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..report.texture import plot_fit_coverage
from ..studies.fit_coverage import fit_coverage
from .threads import single_blas
from ..store.folder import atomic_run_dir, check_output_dir
from ..store.tables import write_json

MARKER = "pmdsim-fit-coverage.json"


@single_blas
def run_fit_coverage(outdir, n: int = 20, seed: int = 0, overwrite: bool = False,
                     progress=None) -> tuple[list, Path]:
    final = Path(outdir).absolute()
    check_output_dir(final, overwrite, MARKER)
    results = fit_coverage(n, seed, progress)
    covered = sum(r.covered for r in results)
    with atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        write_json(tmp / "coverage.json", {"n": n, "seed": seed, "covered_k2": covered,
                                               "cases": [r.as_dict() for r in results]})
        plot_fit_coverage(results, tmp / "coverage.png")
        (tmp / MARKER).write_text(json.dumps({"kind": "fit-coverage", "n": n}) + "\n")
    return results, final


def main(argv=None) -> int:  # pragma: no cover - a study, run by hand
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print(__doc__)
        return 2
    n = int(argv[1]) if len(argv) > 1 else 20
    seed = int(argv[2]) if len(argv) > 2 else 0

    def progress(i, r):
        z = ", ".join(f"{v:+.2f}" for v in r.normalised_errors)
        print(f"case {i}: errors/u ({z}), chi2 {r.chi2_reduced:.3f}, "
              f"{'covered' if r.covered else 'MISSED'}{'' if r.success else ' FAILED ' + r.reason}",
              flush=True)

    results, out = run_fit_coverage(argv[0], n, seed, overwrite=True, progress=progress)
    print(f"{sum(r.covered for r in results)} of {len(results)} covered at k = 2; {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
