"""Rendering camera images through the traced light transport, tile by tile on Dask.

The camera is split into tiles of ``tile_rows`` rows. For each tile the vision rays are
traced (:mod:`pmdsim.trace`) and the compiled bundle kernel
(:func:`pmdsim.kernels.bundle.render_tile`) accumulates, per pixel, the weighted sums that
any number of patterns need in one pass over the scattered rays:

- fringes (:meth:`Simulation.render_fringes`): for each direction and width the complex
  sum ``sum_p f_p exp(i k u_p)``; every phase shift follows exactly from
  ``Re(exp(i delta) sum_p f_p exp(i k u_p))``, so K shifts cost one pass;
- arbitrary monitor images (:meth:`Simulation.render_images`), dots
  (:meth:`Simulation.render_dots`), and the rays themselves (:meth:`Simulation.transport`).

Memory is bounded by the tile size, not by N. Tiles are Dask tasks: the local threaded
scheduler by default (the kernels release the GIL), or a ``dask.distributed`` cluster when a
client is active and ``scheduler="distributed"``.

Estimators (``Scene.estimator``):

- ``paper``: I_C = (1/N) sum_p f_p L_p (N = rays per pixel, P included);
- ``weighted_mean``: I_C = sum_p f_p L_p / sum_p f_p;
- ``radiometric``: I_C = (1/N) sum_p w_p L_p, w_p = f_p cos(theta_p) / pdf_p, over N
  directions importance-sampled from the BRDF lobe (no cone, no P;
  :func:`pmdsim.kernels.bundle.render_tile_lobe`): the rendering integral of f L cos over
  the hemisphere. Its ``f_total`` is the directional albedo estimate.

Rays that miss the monitor see black (L = 0) but keep their weight in sum f.
"""

from __future__ import annotations

import threading
import uuid
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from ..kernels import bundle as kb
from . import control_variate as control
from ..config import SimulationSections
from ..config.monitor import GAMMA_HARMONICS
from ..patterns import DIRECTIONS, Dot, phase_shifts
from ..scene import Scene
from ..scene.brdf_variation import with_params
from ..scene.quadrature import convergence_exponent
from .results import (FringeResult, Geometry, convergence_of_ratios, value_error, worst_phase_error)
from .fringe_finish import FringeFinish, TileErrors, fringe_errors
from .convergence_grid import convergence_stride, keep_grid
from .tile_tasks import fuses, local_scheduler, render_rule_fused
from .geometry_rows import reduce_subrays, scene_geometry_rows, vision_geometry_rows
from ..trace import bundle_geometry, trace_pixels

ProgressFn = Callable[[int, int], None]


def target_not_met(target: float, worst: float | None, n: int, max_rays: int) -> None:
    """Warn that ``sampling.target_error_mrad`` was not met (``UserWarning``: the run
    reports it as a note, without a source path)."""
    import warnings

    stated = "unknown" if worst is None else f"{worst * 1e3:.3g} mrad"
    warnings.warn(
        f"sampling.target_error_mrad = {target * 1e3:g} not met: the stated phase error is "
        f"{stated} (P95, worst fringe) with the rule of n_rays = {n}, the largest that "
        f"sampling.max_rays = {max_rays} allows; raise sampling.max_rays (or accept the "
        "error)", TargetNotMet, stacklevel=3)


class TargetNotMet(UserWarning):
    """The target of the stated phase error was not met within ``max_rays``."""


class RuleTooSmall(UserWarning):
    """A rule too small to state its numerical error (its phase is stated as unknown)."""


@dataclass(frozen=True, eq=False)
class RuleChoice:
    """:meth:`Simulation.choose_rule`'s result: for ``scene`` and the fringes ``key``
    (widths, directions, shifts), the :class:`~pmdsim.render.pilot.Pilot` with its grid
    probes, the rule's ``n_rays`` and the orders ``tried`` [(n_rays, grid P95)] (None
    without a target)."""

    scene: Scene
    key: tuple
    pilot: object
    n_rays: int
    tried: list | None


