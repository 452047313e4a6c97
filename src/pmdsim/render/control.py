"""Fringes on a nearest-pixel monitor with a control variate: the Gauss rule for the smooth
fringe, randomised QMC for the small staircase residual only.

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
"""

from __future__ import annotations

import numpy as np

from ..kernels import bundle as kb

#: Fourier terms of the display response in the smooth part of a non-linear display (gamma,
#: LUT, drive bits): the fundamental only. A higher term m varies over the lobe m times
#: faster, and the Gauss rule does not resolve it: on the realistic example (Ward 0.004, 60 px
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


class _Layout:
    """Columns of the tables (``MODE_TABLES``) and of the smooth part (``MODE_HARMONIC``)."""

    def __init__(self, directions, widths, deltas, linear, coef, n_table_cols):
        self.directions, self.widths, self.deltas = directions, widths, deltas
        self.linear = linear
        self.harm = 1 if linear else CV_HARMONICS
        self.coef = coef
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
        for _, _, tc, hc in self.fringes:
            if self.linear:
                out[..., tc:tc + 2] = h[..., hc:hc + 2]
                continue
            for k, delta in enumerate(self.deltas):
                acc = self.coef[0] * h[..., kb.OUT_FHIT]
                for m in range(1, self.harm + 1):
                    c = hc + 2 * (m - 1)
                    acc = acc + self.coef[m] * (h[..., c] * np.cos(m * delta)
                                                - h[..., c + 1] * np.sin(m * delta))
                out[..., tc + k] = acc
        return out

    def fringe_sums(self, t: np.ndarray) -> np.ndarray:
        """(nd, nw, H, W) complex ``S`` of table-layout sums: ``cos + i sin`` of a linear
        display, ``sum_k I_k exp(-i delta_k)`` of the K shifted profiles otherwise (its
        argument is the decoded phase)."""
        nd, nw = len(self.directions), len(self.widths)
        out = np.empty((nd, nw) + t.shape[:-1], np.complex128)
        rot = np.exp(-1j * np.asarray(self.deltas))
        for di, wi, tc, _ in self.fringes:
            if self.linear:
                out[di, wi] = t[..., tc] + 1j * t[..., tc + 1]
            else:
                out[di, wi] = np.tensordot(t[..., tc:tc + self.per_t], rot, axes=([-1], [0]))
        return out


def render_fringes_cv(sim, directions, widths, deltas, linear, table_u, table_v, progress=None):
    """Table-layout sums (H, W, ncols) of the fringes on ``sim``'s nearest-pixel monitor by
    the control variate (module docstring), the error (nd, nw, H, W) complex of every fringe
    sum :meth:`_Layout.fringe_sums` (real and imaginary parts, >= 0, unnormalised) and what
    was rendered (for :attr:`~pmdsim.render.FringeResult.sampling`)."""
    from ..scene.quadrature import student_t975
    from .results import phase_error

    samp = sim.scene.sampling
    coef = None if linear else response_series(sim.scene.monitor)[0]
    ncols_t = kb.OUT_FIRST + table_u.shape[0] + table_v.shape[0]
    lay = _Layout(tuple(directions), tuple(widths), np.asarray(deltas), linear, coef, ncols_t)
    reps = samp.as_mode("rqmc").error_passes()
    gauss = sim.plan(True)
    n_steps = len(gauss) + 2 * len(reps)
    step = [0]

    def prog():
        if progress is None:
            return None
        k = step[0]
        step[0] += 1
        return lambda done, total: progress(k * total + done, n_steps * total)

    # the smooth part: the rule and its embedded rules (Simulation._render's passes)
    smooth = sim._render_set(gauss[0], kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u, k_v=lay.k_v,
                             progress=prog())
    s_err = None
    if len(gauss) > 1:
        coarse = sim._render_set(gauss[1], kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u,
                                 k_v=lay.k_v, progress=prog())
        s_err = lay.fringe_sums(lay.to_tables(smooth - coarse))
        del coarse
        step[0] += len(gauss) - 2  # the second embedded rule is not needed here
    out = lay.to_tables(smooth)
    del smooth
    # the residual: t - h at the same points, replicate by replicate (Welford on S)
    mean_res = np.zeros_like(out)
    mean_s = m2_re = m2_im = None
    for r, rep in enumerate(reps):
        t = sim._render_set(rep, kb.MODE_TABLES, ncols_t, table_u=table_u, table_v=table_v,
                            progress=prog())
        h = sim._render_set(rep, kb.MODE_HARMONIC, lay.ncols_h, k_u=lay.k_u, k_v=lay.k_v,
                            progress=prog())
        res = t - lay.to_tables(h)
        res[..., :kb.OUT_FIRST] = 0.0  # the same rays: f_total, f_hit cancel exactly
        del t, h
        mean_res += (res - mean_res) / (r + 1)
        s = lay.fringe_sums(res)
        if mean_s is None:
            mean_s, m2_re, m2_im = s.copy(), np.zeros(s.shape), np.zeros(s.shape)
            continue
        d = s - mean_s
        mean_s += d / (r + 1)
        m2_re += d.real * (s - mean_s).real
        m2_im += d.imag * (s - mean_s).imag
    n = len(reps)
    half = student_t975(n - 1) / np.sqrt((n - 1) * n)
    err = half * np.sqrt(m2_re) + 1j * half * np.sqrt(m2_im)
    out += mean_res
    sums = lay.fringe_sums(out)
    stated = phase_error(sums, err, "replicates")
    if s_err is not None:  # the smooth part: the embedded rule's statement
        stated = stated + phase_error(sums, s_err, "embedded")
        err = err + np.abs(s_err) * (1 + 1j)
    rule = gauss[0].rule(sim._lobe)
    info = {"mode": "rule+rqmc", "rule": rule.describe(), "kind": rule.kind, "nodes": rule.n,
            "order": list(rule.order), "passes": len(gauss) + 2 * n,
            "error": "replicates", "smooth": False,
            "control_variate": (f"smooth fringe ({'cos/sin' if linear else f'{lay.harm} response terms'}) "
                                f"on the rule, the staircase residual on {n} rqmc replicates "
                                f"of {max(1, samp.n_rays // samp.replicates)} points"),
            "embedded_rule": gauss[1].rule(sim._lobe).describe() if len(gauss) > 1 else None}
    return out, err, stated, info


def table_fringe_sums(out, directions, widths, deltas, linear) -> np.ndarray:
    """(nd, nw, H, W) complex fringe sums of table-layout sums ``out`` (:class:`_Layout`)."""
    ncols = out.shape[-1]
    return _Layout(tuple(directions), tuple(widths), np.asarray(deltas), linear, None,
                   ncols).fringe_sums(out)


def rays_share(sim) -> float:
    """The rays of one control-variate fringe render per ``n_rays``: the rule and its
    embedded rule, then the replicates twice (the profiles and the smooth part)."""
    gauss = sim.plan(True)[:2]
    return sum(p.rule(sim._lobe).n for p in gauss) / max(sim.scene.rays_per_pixel, 1) + 2.0
