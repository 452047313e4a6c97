"""Convergence diagnostics of a scattering simulation: how much is physics, how much sampling.

Three numbers per camera pixel, each on a coarse grid of pixels (the lobe changes slowly
across the camera) and interpolated to the full image by :func:`full_map`:

- :func:`energy_fraction`: the fraction of the lobe's reflected energy
  ``E(cone) / E(hemisphere)``, ``E(region) = integral of f(i, o) cos(theta_o) d omega``,
  that lies inside the cone ``theta <= theta_max`` about the principal direction P (what the
  cone estimators see at all), and the cone half angle that would hold a target fraction.
  Both integrals are estimated by importance sampling of the lobe on a dense
  low-discrepancy set (``n_samples`` per pixel, the same set for hemisphere and cone).
- :func:`effective_sample_size`: ``(sum w)^2 / sum w^2`` of the weights of the rays of a
  pixel that hit the monitor (BRDF values f for the cone estimators,
  ``f cos_o / pdf`` for the radiometric one): how many equally weighted rays the bundle is
  worth.
- the Monte-Carlo standard error of the decoded phase, ``arg Z`` with
  ``Z = sum_p w_p exp(i k c_p)`` (``c`` the monitor coordinate along the fringe direction,
  ``k = 2 pi / width``), either

  * :func:`phase_error_seeds` (independent sample sets, the default): the pixel's bundle is
    drawn with ``n_seeds`` seeds in mode ``random`` (the lattice rotated per pixel, i.e.
    randomised quasi-Monte Carlo); the standard deviation of the phase over the seeds
    (circular, about the mean) is the error of one run. A ``stratified`` run uses the
    unrotated lattice: its error is a fixed pattern of about this size; or
  * :func:`phase_error_delta` (per-sample variance, delta method):
    ``se = std_p(Im(z_p exp(-i arg Z))) / (sqrt(N) |mean_p z_p|)`` with
    ``z_p = w_p exp(i k c_p)``: the error N *independent* rays would have (plain Monte
    Carlo). The lattice does better, often by a large factor (measured 2-8x in the tests),
    so this is a cheap, pessimistic bound.

:func:`diagnose` computes all of them for a :class:`~pmdsim.render.Simulation`, and
:func:`check` turns them into warnings that name the setting that fixes them, e.g.
``theta_max = 1 deg holds 34 % of the lobe energy ...; theta_max >= 3.2 deg keeps 95 %``.

Linear fringes are assumed (the display's gamma is ignored by the phase error: a harmonic
changes it little for small errors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..brdf import lobe_weight
from ..geometry import dot, dot3, normalize
from ..quantiles import percentile
from ..scene.sampling import fibonacci_lattice

CONE_ESTIMATORS = ("paper", "weighted_mean")


# ----------------------------------------------------------------------------- pixel grid
@dataclass(frozen=True)
class PixelGrid:
    """A coarse grid of camera pixels: ``rows`` (gr,) x ``cols`` (gc,) of a (H, W) camera."""

    rows: np.ndarray
    cols: np.ndarray
    shape: tuple[int, int]

    @classmethod
    def spread(cls, shape: tuple[int, int], n_cols: int, n_rows: int) -> "PixelGrid":
        """``n_cols`` x ``n_rows`` pixels evenly spread over the camera, corners included."""
        h, w = shape
        rows = np.unique(np.round(np.linspace(0, h - 1, min(n_rows, h))).astype(int))
        cols = np.unique(np.round(np.linspace(0, w - 1, min(n_cols, w))).astype(int))
        return cls(rows, cols, (h, w))

    @property
    def pixel_rows(self) -> np.ndarray:
        """Row index of every grid pixel, (gr * gc,) in row-major order."""
        return np.repeat(self.rows, self.cols.size)

    @property
    def pixel_cols(self) -> np.ndarray:
        return np.tile(self.cols, self.rows.size)

    @property
    def grid_shape(self) -> tuple[int, int]:
        return (self.rows.size, self.cols.size)


def full_map(values: np.ndarray, grid: PixelGrid, mask: np.ndarray | None = None) -> np.ndarray:
    """Bilinear interpolation of grid values (..., gr, gc) to the full camera (..., H, W).

    Grid nodes without a value (NaN: no surface there) take the value of the nearest node
    that has one, so pixels near the edge of the surface get a value; ``mask`` (H, W)
    (e.g. the surface mask) sets NaN outside.
    """
    from scipy.interpolate import RegularGridInterpolator
    from scipy.ndimage import distance_transform_edt

    values = np.asarray(values, np.float64)
    lead = values.shape[:-2]
    flat = values.reshape((-1,) + grid.grid_shape)
    h, w = grid.shape
    rr, cc = np.mgrid[0:h, 0:w]
    out = np.full((flat.shape[0], h, w), np.nan)
    for k, v in enumerate(flat):
        bad = ~np.isfinite(v)
        if bad.all():
            continue
        if bad.any():
            idx = distance_transform_edt(bad, return_distances=False, return_indices=True)
            v = v[tuple(idx)]
        if v.shape[0] == 1 or v.shape[1] == 1:  # degenerate grid: nearest along the line
            ri = np.abs(rr[..., None] - grid.rows).argmin(-1)
            ci = np.abs(cc[..., None] - grid.cols).argmin(-1)
            out[k] = v[ri, ci]
            continue
        interp = RegularGridInterpolator((grid.rows, grid.cols), v, bounds_error=False,
                                         fill_value=None)
        out[k] = interp(np.stack([rr.ravel(), cc.ravel()], -1)).reshape(h, w)
    if mask is not None:
        out[:, ~np.asarray(mask, bool)] = np.nan
    return out.reshape(lead + (h, w))


def incidence(scene, rows: np.ndarray, cols: np.ndarray):
    """Vision-ray incidence at arbitrary pixels.

    Returns
    -------
    valid : (K,) bool
        The vision ray hits the front of the surface.
    i_local : (K, 3) float64
        Unit direction to the camera in the BRDF frame (x, y, n); NaN where invalid.
    """
    rows = np.asarray(rows)
    cols = np.asarray(cols)
    cam = scene.camera
    origins, dirs = cam.chief_rays(rows, cols)
    _, point, normal, hit = scene.surface.intersect(origins, dirs)
    normal = normalize(normal)
    i = -dirs
    valid = hit & (dot(i, normal) > 0)
    x, y = scene.anisotropy.frames(point, normal)
    i_local = np.stack([dot(i, x), dot(i, y), dot(i, normal)], -1)
    i_local[~valid] = np.nan
    return valid, i_local


# ----------------------------------------------------------------------------- energy
@dataclass(frozen=True)
class EnergyFraction:
    """Lobe energy inside the cone theta <= ``theta_max_deg`` about P, on a pixel grid.

    ``fraction`` (gr, gc): E(cone) / E(hemisphere); ``theta_needed_deg`` (gr, gc): the
    smallest cone half angle holding ``target`` of the energy; ``albedo`` (gr, gc): E(hemisphere)
    (the directional albedo); NaN where the pixel sees no surface.
    """

    theta_max_deg: float
    target: float
    fraction: np.ndarray
    theta_needed_deg: np.ndarray
    albedo: np.ndarray
    grid: PixelGrid

    def summary(self) -> dict:
        ok = np.isfinite(self.fraction)
        if not ok.any():
            return {"theta_max_deg": self.theta_max_deg, "target": self.target}
        return {
            "theta_max_deg": self.theta_max_deg,
            "target": self.target,
            "fraction_median": float(np.median(self.fraction[ok])),
            "fraction_min": float(np.min(self.fraction[ok])),
            "theta_needed_deg_max": float(np.max(self.theta_needed_deg[ok])),
            "theta_needed_deg_median": float(np.median(self.theta_needed_deg[ok])),
        }


def lobe_energy(brdf, i_local: np.ndarray, theta_max: float | Sequence[float],
                n_samples: int = 4096, target: float = 0.95, chunk: int = 16):
    """Importance-sampling quadrature of the lobe energy for incidence directions.

    Parameters
    ----------
    brdf : BRDF with ``sample``/``pdf`` (not the mirror)
    i_local : (K, 3) float64
        Unit directions to the camera in the BRDF frame (rows with NaN are skipped).
    theta_max : float or (T,) floats, rad
        Cone half angles about P = (-i_x, -i_y, i_z).
    n_samples : int
        Fibonacci-lattice points per direction (4096: the fraction within 1e-3 and the
        95 % angle within 0.01 deg of 65 536 points on the Fig. 3 and turned-sphere lobes).
    target : float
        Energy fraction whose cone angle is returned.

    Returns
    -------
    fraction : (K, T) float64
        E(cone) / E(hemisphere) for each theta_max.
    theta_needed : (K,) float64, rad
        Smallest cone half angle holding ``target`` of the energy.
    albedo : (K,) float64
        E(hemisphere) = integral of f cos(theta_o) over the hemisphere.
    """
    i_local = np.atleast_2d(np.asarray(i_local, np.float64))
    tmax = np.atleast_1d(np.asarray(theta_max, np.float64))
    k = i_local.shape[0]
    frac = np.full((k, tmax.size), np.nan)
    need = np.full(k, np.nan)
    albedo = np.full(k, np.nan)
    u1, u2 = fibonacci_lattice(n_samples)
    ok_rows = np.flatnonzero(np.all(np.isfinite(i_local), axis=1) & (i_local[:, 2] > 0))
    for s in range(0, ok_rows.size, chunk):
        idx = ok_rows[s:s + chunk]
        i = i_local[idx, None, :]  # (c, 1, 3)
        o = brdf.sample(u1[None], u2[None], i)  # (c, M, 3)
        w = lobe_weight(brdf, np.broadcast_to(i, o.shape), o)  # (c, M)
        p = i * np.array([-1.0, -1.0, 1.0])
        ang = np.arccos(np.clip(dot3(o, p), -1.0, 1.0))  # angle to P
        total = w.sum(-1)
        albedo[idx] = total / n_samples
        for t, th in enumerate(tmax):
            frac[idx, t] = np.where(ang <= th, w, 0.0).sum(-1) / total
        order = np.argsort(ang, axis=-1)
        ang_s = np.take_along_axis(ang, order, -1)
        cum = np.cumsum(np.take_along_axis(w, order, -1), -1) / total[:, None]
        pos = np.minimum((cum < target).sum(-1), n_samples - 1)
        need[idx] = ang_s[np.arange(idx.size), pos]
    return frac, need, albedo


def energy_fraction(scene, grid: PixelGrid, theta_max: float | None = None, target: float = 0.95,
                    n_samples: int = 4096) -> EnergyFraction:
    """Fraction of the lobe energy inside the cone of ``theta_max`` (rad; default: the
    scene's) at the grid pixels; see :class:`EnergyFraction`."""
    if scene.brdf.is_delta:
        raise ValueError("energy_fraction: the mirror has no lobe (all its energy is in P)")
    theta_max = scene.sampling.theta_max if theta_max is None else float(theta_max)
    valid, i_local = incidence(scene, grid.pixel_rows, grid.pixel_cols)
    if scene.brdf_variation is None:
        frac, need, albedo = lobe_energy(scene.brdf, i_local, theta_max, n_samples, target)
    else:  # spatially varying BRDF: each pixel's lobe with its own alphas and rho_s
        from ..scene.brdf_variation import with_params
        from ..trace import trace_pixels

        pts = trace_pixels(scene, grid.pixel_rows, grid.pixel_cols).point[0]
        px = scene.brdf_variation.pixel_params(np.nan_to_num(pts), scene.brdf.kernel_params())
        parts = [lobe_energy(with_params(scene.brdf, *px[k]), i_local[k:k + 1], theta_max,
                             n_samples, target) for k in range(i_local.shape[0])]
        frac = np.concatenate([p[0] for p in parts])
        need = np.concatenate([p[1] for p in parts])
        albedo = np.concatenate([p[2] for p in parts])
    shape = grid.grid_shape
    return EnergyFraction(
        math.degrees(theta_max), target, frac[:, 0].reshape(shape),
        np.degrees(need).reshape(shape), albedo.reshape(shape), grid,
    )


# ----------------------------------------------------------------------------- weights
def _transport(sim, grid: PixelGrid):
    rows, cols = grid.pixel_rows, grid.pixel_cols
    valid, _ = incidence(sim.scene, rows, cols)
    u, v, w, _, _ = sim.transport(rows, cols, directions=False)
    return valid, u, v, w


def ess_from_weights(weights: np.ndarray) -> np.ndarray:
    """(sum w)^2 / sum w^2 over the last axis; NaN where all weights are 0."""
    w = np.asarray(weights, np.float64)
    s1 = w.sum(-1)
    s2 = (w * w).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s2 > 0, s1 * s1 / s2, np.nan)


