"""Camera sensor: the EMVA 1288 linear model, seeded and reproducible.

A camera value ``x`` (the renderer's radiance estimate, any units) becomes a digital number
(DN) as a real linear camera makes it (EMVA Standard 1288, release 4.0, linear model):

1. mean electrons ``mu_e = eta mu_p = E x / x_ref`` with ``E`` the exposure of the
   brightest value ``x_ref`` (the largest finite value of the captured stack unless given),
   times the pixel's photo-response factor ``1 + prnu g`` (``g ~ N(0, 1)``, fixed per seed:
   PRNU);
2. electrons: Poisson(``mu_e``) (shot noise; ``mu_e`` itself without it), plus the dark
   signal ``mu_d`` and the pixel's dark offset ``dsnu h`` (``h ~ N(0, 1)``, fixed: DSNU), plus
   temporal dark noise ``N(0, sigma_d^2)``; clipped to ``[0, full well]``;
3. ``y = round(K e + offset)`` clipped to ``[0, 2^bits - 1]`` (gain K in DN/e-, ADC).

Without fixed patterns the moments are EMVA's:
``mu_y = K (mu_e + mu_d) + offset`` and
``sigma_y^2 = K^2 (sigma_d^2 + mu_e) + sigma_q^2`` (``sigma_q^2 = 1/12`` DN^2 of the rounding),
away from clipping. Random numbers come from ``numpy.random.default_rng``: the fixed patterns
from ``[seed, 0]``, the temporal noise of frame ``f`` in stream ``s`` from ``[seed, 1, s, f]``
(whole frames at once: the bytes do not depend on any tiling).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import SensorConfig

DEFAULT_FILL = 0.7


@dataclass(frozen=True)
class Capture:
    """Digital numbers of a captured stack.

    Attributes
    ----------
    dn : (..., H, W) float64, DN
        Integer-valued grey values; NaN where the input value was NaN (no surface).
    saturated : (..., H, W) bool
        The pixel hit the full well or the ADC maximum in that frame.
    electrons_per_value : float, e- per input unit
        ``E / x_ref``: the mean electrons one unit of camera value makes.
    """

    dn: np.ndarray
    saturated: np.ndarray
    electrons_per_value: float


@dataclass(frozen=True)
class Sensor:
    """EMVA 1288 linear sensor (see the module docstring); ``enabled = False`` passes values
    through unchanged."""

    enabled: bool = False
    quantum_efficiency: float = 1.0
    exposure_electrons: float | None = None
    exposure_photons: float | None = None
    target_fill: float | None = None
    full_well_electrons: float = 10000.0
    dark_noise_electrons: float = 0.0
    dark_signal_electrons: float = 0.0
    dsnu_electrons: float = 0.0
    prnu: float = 0.0
    gain_dn_per_electron: float | None = None
    bit_depth: int = 12
    offset_dn: float = 0.0
    shot_noise: bool = True
    seed: int = 0

    @classmethod
    def from_config(cls, cfg: SensorConfig) -> "Sensor":
        return cls(**cfg.model_dump())

    # ------------------------------------------------------------------ derived numbers
    @property
    def max_dn(self) -> int:
        return 2**self.bit_depth - 1

    @property
    def gain(self) -> float:
        """K, DN per electron."""
        if self.gain_dn_per_electron is not None:
            return float(self.gain_dn_per_electron)
        return (self.max_dn - self.offset_dn) / self.full_well_electrons

    @property
    def exposure(self) -> float:
        """Mean electrons at the brightest value."""
        if self.exposure_electrons is not None:
            return float(self.exposure_electrons)
        if self.exposure_photons is not None:
            return float(self.quantum_efficiency * self.exposure_photons)
        fill = DEFAULT_FILL if self.target_fill is None else self.target_fill
        return float(fill * self.full_well_electrons)

    @property
    def saturation_dn(self) -> float:
        """Grey value at which the pixel saturates: the full well or the ADC maximum."""
        return float(min(self.max_dn, np.rint(self.gain * self.full_well_electrons + self.offset_dn)))

    def noise_dn(self, mean_electrons) -> np.ndarray:
        """Temporal noise (std, DN) at ``mean_electrons`` (EMVA, no clipping, fixed
        patterns excluded)."""
        mu = np.asarray(mean_electrons, np.float64)
        shot = mu if self.shot_noise else 0.0
        k = self.gain
        return np.sqrt(k * k * (self.dark_noise_electrons**2 + shot) + 1.0 / 12.0)

    def fixed_patterns(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """(PRNU factor, DSNU offset in e-), each (H, W), fixed by ``seed``."""
        rng = np.random.default_rng([self.seed, 0])
        g = rng.standard_normal(shape)
        h = rng.standard_normal(shape)
        return 1.0 + self.prnu * g, self.dsnu_electrons * h

    # ------------------------------------------------------------------ capture
    def capture(self, values, *, stream: int = 0, reference: float | None = None,
                coupled: bool = False) -> Capture:
        """Capture a stack of camera values ``(..., H, W)`` (every leading index is one frame).

        ``reference``: the value that gets the exposure (default: the largest finite value of
        ``values``). ``stream`` separates independent captures with the same seed (e.g. the
        surface and its reference mirror). ``coupled``: draw the shot noise by inverting the
        Poisson distribution function at fixed uniforms (the same distribution), so that a
        slightly different signal changes a pixel's draw by at most the signal's change on
        average (``numpy``'s sampler would draw anew: ``pmdsim budget`` compares two orders
        of the same render). Input is not modified.
        """
        x = np.asarray(values, np.float64)
        if x.ndim < 2:
            raise ValueError(f"values: need (..., H, W) camera values, got shape {x.shape}")
        nan = ~np.isfinite(x)
        if not self.enabled:
            return Capture(x.copy(), np.zeros(x.shape, bool), 1.0)
        if reference is None:
            finite = x[~nan]
            reference = float(finite.max()) if finite.size else 1.0
        if not reference > 0:
            raise ValueError(f"reference: the brightest value must be positive, got {reference}")
        e_per_x = self.exposure / reference
        shape = x.shape[-2:]
        prnu, dsnu = self.fixed_patterns(shape)
        frames = x.reshape(-1, *shape)
        dn = np.empty(frames.shape)
        sat = np.empty(frames.shape, bool)
        k = self.gain
        for f in range(frames.shape[0]):
            rng = np.random.default_rng([self.seed, 1, int(stream), f])
            mu = np.where(np.isfinite(frames[f]), np.maximum(frames[f], 0.0), 0.0) * e_per_x * prnu
            if self.shot_noise and coupled:
                e = poisson_inverse(rng.random(shape), mu)
            else:
                e = rng.poisson(mu).astype(np.float64) if self.shot_noise else mu
            e = e + self.dark_signal_electrons + dsnu
            if self.dark_noise_electrons > 0:
                e = e + self.dark_noise_electrons * rng.standard_normal(shape)
            full = e >= self.full_well_electrons
            e = np.clip(e, 0.0, self.full_well_electrons)
            y = np.rint(k * e + self.offset_dn)
            top = y >= self.max_dn
            dn[f] = np.clip(y, 0.0, self.max_dn)
            sat[f] = full | top
        dn = dn.reshape(x.shape)
        sat = sat.reshape(x.shape)
        dn[nan] = np.nan
        sat[nan] = False
        return Capture(dn, sat, e_per_x)


def poisson_inverse(u: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """The Poisson quantile (float64): the smallest k with ``P(K <= k; mu) >= u`` (what
    ``scipy.stats.poisson.ppf`` returns, 0 where ``u`` or ``mu`` is 0), found from the
    Cornish-Fisher start ``mu + sqrt(mu) z + (z^2 - 1) / 6`` by stepping k against the
    distribution function (one or two steps per value; ppf itself is ~10x slower)."""
    from scipy.special import ndtri, pdtr

    u = np.asarray(u, np.float64)
    mu = np.broadcast_to(np.asarray(mu, np.float64), u.shape)
    z = ndtri(np.clip(u, 1e-300, 1.0 - 1e-16))
    k = np.maximum(np.floor(mu + np.sqrt(mu) * z + (z * z - 1.0) / 6.0), 0.0)
    k = np.where((u <= 0) | (mu <= 0), 0.0, k)
    todo = np.flatnonzero((u > 0) & (mu > 0))
    while todo.size:
        kk, uu, mm = k.flat[todo], u.flat[todo], mu.flat[todo]
        up = pdtr(kk, mm) < uu
        down = ~up & (kk > 0) & (pdtr(kk - 1.0, mm) >= uu)
        k.flat[todo[up]] += 1.0
        k.flat[todo[down]] -= 1.0
        todo = todo[up | down]
    return k


def capture_dn(sensor: Sensor, values, stream: int, coupled: bool = False) -> np.ndarray:
    """Digital numbers (float32) of a stack of camera values (NaN where no surface);
    ``coupled``: :meth:`Sensor.capture`'s."""
    return sensor.capture(values, stream=stream, coupled=coupled).dn.astype(np.float32)
