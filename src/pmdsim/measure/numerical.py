"""The numerical error of a simulated measurement, propagated from the rendered sums.

A render in mode ``rule`` or ``rqmc`` states the numerical error of every fringe sum
(:attr:`pmdsim.render.FringeResult.sums_err`) and of the phase each sum decodes to
(:meth:`~pmdsim.render.FringeResult.phase_error`, rad). The decoded deviation is taken at
the finest fringe width (coarser widths only pick the fringe order, which a numerical error
far below pi does not change), and the specular reference is exact (one ray), so the
deviation's numerical error is the finest width's phase error carried through the same
linear maps as the deviation itself:

- phase: ``delta phi`` (rad; reported in mrad);
- monitor coordinate: ``delta c = delta phi w / (2 pi)`` (monitor px; times the pitch in mm);
- slope: the slope change for a coordinate change ``delta c`` at the pixel's deviation,
  ``|s(c + delta c) - s(c)|`` with the chain's own slope conversion (3-D or small angle):
  :func:`pmdsim.measure.chain.slope_and_change_urad`.

Everything here works on plain arrays; :func:`propagate` is what the chain uses.
"""

from __future__ import annotations

import math

import numpy as np

from ..quantiles import percentile

#: Quantities of the numerical error (same names and units as the deviation's).
QUANTITIES = ("phase_mrad", "coord_px", "coord_mm", "slope_urad")


def finest_phase_error(fringes, direction: str, phase_error: np.ndarray | None = None
                       ) -> np.ndarray | None:
    """(H, W) rad: the phase error of the finest width of one direction of a
    :class:`~pmdsim.render.FringeResult`; None when the render states none.
    ``phase_error``: ``fringes.phase_error()`` when the caller has it already (it is
    computed from every sum, not stored)."""
    pe = fringes.phase_error() if phase_error is None else phase_error
    if pe is None or direction not in fringes.directions:
        return None
    wi = int(np.argmin(fringes.widths))
    return pe[fringes.directions.index(direction), wi]


def propagate(phase_err: np.ndarray, width_px: float, pitch_mm: float) -> dict:
    """Numerical error maps {quantity: (H, W)} from a phase error (rad) of fringes of
    period ``width_px``: the phase (mrad), the monitor coordinate (px, mm). The slope's
    (urad) is the change of the chain's own slope conversion,
    :func:`pmdsim.measure.chain.slope_and_change_urad` (it needs the geometry)."""
    phase_err = np.asarray(phase_err, np.float64)
    dc = phase_err * width_px / (2 * math.pi)
    return {"phase_mrad": phase_err * 1e3, "coord_px": dc, "coord_mm": dc * pitch_mm}


def summary(error_maps: dict, valid: np.ndarray) -> dict:
    """{quantity: {"rms", "p95", "max"}} of the numerical error over the valid pixels (None
    where there are none)."""
    from .deviation import finite_values

    out = {}
    v = np.asarray(valid, bool)
    for k, m in error_maps.items():
        a, _ = finite_values(m, v)  # one pass: m[v & isfinite(m)]
        if a.size == 0:
            out[k] = {"rms": None, "p95": None, "max": None}
            continue
        out[k] = {"rms": float(np.sqrt(np.mean(a * a))), "p95": percentile(a, 95, overwrite=True),
                  "max": float(a.max())}
    return out


def exceeds(value: float | None, error: float | None, share: float = 0.1) -> bool:
    """Whether a numerical error is more than ``share`` of the value it belongs to."""
    if value is None or error is None or not (math.isfinite(value) and math.isfinite(error)):
        return False
    return error > share * abs(value)
