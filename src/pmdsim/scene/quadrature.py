"""Deterministic quadrature rules for the scattered bundle, and their error estimates.

A pixel's value is an integral ``I = int g(x) dmu(x)`` over a 2-D domain: the cone
``theta <= theta_max`` about P with the estimator's measure (``paper``/``weighted_mean``),
or the lobe's slope space with its Gaussian density (``radiometric``). A fixed sample set
is a quadrature rule; for the smooth integrands of a continuous monitor a Gauss product
rule errs exponentially little (docs/physics.md, "Sampling as quadrature"). The kernels
map points of the unit square to directions (:mod:`pmdsim.kernels.bundle`), so every rule
here is given as nodes ``(u1, u2)`` in that square with weights ``w`` (sum 1) in the
square's uniform measure; the kernels multiply each ray's BRDF weight by ``w``.

Rules (:func:`cone_rule`, :func:`hermite_rule`, :func:`unit_rule`):

- cone estimators: Gauss-Legendre in the kernel's radial coordinate (``u1 = theta /
  theta_max`` for ``polar``, ``(1 - cos theta) / (1 - cos theta_max)`` for ``solid_angle``:
  the estimator's own measure is uniform in u1) times the periodic trapezoid rule in
  ``phi``. The phi-average of a smooth function on the cone is smooth in ``theta^2``, so
  both measures converge exponentially. When the lobe is much narrower than the cone
  (``lobe_sigma`` < theta_max / 3), the radial nodes are laid out in the lobe's radial
  distribution inside the cone (Gauss-Legendre after the inverse CDF of a Gaussian of
  standard deviation ``1.5 lobe_sigma``, truncated to the cone) and weighted by the measure
  over that density. When the lobe is anisotropic and narrower than the cone across
  (:func:`phi_map_ratio`: Fig. 3's lobe in its 1 deg cone and wider ones) the azimuths
  follow it too: the trapezoid's nodes ``t`` become ``phi = atan2(rho sin t, cos t)``
  (:func:`phi_map`, the angular distribution of a central Gaussian of axis ratio ``rho``,
  analytic and periodic: the trapezoid keeps its exponential convergence), with phi = 0
  on the lobe's long axis, onto which the render turns each pixel's cone basis
  (:meth:`pmdsim.scene.sampling.ConeSampling.orient`); an even number of azimuths (nodes in
  pairs phi, phi + pi, as the lobe's halves). Where the cone is much wider than the lobe's
  narrow axis (``theta_max > 10 narrow``: Fig. 3's lobe in a 2 or 4 deg cone) the mapped
  azimuths need fewer nodes and the radial profile more (the phi-integrated lobe has a
  core as narrow as the lobe's narrow axis and falls as 1 / theta beyond it): two azimuths
  per theta node (:func:`cone_order` ``ratio``). Against SciPy's cubature: Fig. 3's lobe
  in a 4 deg cone, 1024 nodes (22 x 46): <= 3e-6 mrad, where the plain 16 x 64 rule errs
  0.1-0.3 mrad (the mapped 16 x 64: 7e-4); in the 1 deg cone 8 x 32: <= 1e-4 mrad (was
  9e-4);
- radiometric estimator with a Gaussian slope density (Ward, Beckmann, ``gaussian``):
  Gauss-Hermite in both normalised slopes ``a / alpha_x``, ``b / alpha_y`` (the slope
  density is ``exp(-x^2 - y^2) / pi``), mapped to the kernel's
  ``(u1, u2) = (exp(-(x^2 + y^2)), atan2(y, x) / 2 pi)``;
- tabulated and grating-order densities: Gauss-Legendre in both coordinates of the unit
  square (the kernel's inverse CDF maps them to the density): exact for piecewise-constant
  densities cell by cell in the limit, but the cell edges make the integrand piecewise
  smooth, so these use randomised QMC by default (:func:`sampling_plan`).

Error of the rendered rule: two **embedded** rules, of about 3/4 the order in each
coordinate (:func:`embedded_order`) and as far below that again
(:func:`second_embedded_order`; 8 x 32 -> 6 x 24 -> 4 x 16: 81 % more rays), are rendered
too (the second, which enters only medians, on a grid of pixels on large cameras:
:func:`pmdsim.render.convergence_grid.convergence_stride`). ``dS1 = S - S_embedded`` is the error of the coarser rule, so
``|Im(dS1 conj S)| / |S|^2 + 0.1 |dS1| / |S|`` (phase difference plus a floor for the
pre-asymptotic case) bounds the rendered rule's phase error, by 10 to 1000 x where the rule
converges fast. ``|dS1| / |dS2|`` (median over the pixels of a fringe) is the observed
convergence factor per step; when it shows the asymptotic regime (its prediction
``q = median(|dS1| / |dS2|)^k`` for ``E(rule) / E(embedded)``, :func:`convergence_exponent`,
is below 1/10 and the median ``|dS1| / |S|`` is below 2e-3) the statement is scaled by it,
with a safety factor 10 on the phase difference (:func:`pmdsim.render.results.phase_error`;
cone rules only: Gauss-Hermite rules keep the unscaled statement, :func:`convergence_exponent`).
Tested against SciPy's adaptive cubature: >= 95 % of pixels bounded, median stated/true
about 9 (X) and 140 (Y) for the finest Fig. 3 fringe (50 and 10 before the azimuths
followed the lobe; the unscaled statement: 800 and 90); on 2 and 4 deg cones (4 x 16 to
22 x 46) it bounded 100 % of (pixel, fringe) against the 45 x 90 rule, 4 deg 22 x 46 a median
80-270 x the true error (with four azimuths per theta node on those cones the mapped rule's
phase error, set by its radial order, converged more slowly than the modulus that
dominates ``|dS1| / |dS2|``, and the scaled statement bounded only 85-87 % on 2 deg at
10 x 40 and 11 x 44). Where the integrand is not smooth (a
``nearest`` monitor's pixel steps, dots, images) the rule converges slowly and the
difference says little: there **randomised QMC** (``rqmc``: R independent Owen-scrambled
Sobol sets of N / R points, :func:`sobol_points`) gives an unbiased mean and its standard
error ``s / sqrt(R)``, stated as ``t(0.975, R - 1) s / sqrt(R)`` (95 % per pixel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Kinds of rule (``Rule.kind``).
KINDS = ("cone", "hermite", "unit", "sobol", "lattice")


@dataclass(frozen=True)
class Rule:
    """Nodes ``(u1, u2)`` (M,) in the unit square and weights ``w`` (M,), sum 1.

    ``order``: (n1, n2) of a product rule ((M, 1) for point sets); ``kind``: one of
    :data:`KINDS`; ``phi_rho``: the axis ratio of a cone rule's azimuth map
    (:func:`phi_map`), None for the plain trapezoid."""

    u1: np.ndarray
    u2: np.ndarray
    w: np.ndarray
    order: tuple[int, int]
    kind: str
    phi_rho: float | None = None

    @property
    def n(self) -> int:
        return int(self.u1.size)

    def describe(self) -> str:
        n1, n2 = self.order
        names = {"cone": "Gauss-Legendre theta x trapezoid phi",
                 "hermite": "Gauss-Hermite x Gauss-Hermite in slope space",
                 "unit": "Gauss-Legendre x Gauss-Legendre in the lobe's CDF coordinates",
                 "sobol": "scrambled Sobol points", "lattice": "Fibonacci lattice"}
        text = f"{names[self.kind]} {n1} x {n2}" if n2 > 1 else f"{names[self.kind]} ({n1})"
        if self.phi_rho is not None:
            text += f" (phi following the lobe, rho {self.phi_rho:.2f})"
        return text


def _gauss_legendre_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes in (0, 1) and weights (sum 1)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def cone_order(n_nodes: int, ratio: int = 4) -> tuple[int, int]:
    """(n_theta, n_phi) of the cone rule of at most ``n_nodes`` nodes: about ``ratio`` = 4
    times as many phi nodes as theta nodes (the integrand turns once round the cone in phi,
    its radial profile is a fraction of a Gaussian in theta), ``n_phi >= 4``. ``ratio`` 2
    where the azimuths follow a lobe much narrower than the cone across
    (:func:`phi_map_ratio`, ``theta_max > 10 narrow``): the mapped azimuths need fewer nodes
    and the radial profile (the lobe's narrow core and wide streak) more."""
    if n_nodes < 1:
        raise ValueError(f"n_nodes must be >= 1, got {n_nodes}")
    nt = max(1, int(math.isqrt(max(n_nodes, ratio) // ratio)))
    nphi = max(1, n_nodes // nt)
    return nt, nphi


def square_order(n_nodes: int) -> tuple[int, int]:
    """(n, n) with n^2 <= n_nodes: the product rules of the lobe's slope space."""
    n = max(1, int(math.isqrt(max(n_nodes, 1))))
    return n, n


def embedded_order(order: tuple[int, int]) -> tuple[int, int]:
    """About 3/4 of the order in each coordinate (at least 1, and below the order where it
    is above 1): the embedded rule whose difference estimates the error."""
    return tuple(max(1, min(n - 1, int(round(0.75 * n)))) if n > 1 else 1 for n in order)


def second_embedded_order(order: tuple[int, int]) -> tuple[int, int]:
    """The second embedded rule, as far below the embedded rule as that is below the rule
    (``2 m - n`` in each coordinate, at least 1; 8 x 32 -> 6 x 24 -> 4 x 16): its
    difference gives the observed convergence factor (:func:`convergence_exponent`)."""
    return tuple(max(1, 2 * m - n) for n, m in zip(order, embedded_order(order)))


def convergence_exponent(order: tuple[int, int], kind: str = "cone") -> float | None:
    """``k = (L0 - L1) / (L1 - L2)``, ``L = sqrt(n1 n2)`` (the rule's linear order) of the
    rule, its embedded and its second embedded rule: an error falling exponentially in L,
    ``E(L) ~ rho^L``, gives ``E(rule) / E(embedded) = (E(embedded) / E(second))^k``; None
    when the three rules are not of decreasing order (orders of 1 or 2), and for rules other
    than the cone's product rule (``kind``): the scaling was validated on cone rules only; on
    the radiometric Gauss-Hermite rules (8 x 8 to 11 x 11, a Ward lobe with unequal alphas
    under 16 px fringes) the scaled statement bounded the true error in only 80-88 % of the
    pixels (``tests/studies/test_budget_error.py``), so they keep the unscaled embedded statement."""
    if kind != "cone":
        return None
    m1, m2 = embedded_order(order), second_embedded_order(order)
    lin = [math.sqrt(a * b) for a, b in (order, m1, m2)]
    if not lin[0] > lin[1] > lin[2]:
        return None
    return (lin[0] - lin[1]) / (lin[1] - lin[2])


def _lobe_radial_map(t, scale, theta_max, solid_angle):
    """The kernel's radial coordinate u1 at CDF value t (array in (0, 1)) of the lobe's
    radial density inside the cone, and that density of u1 (normalised on [0, 1]), so that
    ``int_0^1 g(u1) du1 = int_0^1 g(u1(t)) / density(u1(t)) dt``.

    The density is ``exp(-theta^2 / (2 scale^2))`` in the estimator's measure, written so
    that its CDF inverts in closed form: a truncated normal in ``u1 = theta / theta_max``
    (polar), an exponential in ``u1 = (1 - cos theta) / (1 - cos theta_max)`` with
    ``1 - cos theta ~ theta^2 / 2`` (solid_angle)."""
    from scipy.special import erf, erfinv

    if solid_angle:
        lam = (1.0 - math.cos(theta_max)) / scale**2
        norm = -math.expm1(-lam)
        u = -np.log1p(-t * norm) / lam
        return u, lam * np.exp(-lam * u) / norm
    su = scale / theta_max
    c = math.sqrt(2.0) * su
    e1 = erf(1.0 / c)
    u = c * erfinv(t * e1)
    return u, np.exp(-((u / c) ** 2)) * (2.0 / (math.sqrt(math.pi) * c)) / e1


def phi_map(t, rho: float):
    """The azimuth ``phi = atan2(rho sin t, cos t)`` of the angle ``t`` (array, rad) and
    ``dphi/dt = rho / (cos^2 t + rho^2 sin^2 t)``: the angular distribution of a central
    Gaussian of axis ratio ``rho`` about its long axis (phi = 0), analytic and periodic
    (``phi(t + 2 pi) = phi(t) + 2 pi``), so that the trapezoid rule in ``t`` keeps its
    exponential convergence and puts ``1 / rho`` times as many nodes per radian along the
    long axis (phi = 0, pi) as the plain rule, ``rho`` times as many across it."""
    c, s = np.cos(t), np.sin(t)
    return np.arctan2(rho * s, c), rho / (c * c + (rho * rho) * (s * s))


def phi_map_ratio(narrow: float | None, wide: float | None, theta_max: float) -> float | None:
    """``rho`` of :func:`phi_map` for a lobe of angular standard deviations ``narrow`` <=
    ``wide`` (rad) in a cone of half angle ``theta_max``: ``sqrt(narrow / wide)`` when the
    lobe is anisotropic (``narrow <= wide / 2``) and narrower than the cone across
    (``theta_max > 3 narrow``, where the azimuthal profile at the cone's radii is peaked);
    None (the plain trapezoid) otherwise. Measured on Fig. 3's lobe (axis ratio 0.08):
    ``rho`` from 0.2 to 0.5 gives the same error on a 4 deg cone, 0.27-0.5 on a 1 deg cone,
    0.15 is worse there (docs/physics.md)."""
    if not (narrow and wide) or narrow <= 0 or wide <= 0:
        return None
    if narrow > 0.5 * wide or theta_max <= 3.0 * narrow:
        return None
    return math.sqrt(narrow / wide)


def cone_rule(order: tuple[int, int], scheme: str = "polar", theta_max: float = 0.0,
              lobe_sigma: float | None = None, phi_rho: float | None = None) -> Rule:
    """The product rule (n_theta, n_phi) over the cone in the kernel's unit square (module
    docstring). ``lobe_sigma`` (rad): the lobe's widest angular standard deviation; when
    it is below theta_max / 3 the radial nodes follow the lobe. ``phi_rho``: the azimuths
    follow an anisotropic lobe whose long axis is at phi = 0 (:func:`phi_map`; the
    kernels' per-pixel basis is turned onto that axis,
    :meth:`pmdsim.scene.sampling.ConeSampling.orient`); None: the plain trapezoid."""
    nt, nphi = order
    t, wt = _gauss_legendre_unit(nt)
    if lobe_sigma is not None and lobe_sigma > 0 and theta_max > 3.0 * lobe_sigma:
        u1, dens = _lobe_radial_map(t, 1.5 * lobe_sigma, theta_max, scheme == "solid_angle")
        wt = wt / dens
    else:
        u1 = t
    u2 = (np.arange(nphi) + 0.5) / nphi
    if phi_rho is None:
        w = np.repeat(wt, nphi) / nphi
    else:
        phi, dphi = phi_map(2.0 * math.pi * u2, phi_rho)
        u2 = np.mod(phi / (2.0 * math.pi), 1.0)
        u2 = np.where(u2 >= 1.0, 0.0, u2)  # mod of a tiny negative number rounds to 1
        w = np.outer(wt, dphi / nphi).ravel()
    U1, U2 = np.meshgrid(u1, u2, indexing="ij")
    return Rule(U1.ravel().copy(), U2.ravel().copy(), w, (nt, nphi), "cone", phi_rho)


def hermite_rule(order: tuple[int, int]) -> Rule:
    """Product Gauss-Hermite rule in the normalised slopes (x, y) (weight exp(-x^2 - y^2)
    / pi), as the kernel's unit-square points of the Walter slope map. Nodes and weights
    from SciPy's ``roots_hermite`` (NumPy's ``hermgauss`` overflows above order ~300: NaN
    weights at order 512, the pilot's finer rule of a 128 x 128 rule at the monitor's
    edge, whose phase was then stated as known to within pi)."""
    from scipy.special import roots_hermite

    nx, ny = order
    x, wx = roots_hermite(nx)
    y, wy = roots_hermite(ny)
    X, Y = np.meshgrid(x, y, indexing="ij")
    W = np.outer(wx, wy) / math.pi
    r2 = (X * X + Y * Y).ravel()
    u1 = np.exp(-r2)
    u2 = np.mod(np.arctan2(Y, X).ravel() / (2 * math.pi), 1.0)
    # a node at the origin (odd orders) has u1 = 1, which the kernel's s - floor(s) turns
    # into 0 (r = infinity): move it to the largest double below 1 (r = 1e-8, the same
    # direction to round-off)
    u1 = np.minimum(u1, np.nextafter(1.0, 0.0))
    return Rule(u1, u2, W.ravel(), (nx, ny), "hermite")


def unit_rule(order: tuple[int, int]) -> Rule:
    """Gauss-Legendre x Gauss-Legendre in the unit square."""
    t1, w1 = _gauss_legendre_unit(order[0])
    t2, w2 = _gauss_legendre_unit(order[1])
    U1, U2 = np.meshgrid(t1, t2, indexing="ij")
    return Rule(U1.ravel().copy(), U2.ravel().copy(), np.outer(w1, w2).ravel(), order, "unit")


def sobol_points(n: int, seed: int, replicate: int) -> Rule:
    """``n`` Owen-scrambled Sobol points (SciPy's ``qmc.Sobol``, seeded by
    ``[seed, replicate]``), equal weights. ``n`` need not be a power of 2 (the first n
    points of the sequence; a power of 2 balances best)."""
    import warnings

    from scipy.stats import qmc

    eng = qmc.Sobol(d=2, scramble=True, seed=np.random.default_rng([seed, 7919, replicate]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "balance properties" for n != 2^m
        pts = eng.random(n)
    # strictly inside (0, 1): the kernels' maps take logarithms of u1
    pts = np.clip(pts, 1e-12, 1.0 - 1e-12)
    return Rule(pts[:, 0].copy(), pts[:, 1].copy(), np.full(n, 1.0 / n), (n, 1), "sobol")


def student_t975(dof: int) -> float:
    """The 97.5 % quantile of Student's t with ``dof`` degrees of freedom."""
    from scipy.stats import t

    return float(t.ppf(0.975, dof))