def phase_error_from_rays(u, v, weights, widths, directions, nearest: bool):
    """Delta-method standard error (rad) of ``arg sum_p w_p exp(i k c_p)`` per pixel.

    ``u``, ``v``, ``weights``: (K, N) monitor coordinates (monitor px; NaN for misses) and
    weights of the N rays of K pixels; ``nearest``: use the nearest monitor pixel centre
    (``floor(c + 0.5)``) as the monitor does in pixel model ``nearest``.

    Returns
    -------
    se : (n_directions, n_widths, K) float64, rad
        NaN where no ray hits.
    modulation : (n_directions, n_widths, K) float64
        ``|sum w exp(i k c)| / sum w`` over the hits: the fringe modulation the pixel sees
        (black level 0, gamma 1).
    """
    w = np.asarray(weights, np.float64)
    n = w.shape[-1]
    out = np.full((len(directions), len(widths), w.shape[0]), np.nan)
    mod = np.full_like(out, np.nan)
    wsum = w.sum(-1)
    for di, d in enumerate(directions):
        c = np.asarray(u if d == "x" else v, np.float64)
        c = np.where(np.isfinite(c), c, 0.0)
        if nearest:
            c = np.floor(c + 0.5)
        for wi, width in enumerate(widths):
            z = w * np.exp(1j * 2 * np.pi * c / width)
            zbar = z.mean(-1)
            q = (z * np.exp(-1j * np.angle(zbar))[:, None]).imag
            with np.errstate(divide="ignore", invalid="ignore"):
                se = q.std(-1, ddof=1) / (math.sqrt(n) * np.abs(zbar)) if n > 1 else np.full(zbar.shape, np.inf)
            out[di, wi] = np.where(np.abs(zbar) > 0, se, np.nan)
            with np.errstate(divide="ignore", invalid="ignore"):
                mod[di, wi] = np.where(wsum > 0, np.abs(zbar) * n / wsum, np.nan)
    return out, mod


