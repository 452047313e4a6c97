"""Images to parameters: fit a BRDF's alphas (and brightness) to fringe images.

Given camera fringe images of a part at several fringe widths (X and/or Y fringes, K phase
shifts each) and the set-up (a run configuration: camera, monitor, surface, frame, BRDF
model, sampling), :func:`fit_fringe_images` estimates ``alpha_x`` (tangential in a
rotational frame) and ``alpha_y`` (radial) of the configured model (``ward``, ``beckmann``
or ``slope_density`` with the Gaussian density) and a brightness scale:

1. **closed-form start**: the decoded modulation ``M = B / A`` (median over the valid
   pixels) of each direction against the fringe wavenumber ``k`` (rad per monitor px)
   follows ``M = M0 exp(-beta k^2)`` (Gaussian slopes: ``M = exp(-(k d alpha)^2)`` at
   normal incidence, ``d`` in monitor px); a straight line through ``ln M`` against ``k^2``
   gives ``beta`` per direction, and the small-slope Jacobian ``J`` (monitor px per unit
   facet slope, from the centre pixel's geometry) turns them into alphas:
   ``beta_u = (J_ux^2 ax^2 + J_uy^2 ay^2) / 4`` and the same for v;
2. **least squares on the images** with the full simulator (``scipy.optimize.least_squares``,
   parameters in logarithms so they stay positive), residuals weighted by the sensor's
   noise (EMVA: ``sigma^2 = K^2 sigma_d^2 + K y + 1/12`` DN^2 for a grey value ``y``)
   when ``noise`` is given, unweighted otherwise;
3. **standard uncertainties** from the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1``,
   ``s^2`` the reduced chi-square (so they are right even when the noise model's scale is
   not), carried from the logarithms to the values.

The brightness ``scale`` multiplies the simulated camera values (it absorbs ``rho_s``, the
exposure and the sensor gain, which images alone cannot separate). Simulation is
deterministic per configuration (``sampling.seed``); use the ``stratified`` mode so the
model is smooth in the parameters, and ``monitor.pixel_model = "continuous"`` for the same
reason (a nearest-pixel monitor makes it piecewise constant on the scale of a ray crossing
a pixel edge).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..brdf import equivalent_alphas
from ..config import ConfigError, RunConfig
from ..render import Simulation

#: Models whose alphas can be fitted, with the configuration fields of (alpha_x, alpha_y).
FIT_FIELDS = {"ward": ("alpha_x", "alpha_y"), "beckmann": ("alpha_u", "alpha_v"),
              "slope_density": ("alpha_x", "alpha_y")}


@dataclass(frozen=True)
class NoiseModel:
    """EMVA 1288 temporal noise of a grey value ``y`` (DN): ``K^2 sigma_d^2 + K y + 1/12``."""

    gain_dn_per_electron: float
    dark_noise_electrons: float = 0.0

    def sigma(self, dn) -> np.ndarray:
        k = self.gain_dn_per_electron
        y = np.maximum(np.asarray(dn, np.float64), 0.0)
        return np.sqrt(k * k * self.dark_noise_electrons**2 + k * y + 1.0 / 12.0)


@dataclass(frozen=True)
class FitResult:
    """Fitted parameters and what they rest on.

    ``names``: ("alpha_x", "alpha_y", "scale"); ``values``/``std``: estimates and standard
    uncertainties (k = 1); ``start``: the closed-form start; ``modulation_*``: (direction,
    width) median decoded modulation of the measured images, of the closed-form start curve
    and of the fitted simulation.
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    start: np.ndarray
    directions: tuple[str, ...]
    widths: tuple[float, ...]
    chi2_reduced: float
    residual_rms: float
    n_data: int
    n_evaluations: int
    success: bool
    message: str
    modulation_measured: np.ndarray
    modulation_start: np.ndarray
    modulation_fitted: np.ndarray
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "parameters": {n: {"value": float(v), "std": float(s), "start": float(s0)}
                           for n, v, s, s0 in zip(self.names, self.values, self.std, self.start)},
            "covariance": self.cov.tolist(),
            "chi2_reduced": self.chi2_reduced, "residual_rms": self.residual_rms,
            "n_data": self.n_data, "n_evaluations": self.n_evaluations,
            "success": self.success, "message": self.message,
            "directions": list(self.directions), "widths_px": list(self.widths),
            "modulation_measured": self.modulation_measured.tolist(),
            "modulation_start": self.modulation_start.tolist(),
            "modulation_fitted": self.modulation_fitted.tolist(),
        }


# =========================================================================== helpers
def decoded_modulation(images, shifts=None) -> np.ndarray:
    """Modulation B / A (..., H, W) of phase-shifted images (..., K, H, W) with equal shifts
    2 pi k / K: B = 2 |sum I_k exp(-i delta_k)| / K, A = sum I_k / K; NaN where A <= 0."""
    im = np.asarray(images, np.float64)
    k = im.shape[-3]
    d = 2 * np.pi * np.arange(k) / k if shifts is None else np.asarray(shifts, np.float64)
    z = np.tensordot(np.exp(-1j * d), np.moveaxis(im, -3, 0), axes=(0, 0))
    a = im.mean(-3)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a > 0, 2 * np.abs(z) / k / a, np.nan)


