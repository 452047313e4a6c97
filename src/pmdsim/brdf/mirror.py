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

    def kernel_params(self):
        p = np.zeros(kb.B_SIZE)
        p[kb.B_MODEL] = kb.MODEL_MIRROR
        return p