@dataclass(frozen=True)
class RayStatistics:
    """Per-pixel statistics of the rays on a pixel grid: effective sample size (gr, gc), the
    delta-method phase standard error (n_directions, n_widths, gr, gc), rad, and the fringe
    modulation (same shape) the rays give."""

    n_rays: int
    ess: np.ndarray
    phase_se: np.ndarray
    modulation: np.ndarray
    directions: tuple[str, ...]
    widths: tuple[float, ...]
    grid: PixelGrid
    #: (n_directions, gr, gc) weighted standard deviation of the rays' monitor coordinate
    #: along each direction, monitor px: the width of the lobe's footprint on the monitor
    spread_px: np.ndarray | None = None


def _footprint_spread(c: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted standard deviation over the last axis of the finite coordinates ``c``."""
    ok = np.isfinite(c) & (w > 0)
    ww = np.where(ok, w, 0.0)
    cc = np.where(ok, c, 0.0)
    total = ww.sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (ww * cc).sum(-1) / total
        var = (ww * (cc - mean[:, None]) ** 2).sum(-1) / total
    return np.where(total > 0, np.sqrt(np.maximum(var, 0.0)), np.nan)


def ray_statistics(sim, grid: PixelGrid, widths: Sequence[float] = (50.0,),
                   directions: Sequence[str] = ("x", "y")) -> RayStatistics:
    """Effective sample size and delta-method phase error at the grid pixels (one pass of
    :meth:`~pmdsim.render.Simulation.transport`)."""
    valid, u, v, w = _transport(sim, grid)
    ess = ess_from_weights(w)
    se, mod = phase_error_from_rays(u, v, w, tuple(widths), tuple(directions),
                                    sim.scene.monitor.pixel_model == "nearest")
    spread = np.stack([_footprint_spread(np.asarray(u if d == "x" else v, np.float64),
                                         np.asarray(w, np.float64)) for d in directions])
    ess[~valid] = np.nan
    se[..., ~valid] = np.nan
    mod[..., ~valid] = np.nan
    spread[..., ~valid] = np.nan
    shape = grid.grid_shape
    return RayStatistics(
        sim.scene.rays_per_pixel, ess.reshape(shape), se.reshape(se.shape[:2] + shape),
        mod.reshape(mod.shape[:2] + shape), tuple(directions), tuple(float(x) for x in widths),
        grid, spread.reshape(spread.shape[:1] + shape),
    )


def effective_sample_size(sim, grid: PixelGrid) -> np.ndarray:
    """(sum w)^2 / sum w^2 (gr, gc) of the monitor-hitting rays at the grid pixels."""
    return ray_statistics(sim, grid, (50.0,), ("x",)).ess


def phase_error_delta(sim, grid: PixelGrid, widths: Sequence[float] = (50.0,),
                      directions: Sequence[str] = ("x", "y")) -> np.ndarray:
    """Delta-method phase standard error (n_directions, n_widths, gr, gc), rad."""
    return ray_statistics(sim, grid, widths, directions).phase_se


def phase_error_seeds(sim, grid: PixelGrid, widths: Sequence[float] = (50.0,),
                      directions: Sequence[str] = ("x", "y"), n_seeds: int = 8,
                      first_seed: int = 1000) -> np.ndarray:
    """Phase standard error (n_directions, n_widths, gr, gc), rad, of one run in mode
    ``random``, from ``n_seeds`` independent sample sets (seeds ``first_seed ...``) at the
    grid pixels: the circular standard deviation of ``arg sum_p w_p exp(i k c_p)`` about
    its mean, with ``n_seeds - 1`` degrees of freedom.

    Mode ``random`` rotates a low-discrepancy lattice per pixel (randomised quasi-Monte
    Carlo), so this error is usually well below the plain Monte-Carlo error of N
    independent rays (:func:`phase_error_delta`). With mode ``stratified`` every pixel
    uses the unrotated lattice; its (fixed, structured) error is typically of this size.
    """
    from ..render import Simulation
    from ..scene.sampling import ConeSampling

    if n_seeds < 2:
        raise ValueError(f"n_seeds must be >= 2, got {n_seeds}")
    s = sim.scene.sampling
    nearest = sim.scene.monitor.pixel_model == "nearest"
    rows, cols = grid.pixel_rows, grid.pixel_cols
    valid, _ = incidence(sim.scene, rows, cols)
    phases = []
    for k in range(n_seeds):
        samp = ConeSampling(s.n_rays, s.theta_max, s.scheme, "random", first_seed + k)
        run = Simulation(sim.scene.replace(sampling=samp), sim.tile_rows, sim.scheduler,
                         sim.num_workers)
        u, v, w, _, _ = run.transport(rows, cols, directions=False)
        phases.append(ray_phases(u, v, w, tuple(widths), tuple(directions), nearest))
    ph = np.stack(phases)  # (S, nd, nw, K)
    mean = np.angle(np.exp(1j * ph).sum(0))
    dev = np.angle(np.exp(1j * (ph - mean)))
    se = np.sqrt((dev * dev).sum(0) / (n_seeds - 1))
    se[..., ~valid] = np.nan
    return se.reshape(se.shape[:2] + grid.grid_shape)


def phase_error_rule(sim, grid: PixelGrid, widths: Sequence[float] = (50.0,),
                     directions: Sequence[str] = ("x", "y")) -> np.ndarray:
    """The stated numerical phase error (n_directions, n_widths, gr, gc), rad, of the sample
    sets the run actually renders (mode ``rule``: the rule against its embedded rules; mode
    ``rqmc``: the replicates' spread; a nearest monitor's control variate: both), at the
    grid pixels: the same statement as
    :meth:`pmdsim.render.FringeResult.phase_error`, from the rays of
    :meth:`~pmdsim.render.Simulation.transport` (linear fringes, as the other methods)."""
    from ..render import Simulation
    from ..render.results import convergence_factor, phase_error
    from ..scene.quadrature import convergence_exponent, student_t975

    from ..render import control_variate as control

    nearest = sim.scene.monitor.pixel_model == "nearest"
    rows, cols = grid.pixel_rows, grid.pixel_cols
    valid, _ = incidence(sim.scene, rows, cols)
    cv = control.applies(sim)  # the nearest monitor's control variate: rule + rqmc residual
    # a wide lobe: the box-filtered rule and the alias bound (linear fringes: no replicates)
    sig = control.box_plan(sim, tuple(widths), True)[0] if cv else None
    passes = sim.plan(True)[:2] if cv else sim.plan(sim.fringes_smooth())
    reps = sim.scene.sampling.as_mode("rqmc").error_passes() if cv and sig is None else ()
    sums, res = [], []
    for k, samp in enumerate(passes + reps):
        run = Simulation(sim.scene.replace(sampling=samp), sim.tile_rows, sim.scheduler,
                         sim.num_workers)
        u, v, w, _, _, wtot = run.transport(rows, cols, directions=False, totals=True)
        smooth = ray_sums(u, v, w, tuple(widths), tuple(directions), nearest and not cv)
        if sig is not None:
            smooth = smooth * np.sinc(1.0 / np.asarray(widths, np.float64))[None, :, None]
        if k == 0 and sig is not None:  # the rule's weight on and off the monitor
            wsum = np.where(np.isfinite(u), w, 0.0).sum(-1)
            off, wall = control.off_share(wsum, wtot)
        if k < len(passes):
            sums.append(smooth)
        else:
            res.append(ray_sums(u, v, w, tuple(widths), tuple(directions), True) - smooth)
    z = np.stack(sums)  # (passes, nd, nw, K)
    if sig is not None:
        se = phase_error(z[0], z[0] - z[1], "embedded") if len(passes) > 1 else 0.0
        bound = np.stack([np.stack([control.linear_bound(sig[d], wd, wsum, wall, off)
                                    for wd in widths]) for d in directions])
        se = se + phase_error(z[0], bound * (1 + 1j), "replicates")
        se = np.where(off > control.EDGE_MAX_OFF, np.pi, se)
    elif cv:
        r = np.stack(res)
        half = student_t975(len(res) - 1) / math.sqrt(len(res))
        total = z[0] + r.mean(0)
        se = phase_error(total, half * (r.real.std(0, ddof=1) + 1j * r.imag.std(0, ddof=1)),
                         "replicates")
        if len(passes) > 1:
            se = se + phase_error(total, z[0] - z[1], "embedded")
    elif len(passes) == 1:
        se = np.full(z.shape[1:], np.nan)
    elif passes[0].mode == "rule":
        conv = None
        if len(passes) > 2:  # the observed convergence against the second embedded rule
            rule = passes[0].rule(sim._lobe)
            conv = convergence_factor(z[0], z[0] - z[1], z[0] - z[2], convergence_exponent(
                tuple(rule.order), rule.kind), pixel_axes=1)
        se = phase_error(z[0], z[0] - z[1], "embedded", conv)
    else:
        r = z.shape[0]
        half = student_t975(r - 1) / math.sqrt(r)
        err = half * (z.real.std(0, ddof=1) + 1j * z.imag.std(0, ddof=1))
        se = phase_error(z.mean(0), err, "replicates")
    se[..., ~valid] = np.nan
    return se.reshape(se.shape[:2] + grid.grid_shape)


def ray_sums(u, v, weights, widths, directions, nearest: bool) -> np.ndarray:
    """``sum_p w_p exp(i k c_p)`` (n_directions, n_widths, K) of the rays of K pixels."""
    w = np.asarray(weights, np.float64)
    out = np.zeros((len(directions), len(widths), w.shape[0]), np.complex128)
    for di, d in enumerate(directions):
        c = np.asarray(u if d == "x" else v, np.float64)
        c = np.where(np.isfinite(c), c, 0.0)
        if nearest:
            c = np.floor(c + 0.5)
        for wi, width in enumerate(widths):
            out[di, wi] = (w * np.exp(1j * 2 * np.pi * c / width)).sum(-1)
    return out


def ray_phases(u, v, weights, widths, directions, nearest: bool) -> np.ndarray:
    """``arg sum_p w_p exp(i k c_p)`` (n_directions, n_widths, K) of the rays of K pixels
    (the phase the renderer's fringe sums decode to, gamma 1; NaN where the sum is 0)."""
    z = ray_sums(u, v, weights, widths, directions, nearest)
    return np.where(np.abs(z) > 0, np.angle(z), np.nan)


# ----------------------------------------------------------------------------- report
@dataclass(frozen=True)
class Diagnostics:
    """Everything :func:`diagnose` found. Grid maps are (gr, gc) on ``grid``;
    :meth:`full` interpolates any of them to the camera."""

    estimator: str
    n_rays: int
    theta_max_deg: float
    directions: tuple[str, ...]
    widths: tuple[float, ...]
    grid: PixelGrid
    surface_mask: np.ndarray
    energy: EnergyFraction | None
    rays: RayStatistics | None
    phase_se_method: str
    phase_se: np.ndarray | None  # (nd, nw, gr, gc), rad
    summary: dict = field(default_factory=dict)
    #: (gr, gc) bool: grid pixels left out of the judgement (their bundle hangs off the
    #: monitor: flagged and never valid in the run); None: none
    excluded: np.ndarray | None = None

    def judged(self, values: np.ndarray) -> np.ndarray:
        """``values`` (..., gr, gc) with the excluded grid pixels set to NaN."""
        values = np.asarray(values, np.float64)
        if self.excluded is None:
            return values
        return np.where(self.excluded, np.nan, values)

    def full(self, values: np.ndarray) -> np.ndarray:
        """A grid map (..., gr, gc) interpolated to the camera (..., H, W)."""
        return full_map(values, self.grid, self.surface_mask)


def _pct(a, q):
    a = np.asarray(a, np.float64)
    a = a[np.isfinite(a)]
    return percentile(a, q, overwrite=True) if a.size else float("nan")


def diagnose(sim, widths: Sequence[float] | None = None, directions: Sequence[str] = ("x", "y"),
             grid: tuple[int, int] = (24, 20), target_fraction: float = 0.95,
             phase_method: str = "seeds", n_seeds: int = 8, n_samples: int = 4096,
             exclude: np.ndarray | None = None) -> Diagnostics:
    """Energy fraction, effective sample size and phase standard error of a simulation.

    Parameters
    ----------
    sim : Simulation
    widths : fringe widths (periods), monitor px; default (50,)
    directions : fringe directions
    grid : (columns, rows) of the coarse pixel grid
    target_fraction : energy fraction whose cone angle is reported
    phase_method : ``"seeds"`` (``n_seeds`` independent sample sets, mode ``random``) or
        ``"delta"`` (per-sample variance of one set: the plain Monte-Carlo bound)
    n_samples : quadrature points per pixel for the energy fraction
    exclude : (H, W) bool, optional
        Camera pixels to leave out of the summary and the warnings (the run passes the
        pixels whose bundle hangs off the monitor: their phase error says nothing about the
        sampling of the pixels that are measured). Their maps are kept.
    """
    if phase_method not in ("delta", "seeds", "rule"):
        raise ValueError(f"phase_method must be 'delta', 'seeds' or 'rule', got {phase_method!r}")
    if phase_method == "seeds" and sim.scene.sampling.estimates_error:
        # the run states the error of the rule it renders: judge that, not random rotations
        phase_method = "rule"
    widths = tuple(float(w) for w in (widths or (50.0,)))
    directions = tuple(directions)
    scene = sim.scene
    h, w = sim.shape
    pgrid = PixelGrid.spread((h, w), grid[0], grid[1])
    surface = sim.geometry().surface_mask
    delta = scene.brdf.is_delta
    energy = None if delta else energy_fraction(scene, pgrid, None, target_fraction, n_samples)
    rays = None if delta else ray_statistics(sim, pgrid, widths, directions)
    # a deterministic rule (mode "rule") has no sampling noise: no effective sample size,
    # no noise floor; its phase error is the render's own statement (the pilot), not judged
    # here again
    deterministic = not delta and scene.sampling.mode == "rule"
    if delta or deterministic:
        phase_se = None
    elif phase_method == "delta":
        phase_se = rays.phase_se
    elif phase_method == "rule":
        phase_se = phase_error_rule(sim, pgrid, widths, directions)
    else:
        phase_se = phase_error_seeds(sim, pgrid, widths, directions, n_seeds)
    if rays is not None:
        phase_se, rays = _with_specular_peak(scene.brdf, phase_se, rays)
    vision = scene.camera.rays_per_pixel
    if phase_se is not None and vision > 1 and scene.sampling.mode == "random":
        # camera optics: a pixel averages S vision rays with independently rotated bundles
        # (docs/system.md); the transport above is the chief ray's
        phase_se = phase_se / math.sqrt(vision)
    excluded = None
    if exclude is not None:
        excluded = np.asarray(exclude, bool)[pgrid.pixel_rows, pgrid.pixel_cols].reshape(
            pgrid.grid_shape)

    def judged(a):
        a = np.asarray(a, np.float64)
        return a if excluded is None else np.where(excluded, np.nan, a)

    summary: dict = {
        "estimator": scene.estimator,
        "n_rays": scene.rays_per_pixel,
        "theta_max_deg": math.degrees(scene.sampling.theta_max),
        "vision_rays_per_pixel": vision,
    }
    if energy is not None:
        summary["energy"] = energy.summary()
    if deterministic:
        summary["deterministic_rule"] = True
    elif rays is not None:
        summary["ess_median"] = _pct(judged(rays.ess), 50)
        summary["ess_min"] = float(np.nanmin(rays.ess)) if np.isfinite(rays.ess).any() else float("nan")
    if phase_se is not None:
        summary["phase_se_method"] = phase_method
        summary["phase_se_rad"] = {
            f"{d}/{wd:g}": {"median": _pct(judged(phase_se[di, wi]), 50),
                            "p95": _pct(judged(phase_se[di, wi]), 95)}
            for di, d in enumerate(directions) for wi, wd in enumerate(widths)
        }
    if rays is not None:
        summary["modulation_median"] = {
            f"{d}/{wd:g}": _pct(judged(rays.modulation[di, wi]), 50)
            for di, d in enumerate(directions) for wi, wd in enumerate(widths)
        }
    if excluded is not None:
        summary["excluded_grid_pixels"] = int(np.count_nonzero(
            excluded & surface[pgrid.pixel_rows, pgrid.pixel_cols].reshape(pgrid.grid_shape)))
    return Diagnostics(scene.estimator, scene.rays_per_pixel, math.degrees(scene.sampling.theta_max),
                       directions, widths, pgrid, surface, energy, rays, phase_method, phase_se,
                       summary, excluded)


def _with_specular_peak(brdf, phase_se, rays):
    """A specular peak (reflectance a) beside the lobe (h; ``pmdsim.render.specular``): the
    rays sample the lobe alone, whose fringe of modulation m adds to the peak's full one, so
    the pixel's modulation is (a + h m) / (a + h) and its phase error the lobe's times
    h m / (a + h m)."""
    from dataclasses import replace

    from ..render.specular import specular_reflectance

    a = specular_reflectance(brdf)
    if a <= 0:
        return phase_se, rays
    h = float(brdf.halo_reflectance)
    m = rays.modulation
    share = h * m / (a + h * m)
    rays = replace(rays, modulation=(a + h * m) / (a + h), phase_se=rays.phase_se * share)
    return (None if phase_se is None else phase_se * share), rays

