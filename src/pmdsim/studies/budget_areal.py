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
    numerical error: the nodes' errors (:func:`pmdsim.studies.budget_error.node_errors`)
    and, for the PSDs, the signed changes themselves; ``floors``: the reconstruction
    solvers' floors (:func:`pmdsim.studies.budget_error.solver_floors`), in every node's
    error (alone where nothing is ``shifted``: a mirror's exact render). The bands are
    those of the height error's measured region."""
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
        e = maps = floor = None
        if ne is not None:
            e = np.nan_to_num(np.asarray(ne[attr], np.float64), nan=0.0)
            maps = [np.nan_to_num(np.asarray(getattr(h, attr), np.float64) - z, nan=0.0)
                    for h in shifted or ()] or None
            if maps and floors is not None:  # the solvers' floors beside the maps' changes
                floor = np.where(np.isfinite(z), floors[attr], 0.0)
        out[key] = areal.summary(z, dx, dy, unit, error=e, bands=bands, error_maps=maps,
                                 floor=floor)
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
