"""The fringes' finishing step, run in the render's tile tasks right after the bundle kernel
wrote a tile's rows (:class:`FringeFinish`): normalised sums and shifted images, and the
numerical error of the normalised complex sums (:func:`fringe_errors`, :class:`TileErrors`)."""

from __future__ import annotations
from dataclasses import dataclass
import numpy as np
from ..kernels.fringe_finish import fringe_error_rows, fringe_rows


class FringeFinish:
    """The linear fringes' estimator values, finished tile by tile inside the render.

    ``Simulation._render_brdf`` calls the instance (``finish=``, :meth:`kw`) in each tile's
    task right after the bundle kernel wrote the tile's rows, while they are in cache:
    :func:`~pmdsim.kernels.fringe_finish.fringe_rows` writes the normalisation, f_total, f_hit, the
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
    None: one compiled pass over the differences (:func:`~pmdsim.kernels.fringe_finish.
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
