"""Display physics: response (gamma or measured LUT, drive quantisation, pre-compensation,
black level), angular falloff, and the geometry of the emitting surface (flatness, cover glass).

Response: a pattern level ``x`` in [0, 1] (what the fringe formula asks for) becomes

1. the drive ``d = x`` or, with ``precompensate_gamma``, ``d = r^-1(x)`` (the inverse response,
   so that the *luminance* is the sinusoid);
2. quantised ``d <- round(d (2^b - 1)) / (2^b - 1)`` with ``bit_depth = b`` (none: exact);
3. luminance ``black + (white - black) r(d)``, ``r(d) = d^gamma`` or the measured table
   (CSV rows ``drive, luminance``; linear interpolation, normalised to r(0) = 0, r(1) = 1).

Geometry (applied per scattered ray in :func:`pmdsim.kernels.bundle.monitor_correction`;
NumPy references here): the configured monitor plane is the *nominal* plane. The emitting
surface lies ``h(x, y) = sum c_ij x^i y^j`` mm in front of it; a cover glass of thickness
``t`` and index ``n`` lies in front of the pixels: a ray at incidence ``theta`` reaches them
shifted by ``t (tan theta - tan theta_r)`` towards the point below its entry,
``sin theta_r = sin theta / n``. The exact reflection point every deviation is measured from
stays the nominal-plane hit (what a calibration without a display model assumes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import MonitorConfig, files


def read_response_lut(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(drive, relative luminance) of a CSV file of ``drive, luminance`` rows (a header row
    is skipped); drive scaled to [0, 1] by its maximum, luminance to r(0) = 0, r(1) = 1.
    Every problem is a :class:`~pmdsim.config.files.FileInputError` naming
    ``monitor.response_lut`` (:func:`pmdsim.config.files.read_response_lut`)."""
    return files.read_response_lut(path, "monitor.response_lut")


def read_height_map(path: str | Path) -> np.ndarray:
    """(rows, cols) heights (mm) of a ``.npy`` file, a CSV of rows or a float TIFF; the grid
    spans the monitor from the centre of pixel (0, 0) to that of pixel (W-1, H-1). Errors
    name ``monitor.flatness_map`` (:func:`pmdsim.config.files.read_flatness_map`)."""
    return files.read_flatness_map(path, "monitor.flatness_map")


@dataclass(frozen=True)
class DisplayResponse:
    """Drive -> luminance of the display (module docstring)."""

    gamma: float = 1.0
    black_level: float = 0.0
    white_level: float = 1.0
    bit_depth: int | None = None
    precompensate: bool = False
    lut_drive: np.ndarray | None = field(default=None, compare=False)
    lut_luminance: np.ndarray | None = field(default=None, compare=False)

    @property
    def is_linear(self) -> bool:
        """Luminance exactly affine in the pattern level (the fast analytic fringe path)."""
        return (self.lut_drive is None and self.gamma == 1.0 and self.bit_depth is None)

    def response(self, drive) -> np.ndarray:
        """r(d) in [0, 1] of drive values in [0, 1]."""
        d = np.clip(np.asarray(drive, np.float64), 0.0, 1.0)
        if self.lut_drive is not None:
            return np.interp(d, self.lut_drive, self.lut_luminance)
        return d**self.gamma

    def inverse_response(self, level) -> np.ndarray:
        """r^-1: the drive that gives relative luminance ``level``."""
        x = np.clip(np.asarray(level, np.float64), 0.0, 1.0)
        if self.lut_drive is not None:
            return np.interp(x, self.lut_luminance, self.lut_drive)
        return x ** (1.0 / self.gamma)

    def drive(self, level) -> np.ndarray:
        """The (quantised) drive the display shows for pattern level(s) in [0, 1]."""
        d = np.clip(np.asarray(level, np.float64), 0.0, 1.0)
        if self.precompensate:
            d = self.inverse_response(d)
        if self.bit_depth is not None:
            q = 2.0**self.bit_depth - 1.0
            d = np.rint(d * q) / q
        return d

    def luminance(self, level) -> np.ndarray:
        """Displayed luminance of pattern level(s) in [0, 1]."""
        return self.black_level + (self.white_level - self.black_level) * self.response(self.drive(level))