def median_modulation(images) -> np.ndarray:
    """(direction, width) median over finite pixels of :func:`decoded_modulation`."""
    m = decoded_modulation(images)
    return np.nanmedian(m.reshape(m.shape[:2] + (-1,)), axis=-1)


def _with_alphas(cfg: RunConfig, ax: float, ay: float) -> RunConfig:
    b = cfg.brdf
    if b.model not in FIT_FIELDS or (b.model == "slope_density" and b.density != "gaussian"):
        raise ConfigError(f"fit: brdf.model = {b.model!r} has no alphas to fit; use 'ward', "
                          "'beckmann' or 'slope_density' with density = 'gaussian'")
    var = getattr(b, "variation", None)
    if var is not None and (var.file is not None or var.alpha_tangential is not None
                            or var.alpha_radial is not None):
        raise ConfigError("fit: brdf.variation varies the alphas over the surface, so one pair "
                          "of alphas cannot be fitted; remove brdf.variation (a radius table "
                          "of rho_s_scale alone is allowed)")
    d = cfg.model_dump()
    brdf = d["brdf"]
    for k in ("alpha_tangential", "alpha_radial"):
        brdf.pop(k, None)
    fx, fy = FIT_FIELDS[b.model]
    brdf[fx], brdf[fy] = float(ax), float(ay)
    d["variants"] = []
    return RunConfig.model_validate(d)


def slope_jacobian(sim: Simulation, eps: float = 1e-5) -> np.ndarray:
    """(2, 2) monitor px per unit facet slope at the valid pixel nearest the image centre:
    rows (u, v), columns (slope along local x, local y), by central differences."""
    from ..trace import trace_primary

    hits = trace_primary(sim.scene)
    ok = hits.valid
    if not ok.any():
        raise ValueError("fit: no camera pixel sees the surface")
    h, w = ok.shape
    rr, cc = np.nonzero(ok)
    p = np.argmin((rr - (h - 1) / 2) ** 2 + (cc - (w - 1) / 2) ** 2)
    r, c = rr[p], cc[p]
    x, y, n = hits.x_axis[r, c], hits.y_axis[r, c], hits.normal[r, c]
    i = hits.to_camera[r, c]
    jac = np.zeros((2, 2))
    for col, axis in enumerate((x, y)):
        uv = []
        for s in (eps, -eps):
            m = n - s * axis
            m = m / np.linalg.norm(m)
            o = 2 * (i @ m) * m - i
            mu, mv, _ = sim.scene.monitor.intersect(hits.point[r, c][None], o[None])
            uv.append(np.array([mu[0], mv[0]]))
        jac[:, col] = (uv[0] - uv[1]) / (2 * eps)
    return jac


def closed_form_start(sim: Simulation, widths, directions, modulation) -> tuple[float, float]:
    """(alpha_x, alpha_y) from the median modulation (direction, width) by the Gaussian
    small-slope law (see the module docstring). Directions missing from the data are
    taken as isotropic."""
    k2 = (2 * np.pi / np.asarray(widths, np.float64)) ** 2
    jac = slope_jacobian(sim)
    beta = {}
    for di, d in enumerate(directions):
        m = np.asarray(modulation[di], np.float64)
        good = np.isfinite(m) & (m > 0.02) & (m < 0.995)
        if good.sum() >= 2:
            slope = np.polyfit(k2[good], np.log(m[good]), 1)[0]
        elif good.sum() == 1:
            slope = np.log(m[good][0]) / k2[good][0]
        else:
            continue
        beta[d] = max(-slope, 1e-12)
    rows = {"x": 0, "y": 1}
    if len(beta) == 2:
        a = np.array([jac[0] ** 2, jac[1] ** 2]) / 4
        sq = np.linalg.lstsq(a, np.array([beta["x"], beta["y"]]), rcond=None)[0]
    elif len(beta) == 1:
        d, b = next(iter(beta.items()))
        s = float(np.sum(jac[rows[d]] ** 2) / 4)
        sq = np.array([b / s, b / s])
    else:
        raise ValueError("fit: no fringe width with a usable modulation (0.02 < M < 0.995)")
    floor = 1e-4 * max(float(np.max(sq)), 1e-12)
    return tuple(float(np.sqrt(max(v, floor))) for v in sq)


