"""Sample sets (quadrature rules) of the scattered bundle.

Every pixel value is an integral over a 2-D domain (docs/physics.md, "Sampling as
quadrature"). The kernels take points ``(u1, u2)`` of the unit square and weights ``w_ray``
and map the points to directions:

- cone estimators (``paper``, ``weighted_mean``), about the principal reflection P:
  ``polar``: theta = theta_max u1, phi = 2 pi u2 (uniform in inclination and azimuth, the
  paper's Fig. 2b; the density per solid angle is proportional to 1/sin(theta));
  ``solid_angle``: cos(theta) = 1 - u1 (1 - cos(theta_max)), phi = 2 pi u2;
- ``radiometric``: the BRDF's lobe (Walter 2005 slopes, :mod:`pmdsim.brdf.microfacet`, or a
  slope density's inverse CDF).

``mode`` chooses the points (``n_rays`` counts them):

- ``rule`` (default): a deterministic Gauss rule, :mod:`pmdsim.scene.quadrature` (cone:
  Gauss-Legendre theta x trapezoid phi; Gaussian lobes: Gauss-Hermite in slope space),
  no P; each sum's numerical error comes from the embedded rules of about 3/4 and 1/2
  the order (two smaller passes: :meth:`ConeSampling.error_passes`). Where the
  integrand is not smooth (a ``nearest`` monitor, dots, images, tabulated or grating-order
  slope densities) the renderer uses ``rqmc`` instead (and says so: ``Simulation.plan``);
- ``rqmc``: ``replicates`` independent scrambled Sobol sets of ``n_rays / replicates``
  points each; the value is their mean, the error ``t(0.975, R - 1) s / sqrt(R)``;
- ``stratified`` (the earlier default): P (ray 0, as in the paper) plus ``n_rays - 1``
  points of a Fibonacci lattice (u1 = (j + 1/2) / M, u2 = frac(j / golden ratio)), the
  same for every pixel (its error is a structured pattern, not estimated);
- ``random``: that lattice shifted per pixel by a seeded random offset (r1, r2) modulo 1
  (Cranley-Patterson rotation). The offsets of camera row ``r`` come from
  ``numpy.random.default_rng([seed, r])``: results do not depend on the tiling.

The radiometric estimator adds no P in any mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..kernels import bundle as kb
from . import quadrature as quad

#: Sampling modes.
MODES = ("rule", "rqmc", "stratified", "random")

_GOLDEN = (1.0 + 5.0**0.5) / 2.0


def fibonacci_lattice(m: int) -> tuple[np.ndarray, np.ndarray]:
    """The m-point Fibonacci lattice (u1, u2) in the unit square, u1 = (j + 1/2) / m in (0, 1),
    u2 = frac(j / golden ratio)."""
    j = np.arange(m, dtype=np.float64)
    return (j + 0.5) / max(m, 1), np.mod(j / _GOLDEN, 1.0)


@dataclass(frozen=True)
class ConeSampling:
    """The bundle's sample set (module docstring).

    ``lobe_sigma`` (rad): the lobe's widest angular standard deviation (sqrt(2) alpha):
    cone rules lay their radial nodes out in the lobe when it is narrower than a third of
    the cone. ``lobe_narrow`` (rad): its narrowest (sqrt(2) min(alpha_x, alpha_y)): an
    anisotropic lobe narrower than the cone across (:func:`~.quadrature.phi_map_ratio`)
    gets azimuths that follow it (:attr:`phi_rho`, :meth:`orient`). ``lobe_gaussian``: the radiometric sampler maps Gaussian slopes (Ward,
    Beckmann: Gauss-Hermite rule) rather than a tabulated CDF (Gauss-Legendre in the unit
    square; not smooth at the cells' edges). ``part``: which pass of an error estimate this
    set is (0: the rendered rule; in mode ``rule`` 1 = the embedded rule, 2 = the second
    embedded rule; in mode ``rqmc`` the replicate index).
    """

    n_rays: int = 100
    theta_max: float = np.deg2rad(1.0)  # rad
    scheme: str = "polar"
    mode: str = "stratified"
    seed: int = 0
    replicates: int = 8
    lobe_sigma: float | None = None
    lobe_gaussian: bool = True
    part: int = 0
    error_estimate: bool = True
    #: target of the stated phase error (rad, P95 over pixels) and the cap on n_rays for it
    target_error: float | None = None
    max_rays: int = 65536
    lobe_narrow: float | None = None

    def __post_init__(self):
        if self.n_rays < 1:
            raise ValueError(f"n_rays must be >= 1, got {self.n_rays}")
        if not 0 < self.theta_max < np.pi / 2:
            raise ValueError(f"theta_max must be in (0, pi/2) rad, got {self.theta_max}")
        if self.scheme not in ("polar", "solid_angle"):
            raise ValueError(f"scheme must be 'polar' or 'solid_angle', got {self.scheme!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.replicates < 2:
            raise ValueError(f"replicates must be >= 2, got {self.replicates}")

    @property
    def scheme_id(self) -> int:
        return kb.SCHEME_POLAR if self.scheme == "polar" else kb.SCHEME_SOLID_ANGLE

    @property
    def include_principal(self) -> bool:
        """The cone set starts with P (modes ``stratified`` and ``random``, as the paper)."""
        return self.mode in ("stratified", "random")

    @property
    def estimates_error(self) -> bool:
        """Whether the mode comes with a numerical error (``rule``, ``rqmc``)."""
        return self.mode in ("rule", "rqmc")

    # ------------------------------------------------------------------ rules
    def rule(self, lobe: bool) -> quad.Rule:
        """The quadrature rule of this set (cone: ``lobe=False``; radiometric lobe: True)."""
        if self.mode == "rqmc":
            return quad.sobol_points(max(1, self.n_rays // self.replicates), self.seed, self.part)
        if self.mode != "rule":
            u1, u2 = fibonacci_lattice(self.n_rays if lobe else self.n_rays - 1)
            return quad.Rule(u1, u2, np.full(u1.size, 1.0 / max(self.n_rays, 1)),
                             (u1.size, 1), "lattice")
        if lobe:
            order = self._part_order(quad.square_order(self.n_rays))
            return quad.hermite_rule(order) if self.lobe_gaussian else quad.unit_rule(order)
        rho = self.phi_rho
        wide = rho is not None and self.theta_max > 10.0 * self.lobe_narrow
        order = self._part_order(quad.cone_order(self.n_rays, 2 if wide else 4))
        if rho is not None and order[1] > 1:
            # an even number of azimuths: the mapped nodes then come in pairs phi, phi + pi,
            # as the lobe's two halves do (an odd count errs 10-1000 x more on Fig. 3)
            order = (order[0], order[1] - order[1] % 2)
        return quad.cone_rule(order, self.scheme, self.theta_max, self.lobe_sigma, rho)

    @property
    def phi_rho(self) -> float | None:
        """The axis ratio of the cone rule's azimuth map (:func:`~.quadrature.phi_map`) in
        mode ``rule``, None where the azimuths are the plain trapezoid's."""
        if self.mode != "rule":
            return None
        return quad.phi_map_ratio(self.lobe_narrow, self.lobe_sigma, self.theta_max)

    def orient(self, geo: np.ndarray, brdf: np.ndarray) -> np.ndarray:
        """Turn each pixel's cone basis (b1, b2) about P, in place in the geometry rows
        ``geo`` (P, G_SIZE), so that b1 lies on the lobe's long axis: where the cone rule's
        azimuths follow the lobe (:attr:`phi_rho`), its phi = 0 must be that axis. A no-op
        otherwise. ``brdf``: the kernel's parameter vector (its alphas set the axis).

        Near P the Ward and Beckmann exponents are ``-(h_x^2 / ax^2 + h_y^2 / ay^2) /
        h_z^2`` with ``(h_x, h_y) = M (a, b)`` to first order in the ray's coefficients
        ``(a, b)`` on (b1, b2), ``M = [[b1.x, b2.x], [b1.y, b2.y]]``: the lobe is the
        Gaussian of ``Q = M^T diag(1/ax^2, 1/ay^2) M``, its long axis the eigenvector of
        Q's smaller eigenvalue, at ``phi0 = atan2(2 Q12, Q11 - Q22) / 2 + pi / 2``. For the
        exact integrand the cone integral does not depend on where phi = 0 is; the rule's
        nodes do."""
        if self.phi_rho is None or geo.shape[0] == 0:
            return geo
        from ..kernels.primary import orient_rows

        ax, ay = float(brdf[kb.B_AX]), float(brdf[kb.B_AY])
        orient_rows(geo, 1.0 / (ax * ax), 1.0 / (ay * ay))  # one compiled pass
        return geo

    def _part_order(self, order: tuple[int, int]) -> tuple[int, int]:
        """The order of this pass of the rule ``order`` (:attr:`part`)."""
        if self.part == 1:
            return quad.embedded_order(order)
        if self.part == 2:
            return quad.second_embedded_order(order)
        return order

    def error_passes(self) -> tuple["ConeSampling", ...]:
        """The sets whose renders give the value and its error: (rule, embedded rule,
        second embedded rule) in mode ``rule``, the R replicates in mode ``rqmc``; (self,)
        otherwise."""
        if self.mode == "rule":
            return tuple(replace(self, part=p) for p in range(3))
        if self.mode == "rqmc":
            return tuple(replace(self, part=r) for r in range(self.replicates))
        return (self,)

    def as_mode(self, mode: str) -> "ConeSampling":
        return replace(self, mode=mode, part=0)

    def unit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(u1, u2): the cone's points in the unit square (P, when the set has it, is not
        among them: it is the kernel's ray 0)."""
        r = self.rule(False)
        return r.u1, r.u2

    def lobe_unit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(u1, u2): the radiometric estimator's lobe points in the unit square (no P)."""
        r = self.rule(True)
        return r.u1, r.u2

    def ray_weights(self, lobe: bool) -> np.ndarray:
        """Per-ray quadrature weights (float64) the render kernels multiply each ray's weight
        by (``w_ray`` of :func:`pmdsim.kernels.bundle.render_tile`), indexed like the
        bundle's rays (cone: ray 0 is P when :attr:`include_principal`, then the points of
        :meth:`unit_points`; lobe (``lobe=True``): the points of :meth:`lobe_unit_points`).

        The estimators' normalisation 1/N (N = ``n_rays``) is applied after the sums, so the
        weights are the rule's weights times ``n_rays``: all ones for the equal-weight sets
        of modes ``stratified`` and ``random`` (P counts as one of the N rays, as in the
        paper); for ``rule`` and ``rqmc`` (no P) ``sum_j w_ray[j] / N`` is 1."""
        r = self.rule(lobe)
        w = r.w * self.n_rays
        if self.include_principal and not lobe:
            w = np.concatenate([[1.0], w])
        return w

    def rotations(self, row_start: int, row_stop: int, width: int) -> np.ndarray:
        """Per-pixel offsets (rows * width, 2) for mode ``random``; (0, 2) when stratified."""
        if self.mode != "random":
            return np.zeros((0, 2))
        return np.concatenate(
            [np.random.default_rng([self.seed, r]).random((width, 2)) for r in range(row_start, row_stop)]
        )

    def local_directions(self, offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """Unit directions (rays, 3) of the cone set in the cone frame (z = P), P first when
        the set has it; NumPy reference."""
        u1, u2 = self.unit_points()
        s1 = np.mod(u1 + offset[0], 1.0)
        s2 = np.mod(u2 + offset[1], 1.0)
        if self.scheme == "polar":
            theta = self.theta_max * s1
            ct, st = np.cos(theta), np.sin(theta)
        else:
            ct = 1.0 - s1 * (1.0 - np.cos(self.theta_max))
            st = np.sqrt(np.maximum(0.0, 1.0 - ct**2))
        phi = 2 * np.pi * s2
        d = np.stack([st * np.cos(phi), st * np.sin(phi), ct], axis=-1)
        if not self.include_principal:
            return d
        return np.concatenate([[[0.0, 0.0, 1.0]], d])


def lobe_shape(brdf) -> tuple[float | None, bool, float | None]:
    """(lobe_sigma, lobe_gaussian, lobe_narrow) of a BRDF for :class:`ConeSampling`: the
    widest angular standard deviation of the reflected lobe, sqrt(2) max(alpha_x, alpha_y)
    (None for the mirror), whether the radiometric sampler maps Gaussian slopes (Ward,
    Beckmann), and the narrowest, sqrt(2) min(alpha_x, alpha_y) (None unless both alphas
    are positive)."""
    if getattr(brdf, "is_delta", False):
        return None, True, None
    p = brdf.kernel_params()
    model = int(p[kb.B_MODEL])
    ax, ay = float(p[kb.B_AX]), float(p[kb.B_AY])
    sigma = math.sqrt(2.0) * max(ax, ay) if max(ax, ay) > 0 else None
    narrow = math.sqrt(2.0) * min(ax, ay) if min(ax, ay) > 0 else None
    return sigma, model in (kb.MODEL_WARD, kb.MODEL_BECKMANN), narrow


def sampling_from_config(s, brdf=None) -> ConeSampling:
    """The :class:`ConeSampling` of a ``[sampling]`` section for a BRDF."""
    sigma, gaussian, narrow = lobe_shape(brdf) if brdf is not None else (None, True, None)
    return ConeSampling(s.n_rays, float(np.deg2rad(s.theta_max_deg)), s.scheme, s.mode, s.seed,
                        s.replicates, sigma, gaussian, 0, s.error_estimate,
                        None if s.target_error_mrad is None else s.target_error_mrad * 1e-3,
                        s.max_rays, narrow)
