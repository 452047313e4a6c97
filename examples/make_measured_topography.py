"""Write examples/measured_topography.x3p: a small "measured" patch of a diamond-turned,
optically smooth surface, for examples/measured_topography.toml.

Turned profile (feed f = 5 um, tool nose radius r = 1 mm: arcs of Rt = f^2 / (8 r) = 3.1 nm
repeated every f along the radius, the map's y axis) plus Gaussian random roughness of a
known anisotropic K-correlation PSD (sigma 2.8 nm, correlation lengths B / 2 pi = 8 um
tangential (x) and 3 um radial (y), C = 2.3), on a 128 x 192 grid of 0.8 um (x) by 0.5 um
(y) steps, stored by x3pio as 32-bit floats in metres (ISO 25178-72). Deterministic (seed 20).

Run:  python examples/make_measured_topography.py   (needs pip install 'pmdsim[topography]')
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import x3pio

from pmdsim.brdf.psd import KCorrelation, synthesize
from pmdsim.brdf.turning import arc_profile

FEED_MM, RADIUS_MM = 5e-3, 1.0
DX_MM, DY_MM = 0.8e-3, 0.5e-3
NY, NX = 192, 128
PSD = KCorrelation(2.8e-6, 2 * math.pi * 8e-3, 2 * math.pi * 3e-3, 2.3)


def topography() -> np.ndarray:
    """Heights (NY, NX) in mm, rows along y (radial)."""
    y = np.arange(NY) * DY_MM
    phase = (y + 0.3 * FEED_MM) % FEED_MM - FEED_MM / 2  # position inside the groove
    turned = arc_profile(phase, RADIUS_MM)[:, None] * np.ones((1, NX))
    rough = synthesize(PSD, (NY, NX), DX_MM, DY_MM, seed=20)
    return turned - turned.mean() + rough


def main(path=Path(__file__).with_name("measured_topography.x3p")) -> Path:
    h = topography()
    x3pio.write(path, (h * 1e-3).astype(np.float32), x_scale=DX_MM * 1e-3, y_scale=DY_MM * 1e-3)
    return path


if __name__ == "__main__":
    print(main())
