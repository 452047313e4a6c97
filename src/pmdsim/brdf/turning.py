"""From the machining to the lobe: diamond-turned surfaces (pure functions).

A turning tool of nose radius ``r`` advanced by ``feed`` ``f`` per revolution leaves
circular arcs ``h(x) = r - sqrt(r^2 - x^2)``, ``x`` in ``[-f/2, f/2]``, repeated every ``f``
along the radius (kinematic roughness ``Rt = f^2 / (8 r)``), plus random roughness of RMS
height ``Rq`` and correlation length ``l`` (Gaussian autocorrelation: RMS slope
``sqrt(2) Rq / l`` per axis, ``alpha = 2 Rq / l``).

Two optical regimes (``docs/texture.md``):

- **geometric**: micro-facet reflection on the slope density: radial slopes of the arcs
  (uniform in ``x``, so uniform over ``+-f/(2r)`` for small slopes; RMS ``f / (2 sqrt(3) r)``,
  ``alpha_radial = f / (sqrt(6) r)``) convolved with the random slopes;
  :func:`pmdsim.brdf.slope_density.kinematic_slopes`.
- **diffractive**: the grooves are a grating of period ``f``; light leaves in orders
  ``sin(theta_m) = sin(theta_i) + m lambda / f`` (radial plane) with scalar Kirchhoff
  (thin phase screen) efficiencies
  ``eta_m = |(1/f) int exp(i k (cos theta_i + cos theta_m) h(x)) exp(-i 2 pi m x / f) dx|^2``,
  each order carrying the random-roughness lobe: :func:`grating_orders`.

All lengths are in millimetres unless a name says otherwise (``_um``, ``_nm``); angles in
radians unless ``_deg``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .slope_density import GratingOrders, arc_max_slope

#: Default spectrum: a white display's R, G, B primaries (nm) seen by a camera with a flat
#: response (equal weights). Give ``wavelengths_nm``/``spectral_weights`` for a real one.
DEFAULT_WAVELENGTHS_NM = (610.0, 545.0, 465.0)
DEFAULT_WEIGHTS = (1.0, 1.0, 1.0)

#: Orders inside the geometric lobe above which the order comb is finer than the lobe it
#: samples and the geometric (kinematic) model is used by default.
GEOMETRIC_MIN_ORDERS = 20.0


# =========================================================================== statistics
def kinematic_rt(feed: float, radius: float) -> float:
    """Peak-to-valley height of the arc profile: r - sqrt(r^2 - f^2/4) (~ f^2 / (8 r))."""
    arc_max_slope(feed, radius)
    return radius - math.sqrt(radius**2 - feed**2 / 4)


def kinematic_rms_slope(feed: float, radius: float, exact: bool = True) -> float:
    """RMS radial slope of the arcs, x uniform over a period. Exact:
    mean of x^2 / (r^2 - x^2) = (2 r atanh(f / 2r) - f) / f; small-slope: f / (2 sqrt(3) r)."""
    arc_max_slope(feed, radius)
    if not exact:
        return feed / (2 * math.sqrt(3) * radius)
    return math.sqrt((2 * radius * math.atanh(feed / (2 * radius)) - feed) / feed)


def random_rms_slope(rq: float, correlation_length: float) -> float:
    """RMS slope per axis of Gaussian-correlated roughness: sqrt(2) Rq / l."""
    if not (rq >= 0 and correlation_length > 0):
        raise ValueError("Rq must be >= 0 and the correlation length > 0")
    return math.sqrt(2) * rq / correlation_length


def rayleigh_parameter(rq: float, wavelength: float, theta_i: float = 0.0) -> float:
    """4 pi Rq cos(theta_i) / lambda: << 1 smooth (specular), >~ 1 rough."""
    return 4 * math.pi * rq * math.cos(theta_i) / wavelength


def specular_share(rq: float, wavelength: float, theta_i: float = 0.0) -> float:
    """exp(-(4 pi Rq cos(theta_i) / lambda)^2): the coherent (specular) share of random
    roughness Rq (Davies/Beckmann total integrated scatter)."""
    return math.exp(-rayleigh_parameter(rq, wavelength, theta_i) ** 2)


# =========================================================================== grating
def order_sines(wavelength: float, feed: float, theta_i: float, orders) -> np.ndarray:
    """sin(theta_m) = sin(theta_i) + m lambda / f, (K,); |.| >= 1 means evanescent."""
    return math.sin(theta_i) + np.asarray(orders, np.float64) * wavelength / feed


def propagating_orders(wavelength: float, feed: float, theta_i: float) -> np.ndarray:
    """The orders m with |sin(theta_i) + m lambda / f| < 1."""
    s = math.sin(theta_i)
    lo = math.ceil((-1 - s) * feed / wavelength)
    hi = math.floor((1 - s) * feed / wavelength)
    m = np.arange(lo, hi + 1)
    return m[np.abs(order_sines(wavelength, feed, theta_i, m)) < 1]


def arc_profile(x, radius: float) -> np.ndarray:
    """h(x) = r - sqrt(r^2 - x^2) (valley at x = 0)."""
    x = np.asarray(x, np.float64)
    return radius - np.sqrt(radius**2 - x * x)


def order_efficiencies(feed: float, radius: float, wavelength: float, theta_i: float,
                       orders, n_nodes: int | None = None) -> np.ndarray:
    """Scalar Kirchhoff (thin phase screen) efficiencies eta_m (K,) of the arc grating:
    |(1/f) int_{-f/2}^{f/2} exp(i (2 pi / lambda)(cos theta_i + cos theta_m) h(x))
    exp(-i 2 pi m x / f) dx|^2, by Gauss-Legendre quadrature (nodes enough for the
    largest phase); evanescent orders get 0."""
    orders = np.asarray(orders, np.float64)
    s = order_sines(wavelength, feed, theta_i, orders)
    prop = np.abs(s) < 1
    cos_m = np.sqrt(np.where(prop, 1 - s * s, 0.0))
    k = 2 * math.pi / wavelength * (math.cos(theta_i) + cos_m)
    h = arc_profile(np.array([0.0, feed / 2]), radius)
    phase_span = float(np.max(k) * (h[1] - h[0]) + 2 * math.pi * np.max(np.abs(orders), initial=0))
    # composite Gauss-Legendre, 16 nodes per panel, ~ 4 nodes per radian of phase
    n = n_nodes or int(min(40000, max(256, 4 * phase_span)))
    n_pan = max(1, -(-n // 16))
    xg, wg = np.polynomial.legendre.leggauss(16)
    edges = np.linspace(-0.5, 0.5, n_pan + 1)
    half = 0.5 * np.diff(edges)[:, None]
    x = ((half * xg + 0.5 * (edges[1:] + edges[:-1])[:, None]) * feed).ravel()
    w = (half * wg).ravel()  # (1/f) dx over [-f/2, f/2]
    hx = arc_profile(x, radius)
    out = np.zeros(orders.size)
    for c0 in range(0, orders.size, 64):
        sl = slice(c0, c0 + 64)
        ph = k[sl, None] * hx - 2 * math.pi * orders[sl, None] * x / feed
        amp = np.exp(1j * ph) @ w
        out[sl] = np.abs(amp) ** 2
    return np.where(prop, out, 0.0)


def grating_orders(feed: float, radius: float, alpha_random: tuple[float, float],
                   wavelengths=DEFAULT_WAVELENGTHS_NM, weights=DEFAULT_WEIGHTS,
                   theta_i: float = 0.0, min_weight: float = 1e-9) -> GratingOrders:
    """The diffractive model's slope mixture: every propagating order of every wavelength
    (``wavelengths`` in nm, spectral ``weights`` = display spectrum x camera response),
    weight = spectral weight x efficiency normalised per wavelength; orders with a weight
    below ``min_weight`` of the largest are dropped. ``alpha_random`` = (tangential,
    radial) alphas of the random roughness, the lobe about each order."""
    wl = np.asarray(wavelengths, np.float64) * 1e-6
    sw = np.asarray(weights, np.float64)
    if wl.shape != sw.shape or wl.size == 0 or np.any(wl <= 0) or np.any(sw < 0) or not sw.sum() > 0:
        raise ValueError("wavelengths_nm and spectral_weights must be equally long, "
                         "wavelengths > 0, weights >= 0 with a positive sum")
    qs, ws = [], []
    for lam, wgt in zip(wl, sw / sw.sum()):
        if wgt == 0:
            continue
        m = propagating_orders(lam, feed, theta_i)
        eta = order_efficiencies(feed, radius, lam, theta_i, m)
        qs.append(m * lam / feed)
        ws.append(wgt * eta / eta.sum())
    q = np.concatenate(qs)
    w = np.concatenate(ws)
    keep = w >= min_weight * w.max()
    return GratingOrders(q[keep], w[keep], float(alpha_random[0]), float(alpha_random[1]))


# =========================================================================== report
@dataclass(frozen=True)
class TextureParameters:
    """What the machining means optically (see :func:`texture_parameters`)."""

    feed_um: float
    nose_radius_mm: float
    rq_um: float
    correlation_length_um: float
    wavelength_nm: float
    incidence_deg: float
    distance_mm: float
    pixel_pitch_mm: float
    rt_um: float  # kinematic peak-to-valley
    kinematic_max_slope: float  # f / (2 sqrt(r^2 - f^2/4))
    kinematic_rms_slope: float  # exact
    kinematic_alpha_radial: float  # sqrt(2) x exact RMS slope (~ f / (sqrt(6) r))
    kinematic_alpha_radial_small_slope: float  # f / (sqrt(6) r)
    random_rms_slope: float  # per axis
    random_alpha: float  # 2 Rq / l
    alpha_radial: float  # sqrt(kinematic^2 + random^2): Ward/Beckmann equivalent
    alpha_tangential: float  # random only
    rayleigh_random: float  # 4 pi Rq cos(theta_i) / lambda
    specular_share_random: float
    rayleigh_kinematic: float  # 4 pi Rt cos(theta_i) / lambda (phase depth of the grooves)
    order_spacing_rad: float  # lambda / (f cos(theta_0)) near the specular direction
    order_spacing_monitor_px: float
    lobe_width_rad: float  # full width of the geometric kinematic lobe, 2 f / r
    lobe_width_monitor_px: float
    orders_in_lobe: float  # lobe width / order spacing
    regime: str  # "specular" | "diffractive" | "geometric"
    regime_reason: str

    def as_dict(self) -> dict:
        return asdict(self)


def texture_parameters(feed_um: float, nose_radius_mm: float, rq_um: float = 0.0,
                       correlation_length_um: float = 10.0, wavelength_nm: float = 545.0,
                       incidence_deg: float = 0.0, distance_mm: float = 600.0,
                       pixel_pitch_mm: float = 0.25) -> TextureParameters:
    """Slope statistics, equivalent alphas, specular share, grating order spacing on a
    monitor at ``distance_mm`` (facing the reflected ray, pixels of ``pixel_pitch_mm``) and
    the regime of a turned surface."""
    f = feed_um * 1e-3
    r = nose_radius_mm
    lam = wavelength_nm * 1e-6
    th = math.radians(incidence_deg)
    if not (f > 0 and r > 0 and lam > 0 and distance_mm > 0 and pixel_pitch_mm > 0):
        raise ValueError("feed, nose radius, wavelength, distance and pixel pitch must be > 0")
    rt = kinematic_rt(f, r)
    k_rms = kinematic_rms_slope(f, r)
    r_rms = random_rms_slope(rq_um, correlation_length_um)
    a_kin = math.sqrt(2) * k_rms
    a_rand = math.sqrt(2) * r_rms
    rq = rq_um * 1e-3
    ray_r = rayleigh_parameter(rq, lam, th)
    ray_k = rayleigh_parameter(rt, lam, th)
    spacing = lam / (f * math.cos(th))
    lobe = 2 * f / r
    n_orders = lobe / spacing
    if ray_k < 0.5:
        regime, why = "specular", (f"the grooves' phase depth 4 pi Rt cos / lambda = {ray_k:.2f} "
                                   "< 0.5: most light stays in the zero order")
    elif n_orders < GEOMETRIC_MIN_ORDERS:
        regime, why = "diffractive", (f"{n_orders:.1f} grating orders inside the kinematic lobe "
                                      f"(< {GEOMETRIC_MIN_ORDERS:g}): the lobe is a comb of "
                                      f"orders {spacing * distance_mm / pixel_pitch_mm:.1f} "
                                      "monitor px apart")
    else:
        regime, why = "geometric", (f"{n_orders:.0f} grating orders inside the kinematic lobe: "
                                    "the comb is finer than the lobe")
    return TextureParameters(
        feed_um, nose_radius_mm, rq_um, correlation_length_um, wavelength_nm, incidence_deg,
        distance_mm, pixel_pitch_mm, rt * 1e3, arc_max_slope(f, r), k_rms, a_kin,
        f / (math.sqrt(6) * r), r_rms, a_rand, math.hypot(a_kin, a_rand), a_rand, ray_r,
        specular_share(rq, lam, th), ray_k, spacing, spacing * distance_mm / pixel_pitch_mm,
        lobe, lobe * distance_mm / pixel_pitch_mm, n_orders, regime, why)


def format_texture(p: TextureParameters) -> str:
    """A plain-text table of :class:`TextureParameters`."""
    rows = [
        ("feed f / nose radius r", f"{p.feed_um:g} um / {p.nose_radius_mm:g} mm"),
        ("Rq / correlation length", f"{p.rq_um:g} um / {p.correlation_length_um:g} um"),
        ("wavelength / incidence", f"{p.wavelength_nm:g} nm / {p.incidence_deg:g} deg"),
        ("kinematic Rt = f^2/(8r)", f"{p.rt_um:.4g} um"),
        ("kinematic max slope", f"{p.kinematic_max_slope:.5g}"),
        ("kinematic RMS slope", f"{p.kinematic_rms_slope:.5g}"),
        ("alpha_radial, kinematic part", f"{p.kinematic_alpha_radial:.4f} "
                                         f"(f/(sqrt(6) r) = {p.kinematic_alpha_radial_small_slope:.4f})"),
        ("random RMS slope / alpha", f"{p.random_rms_slope:.4g} / {p.random_alpha:.4g}"),
        ("Ward/Beckmann alpha_radial", f"{p.alpha_radial:.4f}"),
        ("Ward/Beckmann alpha_tangential", f"{p.alpha_tangential:.4f}"),
        ("Rayleigh 4 pi Rq cos/lambda", f"{p.rayleigh_random:.3g} (specular share "
                                        f"{p.specular_share_random:.3g})"),
        ("groove phase 4 pi Rt cos/lambda", f"{p.rayleigh_kinematic:.3g}"),
        ("order spacing", f"{p.order_spacing_rad * 1e3:.3f} mrad = "
                          f"{p.order_spacing_monitor_px:.2f} monitor px at {p.distance_mm:g} mm"),
        ("kinematic lobe full width", f"{p.lobe_width_rad * 1e3:.2f} mrad = "
                                      f"{p.lobe_width_monitor_px:.1f} monitor px"),
        ("orders inside the lobe", f"{p.orders_in_lobe:.1f}"),
        ("regime", f"{p.regime}: {p.regime_reason}"),
    ]
    w = max(len(a) for a, _ in rows)
    return "\n".join(f"{a:<{w}}  {b}" for a, b in rows)
