"""Sample sets of the scattered bundle: directions inside a cone about P.

The bundle of ``n_rays`` rays is P itself (ray 0, as in the paper) plus ``n_rays - 1`` cone
samples. The samples come from a deterministic 2-D point set in the unit square (a
Fibonacci lattice: u1 = (j + 1/2) / M, u2 = frac(j / golden ratio)), mapped to

- ``polar``: theta = theta_max u1, phi = 2 pi u2 (uniform in inclination and azimuth, the
  paper's Fig. 2b; the density per solid angle is proportional to 1/sin(theta));
- ``solid_angle``: cos(theta) = 1 - u1 (1 - cos(theta_max)), phi = 2 pi u2 (uniform over the
  cone's solid angle).

The ``radiometric`` estimator uses the same lattice with ``M = n_rays`` points
(:meth:`ConeSampling.lobe_unit_points`, no principal ray) and maps it to the BRDF's lobe
(Walter 2005 slopes: :mod:`pmdsim.brdf.microfacet`) instead of the cone.

In mode ``stratified`` every pixel uses the same set; in mode ``random`` each pixel's set
is shifted by a seeded random offset (r1, r2) modulo 1 (Cranley-Patterson rotation), so
each sample is uniformly distributed and the error decorrelates between pixels. The
offsets of camera row ``r`` come from ``numpy.random.default_rng([seed, r])``: results do
not depend on how the camera is tiled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels import bundle as kb

_GOLDEN = (1.0 + 5.0**0.5) / 2.0


def fibonacci_lattice(m: int) -> tuple[np.ndarray, np.ndarray]:
    """The m-point Fibonacci lattice (u1, u2) in the unit square, u1 = (j + 1/2) / m in (0, 1),
    u2 = frac(j / golden ratio)."""
    j = np.arange(m, dtype=np.float64)
    return (j + 0.5) / max(m, 1), np.mod(j / _GOLDEN, 1.0)


@dataclass(frozen=True)
class ConeSampling:
    n_rays: int = 100
    theta_max: float = np.deg2rad(1.0)  # rad
    scheme: str = "polar"
    mode: str = "stratified"
    seed: int = 0

    def __post_init__(self):
        if self.n_rays < 1:
            raise ValueError(f"n_rays must be >= 1, got {self.n_rays}")
        if not 0 < self.theta_max < np.pi / 2:
            raise ValueError(f"theta_max must be in (0, pi/2) rad, got {self.theta_max}")
        if self.scheme not in ("polar", "solid_angle"):
            raise ValueError(f"scheme must be 'polar' or 'solid_angle', got {self.scheme!r}")
        if self.mode not in ("stratified", "random"):
            raise ValueError(f"mode must be 'stratified' or 'random', got {self.mode!r}")

    @property
    def scheme_id(self) -> int:
        return kb.SCHEME_POLAR if self.scheme == "polar" else kb.SCHEME_SOLID_ANGLE

    def unit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(u1, u2), each (n_rays - 1,): the cone samples in the unit square."""
        return fibonacci_lattice(self.n_rays - 1)

    def lobe_unit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(u1, u2), each (n_rays,): the radiometric estimator's lobe samples in the unit
        square (all ``n_rays`` rays come from the lobe; P is not added)."""
        return fibonacci_lattice(self.n_rays)

    def ray_weights(self, lobe: bool) -> np.ndarray:
        """Per-ray quadrature weights (float64) the render kernels multiply each ray's weight
        by (``w_ray`` of :func:`pmdsim.kernels.bundle.render_tile`): (n_rays,), indexed like
        the bundle's rays (cone: ray 0 is P, then the points of :meth:`unit_points`; lobe
        (``lobe=True``): the points of :meth:`lobe_unit_points`). All ones for these
        equal-weight sample sets; the estimators' normalisation (1/N or 1/sum f) is applied
        after the sums."""
        return np.ones(self.n_rays)

    def rotations(self, row_start: int, row_stop: int, width: int) -> np.ndarray:
        """Per-pixel offsets (rows * width, 2) for mode ``random``; (0, 2) when stratified."""
        if self.mode == "stratified":
            return np.zeros((0, 2))
        return np.concatenate(
            [np.random.default_rng([self.seed, r]).random((width, 2)) for r in range(row_start, row_stop)]
        )

    def local_directions(self, offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """Unit directions (n_rays, 3) in the cone frame (z = P); NumPy reference."""
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
        return np.concatenate([[[0.0, 0.0, 1.0]], d])
