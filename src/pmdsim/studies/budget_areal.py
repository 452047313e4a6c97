"""Areal parameters and PSDs of the error budget's height rows
(:mod:`pmdsim.measure.areal`): of each row's height error after the removal and its slope
errors dz/dx, dz/dy, with the numerical errors the row states."""

from __future__ import annotations

import numpy as np

from ..measure import areal

#: The maps of a height row: (HeightError attribute, statistics key, unit).
MAPS = (("height_nm", "height_error_nm", "nm"), ("slope_x_urad", "slope_error_x_urad", "urad"),
        ("slope_y_urad", "slope_error_y_urad", "urad"))


def areal_of(err, spacing_mm, shifted=None, floors: dict | None = None) -> dict:
    """``{statistics key: areal summary}`` (:func:`pmdsim.measure.areal.summary`) of the
    maps of a :class:`~pmdsim.studies.height_rows.HeightError` on a grid of ``spacing_mm`` (dx,
    dy). ``shifted``: the row's HeightErrors with the decoded coordinates moved by +-their
    numerical error: the nodes' errors (:func:`pmdsim.studies.budget_error.node_errors`);
    ``floors``: the reconstruction solvers' floors
    (:func:`pmdsim.studies.budget_error.solver_floors`), in every node's error (alone where
    nothing is ``shifted``: a mirror's exact render). The bands are those of the height
    error's measured region.

    Every statistic's error is for node errors of any signs, Ssk, Sku, Sdq and the PSDs
    included: the shifted maps move every coordinate the same way, which is no signed
    pattern of the error. Their changes as the PSDs' and Sdq's error maps (as until
    2026-12-07) missed the change of a full-system row to a target 10 x tighter by up to
    2.1 x (Sdq of the slope error dz/dy on a nearest-pixel monitor, whose staircase part
    is a randomised rule: an error without a smooth pattern) and 1.2 x (the form band of
    dz/dx through a display gamma; tests/studies/test_budget_independent_errors.py)."""
    from .budget_error import node_errors

    dx, dy = (float(s) for s in spacing_mm)
    valid = np.isfinite(err.height_nm)
    if not valid.any():
        return {}
    bands = areal.default_bands(valid, dx, dy)
    ne = node_errors(err, shifted or [], floors) if shifted or floors is not None else None
    out = {}
    for attr, key, unit in MAPS:
        z = np.asarray(getattr(err, attr), np.float64)
        e = None if ne is None else np.nan_to_num(np.asarray(ne[attr], np.float64), nan=0.0)
        out[key] = areal.summary(z, dx, dy, unit, error=e, bands=bands)
    return out


#: Columns of the budget's areal.csv (one row per height row and map).
AREAL_COLUMNS = ("effect", "part", "map", "unit", "sq", "sq_err", "sa", "sa_err", "sz", "sz_err",
                 "ssk", "ssk_err", "sku", "sku_err", "sdq", "sdq_err", "sdq_unit", "band_form",
                 "band_form_err", "band_mid", "band_mid_err", "band_high", "band_high_err",
                 "form_below_per_mm", "high_above_per_mm", "n", "label")


def areal_rows(height_rows) -> list[dict]:
    """One CSV row per (height row, map) with its areal parameters and band RMS."""
    out = []
    for r in height_rows:
        for key, st in (r.get("areal") or {}).items():
            psd = st.get("psd") or {}
            row = {"effect": r["effect"], "part": r["part"], "map": key, "label": r["label"],
                   **{k: st.get(k) for k in AREAL_COLUMNS if k in st}}
            err = psd.get("band_rms_err") or {}
            for b, v in (psd.get("band_rms") or {}).items():
                row[f"band_{b}"] = v
                row[f"band_{b}_err"] = err.get(b)
            bands = psd.get("bands_per_mm") or {}
            if bands:
                row["form_below_per_mm"] = bands["form"][1]
                row["high_above_per_mm"] = bands["high"][0]
            out.append(row)
    return out