class Simulation:
    """Render patterns of one :class:`~pmdsim.scene.Scene` through its light transport.

    Parameters
    ----------
    scene : Scene
    tile_rows : int
        Camera rows per tile (memory ~ tile_rows x width x n_outputs x 8 bytes per task).
    scheduler : {"threads", "synchronous", "processes", "distributed"}
        Dask scheduler for the tiles; ``distributed`` uses the active ``dask.distributed``
        client.
    num_workers : int, optional
        Threads/processes for local schedulers (default: all cores).
    """

    def __init__(self, scene: Scene, tile_rows: int = 32, scheduler: str = "threads",
                 num_workers: int | None = None):
        if tile_rows < 1:
            raise ValueError(f"tile_rows must be >= 1, got {tile_rows}")
        if scheduler not in ("threads", "synchronous", "processes", "distributed"):
            raise ValueError(f"scheduler: unknown Dask scheduler {scheduler!r}")
        self.scene = scene
        self.tile_rows = tile_rows
        self.scheduler = scheduler
        self.num_workers = num_workers
        #: rays the bundle kernels traced, one entry per kernel call (appended from the
        #: tile threads; shared with the simulations of other rules this one renders through,
        #: :meth:`with_sampling`): :attr:`rays_traced`
        self._traced: list[int] = []

    @property
    def rays_traced(self) -> int:
        """Every scattered ray the bundle kernels traced for this simulation's renders
        (each rule, pilot and error pass; a mirror reference one per vision ray)."""
        return int(sum(self._traced))

    def with_sampling(self, sampling) -> "Simulation":
        """The same simulation with another sample set, counting its rays with this one's."""
        sim = Simulation(self.scene.replace(sampling=sampling), self.tile_rows, self.scheduler,
                         self.num_workers)
        sim._traced = self._traced
        return sim

    @classmethod
    def from_config(cls, cfg: SimulationSections) -> "Simulation":
        """The simulation of the scene's sections and ``compute`` (a
        :class:`~pmdsim.config.RunConfig` has them)."""
        return cls(Scene.from_config(cfg), cfg.compute.tile_rows, cfg.compute.scheduler,
                   cfg.compute.num_workers)

    # ------------------------------------------------------------------ plumbing
    @property
    def shape(self) -> tuple[int, int]:
        return (self.scene.camera.height, self.scene.camera.width)

    def _tiles(self):
        h = self.scene.camera.height
        return [(r, min(r + self.tile_rows, h)) for r in range(0, h, self.tile_rows)]

    def _compute(self, fn, tiles, progress: ProgressFn | None):
        import dask
        from dask.callbacks import Callback

        # keys unique per call: a cluster may still hold the previous call's tiles
        call = uuid.uuid4().hex[:12]
        tasks = [dask.delayed(fn, pure=False)(r0, r1, dask_key_name=f"pmdsim-tile-{r0}-{call}")
                 for r0, r1 in tiles]
        kwargs = {}
        if self.scheduler != "distributed":
            kwargs["scheduler"] = local_scheduler(self.scheduler)
            if self.num_workers is not None and self.scheduler != "synchronous":
                kwargs["num_workers"] = self.num_workers
        if progress is None or self.scheduler == "distributed":
            return dask.compute(*tasks, **kwargs)
        total = len(tasks)
        done = [0]

        class _Progress(Callback):
            def _posttask(self, key, result, dsk, state, worker_id):
                done[0] += 1
                progress(min(done[0], total), total)

        with _Progress():
            return dask.compute(*tasks, **kwargs)

    @property
    def _lobe(self) -> bool:
        """True when the radiometric estimator samples the BRDF lobe (not for the mirror)."""
        return self.scene.estimator == "radiometric" and not self.scene.brdf.is_delta

    def plan(self, smooth: bool = True) -> tuple:
        """The sample sets (:class:`~pmdsim.scene.sampling.ConeSampling`) a render uses, the
        rendered one first: in mode ``rule`` the rule and its two embedded rules (none with
        ``error_estimate = false``); in mode ``rqmc`` the R replicates; else one set.
        ``smooth=False`` (a ``nearest`` monitor, dots, images, a tabulated slope density):
        mode ``rule`` becomes ``rqmc`` (when ``n_rays`` >= 2 R), whose error estimate does
        not need a smooth integrand."""
        samp = self.scene.sampling
        if self.scene.brdf.is_delta:
            return (samp.as_mode("stratified"),)
        if samp.mode == "rule" and not smooth and samp.n_rays >= 2 * samp.replicates:
            samp = samp.as_mode("rqmc")
        if samp.mode == "rule" and not samp.error_estimate:
            return (samp,)
        return samp.error_passes()

    def result_pass(self, smooth: bool = True):
        """The sample set whose pass :meth:`_render` returns unchanged as its result (one
        pass; mode ``rule``, whose embedded passes only give the error), or None (the mean
        of rqmc replicates; a specular peak's mirror pass added after the tiles): only then
        can a caller finish the sums inside that pass's tiles (``finish``,
        :class:`~pmdsim.render.fringe_finish.FringeFinish`). Keep in step with :meth:`_render`."""
        from .specular import specular_reflectance

        passes = self.plan(smooth)
        if len(passes) > 1 and passes[0].mode != "rule":
            return None
        brdf = self.scene.brdf
        if not brdf.is_delta and specular_reflectance(brdf) > 0:
            return None
        return passes[0]

    def fringes_smooth(self) -> bool:
        """Whether the fringe integrand is smooth (a Gauss rule converges fast): a continuous
        monitor and, for the radiometric estimator, a Gaussian slope density."""
        return (self.scene.monitor.pixel_model == "continuous"
                and (not self._lobe or self.scene.sampling.lobe_gaussian))

    def _render(self, mode, ncols, smooth=True, progress=None, **kw):
        """Pixel sums (H, W, C) and their numerical error or None, over the sample sets of
        :meth:`plan`: the rule and its differences (H, W, C) to the embedded rules (signed;
        a tuple, the embedded rule first), or the mean of the rqmc replicates and its error
        (H, W, C) ``t(0.975, R - 1) s / sqrt(R)``."""
        from ..scene.quadrature import student_t975

        passes = self.plan(smooth)
        n = len(passes)
        if fuses(self, passes, mode, ncols, kw.get("finish")):  # every pass in one tile task
            finish = kw.pop("finish")
            return render_rule_fused(self, passes, mode, ncols, finish, progress, kw)

        def prog(k):
            if progress is None:
                return None
            return lambda done, total: progress(k * total + done, n * total)

        if n == 1:  # nothing reads the raw sums of rows a tile finished
            return self._render_set(passes[0], mode, ncols, progress=prog(0), raw=False,
                                    **kw), None
        out = self._render_set(passes[0], mode, ncols, progress=prog(0), **kw)
        if passes[0].mode == "rule":  # the differences to the embedded rules, in place
            diffs = []
            for k in range(1, n):
                coarse = self._render_set(passes[k], mode, ncols, progress=prog(k), **kw)
                diffs.append(np.subtract(out, coarse, out=coarse))
            return out, tuple(diffs)
        mean, m2 = out.copy(), np.zeros_like(out)
        for k in range(1, n):  # Welford: one replicate in memory at a time
            o = self._render_set(passes[k], mode, ncols, progress=prog(k), **kw)
            d = o - mean
            mean += d / (k + 1)
            m2 += d * (o - mean)
        return mean, student_t975(n - 1) * np.sqrt(m2 / ((n - 1) * n))

    def _render_set(self, samp, mode, ncols, **kw):
        """Pixel sums of the scene's BRDF with sample set ``samp``; a specular peak beside a
        lobe is a second, mirror pass added by :func:`pmdsim.render.specular.add_specular`."""
        from .specular import add_specular, check_estimator, specular_reflectance

        scene = self.scene.replace(sampling=samp)
        check_estimator(scene.brdf, scene.estimator)
        out = self._render_brdf(scene, mode, ncols, **kw)
        if specular_reflectance(scene.brdf) > 0:
            kw.pop("progress", None)
            mirror = self._render_brdf(scene.specular(), mode, ncols, **kw)
            out = add_specular(out, mirror, scene.brdf, scene.estimator, scene.rays_per_pixel)
        return out

    def _render_brdf(self, scene, mode, ncols, progress=None, finish=None, raw=True,
                     **patterns):
        """Pixel sums (H, W, ncols) of one pass. ``finish``: optional ``(sampling, mode,
        ncols, fn)``: when this pass renders that sample set, mode and columns on an
        in-process scheduler, each tile task calls ``fn(r0, r1, sums)`` (``sums`` the whole
        (H, W, ncols) array, rows ``r0:r1`` final) right after its kernel, while the rows
        are in cache (:meth:`result_pass`). With ``raw=False`` and pinhole rays the caller
        reads only what ``fn`` (a :class:`~pmdsim.render.fringe_finish.FringeFinish`) keeps: the
        tiles' raw sums live in a buffer of the worker thread, and the result is an empty
        (H, W, 0) token that :meth:`FringeFinish.complete` sees as finished."""
        kernel = self._kernel(scene, mode, ncols, **patterns)
        samp, delta = scene.sampling, scene.brdf.is_delta
        width, cam = scene.camera.width, scene.camera
        simple, n_sub = cam.is_simple_pinhole, cam.rays_per_pixel
        stride = 1 if delta else convergence_stride(samp, cam)  # the second embedded rule

        # In-process schedulers: the tiles write straight into one (H, W, ncols) array (no
        # per-tile result arrays, no concatenation copy: half the render's peak memory);
        # none where the tiles finish every row and nothing reads the raw sums (a token)
        local_run = self.scheduler in ("threads", "synchronous")
        fin = (finish[3] if finish is not None and local_run
               and (scene.sampling, mode, ncols) == finish[:3] else None)
        token = np.empty((cam.height, width, 0)) if fin is not None and not raw and simple else None
        full = token if token is not None else (
            np.empty((cam.height, width, ncols)) if local_run else None)

        # In-process schedulers: each worker thread reuses its geometry buffers across tiles
        # (no fresh 200 bytes per pixel, page faults and zeroing per tile).
        local = threading.local() if full is not None else None
        tile_px = self.tile_rows * width

        def tile(r0, r1):
            if simple:
                buffers = None
                if local is not None:
                    if not hasattr(local, "buffers"):
                        local.buffers = (np.empty((tile_px, kb.G_SIZE)), np.empty((tile_px, 2)),
                                         np.empty((tile_px if token is not None else 0, ncols)))
                    buffers = local.buffers[:2]
                geo, _ = scene_geometry_rows(scene, r0, r1, buffers)
                keep_grid(geo, r0, r1, width, stride)
                rot = np.zeros((0, 2)) if delta else samp.rotations(r0, r1, width)
                if token is not None:  # the raw rows in the thread's buffer, finished there
                    out = local.buffers[2][: geo.shape[0]]
                    kernel(geo, rot, out)
                    fin(r0, r1, token, out)
                    return None
                if full is not None:
                    kernel(geo, rot, full[r0:r1].reshape(-1, ncols))
                    if fin is not None:
                        fin(r0, r1, full)
                    return None
                counts: list[int] = []
                return kernel(geo, rot, counts=counts).reshape(r1 - r0, width, ncols), sum(counts)
            # camera optics: S vision rays per pixel, each with its own scattered bundle,
            # one camera row per kernel call; the pixel's sums are the mean over its rays
            res = full[r0:r1] if full is not None else np.empty((r1 - r0, width, ncols))
            counts = None if full is not None else []
            for r in range(r0, r1):
                geo, _ = vision_geometry_rows(scene, r)
                if delta or samp.mode != "random":
                    rot = np.zeros((0, 2))
                else:
                    rot = np.random.default_rng([samp.seed, r]).random((geo.shape[0], 2))
                out = kernel(geo, rot, counts=counts).reshape(width, n_sub, ncols)
                res[r - r0] = reduce_subrays(out, scene.estimator)
            if fin is not None:
                fin(r0, r1, full)
            return None if full is not None else (res, sum(counts))

        parts = self._compute(tile, self._tiles(), progress)
        if full is not None:
            return full
        # a cluster's tiles count their rays in the worker's process: they come back with
        # the sums (appended there, they would be lost)
        self._traced.extend(int(n) for _, n in parts)
        return np.concatenate([res for res, _ in parts], axis=0)

    def _kernel(self, scene, mode, ncols, table_u=None, table_v=None, k_u=None, k_v=None,
                images=None, dots=None, orient=True):
        """The bundle kernel of ``scene`` (its sample set) for ``mode``: ``kernel(geo, rot,
        out=None, counts=None)`` writes the sums (P, ncols) of the geometry rows ``geo`` and
        appends the rays it traced to ``counts`` (default: this simulation's count); with
        ``orient`` it first turns their cone bases onto the lobe's axis in place (as each
        pass needs it; :meth:`~pmdsim.scene.sampling.ConeSampling.orient` is not
        idempotent)."""
        delta = scene.brdf.is_delta
        samp = scene.sampling
        lobe = scene.estimator == "radiometric" and not delta
        if delta:
            u1 = u2 = np.zeros(0)
        elif lobe:
            u1, u2 = samp.lobe_unit_points()
        else:
            u1, u2 = samp.unit_points()
        w_ray = np.ones(1) if delta else samp.ray_weights(lobe)  # the mirror: P alone
        principal = True if delta else samp.include_principal
        brdf = scene.brdf.kernel_params()
        mshape = np.array(scene.monitor.shape, dtype=np.int64)
        e1 = np.zeros((0, 1))
        table_u = e1 if table_u is None else np.ascontiguousarray(table_u, np.float64)
        table_v = e1 if table_v is None else np.ascontiguousarray(table_v, np.float64)
        k_u = np.zeros(0) if k_u is None else np.asarray(k_u, np.float64)
        k_v = np.zeros(0) if k_v is None else np.asarray(k_v, np.float64)
        images = np.zeros((0, 1, 1), np.float32) if images is None else images
        dots = np.zeros((0, 4)) if dots is None else np.asarray(dots, np.float64)
        none = np.zeros((0, 0))
        mc = scene.monitor.correction_params()
        extra = () if mc is None else (mc,)
        var = None if delta else scene.brdf_variation
        per_row, traced = int(w_ray.size), self._traced

        def kernel(geo, rot, out=None, counts=None):
            out = np.empty((geo.shape[0], ncols)) if out is None else out
            (traced if counts is None else counts).append(
                per_row * int(np.count_nonzero(geo[:, kb.G_VALID] > 0)))
            if orient and not (lobe or delta):  # phi = 0 on the lobe's long axis (the rule)
                samp.orient(geo, brdf)
            if var is not None:  # spatially varying alpha/rho_s: per-pixel parameters
                px = var.geometry_params(geo, scene.monitor, brdf)
                args = (geo, brdf, u1, u2, rot)
                tail = (table_u, table_v, k_u, k_v, images, dots, out, none, none, none, mc, px,
                        w_ray)
                if lobe:
                    kb.render_tile_lobe(*args, mshape, mode, *tail)
                else:
                    kb.render_tile(*args, samp.scheme_id, samp.theta_max, principal, mshape, mode,
                                   *tail)
                return out
            if lobe:
                kb.render_tile_lobe(
                    geo, brdf, u1, u2, rot, mshape, mode,
                    table_u, table_v, k_u, k_v, images, dots, out, none, none, none, *extra,
                    w_ray=w_ray,
                )
            else:
                kb.render_tile(
                    geo, brdf, u1, u2, rot, samp.scheme_id, samp.theta_max, principal, mshape, mode,
                    table_u, table_v, k_u, k_v, images, dots, out, none, none, none, *extra,
                    w_ray=w_ray,
                )
            return out

        return kernel

    def _normalise(self, out):
        """(H, W) factor turning weighted sums into estimator values."""
        ftot = out[..., kb.OUT_FTOTAL]
        if self.scene.estimator in ("paper", "radiometric"):
            return np.full(ftot.shape, 1.0 / self.scene.rays_per_pixel)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ftot > 0, 1.0 / ftot, np.nan)

    def describe_sampling(self, smooth: bool = True) -> dict:
        """What a render with :meth:`plan` ``(smooth)`` uses (for reports): effective
        ``mode``, ``rule`` (its name and order), ``nodes`` per pixel and pass, ``passes``,
        ``error`` (``"embedded"``, ``"replicates"`` or None) and ``smooth``."""
        passes = self.plan(smooth)
        first = passes[0]
        if self.scene.brdf.is_delta:
            return {"mode": "mirror", "rule": "principal ray", "nodes": 1, "passes": 1,
                    "error": None, "smooth": smooth}
        rule = first.rule(self._lobe)
        err = None
        if len(passes) > 1:
            err = "embedded" if first.mode == "rule" else "replicates"
        d = {"mode": first.mode, "rule": rule.describe(), "kind": rule.kind, "nodes": rule.n,
             "order": list(rule.order), "passes": len(passes), "error": err, "smooth": smooth}
        if err == "embedded":
            d["embedded_rule"] = " and ".join(p.rule(self._lobe).describe() for p in passes[1:])
        return d

    # ------------------------------------------------------------------ public API
    def footprint_specular(self) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) (H, W): the exact monitor coordinates of the principal reflections averaged
        over each pixel's vision rays (sub-pixels x aperture; NaN where any misses)."""
        h, w = self.shape
        u = np.empty((h, w))
        v = np.empty((h, w))
        n = self.scene.camera.rays_per_pixel
        for r in range(h):
            _, spec = vision_geometry_rows(self.scene, r)
            spec = spec.reshape(w, n, 2)
            u[r] = spec[..., 0].mean(axis=1)
            v[r] = spec[..., 1].mean(axis=1)
        return u, v

    def geometry(self) -> Geometry:
        """Vision-ray results for the whole camera: the chief ray through each pixel centre
        (no bundle)."""
        h, w = self.shape

        def tile(r0, r1):  # per tile: the bundle rows are big (200 bytes a pixel)
            geo, spec = scene_geometry_rows(self.scene, r0, r1)
            valid = geo[:, kb.G_VALID].reshape(r1 - r0, w) > 0
            return valid, spec.reshape(r1 - r0, w, 2), self._points(geo, valid)

        rows = max(self.tile_rows, 64)
        parts = self._compute(tile, [(r, min(r + rows, h)) for r in range(0, h, rows)], None)
        valid = np.concatenate([p[0] for p in parts])
        spec = np.concatenate([p[1] for p in parts])
        points = np.concatenate([p[2] for p in parts])
        del parts
        u = np.ascontiguousarray(spec[..., 0])
        v = np.ascontiguousarray(spec[..., 1])
        return Geometry(valid, valid & np.isfinite(u), u, v, points)

    def _points(self, geo: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """(H, W, 3) surface points from geometry rows: a row holds S in the monitor's
        orthonormal frame (``G_U0``, ``G_V0``: monitor px; ``G_T``: distance along -n)."""
        mon = self.scene.monitor
        pts = mon.pixel_to_world(geo[:, kb.G_U0], geo[:, kb.G_V0])
        pts -= geo[:, kb.G_T, None] * mon.normal
        pts[~valid.ravel()] = np.nan
        return pts.reshape(valid.shape + (3,))

    def render_fringes(
        self,
        widths: Sequence[float] = (50.0,),
        directions: Sequence[str] = DIRECTIONS,
        shifts: int = 4,
        progress: ProgressFn | None = None,
        choice: "RuleChoice | None" = None,
    ) -> FringeResult:
        """Camera images of X/Y fringes of the given widths (periods, monitor px), K shifts.

        One pass over the scattered rays gives all widths, directions and shifts (plus the
        passes of the error estimate, :meth:`plan`). With a ``target_error`` in the
        scene's sampling (``sampling.target_error_mrad``) the number of nodes is doubled
        until the stated phase error (P95 over the pixels whose fringe keeps a modulation
        >= 0.05, worst fringe) is below the target or ``max_rays`` is reached (then a
        ``RuntimeWarning`` with the figure); ``sampling`` of the result reports
        ``target_error_mrad``, ``achieved_p95_mrad``, ``n_rays`` used and ``target_met``.
        ``choice``: the pilot's :meth:`choose_rule` for these fringes, made beforehand (a
        run makes it in a thread while the specular reference renders); the same result.
        """
        samp = self.scene.sampling
        if self.pilot_applies():
            return self._fringes_pilot(widths, directions, shifts, progress, choice)
        if samp.target_error is None or self.scene.brdf.is_delta:
            return self._fringes_once(widths, directions, shifts, progress)

        sim = self
        while True:
            fr = sim._fringes_once(widths, directions, shifts, progress)
            worst = worst_phase_error(fr)
            n = sim.scene.sampling.n_rays
            met = worst is not None and worst <= samp.target_error
            if met or worst is None or 2 * n > samp.max_rays:
                break
            sim = self.with_sampling(replace(sim.scene.sampling, n_rays=2 * n))
        info = dict(fr.sampling or {}, target_error_mrad=samp.target_error * 1e3,
                    achieved_p95_mrad=None if worst is None else worst * 1e3, n_rays=n,
                    target_met=bool(met))
        if not met:
            target_not_met(samp.target_error, worst, n, samp.max_rays)
        return replace(fr, sampling=info)

    def pilot_applies(self) -> bool:
        """Whether the fringes' error comes from the pilot on a sparse grid
        (:mod:`pmdsim.render.pilot`): mode ``rule`` with ``error_estimate`` on a smooth
        integrand (a continuous monitor; the radiometric estimator on a Gaussian slope
        density), a scattering BRDF."""
        samp = self.scene.sampling
        return (not self.scene.brdf.is_delta and samp.mode == "rule" and samp.error_estimate
                and self.fringes_smooth())

    def choose_rule(self, widths, directions, shifts, cancel=None) -> "RuleChoice":
        """The pilot's part of :meth:`render_fringes` that comes before the camera's render
        (mode ``rule`` on a smooth integrand, :meth:`pilot_applies`): the rule of the target
        (:func:`pmdsim.render.order.choose_order`), or ``n_rays`` and its grid probes
        without one. It needs nothing of the camera's render, so it may run beside other
        work (in a thread: the kernels release the GIL); ``cancel``, a
        :class:`threading.Event`, stops it between two probes (:class:`~pmdsim.render.
        pilot.Cancelled`)."""
        from . import pilot as pl
        from .order import choose_order

        if not self.pilot_applies():
            raise ValueError("choose_rule: the pilot applies to mode 'rule' with an error "
                             "estimate on a smooth integrand only (Simulation.pilot_applies)")
        samp = self.scene.sampling
        key = (tuple(float(w) for w in widths), tuple(directions), int(shifts))
        lay, ku, kv, ncols = self._harmonic_layout(key[0], key[1], key[2])
        pilot = pl.Pilot(self, lay, kb.MODE_HARMONIC, ncols, {"k_u": ku, "k_v": kv},
                         self.shape, cancel=cancel)
        if samp.target_error is None:
            pilot.measured(samp.n_rays)  # the rule's and the finer rule's grid probes
            return RuleChoice(self.scene, key, pilot, samp.n_rays, None)
        n, _, tried = choose_order(pilot, samp.n_rays, samp.target_error, samp.max_rays)
        return RuleChoice(self.scene, key, pilot, n, tried)

    def _fringes_pilot(self, widths, directions, shifts, progress, choice=None) -> FringeResult:
        """The fringes of mode ``rule`` on a smooth integrand: the order from the target by
        the pilot (when the sampling has one; ``choice``: :meth:`choose_rule` made
        beforehand), the camera rendered once with that rule, and its phase error from the
        pilot (:mod:`pmdsim.render.pilot`)."""
        import warnings

        from . import pilot as pl
        from .order import choose_order

        samp = self.scene.sampling
        widths = tuple(float(w) for w in widths)
        if choice is None:
            choice = self.choose_rule(widths, directions, shifts)
        elif choice.scene is not self.scene or choice.key != (widths, tuple(directions),
                                                               int(shifts)):
            raise ValueError("choice: made for another simulation or other fringes "
                             "(Simulation.choose_rule of these widths, directions, shifts)")
        pilot, n, tried = choice.pilot, choice.n_rays, choice.tried
        pilot.cancel = None  # the render's own part is not cancelled from outside
        renders = 0
        while True:
            main = self.with_sampling(replace(samp, n_rays=n, error_estimate=False,
                                              target_error=None, max_rays=max(samp.max_rays, n)))
            fr = main._fringes_once(widths, directions, shifts, progress)
            renders += 1
            with np.errstate(divide="ignore", invalid="ignore"):
                off = 1.0 - np.abs(fr.f_hit) / np.abs(fr.f_total)
            ok = np.isfinite(fr.f_total) & np.isfinite(fr.f_hit)
            stated, n_local = pilot.statement(n, ok, fr.images, fr.shifts, off, fr.f_total)
            if samp.target_error is None:
                break
            worst = worst_phase_error(replace(fr, stated_phase_error=stated))
            if (worst is not None and worst <= samp.target_error) or 2 * n > samp.max_rays:
                break
            # the grid did not see what the whole camera states (its local pixels, the
            # monitor's edge): the next order the pilot accepts from twice this one
            n_next, _, more = choose_order(pilot, 2 * n, samp.target_error, samp.max_rays)
            n = max(n_next, 2 * n)  # always a higher order: the loop ends at max_rays
            tried += more
        info = main.describe_sampling(True)
        rule = main.scene.sampling.rule(self._lobe)
        fine = pilot.sampling(pl.FINE_FACTOR * n).rule(self._lobe)
        info.update(error="pilot", passes=1, pilot={
            "grid_step_px": pilot.stride, "grid_pixels": int(pilot.rows.size * pilot.cols.size),
            "finer_rule": fine.describe(), "safety": pl.SAFETY, "local_pixels": n_local,
            "orders_tried": None if tried is None else [t[0] for t in tried],
            "camera_renders": renders})
        # the finest width's signed error pattern (the areal statistics' errors)
        wi, nw = int(np.argmin(widths)), len(widths)
        signed = pilot.signed_field(n, [di * nw + wi for di in range(len(directions))])
        fr = replace(fr, stated_phase_error=stated, sums_err=None, convergence=None,
                     sampling=info, signed_phase_error=signed.astype(np.float32))
        if rule.n < pl.MIN_NODES:
            warnings.warn(
                f"sampling.n_rays = {n}: a rule of {rule.n} nodes is too small to state its "
                f"numerical error (it is stated as unknown, pi); raise sampling.n_rays to >= "
                f"{pl.MIN_NODES} (or set sampling.target_error_mrad)", RuleTooSmall,
                stacklevel=3)
        if samp.target_error is not None:  # worst: of this render's statement (the loop's)
            met = worst is not None and worst <= samp.target_error
            info.update(target_error_mrad=samp.target_error * 1e3,
                        achieved_p95_mrad=None if worst is None else worst * 1e3, n_rays=n,
                        target_met=bool(met))
            if not met:
                target_not_met(samp.target_error, worst, n, samp.max_rays)
        return fr

    def _harmonic_layout(self, widths, directions, shifts):
        """The continuous monitor's fringe columns (as :meth:`_fringes_once` renders them):
        the pilot's :class:`~pmdsim.render.pilot.Layout`, ``k_u``, ``k_v`` and the columns."""
        from .pilot import Layout

        mon = self.scene.monitor
        linear = mon.is_linear
        harm = 1 if linear else GAMMA_HARMONICS
        nw = len(widths)
        n_u = sum(1 for d in directions if d == "x")
        per_width = 2 * harm
        base = {"x": kb.OUT_FIRST, "y": kb.OUT_FIRST + n_u * nw * per_width}
        ks = {"x": [], "y": []}
        for d in directions:
            for w in widths:
                ks[d] += [2 * np.pi * m / w for m in range(1, harm + 1)]
        ku, kv = np.array(ks["x"]), np.array(ks["y"])
        ncols = kb.OUT_FIRST + 2 * (ku.size + kv.size)
        cols = np.array([base[d] + wi * per_width for d in directions for wi in range(nw)])
        coef, g = (None, None) if linear else control.response_series(mon)
        lay = Layout(cols, linear, phase_shifts(shifts), mon.black_level, mon.white_level,
                     harm, coef, g)
        return lay, ku, kv, ncols

    def _fringes_once(self, widths, directions, shifts, progress) -> FringeResult:
        widths = tuple(float(w) for w in widths)
        directions = tuple(directions)
        if not widths or any(not np.isfinite(w) or w <= 0 for w in widths):
            raise ValueError(f"widths: fringe widths must be positive monitor px, got {widths}")
        for d in directions:
            if d not in DIRECTIONS:
                raise ValueError(f"directions: must be 'x' or 'y', got {d!r}")
        deltas = phase_shifts(shifts)
        mon = self.scene.monitor
        black, white = mon.black_level, mon.white_level
        nw, nd = len(widths), len(directions)
        coords = {"x": np.arange(mon.width, dtype=np.float64), "y": np.arange(mon.height, dtype=np.float64)}
        linear = mon.is_linear
        continuous = mon.pixel_model == "continuous"
        # Build the per-direction work lists: each entry is a profile table (nearest) or a
        # frequency (continuous).
        per_dir: dict[str, list] = {"x": [], "y": []}
        cv_info = None
        h, w_ = self.shape
        images = np.empty((nd, nw, len(deltas), h, w_), np.float32)
        # Column offsets of each direction's block.
        n_u = sum(1 for d in directions if d == "x")
        per_width = (2 if linear else len(deltas)) if not continuous else 2 * (1 if linear else GAMMA_HARMONICS)
        base = {"x": kb.OUT_FIRST, "y": kb.OUT_FIRST + n_u * nw * per_width}
        fused = None
        if linear:  # normalisation, sums and shifted images finished tile by tile
            sums = np.empty((nd, nw, h, w_), np.complex128)
            cols = [base[d] + wi * per_width for d in directions for wi in range(nw)]
            fused = FringeFinish(self, images, sums, cols, deltas, black, white)
        if not continuous:
            for d in directions:
                c = coords[d]
                for w in widths:
                    # the phase of c mod P: the same bytes in every period (a level on a
                    # drive step's edge rounds alike in each; control.profile_terms)
                    ph = 2 * np.pi * np.mod(c, w) / w
                    if linear:
                        per_dir[d] += [np.cos(ph), np.sin(ph)]
                    else:
                        for delta in deltas:
                            per_dir[d].append(mon.luminance(0.5 + 0.5 * np.cos(ph + delta)))
            tu = np.array(per_dir["x"]).reshape(-1, mon.width)
            tv = np.array(per_dir["y"]).reshape(-1, mon.height)
            ncols = kb.OUT_FIRST + tu.shape[0] + tv.shape[0]
            if control.applies(self):  # the Gauss rule + rqmc of the staircase residual
                out, cv_err, cv_stated, cv_info = control.render_fringes_cv(
                    self, directions, widths, deltas, linear, tu, tv, progress)
                err = None
            else:
                out, err = self._render(kb.MODE_TABLES, ncols, smooth=self.fringes_smooth(),
                                        table_u=tu, table_v=tv, progress=progress,
                                        **({} if fused is None else fused.kw(kb.MODE_TABLES, ncols)))
        else:
            harm = 1 if linear else GAMMA_HARMONICS
            for d in directions:
                for w in widths:
                    per_dir[d] += [2 * np.pi * m / w for m in range(1, harm + 1)]
            ku, kv = np.array(per_dir["x"]), np.array(per_dir["y"])
            ncols = kb.OUT_FIRST + 2 * (ku.size + kv.size)
            out, err = self._render(kb.MODE_HARMONIC, ncols, smooth=self.fringes_smooth(),
                                    k_u=ku, k_v=kv, progress=progress,
                                    **({} if fused is None else fused.kw(kb.MODE_HARMONIC, ncols)))

        if linear:  # the rows no tile finished (another scheduler, several passes): here
            norm, f_total, f_hit = fused.complete(out)
        else:
            sums = None
            norm = self._normalise(out)
            f_total = out[..., kb.OUT_FTOTAL] * norm
            f_hit = out[..., kb.OUT_FHIT] * norm
        if not linear and continuous:  # g(theta) = sum_m coef_m cos(m theta)
            coef, g = control.response_series(mon)
        sums_err = convergence = stated = None
        info = self.describe_sampling(self.fringes_smooth())
        if cv_info is not None:  # the control variate's error of every fringe sum
            info, stated = cv_info, cv_stated
            if linear:
                sums_err = cv_err * np.abs(norm)
        if linear and err is not None:  # the error of every normalised complex sum
            tiled = isinstance(err, TileErrors)  # computed in the render's tiles
            diffs = () if tiled else err if isinstance(err, tuple) else (err,)
            kexp = (convergence_exponent(tuple(info["order"]), info["kind"])
                    if (err.n_diffs if tiled else len(diffs)) > 1 else None)
            if tiled:
                sums_err, ratios = err.err, (err.ratio, err.rel) if kexp is not None else None
            else:
                sums_err, ratios = fringe_errors(diffs, cols, norm, sums.reshape(nd * nw, h, w_),
                                                 kexp is not None, self.num_workers)
            sums_err = sums_err.reshape(nd, nw, h, w_)
            if kexp is not None:  # the observed convergence from the second embedded rule
                convergence = convergence_of_ratios(ratios[0].reshape(nd, nw, -1),
                                                    ratios[1].reshape(nd, nw, -1), kexp)
                info["convergence"] = [[round(float(c), 6) for c in r] for r in convergence]
            del ratios
            del diffs, err
        for di, d in enumerate(directions if not linear else ()):
            for wi in range(nw):
                col = base[d] + wi * per_width
                if not continuous:
                    for k in range(len(deltas)):
                        images[di, wi, k] = out[..., col + k] * norm
                else:
                    zs = [(out[..., col + 2 * m] + 1j * out[..., col + 2 * m + 1]) * norm
                          for m in range(GAMMA_HARMONICS)]
                    for k, delta in enumerate(deltas):
                        acc = coef[0] * f_hit
                        for m, z in enumerate(zs, start=1):
                            acc = acc + coef[m] * (z * np.exp(1j * m * delta)).real
                        # the truncated series of a steep (quantised) response rings past
                        # the display's range; a weighted mean of luminances cannot: clip
                        # to [min, max] luminance x the weight on the monitor (never < 0)
                        images[di, wi, k] = np.clip(acc, g.min() * f_hit, g.max() * f_hit)
        return FringeResult(directions, widths, deltas, images, sums, f_total, f_hit, sums_err,
                            info, convergence, stated)

    def render_images(self, levels: np.ndarray, progress: ProgressFn | None = None,
                      with_error: bool = False):
        """Camera images (Q, H, W) float32 of monitor images ``levels`` (Q, Hm, Wm) in [0, 1].

        The monitor shows each level as luminance (gamma, black/white); each monitor pixel is
        a flat square emitter (the ray takes the value of the pixel it lands in).
        ``with_error``: (images, their numerical error (Q, H, W) float32 or None): the
        ``rqmc`` replicates' ``t(0.975, R - 1) s / sqrt(R)`` per value (the default ``rule``
        renders ``rqmc`` here: the monitor's pixels make the integrand a step function;
        :func:`~pmdsim.render.results.value_error`); None for modes without an error.
        """
        levels = np.asarray(levels)
        if levels.ndim == 2:
            levels = levels[None]
        mon = self.scene.monitor
        if levels.shape[1:] != mon.shape:
            raise ValueError(
                f"levels: monitor images must be (Q, {mon.height}, {mon.width}), got {levels.shape}"
            )
        lum = np.ascontiguousarray(mon.luminance(levels), dtype=np.float32)
        out, err = self._render(kb.MODE_IMAGES, kb.OUT_FIRST + lum.shape[0], smooth=False,
                                images=lum, progress=progress)
        norm = self._normalise(out)
        vals = out[..., kb.OUT_FIRST:] * norm[..., None]
        images = np.moveaxis(vals, -1, 0).astype(np.float32)
        if not with_error:
            return images
        e = value_error(err, slice(kb.OUT_FIRST, None), norm, vals, self._ratio_col())
        return images, None if e is None else np.moveaxis(e, -1, 0).astype(np.float32)

    def _ratio_col(self) -> int | None:
        """The f_total column when the estimator is a ratio (``weighted_mean``)."""
        return kb.OUT_FTOTAL if self.scene.estimator == "weighted_mean" else None

    def render_dots(self, dots: Sequence[Dot], progress: ProgressFn | None = None,
                    with_error: bool = False):
        """Camera images (Q, H, W) float32 of white square dots on a black monitor;
        ``with_error``: (images, their numerical error (Q, H, W) or None), as
        :meth:`render_images`."""
        if len(dots) == 0:
            raise ValueError("dots: give at least one dot")
        rows = np.array([d.as_row() for d in dots])
        mon = self.scene.monitor
        out, err = self._render(kb.MODE_DOTS, kb.OUT_FIRST + len(dots), smooth=False, dots=rows,
                                progress=progress)
        norm = self._normalise(out)
        hit = out[..., kb.OUT_FIRST:]
        lum = mon.black_level * out[..., kb.OUT_FHIT][..., None] + (mon.white_level - mon.black_level) * hit
        vals = lum * norm[..., None]
        images = np.moveaxis(vals, -1, 0).astype(np.float32)
        if not with_error:
            return images
        e = value_error(err, slice(kb.OUT_FIRST, None), norm, vals, self._ratio_col())
        if e is not None:  # luminance: black x f_hit + (white - black) x the dot's hits
            e = abs(mon.white_level - mon.black_level) * e + abs(mon.black_level) * value_error(
                err, slice(kb.OUT_FHIT, kb.OUT_FHIT + 1), norm)
        return images, None if e is None else np.moveaxis(e, -1, 0).astype(np.float32)

    def transport(self, rows: Sequence[int], cols: Sequence[int], directions: bool = True,
                  totals: bool = False):
        """The scattered rays of selected pixels (``directions=False``: without the world
        directions, returned as None; the other results are the same; ``totals``: a sixth
        result, (P,) the weight of every pixel's rays, those that miss the monitor included,
        as the render's ``f_total``).

        Returns
        -------
        u, v : (P, R) float64
            Monitor coordinates (monitor px) of every ray; NaN where it misses the monitor.
        weight : (P, R) float64
            Weight of every ray that hits the monitor (0 for misses): the BRDF value f for
            the cone estimators, ``f cos(theta_o) / pdf`` for ``radiometric``.
        directions : (P, R, 3) float64
            World unit directions of the rays.
        origin : (P, 3) float64
            Hit point on the surface (mm).
        """
        scene = self.scene
        rows = np.atleast_1d(np.asarray(rows, int))
        cols = np.atleast_1d(np.asarray(cols, int))
        hits = trace_pixels(scene, rows, cols)
        geo = bundle_geometry(scene, hits)
        samp = scene.sampling
        lobe = self._lobe
        if not (lobe or scene.brdf.is_delta):  # as the render (:meth:`_render_brdf`)
            samp.orient(geo, scene.brdf.kernel_params())
        if scene.brdf.is_delta:
            u1 = u2 = np.zeros(0)
            local = np.array([[0.0, 0.0, 1.0]])
            rot = np.zeros((0, 2))
        else:
            u1, u2 = samp.lobe_unit_points() if lobe else samp.unit_points()
            rot = np.zeros((0, 2))
            if samp.mode == "random":  # one draw per camera row (the render's streams)
                by_row = {r: samp.rotations(r, r + 1, scene.camera.width)
                          for r in np.unique(rows).tolist()}
                rot = np.stack([by_row[int(r)][int(c)] for r, c in zip(rows, cols)])
        principal = scene.brdf.is_delta or samp.include_principal
        n = u1.size + 1 if principal and not lobe else u1.size
        w_ray = np.ones(1) if scene.brdf.is_delta else samp.ray_weights(lobe)
        ou, ov, of = (np.empty((len(rows), n)) for _ in range(3))
        out = np.empty((len(rows), kb.OUT_FIRST))
        args = (np.array(scene.monitor.shape, np.int64), kb.MODE_TRANSPORT,
                np.zeros((0, 1)), np.zeros((0, 1)), np.zeros(0), np.zeros(0),
                np.zeros((0, 1, 1), np.float32), np.zeros((0, 4)), out, ou, ov, of)
        px = None
        if scene.brdf_variation is not None and not scene.brdf.is_delta:
            px = scene.brdf_variation.geometry_params(geo, scene.monitor, scene.brdf.kernel_params())
            args = args + (None, px)  # transport renders without the display model, as below
        if lobe:
            kb.render_tile_lobe(geo, scene.brdf.kernel_params(), u1, u2, rot, *args, w_ray=w_ray)
        else:
            kb.render_tile(geo, scene.brdf.kernel_params(), u1, u2, rot, samp.scheme_id,
                           samp.theta_max, principal, *args, w_ray=w_ray)
        extra = (out[:, kb.OUT_FTOTAL].copy(),) if totals else ()
        if not directions:
            return (ou, ov, of, None, hits.point[0].copy()) + extra
        dirs = np.empty((len(rows), n, 3))
        origin = np.empty((len(rows), 3))
        for p in range(len(rows)):
            origin[p] = hits.point[0, p]
            frame = (hits.x_axis[0, p], hits.y_axis[0, p], hits.normal[0, p])
            if lobe:
                i_loc = np.array([hits.to_camera[0, p] @ b for b in frame])
                off = rot[p] if rot.shape[0] else (0.0, 0.0)
                model = scene.brdf if px is None else with_params(scene.brdf, *px[p])
                loc = model.sample(np.mod(u1 + off[0], 1.0), np.mod(u2 + off[1], 1.0), i_loc)
                e1, e2, e3 = frame
            else:
                # the cone basis the kernel traced: the geometry rows' (turned about P where
                # the rule's azimuths follow the lobe, ``samp.orient``), in world axes
                e1, e2, e3 = (geo[p, kb.G_X + k] * frame[0] + geo[p, kb.G_Y + k] * frame[1]
                              + geo[p, kb.G_Z + k] * frame[2] for k in (1, 2, 3))
                if scene.brdf.is_delta:
                    loc = local
                else:
                    off = tuple(rot[p]) if rot.shape[0] else (0.0, 0.0)
                    loc = samp.local_directions(off)
            dirs[p] = loc[:, :1] * e1 + loc[:, 1:2] * e2 + loc[:, 2:3] * e3
        return (ou, ov, of, dirs, origin) + extra

