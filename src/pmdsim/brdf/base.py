"""The BRDF interface.

A BRDF evaluates ``f(i, o)`` for unit vectors in its *local* frame (x, y in the tangent
plane, z = normal), with ``i`` pointing from the surface to the camera and ``o`` from the
surface to the monitor, samples outgoing directions from unit-square points the caller
passes in (``sample``: deterministic, so testable and seedable outside), gives the density
of those samples per solid angle (``pdf``), and exposes a parameter vector for the compiled
kernels (``pmdsim.kernels.bundle.B_*``). Adding a model is one new file here plus its
weight functions and one row in ``pmdsim.kernels.bundle.MODELS`` (per-pixel constants and
ray weight for the cone estimators; micro-normal draw, constants and weight for the
radiometric one).

The NumPy methods here are the reference the compiled kernels are tested against.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class BRDF(Protocol):
    name: str
    #: True for a Dirac reflector (the mirror): the bundle collapses to the principal ray.
    is_delta: bool

    def evaluate(self, i_local: np.ndarray, o_local: np.ndarray) -> np.ndarray:
        """BRDF values (...,) for local unit vectors (..., 3); 0 where either is below the surface."""

    def sample(self, u1: np.ndarray, u2: np.ndarray, i_local: np.ndarray) -> np.ndarray:
        """Outgoing local unit directions (..., 3) for unit-square points (u1, u2) (...,);
        may lie below the surface (then their weight is 0)."""

    def pdf(self, i_local: np.ndarray, o_local: np.ndarray) -> np.ndarray:
        """Density (...,) per solid angle of ``sample``'s directions; 0 below the surface."""

    def kernel_params(self) -> np.ndarray:
        """Parameter vector (B_SIZE,) float64 for ``pmdsim.kernels.bundle``."""


def lobe_weight(brdf: BRDF, i_local: np.ndarray, o_local: np.ndarray) -> np.ndarray:
    """Importance-sampling weight ``f(i, o) cos(theta_o) / pdf(i, o)`` (...,); 0 where ``o``
    is below the surface or has no density. ``(1/N) sum w_p L(o_p)`` over ``o_p =
    brdf.sample(...)`` estimates the integral of ``f L cos(theta_o)`` over the hemisphere."""
    o_local = np.asarray(o_local, np.float64)
    f = brdf.evaluate(i_local, o_local)
    p = brdf.pdf(i_local, o_local)
    ok = (o_local[..., 2] > 0) & (p > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, f * o_local[..., 2] / np.where(ok, p, 1.0), 0.0)
