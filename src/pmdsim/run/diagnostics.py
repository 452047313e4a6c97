"""Run diagnostics as a run stores them: :func:`pmdsim.studies.diagnostics.diagnose` on the
``[diagnostics]`` grid of a run's configuration, reduced to a JSON summary, the
:func:`~pmdsim.studies.diagnostic_warnings.check` warnings and the ``diag_*`` dataset variables."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..config import RunConfig
from ..render import Geometry, Simulation
from ..store.tables import json_safe


#: Quadrature points per grid pixel for the lobe-energy fraction of a run (``diagnose``'s
#: default is 16 384). On the Fig. 3 scene 4096 points give the median fraction to 2e-4 and
#: the 95 % cone angle to 0.01 deg of a 65 536-point quadrature, in a quarter of the time.
DIAGNOSTICS_ENERGY_SAMPLES = 4096



class _KnownGeometry:
    """A :class:`Simulation` whose :meth:`geometry` is the one the run has already traced
    (:func:`pmdsim.studies.diagnostics.diagnose` asks for the surface mask); everything else is the
    simulation's own."""

    def __init__(self, sim: Simulation, geometry: Geometry):
        self._sim = sim
        self._geometry = geometry

    def geometry(self) -> Geometry:
        return self._geometry

    def __getattr__(self, name):
        return getattr(self._sim, name)



@dataclass(frozen=True, eq=False)
class RunDiagnostics:
    """The run diagnostics of one configuration: ``summary`` (statistics.json
    ``"diagnostics"``), the :class:`~pmdsim.studies.diagnostic_warnings.DiagnosticWarning` s, and the
    dataset ``coords`` and ``variables`` ``{name: (dims, data, attrs)}``."""

    summary: dict
    warnings: tuple
    coords: dict
    variables: dict



def diagnose_run(cfg: RunConfig, sim: Simulation, geometry: Geometry,
                 exclude: np.ndarray | None = None) -> RunDiagnostics | None:
    """Energy fraction inside theta_max (cone estimators), effective sample size and the
    phase standard error (``[diagnostics] phase_method``) of every fringe (with fringes) on the coarse pixel
    grid of ``[diagnostics]``, and the :func:`~pmdsim.studies.diagnostic_warnings.check` warnings for its
    bounds. None for the mirror (no lobe). ``exclude`` (H, W): pixels left out of the
    judgement (bundles off the monitor)."""
    if sim.scene.brdf.is_delta:
        return None
    from dataclasses import asdict

    from ..studies import diagnostics as dg
    from ..studies.diagnostic_warnings import check as warnings_of

    fr = cfg.patterns.fringes
    cone = cfg.sampling.estimator in dg.CONE_ESTIMATORS
    widths = fr.widths_px if fr is not None else (50.0,)
    directions = fr.directions if fr is not None else ("x",)
    # The radiometric estimator has no cone: its energy fraction is not used (a token
    # quadrature keeps diagnose() cheap) and is dropped below.
    # target_fraction = the bound, so that check() can name the cone angle that meets it
    diag = dg.diagnose(_KnownGeometry(sim, geometry), widths, directions,
                       grid=cfg.diagnostics.grid,
                       target_fraction=cfg.diagnostics.min_energy_fraction,
                       phase_method=cfg.diagnostics.phase_method,
                       n_samples=DIAGNOSTICS_ENERGY_SAMPLES if cone else 16,
                       exclude=exclude)
    summary = dict(diag.summary)
    if not cone:
        diag = replace(diag, energy=None)
        summary.pop("energy", None)
    if fr is None:  # no fringes: no phase to judge
        diag = replace(diag, phase_se=None)
        for key in ("phase_se_method", "phase_se_rad", "modulation_median"):
            summary.pop(key, None)
    warnings = tuple(warnings_of(diag, bounds=cfg.diagnostics))
    grid = diag.grid
    summary["grid"] = {"columns": int(grid.cols.size), "rows": int(grid.rows.size)}
    if diag.energy is not None:
        summary["energy"]["quadrature_points"] = DIAGNOSTICS_ENERGY_SAMPLES
    summary["bounds"] = cfg.diagnostics.model_dump(mode="json")
    summary["warnings"] = [asdict(w) for w in warnings]
    summary = json_safe(summary)

    coords = {
        "diag_row": ("diag_row", grid.rows.astype(np.int64), {
            "units": "camera px", "description": "camera row of the diagnostics grid pixels"}),
        "diag_col": ("diag_col", grid.cols.astype(np.int64), {
            "units": "camera px", "description": "camera column of the diagnostics grid pixels"}),
    }
    where = "; on the coarse grid diag_row x diag_col, NaN: no surface"
    dims = ("diag_row", "diag_col")
    variables: dict = {}
    if diag.energy is not None:
        e = diag.energy
        variables["diag_energy_fraction"] = (dims, e.fraction, {
            "units": "1", "description": "fraction of the lobe's reflected energy "
            f"(integral of f cos theta_o) inside the sampling cone theta <= {e.theta_max_deg:g} "
            "deg about P" + where})
        variables["diag_theta_needed_deg"] = (dims, e.theta_needed_deg, {
            "units": "deg", "description": f"smallest cone half angle about P holding "
            f"{100 * e.target:g} % of the lobe's reflected energy" + where})
    if diag.rays is not None and not diag.summary.get("deterministic_rule"):  # no noise
        variables["diag_effective_sample_size"] = (dims, diag.rays.ess, {
            "units": "rays", "description": "effective sample size (sum w)^2 / sum w^2 of the "
            f"weights of the monitor-hitting rays, of N = {diag.n_rays}" + where})
    if diag.phase_se is not None:
        variables["diag_phase_se"] = (("direction", "width") + dims, diag.phase_se, {
            "units": "rad", "description": "Monte-Carlo standard error of the decoded phase, "
            + ("spread over independent rotations of the sample set (seeds)"
               if diag.phase_se_method == "seeds" else
               "delta method: std of the per-ray terms / (sqrt(N) |mean|), the error of N "
               "independent rays (an upper bound for the lattice sample sets)") + where})
    return RunDiagnostics(summary, warnings, coords, variables)
