"""``[budget]``: what ``pmdsim budget`` removes from the height error, the rim it excludes,
and the calibration uncertainties it turns into budget rows (docs/system.md).

Defaults of ``[budget.calibration]`` are one standard uncertainty of a typical calibrated
lab PMD set-up (camera calibrated by a plane target, Zhang's method; monitor pose from a
mirror-based calibration): assumed values of the order that published reproducibility
studies report (repeated calibrations scatter the projected image coordinates by
0.2-0.8 camera px: "Reproducibility of two calibration procedures for phase-measuring
deflectometry", https://core.ac.uk/works/126134117; laser-tracker checks of a PMD
calibration: Sperling and Bergmann, J. Sens. Sens. Syst. 13, 1, 2024,
https://doi.org/10.5194/jsss-13-1-2024). Put your own calibration's standard uncertainties
here; every row is linear in its uncertainty (sensitivity x uncertainty).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Bool, Float, Int, _Model

_NonNeg = Annotated[Float, Field(ge=0, le=1e6)]


class CalibrationUncertainty(_Model):
    """One standard uncertainty per calibrated quantity; 0 leaves the row out.

    ``camera_position_mm`` / ``monitor_position_mm``: per axis (x, y, z of the world);
    ``camera_orientation_deg`` / ``monitor_orientation_deg``: per rotation axis;
    ``focal_length_rel``: relative (fx and fy together); ``principal_point_px``: per axis;
    ``distortion_k1``: of OpenCV's k1; ``monitor_pitch_rel``: relative pixel pitch;
    ``surface_distance_mm``: the nominal surface position along its normal that the
    reconstruction assumes (monocular PMD cannot tell height from slope: this is the
    height-slope ambiguity, fixed by the part's mechanical registration)."""

    camera_position_mm: _NonNeg = 0.05
    camera_orientation_deg: _NonNeg = 0.005
    focal_length_rel: _NonNeg = 5e-4
    principal_point_px: _NonNeg = 0.5
    distortion_k1: _NonNeg = 1e-3
    monitor_position_mm: _NonNeg = 0.05
    monitor_orientation_deg: _NonNeg = 0.005
    monitor_pitch_rel: _NonNeg = 1e-4
    surface_distance_mm: _NonNeg = 0.05


RemovalTerm = Literal["piston", "tilt", "power", "astigmatism", "sphere"]


class BudgetConfig(_Model):
    """``pmdsim budget`` settings.

    ``remove``: what is removed from the height error before RMS/PV/P95: a level
    (``none``, ``piston``, ``tilt``, ``power``, ``astigmatism``, ``sphere`` = best-fit
    sphere) or a list of terms; default (None): ``reconstruct.remove``.
    ``remove_zernike``: Noll indices also removed. ``rim_exclusion_mm`` /
    ``rim_exclusion_percent``: nodes this close to the edge of the measured area (mm, or %
    of its inscribed radius) are left out. ``zernike_terms``: size of the Noll table (the
    Fringe table has up to 37). ``calibration``: the rows of the calibration errors
    (``enabled = false`` leaves them out). ``reconstruct``: height rows (None: whenever
    fringes run in x and y)."""

    remove: (Literal["none", "piston", "tilt", "power", "astigmatism", "sphere"]
             | tuple[RemovalTerm, ...] | None) = None
    remove_zernike: tuple[Annotated[Int, Field(ge=1, le=231)], ...] = ()
    rim_exclusion_mm: _NonNeg = 0.0
    rim_exclusion_percent: Annotated[Float, Field(ge=0, lt=100)] = 0.0
    zernike_terms: Annotated[Int, Field(ge=4, le=231)] = 37
    reconstruct: Bool | None = None
    calibration_rows: Bool = True
    calibration: CalibrationUncertainty = CalibrationUncertainty()
