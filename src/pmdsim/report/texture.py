"""Figures of the machining -> lobe relation and of a BRDF fit (matplotlib, Agg, PNG).

- :func:`plot_texture`: the radial profile on the monitor of a turned surface's lobe: the
  geometric (kinematic + random) density as a curve, the diffractive orders of each
  wavelength as stems (efficiency), with the Rayleigh numbers and the regime in the title;
- :func:`plot_fit`: measured median modulation against fringe width, the closed-form start
  curve and the fitted simulation, per direction.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

DPI = 110
_COLOURS = {610.0: "tab:red", 545.0: "tab:green", 465.0: "tab:blue"}


def _figure(size) -> Figure:
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_texture(params, path, wavelengths_nm=(610.0, 545.0, 465.0), weights=(1.0, 1.0, 1.0)) -> Path:
    """Radial lobe of a turned surface on a monitor facing the specular ray at
    ``params.distance_mm`` (normal incidence unless ``params.incidence_deg``): x axis in
    monitor px from the specular point. ``params``: :class:`~pmdsim.brdf.turning.TextureParameters`."""
    from ..brdf import turning
    from ..brdf.slope_density import arc_slope_cdf

    f = params.feed_um * 1e-3
    r = params.nose_radius_mm
    th = math.radians(params.incidence_deg)
    d, pitch = params.distance_mm, params.pixel_pitch_mm
    half_px = 1.3 * (params.lobe_width_monitor_px / 2 + 4 * params.random_rms_slope * 2 * d / pitch)
    x = np.linspace(-half_px, half_px, 2001)
    # geometric: deflection 2 atan(s) from the specular direction in the radial plane
    ang = np.arctan(x * pitch / d)
    s = np.tan(ang / 2)
    cdf = arc_slope_cdf(s, f, r)
    dens = np.gradient(cdf, x)
    sig = params.random_rms_slope * 2 * d / pitch  # px
    if sig > 0:
        kern_x = np.arange(-int(4 * sig / (x[1] - x[0])) - 1, int(4 * sig / (x[1] - x[0])) + 2) * (x[1] - x[0])
        kern = np.exp(-0.5 * (kern_x / sig) ** 2)
        dens = np.convolve(dens, kern / kern.sum(), mode="same")
    fig = _figure((9.0, 4.2))
    ax = fig.add_subplot()
    ax.plot(x, dens / dens.max(), color="0.3", lw=1.5, label="geometric (kinematic arcs + random)")
    wsum = float(np.sum(weights))
    for lam, w in zip(wavelengths_nm, weights):
        lam_mm = lam * 1e-6
        m = turning.propagating_orders(lam_mm, f, th)
        eta = turning.order_efficiencies(f, r, lam_mm, th, m)
        sm = turning.order_sines(lam_mm, f, th, m)
        pos = d * np.tan(np.arcsin(sm) - th) / pitch
        keep = np.abs(pos) <= half_px
        col = _COLOURS.get(float(lam), None)
        ax.vlines(pos[keep], 0, eta[keep] / max(eta.max(), 1e-30) * w / max(weights),
                  color=col, lw=1.6, alpha=0.8,
                  label=f"orders {lam:g} nm (efficiency, scaled; weight {w / wsum:.2f})")
    ax.set_xlim(-half_px, half_px)
    ax.set_ylim(0, 1.08)
    ax.set_xlabel(f"radial position on the monitor from the specular point (monitor px of "
                  f"{pitch:g} mm, d = {d:g} mm)")
    ax.set_ylabel("relative intensity")
    ax.set_title(f"f = {params.feed_um:g} um, r = {params.nose_radius_mm:g} mm: alpha_radial "
                 f"(kinematic) {params.kinematic_alpha_radial:.4f}, order spacing "
                 f"{params.order_spacing_monitor_px:.1f} px, {params.orders_in_lobe:.1f} orders "
                 f"in the lobe; regime {params.regime}", fontsize=9)
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    return path


def plot_fit(res, path, frame: str = "fixed") -> Path:
    """Median decoded modulation against fringe width: measured (dots), closed-form start
    (dashed), fitted simulation (line), per direction; a failed fit says so in red in the
    title. ``res``: :class:`~pmdsim.studies.fit.FitResult`."""
    fig = _figure((5.0 * len(res.directions), 4.0))
    w = np.asarray(res.widths)
    names = {"alpha_x": "alpha_tangential" if frame == "rotational" else "alpha_x",
             "alpha_y": "alpha_radial" if frame == "rotational" else "alpha_y"}
    text = ", ".join(f"{names[n]} = {v:.5g} +- {2 * s:.2g} (k=2)"
                     for n, v, s in zip(res.names[:2], res.values[:2], res.std[:2]))
    for i, d in enumerate(res.directions):
        ax = fig.add_subplot(1, len(res.directions), i + 1)
        ax.plot(w, res.modulation_measured[i], "o", color="k", label="measured (median)")
        ax.plot(w, res.modulation_start[i], "--", color="tab:orange", label="closed-form start")
        ax.plot(w, res.modulation_fitted[i], "-", color="tab:blue", label="fitted simulation")
        ax.set_xscale("log")
        ax.set_xticks(w, [f"{x:g}" for x in w])
        ax.minorticks_off()
        ax.set_ylim(0, 1.05)
        ax.set_xlabel("fringe width (monitor px)")
        ax.set_ylabel("modulation B/A")
        ax.set_title(f"{d.upper()} fringes", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    if not getattr(res, "success", True):
        import textwrap

        why = textwrap.fill(f"FIT FAILED ({res.reason}): not a result",
                            width=int(14 * 5.0 * len(res.directions)))
        text = f"{why}\n{text}"
    elif np.isfinite(res.chi2_reduced):
        text += f"; reduced chi-square {res.chi2_reduced:.3g}"
    fig.suptitle(text, fontsize=9, color="tab:red" if not getattr(res, "success", True) else "k")
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    return path


def plot_fit_coverage(results, path, k: float = 2.0) -> Path:
    """Normalised errors ``(fitted - true) / u`` of alpha_x and alpha_y of each case of a
    coverage study (:mod:`pmdsim.studies.fit_coverage`), with the +-k band; a case covers
    the truth when both points lie inside. ``results``: a list of ``CoverageResult``."""
    z = np.array([r.normalised_errors for r in results])
    covered = np.array([r.covered for r in results])
    idx = np.arange(len(results))
    fig = _figure((9.0, 4.2))
    ax = fig.add_subplot()
    ax.axhspan(-k, k, color="tab:green", alpha=0.12, label=f"k = {k:g} interval")
    ax.axhline(0, color="0.5", lw=0.8)
    ax.plot(idx - 0.12, z[:, 0], "o", color="tab:blue", label="alpha_x")
    ax.plot(idx + 0.12, z[:, 1], "s", color="tab:orange", label="alpha_y")
    for i in idx[~covered]:
        worst = z[i][np.argmax(np.abs(z[i]))]
        ax.annotate("missed", (i, worst), textcoords="offset points",
                    xytext=(0, 8 if worst > 0 else -14), ha="center", fontsize=7,
                    color="tab:red")
    ax.set_xticks(idx, [f"{r.case.seed}" for r in results], fontsize=8)
    ax.set_xlabel("case (seed); alphas 0.004-0.04, incidence 15-40 deg, exposure 1500-9000 e-, "
                  "dark noise 2-20 e-", fontsize=8)
    ax.set_ylabel("(fitted - true) / u  (k = 1)")
    lim = max(3.0, float(np.nanmax(np.abs(z))) * 1.15)
    ax.set_ylim(-lim, lim)
    ax.set_title(f"fit coverage: both alphas inside k = {k:g} in {int(covered.sum())} of "
                 f"{len(results)} cases (default fit settings; truth: Gauss rule, 4096 "
                 "nodes)", fontsize=9)
    ax.legend(fontsize=8, loc="lower right", ncols=3)
    ax.grid(alpha=0.3)
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    return path


def plot_topography(analysis, heights, dx: float, dy: float, path) -> Path:
    """A measured topography (``pmdsim texture --from``): the height map (nm, local frame:
    x tangential, y radial), the PSD along each axis (the periodogram's central row and
    column, positive frequencies, Hann window) with the K-correlation fit, and the slope
    densities per axis with the equivalent Gaussian (Ward/Beckmann) lobes.
    ``analysis``: :class:`~pmdsim.brdf.topography.TopographyAnalysis`; lengths in mm."""
    from ..brdf.psd import KCorrelation, periodogram

    a = analysis
    h = np.asarray(heights, np.float64)
    h = h - h.mean()
    ny, nx = h.shape
    fig = _figure((13.0, 4.2))
    ax0, ax1, ax2 = fig.subplots(1, 3)
    im = ax0.imshow(h * 1e6, origin="lower", cmap="viridis", aspect="equal",
                    extent=(0, nx * dx * 1e3, 0, ny * dy * 1e3))
    fig.colorbar(im, ax=ax0, label="height, nm")
    ax0.set_xlabel("x (tangential), um")
    ax0.set_ylabel("y (radial), um")
    ax0.set_title(f"Sq {a.sq_um * 1e3:.3g} nm, Sdq {a.sdq:.3g}")
    fx, fy, s = periodogram(h, dx, dy, "hann")
    kc = None if a.kc_note else KCorrelation(
        a.kc_sigma_um * 1e-3, 2 * math.pi * a.kc_correlation_tangential_um * 1e-3,
        2 * math.pi * a.kc_correlation_radial_um * 1e-3, a.kc_exponent)
    ix, iy = nx // 2, ny // 2  # zero frequency after fftshift
    for f, row, colour, name, at in (
            (fx[ix + 1:], s[iy, ix + 1:], "tab:blue", "fx (tangential)", lambda f: (f, 0.0)),
            (fy[iy + 1:], s[iy + 1:, ix], "tab:orange", "fy (radial)", lambda f: (0.0, f))):
        ax1.loglog(f * 1e-3, row * 1e12, ".", ms=2, color=colour, alpha=0.5, label=f"periodogram, {name}")
        if kc is not None:
            ax1.loglog(f * 1e-3, kc(*at(f)) * 1e12, "-", color=colour, lw=1.5,
                       label=f"K-correlation fit, {name}")
    ax1.set_xlabel("spatial frequency, 1/um")
    ax1.set_ylabel("PSD, um^4")
    ax1.set_title("K-correlation model: no fit (no knee inside the map)" if kc is None else
                  f"correlation lengths {a.kc_correlation_tangential_um:.3g} / "
                  f"{a.kc_correlation_radial_um:.3g} um, C = {a.kc_exponent:.3g}", fontsize=9)
    ax1.legend(fontsize=7)
    gy, gx = np.gradient(h, dy, dx)
    for g, alpha, colour, name in ((gx, a.alpha_tangential, "tab:blue", "tangential"),
                                   (gy, a.alpha_radial, "tab:orange", "radial")):
        lim = 5 * max(a.alpha_tangential, a.alpha_radial)
        hist, edges = np.histogram(g.ravel(), bins=121, range=(-lim, lim), density=True)
        c = 0.5 * (edges[1:] + edges[:-1])
        ax2.plot(c * 1e3, hist * 1e-3, color=colour, lw=1.2, label=f"slopes, {name}")
        ax2.plot(c * 1e3, np.exp(-(c / alpha) ** 2) / (math.sqrt(math.pi) * alpha) * 1e-3, "--",
                 color=colour, lw=1, label=f"Gaussian, alpha = {alpha:.3g}")
    ax2.set_xlabel("slope, mrad")
    ax2.set_ylabel("density, 1/mrad")
    ax2.set_title(f"{a.regime} (Rayleigh {a.rayleigh:.3g} at {a.wavelength_nm:g} nm, "
                  f"{a.incidence_deg:g} deg)", fontsize=9)
    ax2.legend(fontsize=7)
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    return path
