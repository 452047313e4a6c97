"""Write the pySCATMECH reference values of the Rayleigh-Rice test (issue 20).

pySCATMECH (NIST's SCATMECH library, first-order vector perturbation theory) builds from
C++ source and takes long to compile, so CI does not install it. This script evaluates its
``Microroughness_BRDF_Model`` at the test's points once, on a machine where it is installed,
and stores parameters, points and values in ``tests/data/pyscatmech_rayleigh_rice.json``;
``tests/brdf/test_rayleigh_rice.py`` compares pmdsim's BRDF with those values on every run, and
re-evaluates pySCATMECH live (and checks the stored file against it) where it is importable.

    python tools/pyscatmech_reference.py            # needs pySCATMECH (pip install pySCATMECH)

The PSD is SCATMECH's ``ABC_PSD_Function``, A / (1 + (B f)^2)^(C/2) with f in 1/um, A in
um^4: pmdsim's K-correlation PSD with a = A 1e-12 mm^4, b = B 1e-3 mm and c = C - 1.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "pyscatmech_rayleigh_rice.json"

#: Each case: wavelength (um), substrate (n, k), ABC PSD (A um^4, B um, C), seed of its points.
CASES = [
    {"name": "aluminium 545 nm, K-correlation 3 nm / 5 um", "lambda_um": 0.545, "nk": [0.96, 6.69],
     "A": None, "B": 2 * math.pi * 5.0, "C": 3.3, "sigma_nm": 3.0, "seed": 4, "n": 20},
    {"name": "nickel 633 nm, K-correlation 1.5 nm / 0.8 um", "lambda_um": 0.633, "nk": [1.97, 3.72],
     "A": None, "B": 2 * math.pi * 0.8, "C": 2.8, "sigma_nm": 1.5, "seed": 11, "n": 20},
]


def points(n: int, seed: int) -> np.ndarray:
    """n (theta_i, theta_s, phi_s) in rad: incidence 0-60 deg, scattering 0-70 deg, any azimuth."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(0, 1.05, n), rng.uniform(0, 1.2, n), rng.uniform(-math.pi, math.pi, n)], -1)


def abc_a(sigma_nm: float, b_um: float, c: float) -> float:
    """The A (um^4) of an ABC PSD whose 2-D integral is sigma^2: A pi / (B^2 (C/2 - 1)) = sigma^2."""
    sigma_um = sigma_nm * 1e-3
    return sigma_um**2 * b_um**2 * (c / 2 - 1) / math.pi


def main() -> None:
    import pySCATMECH  # noqa: F401  (fails here, not halfway, where it is missing)
    from pySCATMECH.brdf import BRDF_Model

    cases = []
    for case in CASES:
        a = abc_a(case["sigma_nm"], case["B"], case["C"])
        model = BRDF_Model("Microroughness_BRDF_Model", {
            "lambda": case["lambda_um"], "substrate": f"({case['nk'][0]},{case['nk'][1]})",
            "psd": "ABC_PSD_Function", "psd.A": a, "psd.B": case["B"], "psd.C": case["C"]})
        pts = points(case["n"], case["seed"])
        values = [model.BRDF(float(ti), float(ts), float(ps)) for ti, ts, ps in pts]
        cases.append({**case, "A": a, "points_rad": pts.tolist(), "brdf_per_sr": values})
    OUT.write_text(json.dumps({
        "generator": "tools/pyscatmech_reference.py",
        "pySCATMECH": "0.1.10 (the PyPI sdist, built from source)",
        "model": "Microroughness_BRDF_Model, unpolarised incidence, all polarisations detected (M00)",
        "cases": cases}, indent=1) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
