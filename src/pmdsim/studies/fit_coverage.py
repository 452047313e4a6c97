"""Do the fit's uncertainties cover the truth? A seeded study of synthetic cases.

Each case (:func:`coverage_cases`) draws, from one seed, Ward alphas (log-uniform, unequal
in x and y), the angle of incidence (camera and monitor tilted about the plate's x axis)
and the noise (exposure and dark noise of a 12-bit EMVA sensor), or (half the cases) none:
noise-free 16-bit images of a 256-node Gauss rule, whose own numerical error and
quantisation are all they carry (:data:`NOISE_FREE_RAYS`). Its "measured" images are
rendered with a converged model (radiometric estimator, the Gauss rule with ``TRUTH_RAYS``
nodes: another kind of sample set than the fit's lattice, 40x larger) and captured by the sensor; the fit then runs
with the **default settings** (a configuration without a ``[sampling]`` section: the fit's
defaults, :func:`pmdsim.studies.fit.fit_config`). A case covers the truth when both alphas
lie inside their k = 2 intervals. Small cameras (20 x 16 px) keep a case to seconds.

Returns results and writes nothing (``pmdsim.run.fit_coverage`` writes them).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..config import RunConfig, parse_config
from ..render import Simulation
from ..scene.sensor import Sensor
from .fit import fit_fringe_images
from .fit_stats import NoiseModel

#: Nodes of the converged "truth" renders (Gauss rule; the fit's default is 100 rays).
TRUTH_RAYS = 4096
#: Nodes of the noise-free cases' images (Gauss-Hermite 16 x 16, as the Fig. 3 example's 256): another order than any of
#: the fit's model (100, 400, ... rays of its lattice), with a numerical error of its own.
NOISE_FREE_RAYS = 256
WIDTHS = (12.0, 25.0, 50.0, 100.0, 200.0)
SHIFTS = 4


@dataclass(frozen=True)
class CoverageCase:
    seed: int
    alpha_x: float
    alpha_y: float
    incidence_deg: float
    exposure_electrons: float
    dark_noise_electrons: float
    #: noise-free 16-bit images (no sensor) rendered by the Gauss rule of ``images_rays``
    #: nodes: they carry that rule's numerical error and their quantisation, nothing else
    noise_free: bool = False
    images_rays: int = TRUTH_RAYS


@dataclass(frozen=True)
class CoverageResult:
    case: CoverageCase
    values: tuple[float, float, float]
    std: tuple[float, float, float]
    std_model: tuple[float, float, float]
    chi2_reduced: float
    success: bool
    reason: str
    covered: bool

    @property
    def normalised_errors(self) -> tuple[float, float]:
        """(value - truth) / std of alpha_x and alpha_y."""
        return ((self.values[0] - self.case.alpha_x) / self.std[0],
                (self.values[1] - self.case.alpha_y) / self.std[1])

    def as_dict(self) -> dict:
        return {"case": asdict(self.case), "values": list(self.values), "std": list(self.std),
                "std_model": list(self.std_model), "chi2_reduced": self.chi2_reduced,
                "success": self.success, "reason": self.reason, "covered": self.covered,
                "normalised_errors": list(self.normalised_errors)}


def coverage_cases(n: int = 20, seed: int = 0) -> list[CoverageCase]:
    """``n`` seeded cases: alphas log-uniform in [0.004, 0.04] each, incidence uniform in
    [15, 40] deg, exposure log-uniform in [1500, 9000] e-, dark noise uniform in [2, 20] e-;
    cases 1, 2, 5, 6, ... (i mod 4 in 1, 2) are noise-free 16-bit images of a
    ``NOISE_FREE_RAYS``-node Gauss rule instead (the sensor numbers unused)."""
    rng = np.random.default_rng([seed, 2026])
    out = []
    for i in range(n):
        ax, ay = np.exp(rng.uniform(np.log(0.004), np.log(0.04), 2))
        case = CoverageCase(i, float(ax), float(ay), float(rng.uniform(15.0, 40.0)),
                            float(np.exp(rng.uniform(np.log(1500.0), np.log(9000.0)))),
                            float(rng.uniform(2.0, 20.0)))
        if i % 4 in (1, 2):  # half the cases: a simulated study's noise-free images
            case = replace(case, noise_free=True, images_rays=NOISE_FREE_RAYS)
        out.append(case)
    return out


def case_dict(case: CoverageCase) -> dict:
    """The configuration mapping of a case (no ``[sampling]``: the fit's defaults). A flat
    100 x 80 mm plate, a 20 x 16 px pinhole camera 300 mm away and a 200 x 120 px monitor
    (1 mm pixels, continuous) 200 mm away, both tilted by the incidence in the y-z plane."""
    t = math.radians(case.incidence_deg)
    s, c = math.sin(t), math.cos(t)
    return {
        "name": f"coverage-{case.seed}",
        "camera": {"resolution": [20, 16], "focal_length_px": 40.0,
                   "position_mm": [3.1, -300.0 * s, 300.0 * c], "look_at_mm": [1.7, 2.3, 0.0],
                   "up": [0.0, 1.0, 0.0]},
        "monitor": {"resolution": [200, 120], "pixel_pitch_mm": 1.0,
                    "centre_mm": [-2.3, 200.0 * s + 0.7, 200.0 * c],
                    "look_at_mm": [0.4, -1.1, 0.0], "up": [0.0, 1.0, 0.0],
                    "pixel_model": "continuous"},
        "surface": {"type": "flat", "size_mm": [100.0, 80.0]},
        "anisotropy": {"frame": "fixed", "x_direction": [1.0, 0.0, 0.0]},
        "brdf": {"model": "ward", "alpha_x": 0.02, "alpha_y": 0.02, "rho_s": 0.4},
        "patterns": {"fringes": {"widths_px": list(WIDTHS), "shifts": SHIFTS}},
        "sensor": {"enabled": True, "exposure_electrons": case.exposure_electrons,
                   "full_well_electrons": 10000.0, "bit_depth": 12,
                   "dark_noise_electrons": case.dark_noise_electrons, "seed": case.seed},
        "compute": {"tile_rows": 8, "scheduler": "threads", "num_workers": 1},
    }


def truth_images(case: CoverageCase) -> tuple[np.ndarray, RunConfig]:
    """The captured images (signal DN, saturated values NaN) and the fit's configuration."""
    d = case_dict(case)
    cfg = parse_config(d)
    truth = parse_config(d | {"brdf": {"model": "ward", "alpha_x": case.alpha_x,
                                       "alpha_y": case.alpha_y, "rho_s": 0.4},
                              "sampling": {"estimator": "radiometric", "mode": "rule",
                                           "n_rays": case.images_rays}})
    values = Simulation.from_config(truth).render_fringes(WIDTHS, ("x", "y"), SHIFTS).images
    if case.noise_free:  # 16-bit counts as a run writes them (brightest at 0.95 full scale)
        finite = np.isfinite(values)
        exposure = 0.95 * 65535.0 / float(values[finite].max())
        counts = np.rint(np.clip(np.where(finite, values, 0.0) * exposure, 0.0, 65535.0))
        cfg = parse_config(d | {"sensor": {"enabled": False}})
        return np.where(np.isfinite(values), counts, np.nan), cfg
    sensor = Sensor.from_config(cfg.sensor)
    dn = sensor.capture(values).dn
    noise = NoiseModel.from_sensor(sensor)
    return np.where(dn >= sensor.saturation_dn, np.nan, noise.signal(dn)), cfg


def run_case(case: CoverageCase, k: float = 2.0) -> CoverageResult:
    """Fit one case with the default settings; covered: both alphas within k std."""
    images, cfg = truth_images(case)
    if case.noise_free:  # what `pmdsim fit` reads from a run's 16-bit fringe images
        res = fit_fringe_images(cfg, images, WIDTHS, ("x", "y"), None, quantisation_step=1.0,
                                images_sampling={"estimator": "radiometric", "mode": "rule",
                                                 "n_rays": case.images_rays})
    else:
        noise = NoiseModel.from_sensor(Sensor.from_config(cfg.sensor))
        res = fit_fringe_images(cfg, images, WIDTHS, ("x", "y"), noise)
    truth = np.array([case.alpha_x, case.alpha_y])
    covered = bool(np.all(np.abs(res.values[:2] - truth) <= k * res.std[:2]))
    sm = res.std_model if res.std_model is not None else np.zeros(3)
    return CoverageResult(case, tuple(map(float, res.values)), tuple(map(float, res.std)),
                          tuple(map(float, sm)), float(res.chi2_reduced), bool(res.success),
                          res.reason, covered)


def fit_coverage(n: int = 20, seed: int = 0, progress=None) -> list[CoverageResult]:
    """Run :func:`run_case` on :func:`coverage_cases` (``progress(i, result)`` after each)."""
    out = []
    for i, case in enumerate(coverage_cases(n, seed)):
        out.append(run_case(case))
        if progress is not None:
            progress(i, out[-1])
    return out
