"""Fringes on a nearest-pixel monitor with a control variate: the Gauss rule for the smooth
fringe, randomised QMC for the small staircase residual only; on wide lobes the staircase
by the box-filtered rule, with bounds and no samples.

On a ``nearest`` monitor every ray takes the value of the monitor pixel it lands in: the
integrand over the lobe is ``t(c)``, ``c = floor(u + 1/2)``, a staircase, where a Gauss rule
does not converge fast, and plain ``rqmc`` (scrambled Sobol replicates, the same sample set
for every pixel) converges at a Monte-Carlo-like rate. Its error is then a bias shared by
all pixels: on ``examples/realistic_system.toml`` (Ward 0.004 / 0.001, whose finest X fringe
keeps a modulation of ~2 %) 100 rays gave 0.6-1.6 monitor px of bias depending on the seed,
1600 rays 0.05 px.

The estimator here splits the integrand into the smooth fringe ``h(u)`` (the same profile
at the continuous coordinate: ``cos``/``sin`` of a linear display, the display response's
mean and fundamental otherwise, :data:`CV_HARMONICS`) and the residual ``t(c) - h(u)``:

    I = Gauss[h] + rqmc[t - h]

``Gauss[h]`` is the render's rule (mode ``rule``, with its embedded rules), ``rqmc[t - h]``
the mean of ``R`` scrambled Sobol replicates of the difference, each replicate rendering
``t`` and ``h`` at the *same* points. Both parts are unbiased (the rule up to its tiny
quadrature error), so the sum is the nearest-pixel integral; the residual's variance is that
of the staircase (about ``(pi / P)^2 / 3`` of the fringe's at period ``P`` px) plus the
display's drive quantisation, not the fringe's.

The stated error of every fringe sum ``S = sum_k I_k exp(-i delta_k)`` (per pixel) is the
replicates' ``t(0.975, R - 1) s / sqrt(R)`` of the residual's ``S`` (real and imaginary
parts) plus ``|S_rule - S_embedded|`` of the smooth part (the embedded rule's difference, a
bound on the rule's error) on both parts.

Wide lobes: the staircase by the box rule
-----------------------------------------
Where every sub-ray's lobe is at least :data:`BOX_SIGMA_MIN` monitor px wide (standard
deviation along u and v, :func:`lobe_widths`; the radiometric estimator on a Gaussian slope
density), the staircase needs no samples. For a term ``exp(2 pi i f c)`` of the displayed
profile at the pixel centres ``c`` and the lobe's density ``l(u)`` on the monitor, Poisson's
summation formula gives exactly

    Lambda(f) = sum_c exp(2 pi i f c) int_pixel c l = sinc(f) L(f) + sum_{j != 0} sinc(j - f) L(f - j)

with ``L(f) = int l(u) exp(2 pi i f u) du`` the smooth integral the rule computes (the
harmonic sums) and ``|f| <= 1/2``: the staircase is the rule's fringe times ``sinc(f)``
(the box filter of one monitor pixel) plus aliases at ``|nu| >= 1/2`` cycles per px, where
a lobe several px wide has no weight (:func:`alias_bound`: a Gaussian of 0.8 times the
measured width, ``< 1e-20`` of the weight at 3 px). The displayed profile itself:

- a linear display: ``cos``/``sin`` of ``2 pi c / P``, one term;
- a non-linear display with integer periods ``P``: the profile at the pixel centres is
  ``P``-periodic (the render's tables take the phase of ``c mod P``), so the DFT of one
  period (:func:`profile_terms`) gives it exactly, drive quantisation included; the rule
  integrates terms 1..:data:`BOX_TERMS`, pixel by pixel only where the embedded rule's
  difference is below the term's Gaussian bound (:func:`gauss_bound`; else the term counts
  as zero with its bound as its error), and the terms above are bounded;
- other periods: the response's cosine terms 1..:data:`BOX_SERIES_TERMS` on the rule, and
  the replicates of the rest of the profile at the pixel centres (quantisation, higher
  terms; one table pass per replicate, not two).

Where the monitor's edge cuts a lobe, :func:`edge_bound` adds the pixels beyond the edge;
above :data:`EDGE_MAX_OFF` of the weight off the monitor the phase is stated as known to
within pi. Each term's share of the bound is its weight in ``S``, so terms that do not
alias into the K-step phase weigh nothing. Tests check the box rule against the
replicates of the whole staircase at 16 x the rays and against a NumPy mean over the
rays of the nearest pixels' luminance (``tests/render/test_control_variate.py``).
"""

