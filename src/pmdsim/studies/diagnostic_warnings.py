"""The sampling warnings of a run's diagnostics (:class:`~pmdsim.studies.diagnostics.Diagnostics`):
:func:`check` names, for each, what is wrong and the setting that fixes it
(:class:`DiagnosticWarning`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .diagnostics import CONE_ESTIMATORS, Diagnostics, _pct


@dataclass(frozen=True)
class DiagnosticWarning:
    """One warning: what is wrong (``message``) and the setting that fixes it
    (``setting`` = ``suggested`` value, or a change of estimator)."""

    code: str
    message: str
    setting: str
    suggested: object

    def __str__(self) -> str:
        return self.message


#: Below this effective sample size (median) the fringes are not judged at all (the noise
#: floor 2/sqrt(ESS) of the modulation would exceed 1): a "too_few_rays" warning instead.
MIN_ESS = 4
#: Suggestions never ask for more rays than the configuration allows.
MAX_SUGGESTED_RAYS = 10_000_000


def _wider_width(width: float, spread_px: float, target: float) -> float:
    """The fringe width (monitor px) whose modulation reaches ``target`` if the lobe's
    footprint on the monitor were Gaussian with the rays' standard deviation ``spread_px``,
    ``m(w) = exp(-2 pi^2 sigma^2 / w^2)``, with a margin of 1.2; rounded up, and at least
    twice ``width``."""
    t = min(max(target, 0.01), 0.9)
    if not math.isfinite(spread_px) or spread_px <= 0:
        return float(_nice_up(2 * width))
    need = math.pi * spread_px * math.sqrt(2.0 / math.log(1.0 / t))
    return float(_nice_up(max(1.2 * need, 2 * width)))


def _nice_up(x: float) -> int:
    """Round up to two significant digits (1234 -> 1300)."""
    if x <= 0 or not math.isfinite(x):
        return 0
    e = 10 ** max(0, int(math.floor(math.log10(x))) - 1)
    return int(math.ceil(x / e) * e)


def check(diag: Diagnostics, min_energy_fraction: float = 0.95, max_phase_error_mrad: float = 1.0,
          min_ess_fraction: float = 0.1, min_modulation: float = 0.05,
          bounds=None) -> list[DiagnosticWarning]:
    """Warnings for a :class:`Diagnostics`, each with the setting that would fix it.

    ``bounds``: a :class:`pmdsim.config.DiagnosticsConfig` whose values replace the
    keyword arguments. Grid pixels in ``diag.excluded`` (bundles off the monitor) and NaN
    values (no surface, no hit) are left out of every statistic. The energy fraction is
    judged by its median over the grid pixels (the suggested theta_max covers the worst
    pixel). With a median effective sample size (ESS) below ``MIN_ESS`` the fringes are not
    judged ("too_few_rays", raise n_rays). Otherwise each fringe (direction, width) is
    judged by its median modulation ``m`` against the noise floor ``2 / sqrt(ESS)``:
    ``m`` below a floor that exceeds ``min_modulation`` cannot be told from noise
    ("modulation_undetermined", raise n_rays); ``m < min_modulation`` is washed out (a wider
    width is suggested); the others' phase error, P95 over the pixels of the worst fringe,
    is compared with ``max_phase_error_mrad``. The ESS fraction is judged by its median.
    Every warning's ``setting = suggested``, applied, is meant to clear it (tested).
    """
    if bounds is not None:
        min_energy_fraction = bounds.min_energy_fraction
        max_phase_error_mrad = bounds.max_phase_error_mrad
        min_ess_fraction = bounds.min_ess_fraction
    out: list[DiagnosticWarning] = []
    cone = diag.estimator in CONE_ESTIMATORS
    e = diag.energy
    if cone and e is not None and np.isfinite(e.fraction).any():
        med = float(np.nanmedian(e.fraction))
        if med < min_energy_fraction:
            fr = e.fraction
            # the cone angle that keeps min_energy_fraction is known if it was the target
            theta_ok = float(np.nanmax(e.theta_needed_deg)) if math.isclose(e.target, min_energy_fraction) else None
            msg = (f"theta_max = {diag.theta_max_deg:g} deg holds {100 * med:.0f} % of the lobe "
                   f"energy (median over pixels; min {100 * float(np.nanmin(fr)):.0f} %)")
            if theta_ok is not None:
                sugg = math.ceil(theta_ok * 10) / 10
                msg += f"; theta_max >= {sugg:g} deg keeps {100 * min_energy_fraction:.0f} %"
            else:
                sugg = None
            msg += " (or use sampling.estimator = 'radiometric', which samples the whole lobe)"
            out.append(DiagnosticWarning("energy_fraction", msg, "sampling.theta_max_deg", sugg))
    rays = diag.rays
    # a deterministic rule: no sampling noise, no effective sample size to judge
    det = bool(diag.summary.get("deterministic_rule"))
    ess_med = (_pct(diag.judged(rays.ess), 50) if rays is not None and not det
               else float("nan"))
    few = rays is not None and math.isfinite(ess_med) and ess_med < MIN_ESS
    if few and cone:
        # The cone's rays miss the lobe (narrower than their spacing, or off to one side):
        # more rays of the same cone barely help; importance sampling of the lobe does.
        out.append(DiagnosticWarning(
            "effective_sample_size",
            f"effective sample size {ess_med:.2g} of {diag.n_rays} rays (median over pixels) "
            f"< {MIN_ESS}: almost all the weight sits on one ray of the cone, the fringes' "
            "modulation and phase error cannot be judged; use sampling.estimator = "
            "'radiometric' (importance sampling of the lobe)",
            "sampling.estimator", "radiometric"))
    elif few:
        n_new = min(_nice_up(diag.n_rays * 1.5 * MIN_ESS / max(ess_med, 0.25)), MAX_SUGGESTED_RAYS)
        out.append(DiagnosticWarning(
            "too_few_rays",
            f"effective sample size {ess_med:.2g} (median over pixels) < {MIN_ESS}: too few of "
            f"the {diag.n_rays} rays carry weight to judge the fringes' modulation or phase "
            f"error; raise sampling.n_rays to ~ {n_new}",
            "sampling.n_rays", n_new))
    if (diag.phase_se is not None or det) and not few:
        worst, which = -1.0, None
        floor = 2.0 / math.sqrt(ess_med) if math.isfinite(ess_med) else 0.0
        for di, d in enumerate(diag.directions):
            for wi, wd in enumerate(diag.widths):
                mod = _pct(diag.judged(rays.modulation[di, wi]), 50) if rays is not None else 1.0
                if not math.isfinite(mod):
                    continue  # no pixel to judge (an empty view stops the run before this)
                if mod < floor and floor > min_modulation:
                    # indistinguishable from sampling noise, which is above the bound:
                    # more rays tell whether the lobe washes the fringes out
                    # a modulation below the floor is consistent with none: bring the floor
                    # below min_modulation (ESS grows with N), then the next run can tell
                    n_new = min(_nice_up(diag.n_rays * 1.5 * (floor / min_modulation) ** 2),
                                MAX_SUGGESTED_RAYS)
                    out.append(DiagnosticWarning(
                        "modulation_undetermined",
                        f"{d} fringes of {wd:g} px: modulation {mod:.3g} (median) is within the "
                        f"sampling noise ~ {floor / 2:.2g} of {ess_med:.3g} effective rays: "
                        f"whether the lobe washes them out cannot be told; raise "
                        f"sampling.n_rays to ~ {n_new}",
                        "sampling.n_rays", n_new))
                    continue
                if mod < min_modulation:
                    spread = (_pct(diag.judged(rays.spread_px[di]), 50)
                              if rays is not None and rays.spread_px is not None else float("nan"))
                    wider = _wider_width(wd, spread, 2.0 * max(min_modulation, floor))
                    out.append(DiagnosticWarning(
                        "washed_out",
                        f"{d} fringes of {wd:g} px keep a modulation of {mod:.3g} (median; "
                        f"sampling noise alone gives ~ {floor / 2:.2g}): the lobe washes them "
                        f"out, their phase cannot be measured at any number of rays; use wider "
                        f"fringes (~ {wider:g} px instead of {wd:g})",
                        "patterns.fringes.widths_px",
                        tuple(sorted({wider if w == wd else w for w in diag.widths})),
                    ))
                    continue
                if diag.phase_se is None:
                    continue
                p95 = _pct(diag.judged(diag.phase_se[di, wi]), 95)
                if p95 > worst:
                    worst, which = p95, (d, wd)
        if which is not None and worst * 1e3 > max_phase_error_mrad and diag.phase_se_method == "rule":
            out.append(DiagnosticWarning(
                "phase_error",
                f"stated numerical phase error {worst * 1e3:.2g} mrad for {which[0]} fringes of "
                f"{which[1]:g} px (P95 over pixels, of the rule rendered) > "
                f"{max_phase_error_mrad:g} mrad: set sampling.target_error_mrad = "
                f"{max_phase_error_mrad:g} (raises the rule's order until it is met)",
                "sampling.target_error_mrad", max_phase_error_mrad,
            ))
        elif which is not None and worst * 1e3 > max_phase_error_mrad:
            n_new = min(_nice_up(diag.n_rays * (worst * 1e3 / max_phase_error_mrad) ** 2),
                        MAX_SUGGESTED_RAYS)
            out.append(DiagnosticWarning(
                "phase_error",
                f"phase standard error {worst * 1e3:.2g} mrad for {which[0]} fringes of "
                f"{which[1]:g} px (P95 over pixels, {diag.phase_se_method} method) > "
                f"{max_phase_error_mrad:g} mrad: raise sampling.n_rays to ~ {n_new} (assuming "
                "1/sqrt(N); the lattice often converges faster: see pmdsim converge)",
                "sampling.n_rays", n_new,
            ))
    if cone and rays is not None and math.isfinite(ess_med) and ess_med >= MIN_ESS:
        med = ess_med
        if med < min_ess_fraction * diag.n_rays:
            out.append(DiagnosticWarning(
                "effective_sample_size",
                f"effective sample size {med:.1f} of {diag.n_rays} rays (median over pixels): "
                "most rays of the cone carry almost no weight; use sampling.estimator = "
                "'radiometric' (importance sampling of the lobe)",
                "sampling.estimator", "radiometric",
            ))
    return out
