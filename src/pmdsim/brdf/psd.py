"""Surface power spectral densities (PSD): the models both scattering models use.

The two-sided 2-D PSD per unit spatial-frequency area (``sum S dfx dfy = Sq^2``; lengths
in mm): the anisotropic K-correlation (ABC) model :class:`KCorrelation`, a tabulated PSD
(:class:`TabulatedPSD`), a height map's Hann-windowed periodogram (:func:`periodogram`),
the K-correlation fit to it by Whittle's likelihood (:func:`fit_k_correlation`), and a
Gaussian random surface of a given PSD (:func:`synthesize`, explicit seed). The
topography model (:mod:`pmdsim.brdf.topography`) and the Rayleigh-Rice halo
(:mod:`pmdsim.brdf.rayleigh_rice`) take them.
"""

from __future__ import annotations
import math
from dataclasses import dataclass
import numpy as np

#: Sq (mm) at or below which a levelled map is flat: 0.1 pm, far below any instrument's
#: noise (the rounding residue of levelling a constant or tilted map is ~1e-16 of its heights).
FLAT_SQ_MM = 1e-10
#: A K-correlation fit with C - 1 below this, or a correlation length B / (2 pi) above
#: this many times the map's extent, is not resolved by the map (the ABC model runs off
#: to a power law or a knee beyond the data: a periodic groove, white noise).
KC_MIN_C_MINUS_1 = 1e-3
KC_MAX_EXTENTS = 100.0


class FlatTopography(ValueError):
    """The map has no height variation left (Sq <= :data:`FLAT_SQ_MM` after levelling)."""


class KCorrelationUnresolved(ValueError):
    """The K-correlation (ABC) model does not describe the map's periodogram."""



# =========================================================================== PSD models
@dataclass(frozen=True)
class KCorrelation:
    """Anisotropic K-correlation (ABC) PSD with RMS height ``sigma`` (mm), ``bx``, ``by``
    (mm; correlation lengths ``b / (2 pi)``) and exponent ``c`` > 1 (see module doc)."""

    sigma: float
    bx: float
    by: float
    c: float = 2.0

    def __post_init__(self):
        if not (self.sigma >= 0 and self.bx > 0 and self.by > 0 and self.c > 1):
            raise ValueError(f"K-correlation needs sigma >= 0, bx, by > 0 and c > 1, got {self}")

    @property
    def a(self) -> float:
        return self.sigma**2 * self.bx * self.by * (self.c - 1) / (2 * math.pi)

    @property
    def correlation_lengths(self) -> tuple[float, float]:
        return self.bx / (2 * math.pi), self.by / (2 * math.pi)

    def __call__(self, fx, fy):
        q = 1.0 + (self.bx * np.asarray(fx, np.float64)) ** 2 + (self.by * np.asarray(fy, np.float64)) ** 2
        return self.a * q ** (-(self.c + 1) / 2)

    def band_variance(self, fmax: float) -> float:
        """Variance inside the elliptical band (Bx fx)^2 + (By fy)^2 <= (B fmax)^2 with
        B = min(bx, by): sigma^2 (1 - (1 + (B fmax)^2)^((1 - C) / 2))."""
        b = min(self.bx, self.by)
        return self.sigma**2 * (1 - (1 + (b * fmax) ** 2) ** ((1 - self.c) / 2))


@dataclass(frozen=True, eq=False)
class TabulatedPSD:
    """A PSD on the periodogram grid (``fx`` (nx,), ``fy`` (ny,) increasing, ``s`` (ny, nx)),
    bilinear between nodes, 0 outside the measured band."""

    fx: np.ndarray
    fy: np.ndarray
    s: np.ndarray

    def __call__(self, fx, fy):
        from scipy.interpolate import RegularGridInterpolator

        f = RegularGridInterpolator((self.fy, self.fx), self.s, bounds_error=False, fill_value=0.0)
        fx, fy = np.broadcast_arrays(np.asarray(fx, np.float64), np.asarray(fy, np.float64))
        return f(np.stack([fy, fx], -1))

    @property
    def variance(self) -> float:
        return float(self.s.sum() * (self.fx[1] - self.fx[0]) * (self.fy[1] - self.fy[0]))


# =========================================================================== spectra
def periodogram(heights, dx: float, dy: float, window: str = "hann"):
    """Two-sided 2-D PSD of a height map: ``(fx (nx,), fy (ny,), S (ny, nx))``, zero
    frequency in the middle (``fftshift``), normalised so that ``S.sum() dfx dfy`` is the
    mean square height (the window's power is divided out). ``window``: ``"hann"`` (for
    measured, non-periodic maps: little leakage of the levelling residue) or ``"none"``."""
    h = np.asarray(heights, np.float64)
    h = h - h.mean()
    ny, nx = h.shape
    if window == "hann":
        w = np.outer(np.hanning(ny + 2)[1:-1], np.hanning(nx + 2)[1:-1])
    elif window == "none":
        w = np.ones_like(h)
    else:
        raise ValueError(f"window must be 'hann' or 'none', got {window!r}")
    spec = np.fft.fftshift(np.abs(np.fft.fft2(h * w)) ** 2)
    s = spec * dx * dy / (nx * ny * np.mean(w * w))
    fx = np.fft.fftshift(np.fft.fftfreq(nx, dx))
    fy = np.fft.fftshift(np.fft.fftfreq(ny, dy))
    return fx, fy, s


@dataclass(frozen=True)
class KCorrelationFit:
    """A fitted :class:`KCorrelation` and the standard errors of its parameters (relative:
    ``rel_err`` = (sigma, bx, by, c)), from Whittle's Fisher information."""

    model: KCorrelation
    rel_err: tuple[float, float, float, float]