from __future__ import annotations

import numpy as np

from ..kernels import bundle as kb
from .tile_tasks import fuses_replicates, replicates_fused, welford_update

#: Fourier terms of the display response in the smooth part of a non-linear display (gamma,
#: LUT, drive bits) on a narrow lobe (wide lobes: :data:`BOX_TERMS`): the fundamental only.
#: A higher term m varies over the lobe m times faster, and the Gauss rule does not resolve it: on the realistic example (Ward 0.004, 60 px
#: fringes, gamma 2.2) with 4 terms the embedded rule's difference of the third term (20 px
#: period, 0.5 % of white) stated 9 mrad. The terms above the first stay in the residual:
#: those that do not alias into the K-step phase (m != +-1 mod K) cancel in its fringe sum
#: exactly; the others (gamma 2.2: m = 3, 0.5 %) are smooth and small next to the staircase.
CV_HARMONICS = 1


def response_series(monitor, n: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """``(c_m, g)``: ``g`` the monitor's luminance of the fringe level
    ``0.5 + 0.5 cos(theta)`` at ``n`` samples of ``theta``, ``c_m`` its cosine series
    ``g(theta) = sum_m c_m cos(m theta)`` (FFT)."""
    theta = 2 * np.pi * np.arange(n) / n
    g = monitor.luminance(0.5 + 0.5 * np.cos(theta))
    coef = np.fft.rfft(g).real / theta.size
    coef[1:] *= 2
    return coef, g


#: The smallest lower bound of the lobe's standard deviation on the monitor (px, both
#: directions, :func:`lobe_widths`) from which the staircase is integrated deterministically
#: (module docstring, "Wide lobes"); below it the replicates sample it.
BOX_SIGMA_MIN = 3.0

#: The bounds take the lobe 0.8 times as wide as its measured lower bound: they assume that
#: the lobe's Fourier transform falls as a Gaussian's of that width (a Gaussian slope density
#: pushed onto the monitor by a smooth map); a factor a on the width raises the bounds to
#: the power 1 / a^2.
ALIAS_SIGMA_SAFETY = 0.8

#: Terms of the smooth fringe the rule integrates on a wide lobe: the display profile's
#: Fourier terms 1..8 at the pixel centres (integer periods: exact, quantisation included;
#: the terms above are bounded), else the response's cosine terms 1..3 (the replicates take
#: the rest). Each pixel keeps a term only where the embedded rule's difference is below the
#: term's Gaussian bound; else the term counts as zero and its bound as its error. Each term
#: is two columns per fringe and pixel in the rule's sums (float64) and the embedded rule's
#: (float32).
BOX_TERMS = 8
BOX_SERIES_TERMS = 3

#: Where more than this share of a lobe's weight is off the monitor (the chain masks such
#: pixels above 5 %), the box rule states no bound: the phase error is stated as pi.
EDGE_MAX_OFF = 0.5


def lobe_widths(sim, n: int = 12) -> dict | None:
    """Lower bounds (monitor px) of the standard deviation of one sub-ray's lobe on the
    monitor along u (``"x"``) and v (``"y"``), or None where the staircase is not integrated
    deterministically (the cone estimators: the cone's edge; a tabulated slope density; a
    specular peak; a BRDF that varies over the part).

    The rule's own rays of the chief ray of ``n x n`` pixels over the camera
    (:meth:`~pmdsim.render.Simulation.transport`): the weighted standard deviation of their
    monitor coordinates, the smallest over the pixels, less 10 %."""
    from .specular import specular_reflectance

    scene = sim.scene
    samp = scene.sampling
    if (not sim._lobe or not samp.lobe_gaussian or scene.brdf_variation is not None
            or specular_reflectance(scene.brdf) > 0):
        return None
    h, w = sim.shape
    rr, cc = np.meshgrid(np.unique(np.linspace(0, h - 1, n).round().astype(int)),
                         np.unique(np.linspace(0, w - 1, n).round().astype(int)), indexing="ij")
    u, v, wt, _, _ = sim.transport(rr.ravel(), cc.ravel(), directions=False)
    ok = (wt > 0) & np.isfinite(u) & np.isfinite(v)
    wt = np.where(ok, wt, 0.0)
    tot = wt.sum(axis=1)
    use = tot > 0
    if not use.any():
        return None
    out = {}
    for name, c in (("x", u), ("y", v)):
        c = np.where(ok, c, 0.0)[use]
        ww = wt[use] / tot[use, None]
        mean = (ww * c).sum(axis=1)
        var = (ww * (c - mean[:, None]) ** 2).sum(axis=1)
        out[name] = 0.9 * float(np.sqrt(max(float(var.min()), 0.0)))
    return out


def gauss_bound(sigma: float, f) -> np.ndarray:
    """``sinc(f) exp(-2 pi^2 (ALIAS_SIGMA_SAFETY sigma)^2 f^2)``: the bound taken for the
    box-filtered lobe's Fourier transform at ``f`` cycles per monitor px, per unit weight."""
    f = np.asarray(f, np.float64)
    s = ALIAS_SIGMA_SAFETY * sigma
    return np.abs(np.sinc(f)) * np.exp(-2 * np.pi**2 * s * s * f * f)


def alias_bound(sigma: float, f) -> np.ndarray:
    """Bound of ``|Lambda(f) - sinc(f) L(f)|`` per unit weight (module docstring): the
    aliases ``sum_{j != 0} |sinc(j - f)| |L(j - f)|`` with ``|L(nu)| <=
    exp(-2 pi^2 (ALIAS_SIGMA_SAFETY sigma)^2 nu^2)``, ``|f| <= 1/2`` (j = +-1..+-4; the
    rest are smaller than the last by far)."""
    s = ALIAS_SIGMA_SAFETY * sigma
    f = np.asarray(f, np.float64)
    out = np.zeros_like(f)
    for j in (-4, -3, -2, -1, 1, 2, 3, 4):
        nu = np.abs(j - f)
        out += np.exp(-2 * np.pi**2 * s * s * nu * nu) / (np.pi * nu)
    return out


def edge_bound(sigma: float, f, off) -> np.ndarray:
    """Bound per unit weight of the staircase's error beyond the box rule where the
    monitor's edge cuts the lobe (a share ``off`` of its weight off the monitor), per term
    of ``f`` cycles per px: ``(1 - sinc^2 f) off + (pi f / 3) l_E``, the pixels beyond the
    edge each contributing their mean residual and twice their first moment; ``l_E`` the
    lobe's density at the edge, at most ``off (sqrt(2 ln(1 / off)) + 2.5)`` and
    ``1 / sqrt(2 pi)`` over ``ALIAS_SIGMA_SAFETY sigma`` (a Gaussian tail)."""
    off = np.clip(np.asarray(off, np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.sqrt(2.0 * np.log(1.0 / np.where(off > 0, off, 1.0)))
    dens = np.minimum(off * (z + 2.5), 1.0 / np.sqrt(2 * np.pi)) / (ALIAS_SIGMA_SAFETY * sigma)
    f = float(f)
    return (1.0 - np.sinc(f) ** 2) * off + (np.pi * f / 3.0) * dens


def off_share(f_hit, f_total) -> tuple[np.ndarray, np.ndarray]:
    """(off, f_total): the share of each lobe's weight off the monitor from the weights on
    it (``f_hit``) and in all (``f_total``, at least ``f_hit``)."""
    f_hit = np.abs(np.asarray(f_hit, np.float64))
    f_tot = np.maximum(np.abs(np.asarray(f_total, np.float64)), f_hit)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(f_tot > 0, 1.0 - f_hit / np.where(f_tot > 0, f_tot, 1.0), 0.0)
    return off, f_tot


def linear_bound(sigma: float, width: float, f_hit, f_tot, off) -> np.ndarray:
    """The box rule's bound on a linear fringe sum ``cos + i sin`` (unnormalised, as the
    weights): its aliases and the monitor edge's share, on both parts."""
    f = 1.0 / width
    return 2.0 * (float(alias_bound(sigma, f)) * np.abs(f_hit) + edge_bound(sigma, f, off) * f_tot)


def box_plan(sim, widths, linear) -> tuple[dict | None, bool]:
    """(lobe widths, exact): the lobe's lower widths where the staircase is integrated
    deterministically (:data:`BOX_SIGMA_MIN`), else None; ``exact``: no replicates at all
    (a linear display, or integer fringe periods, whose displayed profile is periodic in
    the pixel index)."""
    sig = lobe_widths(sim)
    if sig is None or min(sig.values()) < BOX_SIGMA_MIN:
        return None, False
    integer = all(abs(w - round(w)) < 1e-9 and round(w) >= 3 for w in widths)
    return sig, bool(linear or integer)


def applies(sim) -> bool:
    """Whether :func:`render_fringes_cv` renders ``sim``'s fringes: mode ``rule`` on a
    ``nearest`` monitor, a scattering BRDF whose smooth part the rule integrates fast (a
    cone estimator, or the radiometric one on a Gaussian slope density), and enough rays for
    the replicates (``n_rays >= 2 R``)."""
    scene = sim.scene
    samp = scene.sampling
    return (not scene.brdf.is_delta and samp.mode == "rule"
            and scene.monitor.pixel_model == "nearest"
            and (not sim._lobe or samp.lobe_gaussian)
            and samp.n_rays >= 2 * samp.replicates)


def series_terms(coef, deltas, n_terms) -> np.ndarray:
    """(K, n_terms + 1) complex ``A``: the response's cosine series as the shifted
    profiles' terms, ``profile_k(c) = Re sum_j A[k, j] exp(2 pi i j c / P)``,
    ``A[k, j] = coef_j exp(i j delta_k)``."""
    j = np.arange(n_terms + 1)
    return coef[j][None, :] * np.exp(1j * j[None, :] * np.asarray(deltas)[:, None])


def profile_terms(monitor, width: float, deltas) -> np.ndarray:
    """(K, P // 2 + 1) complex ``A`` of the displayed profiles at the pixel centres of an
    integer period ``P``: ``profile_k(c) = Re sum_j A[k, j] exp(2 pi i j c / P)`` exactly
    for every integer ``c`` (the DFT of one period; drive quantisation included; the
    render's tables take the phase of ``c mod P``, so that every period shows the same
    bytes)."""
    p = int(round(width))
    c = np.arange(p, dtype=np.float64)
    prof = np.array([monitor.luminance(0.5 + 0.5 * np.cos(2 * np.pi * np.mod(c, width) / width + d))
                     for d in deltas])
    a = np.fft.rfft(prof, axis=1) / p
    a[:, 1:] *= 2
    if p % 2 == 0:
        a[:, -1] /= 2
    return a


class _Layout:
    """Columns of the tables (``MODE_TABLES``) and of the smooth part (``MODE_HARMONIC``):
    per fringe ``terms`` harmonic pairs ``sum w cos/sin(2 pi j u / P)``, j = 1..terms, and
    the coefficients ``A`` (K, >= terms + 1) that make the shifted profiles of them
    (:func:`series_terms`, :func:`profile_terms`; None on a linear display: cos and sin)."""

    def __init__(self, directions, widths, deltas, linear, terms, n_table_cols, n_terms=1):
        self.directions, self.widths, self.deltas = directions, widths, deltas
        self.linear = linear
        self.harm = 1 if linear else n_terms
        self.terms = terms  # {(di, wi): (K, J) complex}
        nw = len(widths)
        n_u = sum(1 for d in directions if d == "x")
        self.per_t = 2 if linear else len(deltas)
        self.base_t = {"x": kb.OUT_FIRST, "y": kb.OUT_FIRST + n_u * nw * self.per_t}
        self.base_h = {"x": kb.OUT_FIRST, "y": kb.OUT_FIRST + n_u * nw * 2 * self.harm}
        ks = {d: [2 * np.pi * m / w for d_ in directions if d_ == d for w in widths
                  for m in range(1, self.harm + 1)] for d in ("x", "y")}
        self.k_u, self.k_v = np.array(ks["x"]), np.array(ks["y"])
        self.ncols_h = kb.OUT_FIRST + 2 * (self.k_u.size + self.k_v.size)
        self.ncols_t = n_table_cols
        self.fringes = [(di, wi, self.base_t[d] + wi * self.per_t, self.base_h[d] + wi * 2 * self.harm)
                        for di, d in enumerate(directions) for wi in range(nw)]

    def to_tables(self, h: np.ndarray) -> np.ndarray:
        """Harmonic sums (H, W, ncols_h) -> the tables' columns (H, W, ncols_t) of the smooth
        profile (linear in ``h``: also for differences of sums)."""
        out = np.zeros(h.shape[:-1] + (self.ncols_t,))
        out[..., :kb.OUT_FIRST] = h[..., :kb.OUT_FIRST]
        for di, wi, tc, hc in self.fringes:
            if self.linear:
                out[..., tc:tc + 2] = h[..., hc:hc + 2]
                continue
            a = self.terms[di, wi]
            for k in range(len(self.deltas)):
                acc = a[k, 0].real * h[..., kb.OUT_FHIT]
                for m in range(1, self.harm + 1):
                    c = hc + 2 * (m - 1)
                    acc = acc + (a[k, m].real * h[..., c] - a[k, m].imag * h[..., c + 1])
                out[..., tc + k] = acc
        return out

    def residual_tables(self, table_u: np.ndarray, table_v: np.ndarray):
        """The profile tables less the smooth fringe ``Re sum_{j <= terms} A[k, j]
        exp(2 pi i j c / P)`` at every monitor pixel centre ``c`` (non-linear displays)."""
        out = {"x": np.array(table_u, np.float64, copy=True),
               "y": np.array(table_v, np.float64, copy=True)}
        row = {"x": 0, "y": 0}
        for di, d in enumerate(self.directions):
            c = np.arange(out[d].shape[1], dtype=np.float64)
            for wi, w in enumerate(self.widths):
                a = self.terms[di, wi]
                e = np.exp(2j * np.pi * np.outer(np.arange(self.harm + 1), c) / w)
                for k in range(len(self.deltas)):
                    out[d][row[d]] -= (a[k, :self.harm + 1] @ e).real
                    row[d] += 1
        return out["x"], out["y"]

    def select_terms(self, sig: dict, smooth: np.ndarray, coarse: np.ndarray | None,
                     exact: bool) -> np.ndarray:
        """Wide lobes: the bound (nd, nw, H, W) on every fringe sum ``S`` of what the rule
        does not integrate, unnormalised; drops, pixel by
        pixel, the terms ``j >= 2`` whose embedded difference exceeds their bound
        :func:`gauss_bound` (zeroed in ``smooth`` and ``coarse``: the term counts as zero,
        its bound as its error). Adds the aliases of the kept terms (:func:`alias_bound`),
        the monitor edge's share where it cuts the lobe (:func:`edge_bound`) and, with
        ``exact`` profile terms, the bound of the terms above ``terms``."""
        f_hit = np.abs(smooth[..., kb.OUT_FHIT])
        off, f_tot = off_share(f_hit, smooth[..., kb.OUT_FTOTAL])
        nd, nw = len(self.directions), len(self.widths)
        out = np.zeros((nd, nw) + f_hit.shape)
        for di, wi, _, hc in self.fringes:
            d, w = self.directions[di], self.widths[wi]
            s = sig[d]
            if self.linear:
                out[di, wi] = linear_bound(s, w, f_hit, f_tot, off)
                continue
            # each term's weight in S = sum_k I_k exp(-i delta_k), I_k = Re sum_j A_kj L_j:
            # (|sum_k e^-i delta_k A_kj| + |sum_k e^-i delta_k conj A_kj|) / 2 (terms that
            # do not alias into the K-step phase weigh nothing)
            rot = np.exp(-1j * np.asarray(self.deltas))[:, None]
            a = 0.5 * (np.abs((rot * self.terms[di, wi]).sum(axis=0))
                       + np.abs((rot * np.conj(self.terms[di, wi])).sum(axis=0)))
            j = np.arange(a.size)
            g = gauss_bound(s, j / w)
            al = alias_bound(s, np.minimum(j / w, 0.5))
            bound = float(np.sum(a[1:self.harm + 1] * al[1:self.harm + 1]))
            if exact:
                bound += float(np.sum(a[self.harm + 1:] * np.minimum(1.0, g + al)[self.harm + 1:]))
            acc = bound * f_hit
            for m in range(1, self.harm + 1):  # the monitor's edge
                acc = acc + a[m] * edge_bound(s, m / w, off) * f_tot
            for m in range(2, self.harm + 1):
                c = hc + 2 * (m - 1)
                gm = g[m] * f_hit
                if coarse is None:
                    dead = np.abs(smooth[..., c] + 1j * smooth[..., c + 1]) > gm
                else:
                    dead = np.hypot(smooth[..., c] - coarse[..., c],
                                    smooth[..., c + 1] - coarse[..., c + 1]) > gm
                for arr in (smooth,) if coarse is None else (smooth, coarse):
                    arr[..., c][dead] = 0.0
                    arr[..., c + 1][dead] = 0.0
                acc = acc + np.where(dead, a[m] * gm, 0.0)
            out[di, wi] = acc
        return out

    def fringe_sums(self, t: np.ndarray) -> np.ndarray:
        """(nd, nw, H, W) complex ``S`` of table-layout sums: ``cos + i sin`` of a linear
        display, ``sum_k I_k exp(-i delta_k)`` of the K shifted profiles otherwise (its
        argument is the decoded phase)."""
        nd, nw = len(self.directions), len(self.widths)
        out = np.empty((nd, nw) + t.shape[:-1], np.complex128)
        if self.linear:  # one compiled pass: t[..., tc] + 1j t[..., tc + 1], NumPy's bytes
            return self.sums_of_columns(t, [f[2] for f in self.fringes], out)
        rot = np.exp(-1j * np.asarray(self.deltas))
        for di, wi, tc, _ in self.fringes:
            out[di, wi] = np.tensordot(t[..., tc:tc + self.per_t], rot, axes=([-1], [0]))
        return out

    def sums_of_columns(self, t: np.ndarray, cols, out=None) -> np.ndarray:
        """(nd, nw, H, W) complex ``t[..., c] + 1j t[..., c + 1]`` for the fringes' first
        columns ``cols`` of ``t`` (H, W, C) (float32 or float64, taken as float64): for a
        linear display the sums of the tables' layout (``cols`` its columns) or of the
        harmonic layout (the harmonic columns: ``fringe_sums(to_tables(h))`` without the
        tables)."""
        from ..kernels.fringe_finish import complex_of_columns
        from .results import in_blocks

        nd, nw = len(self.directions), len(self.widths)
        if out is None:
            out = np.empty((nd, nw) + t.shape[:-1], np.complex128)
        flat = np.ascontiguousarray(t).reshape(-1, t.shape[-1])
        cols = np.asarray(cols, np.int64)
        dest = out.reshape(nd * nw, -1)
        in_blocks(flat.shape[0], lambda p0, p1: complex_of_columns(flat, cols, p0, p1, dest))
        return out


def render_fringes_cv(sim, directions, widths, deltas, linear, table_u, table_v, progress=None):
    """Table-layout sums (H, W, ncols) of the fringes on ``sim``'s nearest-pixel monitor by
    the control variate (module docstring), the error (nd, nw, H, W) complex of every fringe
    sum :meth:`_Layout.fringe_sums` (real and imaginary parts, >= 0, unnormalised), the
    stated phase error and what was rendered (for
    :attr:`~pmdsim.render.FringeResult.sampling`).

    On a wide lobe (:func:`box_plan`) the rule integrates the box-filtered terms of the
    displayed profile, with bounds for its aliases and for the terms it leaves out; the
    replicates sample only what the terms leave out of the profile at the pixel centres
    (none for a linear display or integer periods)."""
    from ..scene.quadrature import student_t975
    from .results import phase_error

    samp = sim.scene.sampling
    mon = sim.scene.monitor
    ncols_t = kb.OUT_FIRST + table_u.shape[0] + table_v.shape[0]
    sig, exact = box_plan(sim, widths, linear)
    box = sig is not None
    terms, n_terms = None, 1
    if not linear:
        if box and exact:
            n_terms = min(BOX_TERMS, min(int(round(w)) // 2 for w in widths) - 1)
            terms = {(di, wi): profile_terms(mon, w, deltas)
                     for di in range(len(directions)) for wi, w in enumerate(widths)}
        else:
            n_terms = BOX_SERIES_TERMS if box else CV_HARMONICS
            t = series_terms(response_series(mon)[0], deltas, n_terms)
            terms = {(di, wi): t for di in range(len(directions)) for wi in range(len(widths))}
    lay = _Layout(tuple(directions), tuple(widths), np.asarray(deltas), linear, terms, ncols_t,
                  n_terms)
    reps = () if box and exact else samp.as_mode("rqmc").error_passes()
    gauss = sim.plan(True)
    per_rep = 1 if box else 2
    n_steps = len(gauss) + per_rep * len(reps)
    step = [0]

    def prog():
        if progress is None:
            return None
        k = step[0]
        step[0] += 1
        return lambda done, total: progress(k * total + done, n_steps * total)

    # the box filter of every harmonic column: sinc(k / 2 pi), the staircase's mean of
    # exp(i k c) over a monitor pixel
    fbox = np.concatenate([lay.k_u, lay.k_v]) / (2 * np.pi)
    scale = np.ones(lay.ncols_h)
    if box:
        scale[kb.OUT_FIRST::2] = np.sinc(fbox)
        scale[kb.OUT_FIRST + 1::2] = np.sinc(fbox)
    # the smooth part: the rule and its embedded rule (Simulation._render's passes); the
    # embedded rule first, kept in float32 (it only gives the difference; its rounding,
    # 6e-8 of a sum, is far below any statement), so that the rule's float64 sums and it
    # never make two float64 (H, W, 2 terms) arrays at once
    coarse = None
    if len(gauss) > 1:
        step[0] = 1
        c64 = sim._render_set(gauss[1], kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u,
                              k_v=lay.k_v, progress=prog())
        c64 *= scale
        coarse = c64.astype(np.float32)
        del c64
        step[0] = 0
    smooth = sim._render_set(gauss[0], kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u, k_v=lay.k_v,
                             progress=prog())
    smooth *= scale
    step[0] = len(gauss)  # the second embedded rule is not needed here
    bound = lay.select_terms(sig, smooth, coarse, exact) if box else None
    s_err = None
    if coarse is not None:  # the difference in place, in float32 (6e-8 of itself)
        np.subtract(smooth, coarse, out=coarse, casting="unsafe")
        s_err = (lay.sums_of_columns(coarse, [f[3] for f in lay.fringes]) if linear
                 else lay.fringe_sums(lay.to_tables(coarse)))
        del coarse
    out = lay.to_tables(smooth)
    del smooth
    if box and not linear and not exact:  # the profile less the terms, at the pixel centres
        table_u, table_v = lay.residual_tables(table_u, table_v)
    # the residual, replicate by replicate (Welford on S): t - h at the same points, or
    # (box) the residual tables alone
    fused = fuses_replicates(sim, reps)
    if fused:  # every replicate in each tile's task: the same bytes as the loop below
        k0, left = step[0], n_steps - step[0]
        mean_res, mean_s, m2_re, m2_im = replicates_fused(
            sim, reps, lay, box, table_u, table_v,
            None if progress is None else
            lambda done, total: progress(k0 * total + done * left, n_steps * total))
    else:
        mean_res = np.zeros_like(out)
        mean_s = m2_re = m2_im = None
        if reps:
            fringes = (len(directions), len(widths)) + out.shape[:-1]
            mean_s = np.empty(fringes, np.complex128)
            m2_re, m2_im = np.zeros(fringes), np.zeros(fringes)
    for r, rep in enumerate(() if fused else reps):
        t = sim._render_set(rep, kb.MODE_TABLES, ncols_t, table_u=table_u, table_v=table_v,
                            progress=prog())
        if box:
            res = t
        else:
            h = sim._render_set(rep, kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u, k_v=lay.k_v,
                                progress=prog())
            res = t - lay.to_tables(h)
            del h
        res[..., :kb.OUT_FIRST] = 0.0  # f_total, f_hit: the rule's
        del t
        welford_update(res, r, lay, mean_res, mean_s, m2_re, m2_im)
    n = len(reps)
    out += mean_res
    sums = lay.fringe_sums(out)
    if n:
        half = student_t975(n - 1) / np.sqrt((n - 1) * n)
        err = _half_widths(m2_re, m2_im, float(half))
        stated = phase_error(sums, err, "replicates")
    else:
        err = np.zeros(sums.shape, np.complex128)
        stated = np.zeros(sums.shape)
    if s_err is not None:  # the smooth part: the embedded rule's statement
        stated = stated + phase_error(sums, s_err, "embedded")
        err = err + np.abs(s_err) * (1 + 1j)
    if bound is not None:  # the terms left out and the aliases: bounds
        stated = stated + phase_error(sums, bound * (1 + 1j), "replicates")
        err = err + bound * (1 + 1j)
        # a lobe mostly off the monitor: no bound (the phase is known to within pi)
        far = off_share(out[..., kb.OUT_FHIT], out[..., kb.OUT_FTOTAL])[0] > EDGE_MAX_OFF
        stated = np.where(far, np.pi, stated)
        big = np.abs(sums)
        err = np.where(far, np.maximum(err.real, big) + 1j * np.maximum(err.imag, big), err)
    rule = gauss[0].rule(sim._lobe)
    kind = "cos/sin" if linear else f"{lay.harm} response terms"
    if box:
        kind = "cos/sin" if linear else (f"the displayed profile's Fourier terms 1-{lay.harm} at the "
                                         "pixel centres" if exact else kind)
        what = (f"the staircase of the smooth fringe ({kind}) as the rule's box-filtered "
                f"fringe (sinc per term), its aliases and the terms the rule leaves out bounded "
                f"for lobes at least {sig['x']:.3g} x {sig['y']:.3g} monitor px wide (u x v, "
                f"std.)")
        if n:
            what += (f"; the profile's rest at the pixel centres on {n} rqmc replicates of "
                     f"{max(1, samp.n_rays // samp.replicates)} points")
    else:
        what = (f"smooth fringe ({kind}) on the rule, the staircase residual on {n} rqmc "
                f"replicates of {max(1, samp.n_rays // samp.replicates)} points")
    info = {"mode": ("rule+box+rqmc" if n else "rule+box") if box else "rule+rqmc",
            "rule": rule.describe(), "kind": rule.kind, "nodes": rule.n,
            "order": list(rule.order), "passes": len(gauss) + per_rep * n,
            "error": "replicates" if n else "embedded", "smooth": False,
            "control_variate": what, "lobe_width_px": sig,
            "embedded_rule": gauss[1].rule(sim._lobe).describe() if len(gauss) > 1 else None}
    return out, err, stated, info


def _half_widths(m2_re, m2_im, half: float) -> np.ndarray:
    """``half * sqrt(m2_re) + 1j * half * sqrt(m2_im)`` in one compiled pass (the same
    bytes; no whole-camera temporaries)."""
    from ..kernels.fringe_finish import half_width_rows
    from .results import in_blocks

    out = np.empty(m2_re.shape, np.complex128)
    re, im = np.ascontiguousarray(m2_re).reshape(-1), np.ascontiguousarray(m2_im).reshape(-1)
    flat = out.reshape(-1)
    in_blocks(flat.size, lambda p0, p1: half_width_rows(re, im, half, p0, p1, flat))
    return out


#: Replicate passes of each control-variate mode, per ``n_rays`` (:func:`rays_share`).
REPLICATE_PASSES = {"rule+rqmc": 2.0, "rule+box+rqmc": 1.0, "rule+box": 0.0}


def rays_share(sim, mode: str) -> float:
    """The rays of one control-variate fringe render per ``n_rays``: the rule and its
    embedded rule, then, by the ``mode`` it rendered (:attr:`FringeResult.sampling`), the
    replicates twice (the profiles and the smooth part), once (wide lobes: the residual
    tables) or not at all (wide lobes: a linear display or integer periods)."""
    gauss = sim.plan(True)[:2]
    return (sum(p.rule(sim._lobe).n for p in gauss) / max(sim.scene.rays_per_pixel, 1)
            + REPLICATE_PASSES[mode])
