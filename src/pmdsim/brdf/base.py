"""The BRDF interface.

A BRDF evaluates ``f(i, o)`` for unit vectors in its *local* frame (x, y in the tangent
plane, z = normal), with ``i`` pointing from the surface to the camera and ``o`` from the
surface to the monitor, and exposes a parameter vector for the compiled kernels
(``pmdsim.kernels.bundle.B_*``). Adding a model is one new file here plus its case in the
kernel's weight loop.
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

    def kernel_params(self) -> np.ndarray:
        """Parameter vector (B_SIZE,) float64 for ``pmdsim.kernels.bundle``."""