def fit_k_correlation(fx, fy, s, c0: float = 2.0, effective_fraction: float = 1.0) -> KCorrelationFit:
    """Whittle fit of :class:`KCorrelation` to a periodogram (zero frequency left out).

    Standard errors from the Fisher information ``(n / 2) mean(g g^T)``, ``g`` the gradient
    of ``log S`` in the parameters, ``n`` the frequencies used x ``effective_fraction``
    (the share of independent periodogram values: 1 without a window; see
    :func:`periodogram`'s ``window``); the half: a real map's spectrum is Hermitian."""
    from scipy.optimize import minimize

    fxx, fyy = np.meshgrid(fx, fy)
    keep = (fxx != 0) | (fyy != 0)
    fxx, fyy, p = fxx[keep], fyy[keep], s[keep]
    dfa = (fx[1] - fx[0]) * (fy[1] - fy[0])
    var = float(s.sum() * dfa)
    if not (math.isfinite(var) and var > FLAT_SQ_MM**2 and np.all(np.isfinite(p))):
        raise FlatTopography(f"the periodogram holds no variance (Sq^2 = {var:.3g} mm^2): "
                             "a flat map has no PSD to fit")
    # start: the knee at a tenth of the band along each axis
    b0 = [10.0 / max(np.abs(fx).max(), 1e-30), 10.0 / max(np.abs(fy).max(), 1e-30)]
    f2x, f2y = fxx * fxx, fyy * fyy

    def grads(x):
        bx2, by2, e = math.exp(2 * x[1]), math.exp(2 * x[2]), (math.exp(x[3]) + 2) / 2
        q = 1 + bx2 * f2x + by2 * f2y
        lq = np.log(q)
        g = (np.ones_like(q), -e * 2 * bx2 * f2x / q, -e * 2 * by2 * f2y / q, -math.exp(x[3]) / 2 * lq)
        return x[0] - e * lq, g

    def nll(x):  # x = log A, log Bx, log By, log(C - 1); value and gradient
        lm, g = grads(np.clip(x, -300, 300))
        with np.errstate(over="ignore", invalid="ignore"):
            r = p * np.exp(-lm)  # p / m
        if not np.all(np.isfinite(r)):
            return 1e300, np.zeros(4)
        w = 1 - r
        return float(np.mean(lm + r)), np.array([np.mean(w * gi) for gi in g])

    extent = max(1.0 / (fx[1] - fx[0]), 1.0 / (fy[1] - fy[0]))  # the map's larger side

    def model(x):
        # sigma^2 = 2 pi A / (Bx By (C - 1)) in logarithms: no product under- or overflows
        bx, by, cm1 = math.exp(min(x[1], 700)), math.exp(min(x[2], 700)), math.exp(min(x[3], 700))
        if not (cm1 >= KC_MIN_C_MINUS_1 and
                max(bx, by) / (2 * math.pi) <= KC_MAX_EXTENTS * extent and min(bx, by) > 0):
            raise KCorrelationUnresolved(
                f"the K-correlation (ABC) model does not describe this map's PSD: the fit runs "
                f"to C - 1 = {cm1:.3g} and correlation lengths {bx / (2 * math.pi) * 1e3:.3g} / "
                f"{by / (2 * math.pi) * 1e3:.3g} um against a map of {extent * 1e3:.3g} um "
                "(a periodic groove, white noise or a power law: no knee inside the map)")
        sigma = math.sqrt(2 * math.pi) * math.exp(0.5 * (x[0] - x[1] - x[2] - x[3]))
        return KCorrelation(sigma, bx, by, 1 + cm1)

    starts = []
    for k in (1.0, 0.1):
        bx, by = b0[0] * k, b0[1] * k
        starts.append([math.log(var * bx * by * (c0 - 1) / (2 * math.pi)), math.log(bx),
                       math.log(by), math.log(c0 - 1)])
    r = min((minimize(nll, x0, jac=True, method="L-BFGS-B",
                      options=dict(maxiter=2000, ftol=1e-15, gtol=1e-12)) for x0 in starts),
            key=lambda r: r.fun)
    m = model(r.x)
    _, g = grads(r.x)
    g = np.stack(g)
    info = (p.size * effective_fraction / 2) * (g @ g.T) / p.size
    cov = np.linalg.pinv(info)
    js = np.array([0.5, -0.5, -0.5, -0.5])
    rel = (math.sqrt(max(js @ cov @ js, 0.0)), math.sqrt(max(cov[1, 1], 0.0)),
           math.sqrt(max(cov[2, 2], 0.0)), (m.c - 1) / m.c * math.sqrt(max(cov[3, 3], 0.0)))
    return KCorrelationFit(m, rel)


def window_fraction(window: str) -> float:
    """Share of independent periodogram values under a 2-D window: (mean w^2)^2 / mean w^4
    per axis (1 without a window; 0.514^2 for Hann)."""
    if window == "none":
        return 1.0
    return ((3 / 8) ** 2 / (35 / 128)) ** 2


def synthesize(psd, shape, dx: float, dy: float, seed: int) -> np.ndarray:
    """A periodic Gaussian random surface (``shape`` = (ny, nx)) whose expected periodogram
    is ``psd(fx, fy)`` (per unit frequency area): white noise filtered in Fourier space
    (``numpy.random.default_rng(seed)``)."""
    ny, nx = shape
    fx = np.fft.fftfreq(nx, dx)
    fy = np.fft.fftfreq(ny, dy)
    s = psd(fx[None, :], fy[:, None])
    s[0, 0] = 0.0
    rng = np.random.default_rng(seed)
    noise = np.fft.fft2(rng.standard_normal((ny, nx)))
    return np.real(np.fft.ifft2(noise * np.sqrt(s / (dx * dy)))) * 1.0