# =========================================================================== the fit
def fit_fringe_images(cfg: RunConfig, images, widths, directions=("x", "y"),
                      noise: NoiseModel | None = None, start=None, diff_step: float = 2e-3,
                      max_nfev: int = 60) -> FitResult:
    """Fit (alpha_x, alpha_y, scale) to fringe images.

    Parameters
    ----------
    cfg : RunConfig
        The set-up and the model (its alphas are only a fallback start).
    images : (n_directions, n_widths, K, H, W) array, DN or camera values
        Measured fringe images (NaN where no surface), equal phase shifts 2 pi k / K of
        ``cos(k u + delta)`` fringes as pmdsim displays them.
    widths : (n_widths,) monitor px; directions : subset of ("x", "y").
    noise : NoiseModel, optional
        Weights the residuals by the sensor's temporal noise.
    start : (alpha_x, alpha_y), optional
        Replaces the closed-form start.
    """
    images = np.asarray(images, np.float64)
    widths = tuple(float(w) for w in widths)
    directions = tuple(directions)
    if images.ndim != 5 or images.shape[:2] != (len(directions), len(widths)):
        raise ValueError(f"images: need (directions={len(directions)}, widths={len(widths)}, "
                         f"K, H, W), got {images.shape}")
    shifts = images.shape[2]
    if shifts < 3:
        raise ValueError("images: need at least 3 phase shifts per width")
    base = _with_alphas(cfg, *equivalent_alphas(cfg.brdf))
    sim0 = Simulation.from_config(base)
    if images.shape[-2:] != sim0.shape:
        raise ValueError(f"images: {images.shape[-2:]} pixels, but the camera of the "
                         f"configuration has {sim0.shape}")
    m_meas = median_modulation(images)
    if start is None:
        start = closed_form_start(sim0, widths, directions, m_meas)
    start = tuple(float(s) for s in start)

    def render(ax, ay):
        sim = Simulation.from_config(_with_alphas(cfg, ax, ay))
        return sim.render_fringes(widths, directions, shifts).images.astype(np.float64)

    r0 = render(*start)
    valid = np.isfinite(images) & np.isfinite(r0)
    if valid.sum() < 10:
        raise ValueError("fit: fewer than 10 finite pixels shared by the images and the model")
    meas = images[valid]
    scale0 = float(np.sum(meas * r0[valid]) / np.sum(r0[valid] ** 2))
    sigma = noise.sigma(meas) if noise is not None else np.ones_like(meas)
    n_eval = [0]

    def residuals(x):
        n_eval[0] += 1
        model = render(np.exp(x[0]), np.exp(x[1]))
        return (np.exp(x[2]) * model[valid] - meas) / sigma

    x0 = np.array([np.log(start[0]), np.log(start[1]), np.log(scale0)])
    sol = least_squares(residuals, x0, diff_step=diff_step, x_scale=np.array([0.1, 0.1, 0.1]),
                        max_nfev=max_nfev, method="trf", xtol=1e-6)
    n, p = sol.fun.size, sol.x.size
    chi2 = float(np.sum(sol.fun**2) / max(n - p, 1))
    jtj = sol.jac.T @ sol.jac
    cov_log = np.linalg.pinv(jtj) * chi2
    values = np.exp(sol.x)
    jac_exp = np.diag(values)
    cov = jac_exp @ cov_log @ jac_exp
    std = np.sqrt(np.diag(cov))
    fitted = render(values[0], values[1]) * values[2]
    m_fit = median_modulation(fitted)
    k2 = (2 * np.pi / np.asarray(widths)) ** 2
    jac = slope_jacobian(sim0)
    rows = {"x": 0, "y": 1}
    m_start = np.array([np.exp(-k2 * float(jac[rows[d]] ** 2 @ np.array(start) ** 2) / 4)
                        for d in directions])
    res_dn = (fitted[valid] - meas)
    return FitResult(
        ("alpha_x", "alpha_y", "scale"), values, std, cov,
        np.array([start[0], start[1], scale0]), directions, widths, chi2,
        float(np.sqrt(np.mean(res_dn**2))), int(n), n_eval[0], bool(sol.success),
        str(sol.message), m_meas, m_start, m_fit)


def format_fit(res: FitResult, frame: str = "fixed") -> str:
    """Plain-text table of a :class:`FitResult` (names by direction in a rotational frame)."""
    label = {"alpha_x": "alpha_tangential (x)" if frame == "rotational" else "alpha_x",
             "alpha_y": "alpha_radial (y)" if frame == "rotational" else "alpha_y",
             "scale": "scale"}
    lines = [f"{'parameter':<22} {'value':>12} {'u (k=1)':>12} {'U (k=2)':>12} {'start':>12}"]
    for n, v, s, s0 in zip(res.names, res.values, res.std, res.start):
        lines.append(f"{label[n]:<22} {v:12.6g} {s:12.3g} {2 * s:12.3g} {s0:12.6g}")
    lines.append(f"reduced chi-square {res.chi2_reduced:.3g}, residual RMS {res.residual_rms:.4g} "
                 f"over {res.n_data} values, {res.n_evaluations} simulations; {res.message}")
    return "\n".join(lines)
