"""The numerical error of a Gauss rule measured by a pilot on a sparse grid of pixels, and
the rule's order chosen from a target by that pilot (issue 36).

A pixel's fringe sum is an integral over the lobe (docs/physics.md, "Sampling as
quadrature"); its integrand changes slowly from pixel to pixel, and so does the error of a
fixed rule. The pilot measures that error where it is cheap and carries it to every pixel:

- **grid**: one pixel in every ``s x s`` block (:func:`grid_stride`, ``s = 8``: 1/64 of the
  pixels; smaller steps only on cameras narrower than 3 blocks), rendered with the rule
  and with a finer rule of :data:`FINE_FACTOR` x the nodes (about twice the order in each
  coordinate: its error is far below the rule's where the rule converges);
- **measured error** at a grid pixel: the phase difference ``|arg(Z_rule / Z_fine)|`` of
  the quantity the decoder takes the phase of (``Z = sum_k I_k exp(-i delta_k)`` of the K
  shifted images; the complex fringe sum itself on a linear display);
- **envelope**: every pixel's statement is :data:`SAFETY` times the largest measured error
  over the 3 x 3 grid pixels around its block (the block's own and its eight neighbours':
  every pixel of the block lies between them);
- **local fallback** where the grid says nothing: pixels whose 3 x 3 grid pixels are not
  all valid (the surface's or the mask's edge, a grid pixel off the monitor): there the
  two rules are rendered at the pixel itself and the statement is :data:`SAFETY` times
  their own difference;
- **the monitor's edge**: where it cuts a lobe the integrand has a step, across which the
  rules converge only erratically (a rule and the one 4 x finer can agree to 1/30 of
  their error): such pixels are measured against rules 4 x and 16 x finer
  (:data:`CUT_MEASURED` < off share <= :data:`MAX_OFF`), or add the bound
  :func:`image_floors` of what misplacing the weight beyond the edge can do (a share below
  :data:`CUT_MEASURED`, or above :data:`MAX_OFF`, where the chain masks them);
- **floors** that do not shrink with the order, added: the images' float32 storage
  (``2^-24 sum_k |I_k| / |Z|`` per pixel: every image rounded to nearest, a bound) and the
  kernels' arithmetic (:data:`~pmdsim.render.results.ROUNDOFF_PHASE`).

Rules of fewer than :data:`MIN_NODES` nodes have no regime in which the difference to a
finer rule bounds their error (a 1-node rule and its 4-node refinement can agree by
accident): their phase is stated as known to within pi, with a warning naming
``sampling.n_rays``.

The order from a target, by the pilot's statement on its grid: :mod:`pmdsim.render.order`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..kernels import bundle as kb
from ..kernels.fringe_finish import add_phase_floors, fill_blocks, phase_floor_rows
from .results import MAX_OFF, ROUNDOFF_PHASE, in_blocks
from .geometry_rows import reduce_subrays, scene_geometry_rows, vision_geometry_rows

#: Grid step (camera px): one pilot pixel in every ``GRID_STRIDE^2`` (1/64).
GRID_STRIDE = 8
#: The finer rule's nodes per node of the rule (about twice the order in each coordinate).
FINE_FACTOR = 4
#: Safety factor on the envelope of the measured error (validated by
#: tests/render/test_pilot.py: >= 95 % of pixels bounded, median stated / true <= 5).
SAFETY = 2.0
#: Safety factor on the error's signed pattern (:meth:`Pilot.signed_field`) where a
#: statistic takes its error from it (the areal parameters' Ssk, Sku, Sdq and the PSDs of
#: a run's surface errors): validated by tests/render/test_pilot.py (every statistic within
#: its error of a 4 x finer run, N = 16 ... 4096).
PATTERN_SAFETY = 2.0
#: Where the monitor's edge cuts a lobe, a share of its weight above this off the monitor
#: (and at most :data:`~pmdsim.render.results.MAX_OFF`, beyond which the chain masks
#: a pixel) is measured at the pixel against rules 4 x and 16 x
#: finer (a rule and the one 4 x finer can agree to 1/30 of their error across the step;
#: the one 16 x finer did not); below it, and above :data:`MAX_OFF`, the analytic
#: :func:`image_floors` is added.
CUT_MEASURED = 1e-6
#: Rules below this many nodes state no error (pi: the phase is known to within pi).
MIN_NODES = 16
#: Relative rounding of a float32 image value (round to nearest).
F32_EPS = 2.0**-24


class Cancelled(Exception):
    """A pilot stopped from outside (:attr:`Pilot.cancel`) before its next probe."""


def grid_stride(shape) -> int:
    """The grid step of a camera ``shape`` (H, W): :data:`GRID_STRIDE`, halved until the
    camera holds at least 3 blocks each way."""
    h, w = shape
    s = GRID_STRIDE
    while s > 1 and (h < 3 * s or w < 3 * s):
        s //= 2
    return s


def grid_nodes(n: int, s: int) -> np.ndarray:
    """The pilot pixels' coordinates along an axis of ``n`` px: the centre of every block
    of ``s`` (the last block's within the camera)."""
    return np.minimum(np.arange(0, n, s) + s // 2, n - 1)


@dataclass
class Layout:
    """What a fringe render's columns hold (the continuous monitor's harmonic layout):
    ``cols`` the first column of each fringe (direction, width) block; ``harm`` harmonic
    pairs per fringe (1 on a linear display); ``coef``/``g`` the display response's cosine
    series and samples (non-linear displays), ``deltas`` the phase shifts."""

    cols: np.ndarray
    linear: bool
    deltas: np.ndarray
    black: float = 0.0
    white: float = 1.0
    harm: int = 1
    coef: np.ndarray | None = None
    g: np.ndarray | None = None

    @property
    def lmax(self) -> float:
        """The largest luminance the display shows (the weight's worth at most)."""
        if self.g is not None:
            return float(np.max(np.abs(self.g)))
        return float(max(abs(self.black), abs(self.white)))

    def _fringe(self, out: np.ndarray, norm: np.ndarray, f_hit: np.ndarray, b: int):
        """``(Z, images)`` of fringe ``b``: ``Z = sum_k I_k exp(-i delta_k)`` whose argument
        the decoder returns (on a linear display the fringe sum itself) and the K shifted
        images (K, P) of raw sums ``out`` (P, C) normalised by ``norm`` (P,)."""
        c = self.cols[b]
        span = self.white - self.black
        if self.linear:
            s = (out[:, c] + 1j * out[:, c + 1]) * norm
            base = (self.black + 0.5 * span) * f_hit
            return s, np.stack([base + 0.5 * span * (s * np.exp(1j * d)).real
                                for d in self.deltas])
        zs = [(out[:, c + 2 * m] + 1j * out[:, c + 2 * m + 1]) * norm for m in range(self.harm)]
        imgs = []
        for d in self.deltas:
            acc = self.coef[0] * f_hit
            for m, zm in enumerate(zs, start=1):
                acc = acc + self.coef[m] * (zm * np.exp(1j * m * d)).real
            imgs.append(np.clip(acc, self.g.min() * f_hit, self.g.max() * f_hit))
        imgs = np.stack(imgs)
        return sum(im * np.exp(-1j * d) for im, d in zip(imgs, self.deltas)), imgs

    def phasors(self, out: np.ndarray, norm: np.ndarray):
        """``(Z, mod)`` (B, P) of raw sums ``out`` (P, C) normalised by ``norm`` (P,): ``Z``
        (:meth:`_fringe`) and the fringe's modulation ``B / A`` as the decoder sees it
        (``2 |Z| / K`` over the images' mean)."""
        f_hit = out[:, kb.OUT_FHIT] * norm
        nb = len(self.cols)
        z = np.empty((nb, out.shape[0]), np.complex128)
        mod = np.empty((nb, out.shape[0]))
        k = len(self.deltas)
        with np.errstate(divide="ignore", invalid="ignore"):
            for b in range(nb):
                z[b], imgs = self._fringe(out, norm, f_hit, b)
                mean = imgs.sum(axis=0) / k
                if self.linear:  # the images' Z is (span K / 4) S
                    mod[b] = 2.0 * np.abs(0.25 * (self.white - self.black) * k * z[b]) / k / mean
                else:
                    mod[b] = 2.0 * np.abs(z[b]) / k / mean
        return z, mod

    def floors(self, out: np.ndarray, norm: np.ndarray):
        """``(floor, edge)`` (B, P) of raw sums ``out`` (P, C) normalised by ``norm`` (P,):
        the images' float32 floor (:func:`image_floor`) and the phase change per unit share
        of the lobe's weight misplaced (:func:`image_floors`)."""
        f_hit = out[:, kb.OUT_FHIT] * norm
        ftot = np.abs(out[:, kb.OUT_FTOTAL] * norm)
        nb = len(self.cols)
        floor = np.empty((nb, out.shape[0]))
        edge = np.empty((nb, out.shape[0]))
        with np.errstate(divide="ignore", invalid="ignore"):
            for b in range(nb):
                _, imgs = self._fringe(out, norm, f_hit, b)
                floor[b], edge[b] = _floor_rows(imgs, self.deltas, ftot, self.lmax)
        return floor, edge


def image_floor(images: np.ndarray, deltas) -> np.ndarray:
    """(nd, nw, H, W) rad: the phase error of the float32 storage of the shifted images
    (nd, nw, K, H, W): each value rounded to nearest, an error uniform within half its
    spacing ``u_k`` (``numpy.spacing``), independent from image to image, gives the phase
    ``arg Z`` an error of standard deviation ``sigma = sqrt(sum_k (u_k^2 / 12)
    sin^2(phi + delta_k)) / |Z|``; stated as :data:`F32_SIGMAS` sigma (compiled:
    :func:`pmdsim.kernels.fringe_finish.phase_floor_rows`)."""
    return image_floors(images, deltas, None, 0.0)[0]


#: Standard deviations of the float32 rounding stated (:func:`image_floor`): the
#: difference of two renders' roundings (independent) stays within it in >= 95 % of
#: pixels (2.8 sigma would be the normal 95 % of their difference).
F32_SIGMAS = 3.0


def _edge_weight(f_total, off) -> np.ndarray:
    """The weight a step in the integrand at the monitor's edge can misplace where a share
    ``off`` (NaN: all of it) of the lobe's weight ``f_total`` falls beyond it: twice that
    share of ``|f_total|`` (the rule's own share and the true one)."""
    return 2.0 * np.nan_to_num(np.asarray(off, np.float64), nan=1.0).clip(0.0, 1.0) * np.abs(f_total)


def image_floors(images: np.ndarray, deltas, weight, lmax: float):
    """``(floor, edge)`` (nd, nw, H, W) rad of images (nd, nw, K, H, W) in one pass:
    :func:`image_floor`, and a bound of the phase error that misplacing ``weight`` (H, W)
    of the lobe at the monitor's edge can add (:func:`_edge_weight`; None: zeros): each
    image moves by at most that weight times the display's largest luminance ``lmax``, the
    decoded ``Z = sum_k I_k exp(-i delta_k)`` by K times it."""
    nd, nw, k = images.shape[:3]
    floor = np.empty((nd, nw) + images.shape[3:])
    edge = np.empty_like(floor)
    for di in range(nd):
        for wi in range(nw):
            f, e = _floor_rows(images[di, wi].reshape(k, -1), deltas, weight, lmax)
            floor[di, wi] = f.reshape(images.shape[3:])
            edge[di, wi] = e.reshape(images.shape[3:])
    return floor, edge


def _floor_rows(imgs: np.ndarray, deltas, weight, lmax: float):
    """``(floor, edge)`` (P,) of one fringe's images (K, P) (rounded to float32 first)."""
    d = np.asarray(deltas, np.float64)
    n = imgs.shape[1]
    w = (np.zeros(n) if weight is None
         else np.ascontiguousarray(np.broadcast_to(np.asarray(weight, np.float64).reshape(-1), (n,))))
    floor, edge = np.empty(n), np.empty(n)
    phase_floor_rows(np.ascontiguousarray(imgs, np.float32), np.cos(d), np.sin(d), w, float(lmax),
                     F32_SIGMAS, floor, edge)
    return floor, edge


def render_pixels(sim, samp, rows, cols, mode, ncols, patterns, cache=None) -> np.ndarray:
    """Raw sums (P, ncols) of camera pixels ``(rows, cols)`` with sample set ``samp``: the
    same geometry rows, kernels and sub-ray reduction as the whole-camera render
    (:meth:`pmdsim.render.Simulation._render_set`), pixel by pixel (a specular peak's
    mirror pass added). ``cache``: a dict that keeps the pixels' geometry rows between
    calls for the same scene (they do not depend on the sampling or the BRDF)."""
    from .specular import add_specular, specular_reflectance

    scene = sim.scene.replace(sampling=samp)
    out = _pixels_brdf(sim, scene, rows, cols, mode, ncols, patterns, cache)
    if specular_reflectance(scene.brdf) > 0:
        mirror = _pixels_brdf(sim, scene.specular(), rows, cols, mode, ncols, patterns, cache)
        out = add_specular(out, mirror, scene.brdf, scene.estimator, scene.rays_per_pixel)
    return out


def _pixels_geometry(scene, rows, cols):
    """The geometry rows of pixels ``(rows, cols)`` (their S vision rays each, pixel-major)
    and the pixels' order in them."""
    cam = scene.camera
    simple, n_sub = cam.is_simple_pinhole, cam.rays_per_pixel
    geos, where = [], []
    for r in np.unique(rows):
        idx = np.nonzero(rows == r)[0]
        if simple:
            geo, _ = scene_geometry_rows(scene, int(r), int(r) + 1)
            geos.append(geo[cols[idx]])
        else:
            geo, _ = vision_geometry_rows(scene, int(r))
            geos.append(geo.reshape(cam.width, n_sub, -1)[cols[idx]].reshape(-1, kb.G_SIZE))
        where.append(idx)
    return np.ascontiguousarray(np.concatenate(geos)), np.concatenate(where)


def _pixels_brdf(sim, scene, rows, cols, mode, ncols, patterns, cache=None):
    cam = scene.camera
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    out = np.empty((rows.size, ncols))
    if rows.size == 0:
        return out
    kernel = sim._kernel(scene, mode, ncols, **patterns)
    simple, n_sub = cam.is_simple_pinhole, cam.rays_per_pixel
    key = (rows.tobytes(), cols.tobytes())
    if cache is not None and key in cache:
        geo, idx = cache[key]
    else:
        geo, idx = _pixels_geometry(scene, rows, cols)
        if cache is not None:
            cache[key] = (geo, idx)
    raw = np.empty((geo.shape[0], ncols))
    rot = np.zeros((0, 2))
    step = n_sub * max(1, -(-rows.size // 16))

    def block(p0, p1):
        kernel(geo[p0:p1], rot, raw[p0:p1])

    if geo.shape[0] > step:
        in_blocks(geo.shape[0], block, workers=sim.num_workers or 2)
    else:
        block(0, geo.shape[0])
    if not simple:
        raw = reduce_subrays(raw.reshape(-1, n_sub, ncols), scene.estimator)
    out[idx] = raw
    return out


def normalise(out: np.ndarray, estimator: str, n_rays: int) -> np.ndarray:
    """(P,) the estimator's normalisation of raw sums (P, C) (``Simulation._normalise``)."""
    ftot = out[:, kb.OUT_FTOTAL]
    if estimator in ("paper", "radiometric"):
        return np.full(ftot.shape, 1.0 / n_rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ftot > 0, 1.0 / ftot, np.nan)


@dataclass
class Probe:
    """One rule's phasors at the pilot pixels: ``z`` (B, P) complex, ``mod`` (B, P) the
    fringe's modulation, ``off`` (P,) the share of each lobe's weight off the monitor,
    ``nodes`` per pixel; :meth:`floors` the float32 floor and the phase change per unit
    of the lobe's weight share misplaced (B, P) each (:func:`image_floors`), computed
    when first asked (a finer rule's are never asked)."""

    z: np.ndarray
    mod: np.ndarray
    off: np.ndarray
    nodes: int
    layout: Layout
    raw: np.ndarray
    norm: np.ndarray
    _floors: tuple | None = None

    def floors(self) -> tuple[np.ndarray, np.ndarray]:
        if self._floors is None:
            self._floors = self.layout.floors(self.raw, self.norm)
        return self._floors


@dataclass
class Pilot:
    """The pilot of one render (module docstring): the grid (``stride``, node rows and
    columns), its rules' probes by ``n_rays``, the probed pixels' geometry rows (traced
    once, whatever the rule), and the rays it traced."""

    sim: object
    layout: Layout
    mode: int
    ncols: int
    patterns: dict
    shape: tuple
    stride: int = 0
    rows: np.ndarray = field(default=None)
    cols: np.ndarray = field(default=None)
    probes: dict = field(default_factory=dict)
    geometry: dict = field(default_factory=dict)
    #: the last :meth:`statement`'s own-pilot pixels: (rows, cols, rule probe, finer probe)
    _local: tuple | None = None
    #: a :class:`threading.Event`: once set, the next probe raises :class:`Cancelled`
    cancel: object = None

    def __post_init__(self):
        h, w = self.shape
        self.stride = grid_stride(self.shape)
        self.rows = grid_nodes(h, self.stride)
        self.cols = grid_nodes(w, self.stride)

    # ------------------------------------------------------------------ probes
    def sampling(self, n_rays: int):
        s = self.sim.scene.sampling
        return replace(s, n_rays=int(n_rays), part=0, error_estimate=False, target_error=None,
                       max_rays=max(s.max_rays, int(n_rays)))

    def nodes(self, n_rays: int) -> int:
        """The nodes of the rule of ``n_rays`` (its Gauss orders may give fewer)."""
        return self.sampling(n_rays).rule(self.sim._lobe).n

    def probe(self, n_rays: int, rows=None, cols=None) -> Probe:
        """The probe of the rule of ``n_rays`` at the grid pixels (or at ``rows, cols``)."""
        grid = rows is None
        if grid and n_rays in self.probes:
            return self.probes[n_rays]
        if self.cancel is not None and self.cancel.is_set():
            raise Cancelled("the pilot was cancelled")
        if grid:
            rr, cc = np.meshgrid(self.rows, self.cols, indexing="ij")
            rows, cols = rr.ravel(), cc.ravel()
        samp = self.sampling(n_rays)
        out = render_pixels(self.sim, samp, rows, cols, self.mode, self.ncols, self.patterns,
                            self.geometry)
        norm = normalise(out, self.sim.scene.estimator, n_rays)
        z, mod = self.layout.phasors(out, norm)
        with np.errstate(divide="ignore", invalid="ignore"):
            ft = np.abs(out[:, kb.OUT_FTOTAL])
            off = np.where(ft > 0, 1.0 - np.abs(out[:, kb.OUT_FHIT]) / ft, 0.0)
        p = Probe(z, mod, off, samp.rule(self.sim._lobe).n, self.layout, out, norm)
        if grid:
            self.probes[n_rays] = p
        return p

    def measured(self, n_rays: int, fine: int | None = None) -> np.ndarray:
        """(B, gh, gw) the rule's phase error measured at the grid pixels against the rule
        of ``fine`` (default :data:`FINE_FACTOR` x) nodes; NaN where either is invalid."""
        a = self.probe(n_rays)
        b = self.probe(fine or FINE_FACTOR * n_rays)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.abs(np.angle(a.z * np.conj(b.z)))
        e[~(np.isfinite(a.z) & np.isfinite(b.z) & (np.abs(a.z) > 0) & (np.abs(b.z) > 0))] = np.nan
        return e.reshape(e.shape[0], self.rows.size, self.cols.size)

    # ------------------------------------------------------------------ statements
    def envelope(self, n_rays: int) -> tuple[np.ndarray, np.ndarray]:
        """``(env, trusted)``: (B, gh, gw) :data:`SAFETY` times the largest measured error
        over each block's 3 x 3 grid pixels, and (gh, gw) whether all nine are valid and
        on the monitor (else the block's pixels take their own pilot)."""
        from scipy.ndimage import maximum_filter, minimum_filter

        e = self.measured(n_rays)
        good = np.isfinite(e).all(axis=0)
        trusted = minimum_filter(good.astype(np.uint8), size=3, mode="nearest") > 0
        env = np.stack([maximum_filter(np.where(np.isfinite(x), x, 0.0), size=3, mode="nearest")
                        for x in e])
        return SAFETY * env, trusted

    def grid_statement(self, n_rays: int) -> np.ndarray:
        """(B, gh, gw) the statement at the grid pixels (the envelope where trusted, else the
        pixel's own measured error times :data:`SAFETY`, plus its floors): what
        :meth:`statement` gives there, for :func:`choose_order`."""
        env, trusted = self.envelope(n_rays)
        own = SAFETY * self.measured(n_rays)
        p = self.probe(n_rays)
        p_floor, p_edge = p.floors()
        floor = (p_floor + 2.0 * np.nan_to_num(p.off, nan=1.0) * p_edge).reshape(own.shape)
        floor = floor + ROUNDOFF_PHASE
        out = np.where(trusted[None], env, own) + floor
        if p.nodes < MIN_NODES:
            out = np.where(np.isfinite(out), math.pi, out)
        return out

    def statement(self, n_rays: int, sums_ok: np.ndarray, images: np.ndarray, deltas,
                  off: np.ndarray, f_total: np.ndarray) -> tuple[np.ndarray, int]:
        """(B, H, W) rad: the stated phase error of the rendered rule of ``n_rays`` at every
        pixel (module docstring), and the number of pixels that took their own pilot.
        ``sums_ok`` (H, W): pixels with a valid render; ``images`` (nd, nw, K, H, W) the
        rendered images (their float32 floor); ``off`` (H, W) the share of each lobe's
        weight off the monitor in the render and ``f_total`` (H, W) its weight
        (:func:`image_floors`)."""
        h, w = self.shape
        s = self.stride
        env, trusted = self.envelope(n_rays)
        bi = np.minimum(np.arange(h) // s, self.rows.size - 1)
        bj = np.minimum(np.arange(w) // s, self.cols.size - 1)
        # every block's value over its s x s pixels (the grid has ceil(h / s) rows: bi and
        # bj index its blocks), one compiled pass
        stated = np.empty((env.shape[0], h, w))
        fill_blocks(np.ascontiguousarray(env, np.float64), s, stated)
        off = np.nan_to_num(np.asarray(off, np.float64), nan=1.0)
        cut = sums_ok & (off > CUT_MEASURED) & (off <= MAX_OFF)
        local = sums_ok & ~(trusted[bi][:, bj]) | cut
        rr, cc = np.nonzero(local)
        if rr.size:
            a, b = self.probe(n_rays, rr, cc), self.probe(FINE_FACTOR * n_rays, rr, cc)
            e = self._difference(a, b)
            k = np.nonzero(cut[rr, cc])[0]
            if k.size:  # across the step: the rule 16 x finer too
                far = self._difference(self.probe(n_rays, rr[k], cc[k]),
                                       self.probe(FINE_FACTOR**2 * n_rays, rr[k], cc[k]))
                e[:, k] = np.maximum(e[:, k], far)
            stated[:, rr, cc] = SAFETY * e
        self._local = (rr, cc, a, b) if rr.size else None
        nd, nw, k = images.shape[:3]
        stated = stated.reshape(nd, nw, h * w)
        bounded = np.where((off <= CUT_MEASURED) | (off > MAX_OFF), off, 0.0)
        weight = _edge_weight(f_total, bounded).reshape(-1)
        d = np.asarray(deltas, np.float64)
        cos_d, sin_d = np.cos(d), np.sin(d)
        unknown = self.probe(n_rays).nodes < MIN_NODES
        ok = np.ascontiguousarray(sums_ok, np.bool_).reshape(-1)
        for di in range(nd):  # stated + floor + ROUNDOFF_PHASE + edge, pi at most, in place
            for wi in range(nw):
                add_phase_floors(np.ascontiguousarray(images[di, wi], np.float32).reshape(k, -1),
                                 cos_d, sin_d, weight, float(self.layout.lmax),
                                 F32_SIGMAS, ROUNDOFF_PHASE, unknown, ok, stated[di, wi])
        return stated.reshape(nd, nw, h, w), int(rr.size)

    def signed_field(self, n_rays: int, fringes) -> np.ndarray:
        """(len(fringes), H, W) rad: the rule's signed phase error ``arg(Z_rule / Z_fine)``
        (rule minus the rule :data:`FINE_FACTOR` x finer) of the fringes ``fringes``
        (indices into the B fringes), an estimate of the error's pattern, not a bound: the
        grid pixels' measured values interpolated bilinearly to every pixel (held constant
        beyond the outermost grid pixels; a grid pixel without a valid value takes its
        nearest valid neighbour's), and the pixels that took their own pilot in the last
        :meth:`statement` their own. The rule's error varies smoothly across the camera
        (the premise of the envelope): its areal statistics take their errors from this
        pattern (:mod:`pmdsim.run.reconstruction`), where the envelope's magnitudes with
        any signs between neighbouring nodes would state a gradient and high-frequency
        content the error does not have. 0 where nothing is known."""
        from scipy.ndimage import distance_transform_edt

        h, w = self.shape
        fringes = list(fringes)
        a, b = self.probe(n_rays), self.probe(FINE_FACTOR * n_rays)
        gh, gw = self.rows.size, self.cols.size
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.angle(a.z[fringes] * np.conj(b.z[fringes])).reshape(len(fringes), gh, gw)
        ok = np.isfinite(g) & (np.abs(a.z[fringes]) > 0).reshape(g.shape) \
            & (np.abs(b.z[fringes]) > 0).reshape(g.shape)
        out = np.zeros((len(fringes), h, w))
        wr, wc = _linear_weights(self.rows, h), _linear_weights(self.cols, w)
        for k in range(len(fringes)):
            if not ok[k].any():
                continue
            gk = g[k]
            if not ok[k].all():  # the nearest valid grid pixel's value
                idx = distance_transform_edt(~ok[k], return_distances=False,
                                             return_indices=True)
                gk = gk[tuple(idx)]
            out[k] = wr @ gk @ wc.T
        if self._local is not None:
            rr, cc, pa, pb = self._local
            with np.errstate(divide="ignore", invalid="ignore"):
                e = np.angle(pa.z[fringes] * np.conj(pb.z[fringes]))
            out[:, rr, cc] = np.where(np.isfinite(e), e, 0.0)
        return out

    @staticmethod
    def _difference(a: Probe, b: Probe) -> np.ndarray:
        """(B, P) ``|arg(Z_a / Z_b)|``, pi where either is not valid."""
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.abs(np.angle(a.z * np.conj(b.z)))
        return np.where(np.isfinite(e) & (np.abs(a.z) > 0) & (np.abs(b.z) > 0), e, math.pi)

    def rays(self) -> int:
        """Rays the pilot traced so far (grid probes), per camera sub-ray."""
        n_px = self.rows.size * self.cols.size
        return sum(p.nodes for p in self.probes.values()) * n_px


def _linear_weights(nodes: np.ndarray, n: int) -> np.ndarray:
    """(n, len(nodes)) weights of linear interpolation from the increasing ``nodes`` to
    0 .. n - 1 (constant beyond the first and last node)."""
    x = np.clip(np.arange(n, dtype=np.float64), nodes[0], nodes[-1])
    wts = np.zeros((n, nodes.size))
    if nodes.size == 1:
        wts[:, 0] = 1.0
        return wts
    j = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    t = (x - nodes[j]) / (nodes[j + 1] - nodes[j])
    wts[np.arange(n), j] = 1.0 - t
    wts[np.arange(n), j + 1] = t
    return wts