@dataclass(frozen=True)
class DisplayGeometry:
    """Flatness of the emitting surface, cover glass and angular falloff (module docstring)."""

    glass_thickness: float = 0.0  # mm
    glass_index: float = 1.5
    flatness: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False)  # c[i, j], mm
    falloff_exponent: float = 0.0
    falloff_table: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), compare=False)  # deg, factor
    height_map: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False)  # mm
    monitor_size: tuple[int, int] = (1, 1)  # (W, H) monitor px: the map spans their centres

    @property
    def is_ideal(self) -> bool:
        return (self.glass_thickness == 0.0 and not np.any(self.flatness)
                and self.falloff_exponent == 0.0 and self.falloff_table.shape[0] == 0
                and self.height_map.size == 0)

    def height(self, x, y, pitch: float = 1.0) -> np.ndarray:
        """h(x, y), mm, of the emitting surface in front of the nominal plane (x, y in mm from
        the monitor centre; ``pitch`` places the height map)."""
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        h = np.zeros(np.broadcast(x, y).shape)
        if self.flatness.size:
            h = h + np.polynomial.polynomial.polyval2d(x, y, self.flatness)
        if self.height_map.size:
            from scipy.interpolate import RegularGridInterpolator

            w, hh = self.monitor_size
            rows, cols = self.height_map.shape
            gv = np.linspace(-(hh - 1) / 2 * pitch, (hh - 1) / 2 * pitch, rows)
            gu = np.linspace(-(w - 1) / 2 * pitch, (w - 1) / 2 * pitch, cols)
            f = RegularGridInterpolator((gv, gu), self.height_map, method="linear")
            pts = np.stack([np.clip(y, gv[0], gv[-1]), np.clip(x, gu[0], gu[-1])], axis=-1)
            h = h + f(pts.reshape(-1, 2)).reshape(h.shape)
        return h

    def glass_shift(self, theta) -> np.ndarray:
        """t (tan theta - tan theta_r), mm: how much closer to the entry point's foot a ray
        at incidence ``theta`` (rad) reaches the pixels than without glass."""
        theta = np.asarray(theta, np.float64)
        theta_r = np.arcsin(np.sin(theta) / self.glass_index)
        return self.glass_thickness * (np.tan(theta) - np.tan(theta_r))

    def falloff(self, theta) -> np.ndarray:
        """Relative luminance at emission angle ``theta`` (rad)."""
        c = np.cos(np.asarray(theta, np.float64))
        f = c**self.falloff_exponent
        if self.falloff_table.shape[0]:
            f = f * np.interp(np.degrees(np.arccos(c)), self.falloff_table[:, 0], self.falloff_table[:, 1])
        return f

    def kernel_params(self, pitch: float, width: int, height: int) -> np.ndarray | None:
        """``mon_corr`` vector for the render kernels (layout ``MC_*``); None when ideal."""
        if self.is_ideal:
            return None
        from ..kernels import bundle as kb

        n = self.flatness.shape[0]
        tab = self.falloff_table
        nf = tab.shape[0]
        hm = self.height_map
        p = np.zeros(kb.MC_COEF + n * n + 2 * nf + hm.size)
        p[kb.MC_GLASS_T] = self.glass_thickness
        p[kb.MC_GLASS_N] = self.glass_index
        p[kb.MC_PITCH] = pitch
        p[kb.MC_UC] = (width - 1) / 2.0
        p[kb.MC_VC] = (height - 1) / 2.0
        p[kb.MC_FLAT_N] = n
        p[kb.MC_FALL_M] = self.falloff_exponent
        p[kb.MC_FALL_N] = nf
        p[kb.MC_COEF : kb.MC_COEF + n * n] = self.flatness.reshape(-1)
        t0 = kb.MC_COEF + n * n
        if nf:
            p[t0 : t0 + nf] = tab[:, 0]
            p[t0 + nf : t0 + 2 * nf] = tab[:, 1]
        if hm.size:
            p[kb.MC_MAP_R], p[kb.MC_MAP_C] = hm.shape
            p[t0 + 2 * nf :] = hm.reshape(-1)
        return p


def display_from_config(cfg: MonitorConfig) -> tuple[DisplayResponse, DisplayGeometry]:
    """The response and geometry of a :class:`~pmdsim.config.MonitorConfig`."""
    lut_d = lut_l = None
    if cfg.response_lut is not None:
        lut_d, lut_l = read_response_lut(cfg.response_lut)
    resp = DisplayResponse(
        float(cfg.gamma), float(cfg.black_level), float(cfg.white_level), cfg.bit_depth,
        bool(cfg.precompensate_gamma), lut_d, lut_l,
    )
    flat = np.asarray(cfg.flatness_coefficients_mm, np.float64).reshape(
        len(cfg.flatness_coefficients_mm), len(cfg.flatness_coefficients_mm))
    hmap = np.zeros((0, 0))
    if cfg.flatness_map is not None:
        hmap = read_height_map(cfg.flatness_map)
    geom = DisplayGeometry(
        float(cfg.cover_glass_thickness_mm), float(cfg.cover_glass_index), flat,
        float(cfg.falloff_exponent), np.asarray(cfg.falloff_table, np.float64).reshape(-1, 2),
        hmap, tuple(cfg.resolution),
    )
    return resp, geom
