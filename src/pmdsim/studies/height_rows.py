"""HROWS DOC"""

from __future__ import annotations
from dataclasses import dataclass
import numpy as np
from ..config import RunConfig
from ..measure.form import FormSpec, remove_form
from ..measure.integrate import height_stats
from ..measure.reconstruct import Reconstruction, reconstruct
from ..quantiles import percentile
from ..scene import Scene


@dataclass(frozen=True, eq=False)
class Decoded:
    """Decoded monitor coordinates (monitor px) per direction and their validity;
    ``error_px``: per direction the numerical error of the coordinates (monitor px, >= 0)
    the render states (None where it states none); ``sampling``: what was rendered
    (:attr:`pmdsim.render.FringeResult.sampling`, with the order a target error chose)."""

    coord: dict
    valid: dict
    seconds: float
    error_px: dict | None = None
    sampling: dict | None = None


# ------------------------------------------------------------------- height rows
def form_spec(cfg: RunConfig) -> FormSpec:
    """The removal of ``[budget]`` (``remove`` None: ``reconstruct.remove``)."""
    b = cfg.budget
    return FormSpec.of(cfg.reconstruct.remove if b.remove is None else b.remove, b.remove_zernike,
                       b.rim_exclusion_mm, b.rim_exclusion_percent, b.zernike_terms)


def wants_heights(cfg: RunConfig) -> bool:
    """Height rows? ``budget.reconstruct``, or (None) whenever fringes run in x and y."""
    both = {"x", "y"} <= set(cfg.patterns.fringes.directions)
    if cfg.budget.reconstruct is True and not both:
        raise ValueError("budget.reconstruct = true needs fringes in both directions: "
                         "set patterns.fringes.directions = ['x', 'y']")
    return both if cfg.budget.reconstruct is None else bool(cfg.budget.reconstruct) and both


def prior_of(cfg: RunConfig, scene: Scene):
    """The nominal shape of the reconstruction: ``reconstruct.prior`` or the surface."""
    if cfg.reconstruct.prior is None:
        return scene.surface
    from ..scene.surfaces import surface_from_config

    return surface_from_config(cfg.reconstruct.prior)


def reconstruct_decoded(cfg: RunConfig, scene: Scene, dec: "Decoded", camera=None, monitor=None,
                        prior=None) -> Reconstruction:
    """Reconstruct a decoding as ``simulate`` does (``[reconstruct]``), with the scene's (or
    the given, e.g. perturbed) camera, monitor and prior."""
    rc = cfg.reconstruct
    u = np.where(dec.valid["x"], dec.coord["x"], np.nan)
    v = np.where(dec.valid["y"], dec.coord["y"], np.nan)
    return reconstruct(u, v, camera or scene.camera, monitor or scene.monitor,
                       prior if prior is not None else prior_of(cfg, scene),
                       valid=np.isfinite(u) & np.isfinite(v), spacing_mm=rc.spacing_mm,
                       anchor=rc.anchor, order=rc.order)


@dataclass(frozen=True, eq=False)
class SurfaceMaps:
    """Height (mm) and slopes on a reconstruction grid: a reconstruction's or the true
    surface's; ``mask``: where defined."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    height_mm: np.ndarray
    slope_x: np.ndarray
    slope_y: np.ndarray
    mask: np.ndarray

    @classmethod
    def of(cls, rec: Reconstruction) -> "SurfaceMaps":
        return cls(rec.x_mm, rec.y_mm, rec.height_mm, rec.slope_x, rec.slope_y, rec.mask)


def true_maps(rec: Reconstruction, surface) -> SurfaceMaps:
    """The true surface's sag and slopes on ``rec``'s grid (its local frame)."""
    x, y = np.meshgrid(rec.x_mm, rec.y_mm)
    if hasattr(surface, "sag"):
        z, gx, gy, _ = surface.sag(x, y)
        ok = np.asarray(surface.in_aperture(x, y), bool) & np.isfinite(z)
    else:  # flat rectangle
        z = np.zeros_like(x)
        gx = gy = z
        ok = np.ones(x.shape, bool)
    return SurfaceMaps(rec.x_mm, rec.y_mm, np.asarray(z, np.float64), np.asarray(gx, np.float64),
                       np.asarray(gy, np.float64), ok)


@dataclass(frozen=True, eq=False)
class HeightError:
    """A height row's maps: slope errors (urad) and the height error after removal (nm)."""

    slope_x_urad: np.ndarray
    slope_y_urad: np.ndarray
    height_nm: np.ndarray
    form: object


def height_error(meas: SurfaceMaps, base: SurfaceMaps, spec: FormSpec, disc=(None, None),
                 shift_mm: float = 0.0) -> HeightError:
    """``meas`` minus ``base`` on the same grid: slope errors and the height error after
    ``spec`` (``shift_mm`` added to ``meas``'s height: its frame's offset along z)."""
    m = meas.mask & base.mask & np.isfinite(meas.height_mm) & np.isfinite(base.height_mm)
    x, y = np.meshgrid(meas.x_mm, meas.y_mm)
    e = np.where(m, meas.height_mm + shift_mm - base.height_mm, np.nan)
    form = remove_form(e, m, x, y, spec, true_height=np.where(m, base.height_mm, 0.0), disc=disc)
    keep = form.mask
    ex = np.where(keep, meas.slope_x - base.slope_x, np.nan) * 1e6
    ey = np.where(keep, meas.slope_y - base.slope_y, np.nan) * 1e6
    return HeightError(ex, ey, form.residual * 1e6, form)


def zernike_disc(surface):
    ap = getattr(surface, "aperture", None)
    if isinstance(ap, tuple) and ap[0] in ("circular", "annular"):
        return (ap[1], ap[2]), ap[3]
    return None, None


def _about_zero(a) -> tuple[float, float]:
    f = np.abs(a[np.isfinite(a)])
    if not f.size:
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(f * f))), percentile(f, 95, overwrite=True)


def height_row(effect: str, label: str, part: str, err: HeightError, seconds: float = 0.0,
               how: str = "") -> dict:
    """Slope errors X/Y (urad RMS and P95 about zero) and height error after removal (nm
    RMS about the mean, PV, P95) of one effect; Zernike tables and sphere radii alongside."""
    row = {"effect": effect, "label": label, "part": part}
    for k, a in (("x", err.slope_x_urad), ("y", err.slope_y_urad)):
        row[f"slope_rms_{k}_urad"], row[f"slope_p95_{k}_urad"] = _about_zero(a)
    hs = height_stats(err.height_nm)
    row.update(height_rms_nm=hs.rms, height_pv_nm=hs.pv, height_p95_nm=hs.p95, n_nodes=hs.n,
               removed=err.form.removed, rim_excluded=err.form.excluded_rim,
               seconds=round(seconds, 2), how=how)
    if err.form.sphere is not None:
        row["sphere"] = err.form.sphere
    row["zernike_noll_nm"] = [dict(t, coefficient=t["coefficient"] * 1e6) for t in err.form.noll]
    row["zernike_fringe_nm"] = [dict(t, coefficient=t["coefficient"] * 1e6) for t in err.form.fringe]
    return row
