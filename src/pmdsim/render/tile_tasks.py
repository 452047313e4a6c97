"""The render's tile tasks on Dask: the in-process scheduler (:func:`local_scheduler`), and
one task per tile that traces the tile's vision rays, renders a rule's passes with its
embedded rules and finishes the fringes while the rows are in cache
(:func:`render_rule_fused`), or accumulates the replicates of a randomised rule
(:func:`replicates_fused`, Welford's update)."""

from __future__ import annotations
import threading
import numpy as np
from ..kernels import bundle as kb
from ..kernels.fringe_finish import replicate_update_rows
from .geometry_rows import scene_geometry_rows
from .convergence_grid import convergence_stride, keep_grid


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
    """The nearest monitor's control variate (:func:`pmdsim.render.control_variate.
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
    tile task's rows and the whole-camera loop of :func:`pmdsim.render.control_variate.
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
