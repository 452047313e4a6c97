"""The ideal specular mirror: a Dirac lobe at the principal reflection direction P.

Rendering with it traces exactly one ray per pixel (P) with weight 1, so every estimator
returns the monitor luminance at the exact mirror-reflection point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels import bundle as kb


@dataclass(frozen=True)
class Mirror:
    name: str = "mirror"
    is_delta: bool = True

    def evaluate(self, i_local, o_local):
        """Zero almost everywhere: a Dirac lobe has no finite value; use the principal ray."""
        return np.zeros(np.broadcast_shapes(np.shape(i_local), np.shape(o_local))[:-1])

    def sample(self, u1, u2, i_local):
        """The principal direction P = (-i_x, -i_y, i_z) for every point (the lobe is a Dirac)."""
        i_local = np.asarray(i_local, np.float64)
        shape = np.broadcast_shapes(np.shape(u1), np.shape(u2), i_local.shape[:-1]) + (3,)
        return np.broadcast_to(i_local * np.array([-1.0, -1.0, 1.0]), shape).copy()

    def pdf(self, i_local, o_local):
        """A Dirac lobe has no density per solid angle: the renderer traces P with weight 1."""
        raise ValueError("the mirror BRDF has no pdf per solid angle (a Dirac lobe); "
                         "its bundle is the principal ray P with weight 1")

    def kernel_params(self):
        p = np.zeros(kb.B_SIZE)
        p[kb.B_MODEL] = kb.MODEL_MIRROR
        return p
