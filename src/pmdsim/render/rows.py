"""Per-pixel geometry rows of the vision rays for the bundle kernels, the reduction of a
pixel's sub-ray sums (moved from :mod:`pmdsim.render.simulation`, which re-exports them), and
the fringes' finishing step run in the render's tile tasks (:class:`FringeFinish`)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ..kernels import bundle as kb
from ..kernels import primary as kprim
from ..kernels.synth import fringe_error_rows, fringe_rows, replicate_update_rows
from ..scene import Scene


def local_scheduler(name: str):
    """Dask's in-process scheduler ``name`` ("threads" or "synchronous") as its ``get``
    function, to pass as ``scheduler=``: a name makes Dask import ``distributed`` (when it
    is installed) to look for an active client, 0.25 s of a run's start-up for nothing.
    Other names are returned as they are."""
    if name == "threads":
        from dask.threaded import get

        return get
    if name == "synchronous":
        from dask.local import get_sync

        return get_sync
    return name


#: The second embedded rule of a rule's error estimate enters nothing but medians over each
#: fringe's pixels (the observed convergence, :func:`pmdsim.render.results.
#: convergence_of_ratios`): where a grid of every 2nd (4th) camera row and column still
#: holds this many pixels, it is rendered on that grid alone (:func:`convergence_stride`).
#: Fig. 3 (1.3 MP): every 4th, 81,920 pixels, 1/16 of the pass's rays (it was 14 % of the
#: render's); the factors moved by 0.02-0.6 % of themselves against all pixels.
CONVERGENCE_GRID_PIXELS = 65536


def convergence_stride(sampling, camera) -> int:
    """The grid step (1, 2 or 4 camera px) of the pixels a render of ``sampling`` traces:
    1 but for the second embedded rule (``mode`` "rule", ``part`` 2) on a pinhole camera of
    at least ``s^2`` :data:`CONVERGENCE_GRID_PIXELS` pixels, then the largest such ``s``;
    the other pixels of that pass are left out (:func:`keep_grid`: NaN, no rays). Cameras
    with sub-rays per pixel (a lens, a footprint) render it on every pixel."""
    if (getattr(sampling, "mode", None) != "rule" or getattr(sampling, "part", 0) != 2
            or not camera.is_simple_pinhole):
        return 1
    n = camera.width * camera.height
    return next((s for s in (4, 2) if n >= s * s * CONVERGENCE_GRID_PIXELS), 1)


def keep_grid(geo, r0: int, r1: int, width: int, stride: int) -> None:
    """Mark the geometry rows ``geo`` of camera rows ``r0:r1`` (``width`` pixels each)
    invalid (``G_VALID = 0``: the kernels trace no ray there and write NaN) but for the
    pixels whose row and column are multiples of ``stride``: the same pixels, whatever
    the tiling."""
    if stride <= 1:
        return
    off = ((np.arange(r0, r1) % stride != 0)[:, None]
           | (np.arange(width) % stride != 0)[None, :]).ravel()
    geo[off, kb.G_VALID] = 0.0


def grid_share(mask, stride: int) -> float:
    """The share of the pixels of ``mask`` (H, W) (surface pixels) on the grid of
    ``stride``: what a pass of that stride traces of a full pass."""
    if stride <= 1:
        return 1.0
    total = int(np.count_nonzero(mask))
    return int(np.count_nonzero(mask[::stride, ::stride])) / total if total else 0.0


def scene_geometry_rows(scene: Scene, row0: int, row1: int, buffers=None):
    """Compiled vision-ray trace of camera rows ``row0:row1``, one pinhole ray per pixel
    centre (cameras with sub-pixels, a lens or distortion: :func:`vision_geometry_rows`).

    Returns the bundle geometry rows ((row1-row0)*W, G_SIZE) and the exact monitor
    coordinates of P ((row1-row0)*W, 2), NaN where P misses the monitor. ``buffers``:
    optional (geo, spec) arrays of at least that many rows to write into (the returned
    arrays are their leading rows), so that a tile loop reuses one allocation.
    """
    if not scene.camera.is_simple_pinhole:
        rows, cols = np.mgrid[row0:row1, 0 : scene.camera.width]
        o, d = scene.camera.chief_rays(rows.ravel(), cols.ravel())
        return _rays_geometry(scene, o, d)
    n = (row1 - row0) * scene.camera.width
    if buffers is not None and buffers[0].shape[0] >= n:
        geo, spec = buffers[0][:n], buffers[1][:n]
    else:
        geo = np.empty((n, kb.G_SIZE))
        spec = np.empty((n, 2))
    kprim.geometry_tile(
        scene.camera.kernel_params(), scene.surface.kernel_params(),
        scene.anisotropy.kernel_params(), scene.monitor.kernel_params(),
        row0, row1, scene.camera.width, geo, spec,
    )
    return geo, spec

def _rays_geometry(scene: Scene, origins, dirs):
    n = origins.shape[0]
    geo = np.empty((n, kb.G_SIZE))
    spec = np.empty((n, 2))
    kprim.geometry_rays(
        np.ascontiguousarray(origins, np.float64), np.ascontiguousarray(dirs, np.float64),
        scene.surface.kernel_params(), scene.anisotropy.kernel_params(),
        scene.monitor.kernel_params(), geo, spec,
    )
    return geo, spec


def vision_geometry_rows(scene: Scene, row: int):
    """Geometry rows (W * S, G_SIZE) and exact monitor hits (W * S, 2) of the S vision rays
    (sub-pixels x aperture samples, :meth:`pmdsim.scene.Camera.vision_rays`) of every pixel
    of camera row ``row``, pixel-major."""
    cam = scene.camera
    w = cam.width
    if cam.telecentric:  # parallel rays from the entrance plane: explicit rays
        o, d = cam.vision_rays(np.full(w, row), np.arange(w))
        return _rays_geometry(scene, o.reshape(-1, 3), d.reshape(-1, 3))
    chief, aperture, focus = cam.lens_inputs(np.full(w, row), np.arange(w))
    n = w * cam.rays_per_pixel
    geo = np.empty((n, kb.G_SIZE))
    spec = np.empty((n, 2))
    kprim.geometry_lens(
        cam.position, np.ascontiguousarray(cam.rotation), chief, aperture, focus,
        scene.surface.kernel_params(), scene.anisotropy.kernel_params(),
        scene.monitor.kernel_params(), geo, spec,
    )
    return geo, spec


def reduce_subrays(out: np.ndarray, estimator: str) -> np.ndarray:
    """Pixel sums (P, C) from the kernel sums of their S vision rays (P, S, C).

    A pixel integrates radiance over its footprint and the aperture: its value is the mean
    over its S rays of each ray's estimate. The ``paper`` and ``radiometric`` estimators
    share the factor 1/N, so the raw sums are averaged; ``weighted_mean`` normalises every
    ray by its own sum of weights first (the pixel's ``OUT_FTOTAL`` becomes 1). Rays that
    miss the surface (NaN) see a black background; a pixel none of whose rays hits is NaN.
    """
    s = out.shape[1]
    ft = out[..., kb.OUT_FTOTAL]
    hit = np.isfinite(ft)
    if estimator == "weighted_mean":
        hit &= ft > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            out = out / ft[..., None]
    elif not hit.all():
        out = out.copy()
    out[~hit] = 0.0  # a ray that misses the surface sees black
    summed = out.sum(axis=1) / s
    if estimator == "weighted_mean":
        summed[:, kb.OUT_FTOTAL] = 1.0
    summed[~hit.any(axis=1)] = np.nan
    return summed


class FringeFinish:
    """The linear fringes' estimator values, finished tile by tile inside the render.

    ``Simulation._render_brdf`` calls the instance (``finish=``, :meth:`kw`) in each tile's
    task right after the bundle kernel wrote the tile's rows, while they are in cache:
    :func:`~pmdsim.kernels.synth.fringe_rows` writes the normalisation, f_total, f_hit, the
    normalised complex sums ``sums`` (B blocks, (direction, width) order) and the shifted
    ``images`` (B, K) of those rows. Only in the pass that is the render's result
    (``Simulation.result_pass``: one pass, or mode ``rule``, whose embedded passes only
    give the error; no specular peak, whose mirror pass is added after the tiles);
    :meth:`complete` finishes whatever rows no tile did (another scheduler, the mean of
    rqmc replicates).
    """

    def __init__(self, sim, images, sums, cols, deltas, black: float, white: float):
        h, w = sim.shape
        self.sampling = sim.result_pass(sim.fringes_smooth())
        self.shape = (h, w)
        self.workers = sim.num_workers
        self.ratio = sim.scene.estimator == "weighted_mean"
        self.inv_n = 1.0 / sim.scene.rays_per_pixel
        self.norm, self.f_total, self.f_hit = (np.empty((h, w)) for _ in range(3))
        nb, nk = len(cols), len(deltas)
        self.sums = sums.reshape(nb, h * w)
        self.images = images.reshape(nb, nk, h * w)
        self.cols = np.asarray(cols, np.int64)
        self.cos_d, self.sin_d = np.cos(deltas), np.sin(deltas)
        self.black, self.white = float(black), float(white)
        self.done: list = []  # (sums array, rows) per finished tile (list.append: atomic)
        self.tile_errors: TileErrors | None = None

    def kw(self, mode: int, ncols: int) -> dict:
        """The ``finish`` keyword of the render of ``mode`` into ``ncols`` columns (empty
        when the tiles cannot finish)."""
        return {} if self.sampling is None else {"finish": (self.sampling, mode, ncols, self)}

    def __call__(self, r0: int, r1: int, full: np.ndarray, raw: np.ndarray | None = None
                 ) -> None:
        """Finish rows ``r0:r1`` of the render's result ``full`` (H, W, C), from ``raw``
        ((r1 - r0) * W, C) where the tile kept its raw sums elsewhere (``full`` then an
        empty token), and count them as finished for ``full`` (:meth:`complete`)."""
        w = self.shape[1]
        if raw is None:
            raw = full.reshape(-1, full.shape[-1])[r0 * w:r1 * w]
        self.rows(r0, r1, raw)
        self.done.append((full, r1 - r0))

    def rows(self, r0: int, r1: int, raw: np.ndarray) -> None:
        """Finish rows ``r0:r1`` from their raw sums ``raw`` ((r1 - r0) * W, C)."""
        w = self.shape[1]
        p0, p1 = r0 * w, r1 * w
        fringe_rows(raw, self.cols, self.ratio, self.inv_n, self.cos_d, self.sin_d,
                    self.black, self.white, self.norm.reshape(-1)[p0:p1],
                    self.f_total.reshape(-1)[p0:p1], self.f_hit.reshape(-1)[p0:p1],
                    self.sums[:, p0:p1], self.images[:, :, p0:p1])

    def want_errors(self, second: bool) -> "TileErrors":
        """Buffers for the numerical error of the sums, filled tile by tile
        (:meth:`errors`) by :func:`render_rule_fused`; ``second``: with the inputs of the
        observed convergence (a second embedded rule)."""
        nb, (h, w) = len(self.cols), self.shape
        ratio = np.empty((nb, h * w)) if second else np.empty((nb, 0))
        self.tile_errors = TileErrors(np.empty((nb, h, w), np.complex128), ratio,
                                      np.empty_like(ratio), 2 if second else 1)
        return self.tile_errors

    def errors(self, r0: int, r1: int, diffs) -> None:
        """The error of rows ``r0:r1`` from their differences to the embedded rules
        (``diffs``, (rows * W, C) each), after :meth:`__call__` finished those rows: what
        :func:`fringe_errors` computes for them, in the tile's task."""
        w, te = self.shape[1], self.tile_errors
        p0, p1 = r0 * w, r1 * w
        second = te.n_diffs > 1
        fringe_error_rows(diffs[0], diffs[1] if second else np.zeros((0, 0)), self.cols,
                          self.norm.reshape(-1)[p0:p1], self.sums[:, p0:p1],
                          te.err.reshape(len(self.cols), -1)[:, p0:p1],
                          te.ratio[:, p0:p1] if second else te.ratio,
                          te.rel[:, p0:p1] if second else te.rel)

    def complete(self, out: np.ndarray):
        """Finish from the render's result ``out`` (H, W, C) unless its tiles did; returns
        (norm, f_total, f_hit), each (H, W)."""
        h = self.shape[0]
        if sum(n for a, n in self.done if a is out) != h:
            from concurrent.futures import ThreadPoolExecutor

            step = max(1, -(-h // 32))
            with ThreadPoolExecutor(self.workers) as pool:  # the kernel releases the GIL
                list(pool.map(lambda r: self(r, min(r + step, h), out), range(0, h, step)))
        self.done.clear()
        return self.norm, self.f_total, self.f_hit


def fringe_errors(diffs, cols, norm, sums, second: bool, workers=None):
    """The numerical error of the normalised complex sums (B, H, W) complex128 from the
    render's differences to the embedded rules ``diffs`` ((H, W, C) each), and with
    ``second`` the per-pixel inputs of the observed convergence ``(|dS1| / |dS2|,
    |dS1| / |S|)`` (B, H*W) each (:func:`pmdsim.render.results.convergence_of_ratios`), else
    None: one compiled pass over the differences (:func:`~pmdsim.kernels.synth.
    fringe_error_rows`) in row blocks on a thread pool."""
    from concurrent.futures import ThreadPoolExecutor

    h, w = norm.shape
    nb = len(cols)
    cols = np.asarray(cols, np.int64)
    err = np.empty((nb, h, w), np.complex128)
    ratio = np.empty((nb, h * w)) if second else np.empty((nb, 0))
    rel = np.empty_like(ratio)
    d1 = diffs[0].reshape(h * w, -1)
    d2 = diffs[1].reshape(h * w, -1) if second else np.zeros((0, 0))
    e2, s2, nf = err.reshape(nb, -1), sums.reshape(nb, -1), norm.reshape(-1)
    step = max(1, -(-h // 32)) * w

    def block(p0):
        p1 = min(p0 + step, h * w)
        fringe_error_rows(d1[p0:p1], d2[p0:p1] if second else d2, cols, nf[p0:p1],
                          s2[:, p0:p1], e2[:, p0:p1], ratio[:, p0:p1] if second else ratio,
                          rel[:, p0:p1] if second else rel)

    with ThreadPoolExecutor(workers) as pool:  # the kernel releases the GIL
        list(pool.map(block, range(0, h * w, step)))
    return err, ((ratio, rel) if second else None)


@dataclass(frozen=True)
class TileErrors:
    """The numerical error of the normalised complex sums (B, H, W) and the inputs of the
    observed convergence ((B, H*W) each, empty without a second embedded rule), computed
    tile by tile inside the render (:func:`render_rule_fused`): what :func:`fringe_errors`
    returns, and the number of embedded rules they came from."""

    err: np.ndarray
    ratio: np.ndarray
    rel: np.ndarray
    n_diffs: int


def _fusable(sim) -> bool:
    """Whether a render's passes can share each tile's task: an in-process scheduler
    (one array the tiles write into), pinhole camera rays (one geometry row per pixel),
    no specular peak (its mirror pass is added after the tiles) and one BRDF for the
    whole part."""
    from .specular import specular_reflectance

    scene = sim.scene
    return (sim.scheduler in ("threads", "synchronous") and scene.camera.is_simple_pinhole
            and not scene.brdf.is_delta and specular_reflectance(scene.brdf) == 0
            and scene.brdf_variation is None)


def fuses(sim, passes, mode: int, ncols: int, finish) -> bool:
    """Whether :func:`render_rule_fused` renders this rule with its embedded rules
    (:func:`_fusable`): tiles that finish the rule's linear fringes (``finish`` of that
    sample set, mode and columns) and one orientation of the cone bases for every pass."""
    return (finish is not None and len(passes) > 1 and passes[0].mode == "rule"
            and tuple(finish[:3]) == (passes[0], mode, ncols)
            and len({p.phi_rho is None for p in passes}) == 1 and _fusable(sim))


def render_rule_fused(sim, passes, mode: int, ncols: int, finish, progress=None,
                      patterns=None):
    """The linear fringes of the rule ``passes[0]`` (finished into ``finish``'s
    :class:`FringeFinish`) and their numerical error, with every embedded rule
    ``passes[1:]`` rendered in the same tile task: the tile's geometry rows are traced
    and turned onto the lobe's axis once, the rule's rows finished
    (:class:`FringeFinish`), each embedded rule's rows rendered into a buffer of the
    worker thread and differenced in place, and the error of those rows computed
    (:meth:`FringeFinish.errors`) while they are in cache. The same bytes as rendering the
    passes one after another (:meth:`pmdsim.render.Simulation._render`) and
    :func:`fringe_errors` over the whole differences, without the (H, W, ncols) arrays of
    the embedded passes, nor the rule's own: its raw sums live in a buffer of the worker
    thread too, as only their finished values (:class:`FringeFinish`) are kept. Returns
    ``(token, TileErrors)``, the token an empty (H, W, 0) array that
    :meth:`FringeFinish.complete` recognises as finished; :func:`fuses` says when it
    applies."""
    fin = finish[3]
    patterns = patterns or {}
    scenes = [sim.scene.replace(sampling=p) for p in passes]
    kernels = [sim._kernel(sc, mode, ncols, orient=False, **patterns) for sc in scenes]
    strides = [convergence_stride(p, sim.scene.camera) for p in passes]
    if any(s > 1 for s in strides[:-1]):  # keep_grid leaves invalid rows for later passes
        raise AssertionError("only the last pass may be rendered on a grid")
    brdf = sim.scene.brdf.kernel_params()
    h, w = sim.shape
    token = np.empty((h, w, 0))
    errors = fin.want_errors(len(passes) > 2)
    local = threading.local()
    tile_px = sim.tile_rows * w

    def tile(r0, r1):
        if not hasattr(local, "buffers"):  # per worker thread, reused across its tiles
            local.buffers = (np.empty((tile_px, kb.G_SIZE)), np.empty((tile_px, 2)),
                             [np.empty((tile_px, ncols)) for _ in passes])
        geo_buf, spec_buf, raw = local.buffers
        geo, _ = scene_geometry_rows(scenes[0], r0, r1, (geo_buf, spec_buf))
        if not sim._lobe:  # the cone rules' phi = 0 on the lobe's axis (once for all passes)
            passes[0].orient(geo, brdf)
        rot = np.zeros((0, 2))
        out = raw[0][: geo.shape[0]]
        kernels[0](geo, rot, out)
        fin(r0, r1, token, out)
        diffs = []
        for kernel, buf, stride in zip(kernels[1:], raw[1:], strides[1:]):
            c = buf[: out.shape[0]]
            keep_grid(geo, r0, r1, w, stride)  # the last pass: nothing reads geo after it
            kernel(geo, rot, c)
            diffs.append(np.subtract(out, c, out=c))
        fin.errors(r0, r1, diffs)

    sim._compute(tile, sim._tiles(), progress)
    return token, errors


def fuses_replicates(sim, reps) -> bool:
    """Whether :func:`replicates_fused` renders the control variate's rqmc replicates
    ``reps`` (:func:`_fusable`): at least one, none whose cone bases need turning (rqmc
    sets do not follow the lobe)."""
    return len(reps) > 0 and all(rep.phi_rho is None for rep in reps) and _fusable(sim)


def replicates_fused(sim, reps, lay, box: bool, table_u, table_v, progress=None):
    """The nearest monitor's control variate (:func:`pmdsim.render.control.
    render_fringes_cv`): every rqmc replicate of ``reps`` rendered in each tile's task,
    the tile's geometry traced once, its residual (the profile tables less the smooth
    fringe at the same points, or with ``box`` the residual tables alone) and the
    replicates' running means and sums of squares (Welford, replicate by replicate as
    the whole-camera loop does) updated for those rows while they are in cache. Returns
    ``(mean_res (H, W, ncols_t), mean_s, m2_re, m2_im)`` ((nd, nw, H, W) each): the same
    bytes as the loop over whole-camera renders, without its whole-camera temporaries.
    ``lay`` is the control variate's column layout (``_Layout``)."""
    h, w = sim.shape
    nd, nw = len(lay.directions), len(lay.widths)
    scenes = [sim.scene.replace(sampling=rep) for rep in reps]
    tables = [sim._kernel(sc, kb.MODE_TABLES, lay.ncols_t, table_u=table_u,
                          table_v=table_v, orient=False) for sc in scenes]
    smooth = [None if box else sim._kernel(sc, kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u,
                                            k_v=lay.k_v, orient=False) for sc in scenes]
    mean_res = np.zeros((h, w, lay.ncols_t))
    mean_s = np.empty((nd, nw, h, w), np.complex128)
    m2_re, m2_im = np.zeros((nd, nw, h, w)), np.zeros((nd, nw, h, w))
    local = threading.local()
    tile_px = sim.tile_rows * w
    # a linear display: the residual, its mean and the sums' Welford update in one
    # compiled pass per replicate (replicate_update_rows), the same bytes as the NumPy below
    # (its box rule leaves no replicates)
    compiled = lay.linear and not box
    tcols = np.array([f[2] for f in lay.fringes], np.int64)
    hcols = np.array([f[3] for f in lay.fringes], np.int64)

    def tile(r0, r1):
        if not hasattr(local, "buffers"):  # per worker thread, reused across its tiles
            local.buffers = (np.empty((tile_px, kb.G_SIZE)), np.empty((tile_px, 2)),
                             np.empty((tile_px, lay.ncols_t)), np.empty((tile_px, lay.ncols_h)))
        geo_buf, spec_buf, t_buf, h_buf = local.buffers
        geo, _ = scene_geometry_rows(scenes[0], r0, r1, (geo_buf, spec_buf))
        n = geo.shape[0]
        mr = mean_res[r0:r1].reshape(n, -1)
        ms = mean_s[:, :, r0:r1].reshape(nd, nw, n)
        q_re = m2_re[:, :, r0:r1].reshape(nd, nw, n)
        q_im = m2_im[:, :, r0:r1].reshape(nd, nw, n)
        rot = np.zeros((0, 2))
        for r, (kt, kh) in enumerate(zip(tables, smooth)):
            t = kt(geo, rot, t_buf[:n])
            if compiled:
                replicate_update_rows(t, kh(geo, rot, h_buf[:n]), hcols, tcols, r, mr,
                                      ms.reshape(nd * nw, n), q_re.reshape(nd * nw, n),
                                      q_im.reshape(nd * nw, n))
                continue
            res = t if box else t - lay.to_tables(kh(geo, rot, h_buf[:n]))
            res[..., :kb.OUT_FIRST] = 0.0  # f_total, f_hit: the rule's
            welford_update(res, r, lay, mr, ms, q_re, q_im)

    sim._compute(tile, sim._tiles(), progress)
    return mean_res, mean_s, m2_re, m2_im


def welford_update(res, r, lay, mean_res, mean_s, m2_re, m2_im) -> None:
    """Replicate ``r`` (0: the first) of the control variate's residual ``res`` (..., C,
    table layout) into the running mean ``mean_res`` (..., C) and the Welford statistics of
    its fringe sums ``lay.fringe_sums(res)``: ``mean_s`` (nd, nw, ...) complex and the
    sums of squares ``m2_re``/``m2_im`` of their real and imaginary parts, in place (the
    tile task's rows and the whole-camera loop of :func:`pmdsim.render.control.
    render_fringes_cv` alike)."""
    mean_res += (res - mean_res) / (r + 1)
    s = lay.fringe_sums(res)
    if r == 0:
        mean_s[...] = s
        return
    d = s - mean_s
    mean_s += d / (r + 1)
    m2_re += d.real * (s - mean_s).real
    m2_im += d.imag * (s - mean_s).imag
