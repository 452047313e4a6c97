"""Does the set-up see anything? Geometry sanity before rendering, and the pixels whose
scattered bundle hangs off the monitor after it.

Before any scattered ray is traced, the vision rays (``Simulation.geometry()``) tell
whether the camera sees the surface at all and whether the surface reflects the camera,
along the principal reflection P, into the monitor. A set-up in which either never happens
would render black images, decode nothing and still "succeed"; :func:`check_view` stops it
with a :class:`~pmdsim.config.ConfigError` naming the poses to change, and returns the
fractions (with a warning text when only part of the view is usable).

After rendering, :func:`off_monitor_mask` flags the surface pixels whose bundle puts more
than ``diagnostics.max_off_monitor_fraction`` of its weight off the monitor: their camera
value is the average over a truncated lobe (biased towards the monitor's edge), so they are
counted and excluded from the valid pixels, never silently kept.

All functions work on plain arrays: ``surface_mask``/``monitor_mask`` (H, W) bool from the
vision rays, ``f_total``/``f_hit`` (H, W) the bundle's weight sums over all rays / over the
rays that hit the monitor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ConfigError

#: Below this fraction of camera pixels that see the monitor in the surface the run warns
#: (above ``diagnostics.min_view_fraction``, below which it stops).
WARN_VIEW_FRACTION = 0.5


@dataclass(frozen=True)
class Coverage:
    """What the camera sees: counts of camera pixels.

    Attributes
    ----------
    pixels : int
        All camera pixels.
    surface_pixels : int
        Pixels whose vision ray hits the surface.
    monitor_pixels : int
        Surface pixels whose principal reflection P hits the monitor.
    warning : str or None
        Set when less than ``WARN_VIEW_FRACTION`` of the camera is usable.
    """

    pixels: int
    surface_pixels: int
    monitor_pixels: int
    warning: str | None = None

    @property
    def surface_fraction(self) -> float:
        return self.surface_pixels / self.pixels if self.pixels else 0.0

    @property
    def monitor_fraction(self) -> float:
        """Fraction of all camera pixels that see the monitor in the surface."""
        return self.monitor_pixels / self.pixels if self.pixels else 0.0

    @property
    def reflected_fraction(self) -> float:
        """Fraction of the surface pixels whose P hits the monitor."""
        return self.monitor_pixels / self.surface_pixels if self.surface_pixels else 0.0

    def as_dict(self) -> dict:
        return {"pixels": self.pixels, "surface_pixels": self.surface_pixels,
                "monitor_pixels": self.monitor_pixels,
                "surface_fraction": self.surface_fraction,
                "monitor_fraction": self.monitor_fraction,
                "reflected_fraction": self.reflected_fraction}


def check_view(surface_mask: np.ndarray, monitor_mask: np.ndarray,
               min_view_fraction: float = 0.01, roi=None) -> Coverage:
    """Stop a set-up that cannot see anything; describe one that sees little.

    Raises
    ------
    ConfigError
        No camera pixel sees the surface (``camera.roi`` when a window is set, else
        ``camera.look_at_mm``/``position_mm``); no surface
        pixel reflects into the monitor (``monitor.centre_mm``/``look_at_mm``); or fewer
        than ``min_view_fraction`` of the camera pixels do
        (``diagnostics.min_view_fraction``).
    """
    surface_mask = np.asarray(surface_mask, bool)
    monitor_mask = np.asarray(monitor_mask, bool) & surface_mask
    cov = Coverage(int(surface_mask.size), int(surface_mask.sum()), int(monitor_mask.sum()))
    if cov.surface_pixels == 0 and isinstance(roi, tuple):
        raise ConfigError(
            f"invalid set-up:\n  camera.roi = {list(roi)}: the window (col0, row0, width, "
            f"height) sees no surface: none of its {cov.pixels} pixels' vision rays hits it; "
            "move or widen the window, or set camera.roi = 'auto' (the window that sees the "
            "part)")
    if cov.surface_pixels == 0:
        raise ConfigError(
            "invalid set-up:\n  camera.look_at_mm: the camera sees no surface: none of its "
            f"{cov.pixels} pixels' vision rays hits the surface; point the camera at the "
            "surface (camera.position_mm, camera.look_at_mm, camera.rotation) or check "
            "surface.centre_mm/size_mm/normal (the surface faces the camera)")
    if cov.monitor_pixels == 0:
        raise ConfigError(
            "invalid set-up:\n  monitor.centre_mm: the surface reflects the camera into no "
            f"part of the monitor: none of the {cov.surface_pixels} camera pixels that see the "
            "surface sees the monitor along its mirror reflection; place the monitor where "
            "the camera's mirror image looks (monitor.centre_mm, monitor.look_at_mm; see "
            "docs/fig3-geometry.md)")
    if cov.monitor_fraction < min_view_fraction:
        raise ConfigError(
            f"invalid set-up:\n  diagnostics.min_view_fraction: only {cov.monitor_pixels} of "
            f"{cov.pixels} camera pixels ({100 * cov.monitor_fraction:.2g} %) see the monitor "
            f"in the surface, below {100 * min_view_fraction:g} %; move the monitor or the "
            "camera (monitor.centre_mm, camera.look_at_mm) or lower "
            "diagnostics.min_view_fraction to run anyway")
    if cov.monitor_fraction < WARN_VIEW_FRACTION:
        what = ("the camera sees the surface in " f"{100 * cov.surface_fraction:.0f} % of its "
                f"pixels, and {100 * cov.reflected_fraction:.0f} % of those see the monitor")
        cov = Coverage(cov.pixels, cov.surface_pixels, cov.monitor_pixels,
                       f"only {100 * cov.monitor_fraction:.0f} % of the camera pixels see the "
                       f"monitor in the surface ({what}); the rest of the images is empty")
    return cov


def off_monitor_fraction(f_total: np.ndarray, f_hit: np.ndarray) -> np.ndarray:
    """(H, W) share of each bundle's weight that misses the monitor, ``1 - f_hit/f_total``;
    1 where the bundle carries no weight at all, NaN off the surface (``f_total`` NaN)."""
    f_total = np.asarray(f_total, np.float64)
    f_hit = np.asarray(f_hit, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(f_total > 0, 1.0 - f_hit / f_total, 1.0)
    share = np.clip(share, 0.0, 1.0)
    return np.where(np.isfinite(f_total), share, np.nan)


def off_monitor_mask(f_total: np.ndarray, f_hit: np.ndarray, surface_mask: np.ndarray,
                     max_fraction: float = 0.05) -> np.ndarray:
    """(H, W) bool: surface pixels whose bundle puts more than ``max_fraction`` of its
    weight off the monitor."""
    share = off_monitor_fraction(f_total, f_hit)
    return np.asarray(surface_mask, bool) & ~(share <= max_fraction)


def check_rendered(fringe_images: np.ndarray | None = None,
                   dot_images: np.ndarray | None = None) -> None:
    """Stop a run whose images came out empty (before anything is written).

    Fringes have a mean level of half the monitor's range: wherever a bundle reaches the
    monitor with a non-zero BRDF value the camera value is positive. Every fringe image
    black means the BRDF is effectively zero over the sampled bundles (or no bundle reaches
    the monitor); every dot image black means the camera sees none of the dots.

    Raises
    ------
    ConfigError
        Naming ``brdf`` (fringes) or ``patterns.dots`` (dots).
    """
    def lit(a) -> bool:  # any value > 0 (NaN compares False), stopping at the first
        from ..kernels.images import any_positive

        a = np.asarray(a)
        if a.dtype.kind != "f":
            return bool(np.any(a > 0))
        return bool(any_positive(np.ascontiguousarray(a).reshape(-1)))

    if fringe_images is not None and not lit(fringe_images):
        raise ConfigError(
            "invalid set-up:\n  brdf: every fringe image is black: no scattered ray of any "
            "pixel carries a non-zero BRDF value onto the monitor; check the BRDF (brdf.*: a "
            "lobe that puts no weight into the sampled cone), sampling.theta_max_deg, and "
            "that the monitor lies in the surface's reflection (monitor.centre_mm)")
    if dot_images is not None and not lit(dot_images):
        raise ConfigError(
            f"invalid set-up:\n  patterns.dots: the camera sees none of the "
            f"{np.asarray(dot_images).shape[0]} dots (every dot image is black); place the "
            "dots on the part of the monitor that the camera sees in the surface "
            "(patterns.dots.positions_px / grid, margin_px)")
