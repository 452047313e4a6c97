"""The statistics of the image fit (:mod:`pmdsim.studies.fit`): what the residuals' covariance
is made of, and what the parameters' covariance follows from it.

The residual of one image value is ``r = s m(theta) - y`` (``y`` the measured value, dark
level removed; ``m`` the simulated camera value, ``s`` the brightness scale). Its covariance
is modelled as

    C = D + V + U U^T

- ``D = diag(sigma^2)``: the sensor's noise of each value (:class:`NoiseModel`, EMVA 1288:
  dark noise, shot noise, quantisation and the fixed patterns PRNU/DSNU), or, without a
  sensor model, one variance estimated from the images themselves
  (:func:`harmonic_split`: the part of the residual that no phase-shifted sinusoid can make);
- ``V + U U^T``: the model's own numerical error (the sampling error of the simulated
  images): ``V`` the variance of each value's error (diagonal;
  :func:`pmdsim.studies.fit.model_error_variance` estimates it), ``U`` error patterns
  correlated over all values, ``m`` columns of unit standard uncertainty. They enter only
  here, through :func:`parameter_covariance`; the model's error carried to the parameters
  (how far they move when the sample set is refined) enters there as ``shift``.

The fit minimises ``|D^(-1/2) r|^2`` (the noise-weighted least squares); the parameters'
covariance is the sandwich of that estimator under ``C``:

    A = (J^T J)^-1 J^T,   cov = b (J^T J)^-1 + (A U_w)(A U_w)^T + shift shift^T

with ``J`` the Jacobian of the weighted residuals, ``U_w = D^(-1/2) U``, and ``b`` the Birge
factor ``max(1, chi2_nu)`` that widens the noise part when the residuals are larger than
``C`` says (never narrows it). ``chi2_nu = r_w^T (I + V_w + U_w U_w^T)^-1 r_w / (n - p)``
(Woodbury) is the reduced chi-square against the whole covariance, the number the fit's
verdict tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NoiseModel:
    """EMVA 1288 noise (DN) of a grey value ``y`` (DN, the dark level already subtracted):

    ``sigma^2 = K^2 (sigma_d^2 + dsnu^2) + K y + (prnu y)^2 + 1/12``

    (``K y`` only with shot noise). ``dark_level_dn`` (``offset + K mu_d``) is what a dark
    frame reads; :meth:`signal` subtracts it from measured grey values. The fixed patterns
    (PRNU, DSNU) are the same in every frame of a pixel; they are counted as noise of each
    value, which is what they are to a model without them.
    """

    gain_dn_per_electron: float
    dark_noise_electrons: float = 0.0
    prnu: float = 0.0
    dsnu_electrons: float = 0.0
    shot_noise: bool = True
    dark_level_dn: float = 0.0

    @classmethod
    def from_sensor(cls, sensor) -> "NoiseModel":
        """The noise of a :class:`pmdsim.scene.sensor.Sensor` (enabled)."""
        k = sensor.gain
        return cls(k, sensor.dark_noise_electrons, sensor.prnu, sensor.dsnu_electrons,
                   sensor.shot_noise, sensor.offset_dn + k * sensor.dark_signal_electrons)

    def signal(self, dn) -> np.ndarray:
        """Measured grey values (DN) minus the dark level."""
        return np.asarray(dn, np.float64) - self.dark_level_dn

    def sigma(self, y) -> np.ndarray:
        """Standard deviation (DN) of a value whose noise-free signal is ``y`` (DN, dark
        level subtracted; negative values count as 0)."""
        k = self.gain_dn_per_electron
        y = np.maximum(np.asarray(y, np.float64), 0.0)
        var = k * k * (self.dark_noise_electrons**2 + self.dsnu_electrons**2) + 1.0 / 12.0
        var = var + (k * y if self.shot_noise else 0.0) + (self.prnu * y) ** 2
        return np.sqrt(var)


def harmonic_split(values, shifts=None) -> tuple[np.ndarray, np.ndarray]:
    """Split phase-shifted values ``(..., K, H, W)`` into the part a sinusoid of the phase
    shift can make (mean + first harmonic: 3 of the K dimensions) and the rest.

    Returns ``(sinusoid, rest)``, both of the input's shape, ``sinusoid + rest == values``.
    Shifts are ``2 pi k / K`` unless given (they must be equally spaced over 2 pi for the
    three basis vectors to be orthogonal). A fringe pattern rendered by pmdsim on a linear
    display is a pure sinusoid in the shift, so a residual's ``rest`` is noise only.
    """
    v = np.asarray(values, np.float64)
    k = v.shape[-3]
    d = 2 * np.pi * np.arange(k) / k if shifts is None else np.asarray(shifts, np.float64)
    c = np.cos(d)[:, None, None]
    s = np.sin(d)[:, None, None]
    mean = v.mean(-3, keepdims=True)
    a = 2.0 / k * np.sum(v * c, axis=-3, keepdims=True)
    b = 2.0 / k * np.sum(v * s, axis=-3, keepdims=True)
    sinusoid = mean + a * c + b * s
    return sinusoid, v - sinusoid


def harmonic_noise_variance(residual) -> tuple[float, int]:
    """Noise variance per value from the residual ``(..., K, H, W)`` (NaN where missing)
    orthogonal to the phase-shift sinusoids: ``sum(rest^2) / (pixels (K - 3))`` over the
    pixels whose K values are all finite. Returns ``(variance, degrees of freedom)``;
    ``(nan, 0)`` for K = 3 (no degree of freedom left) or no complete pixel."""
    r = np.asarray(residual, np.float64)
    k = r.shape[-3]
    if k <= 3:
        return float("nan"), 0
    complete = np.all(np.isfinite(r), axis=-3, keepdims=True)
    _, rest = harmonic_split(np.where(complete, r, 0.0))
    dof = int(complete.sum()) * (k - 3)
    if dof == 0:
        return float("nan"), 0
    return float(np.sum(rest**2) / dof), dof


def fringe_signal_ratio(values, variance) -> np.ndarray:
    """(..., ) ratio of the first harmonic's power to what noise alone gives, per leading
    index of ``values (..., K, H, W)``: ``mean |Z|^2 / mean(4 sigma^2 / K)`` over the
    complete pixels, ``Z = (2/K) sum_k I_k exp(-i delta_k)`` (pure noise of variance
    ``sigma^2``: ``E|Z|^2 = 4 sigma^2 / K``, so the ratio is 1 +- 1/sqrt(pixels)).
    ``variance``: a number or an array broadcast to ``values`` (per value)."""
    v = np.asarray(values, np.float64)
    k = v.shape[-3]
    d = 2 * np.pi * np.arange(k) / k
    var = np.broadcast_to(np.asarray(variance, np.float64), v.shape)
    complete = np.all(np.isfinite(v), axis=-3)
    z = np.tensordot(np.exp(-1j * d), np.moveaxis(np.where(np.isfinite(v), v, 0.0), -3, 0),
                     axes=(0, 0)) * (2.0 / k)
    expected = 4.0 / k * np.mean(np.where(np.isfinite(var), var, 0.0), axis=-3)
    lead = v.shape[:-3]
    out = np.full(lead, np.nan)
    for idx in np.ndindex(*lead) if lead else [()]:
        ok = complete[idx]
        if ok.any():
            out[idx] = float(np.mean(np.abs(z[idx][ok]) ** 2) / np.mean(expected[idx][ok]))
    return out


@dataclass(frozen=True)
class Covariance:
    """What :func:`parameter_covariance` returns (parameters in the fit's coordinates).

    ``cov``: the total; ``cov_noise``: the noise part (Birge factor included);
    ``cov_model``: the part of the model's numerical error; ``chi2_reduced``: against
    ``I + U_w U_w^T``; ``birge``: the factor applied to the noise part.
    """

    cov: np.ndarray
    cov_noise: np.ndarray
    cov_model: np.ndarray
    chi2_reduced: float
    birge: float
    dof: int


def parameter_covariance(jac, residual, model_error=None, birge: bool = True,
                         shift=None, model_variance=None) -> Covariance:
    """Covariance of least-squares parameters from the Jacobian ``jac`` (n, p) of the
    noise-weighted residuals ``residual`` (n,) at the optimum, and the model's numerical
    error: ``model_error`` (n, m), columns of noise-weighted error patterns, each of unit
    standard uncertainty (``U``); ``model_variance`` (n,), the noise-weighted variance of
    each value's own error (a diagonal ``V``: it enters the chi-square, ``C = I + V + U U^T``,
    not the parameters, whose share of a correlated error ``V`` cannot say); ``shift`` (p,)
    or (p, k): the error already carried to the parameters (e.g. how far they move when the
    model's sample set is refined), each column a standard uncertainty, adding
    ``shift shift^T``. ``None``: no such term. See the module docstring."""
    j = np.asarray(jac, np.float64)
    r = np.asarray(residual, np.float64)
    n, p = j.shape
    u = np.zeros((n, 0)) if model_error is None else np.asarray(model_error, np.float64)
    if u.ndim == 1:
        u = u[:, None]
    d = np.ones(n) if model_variance is None else 1.0 + np.asarray(model_variance, np.float64)
    jtj_inv = np.linalg.pinv(j.T @ j)
    a = jtj_inv @ j.T
    # r^T (D + U U^T)^-1 r by Woodbury: r D^-1 r - (U^T D^-1 r)^T (I + U^T D^-1 U)^-1 (...)
    rd = r / d
    utr = u.T @ rd
    small = np.eye(u.shape[1]) + u.T @ (u / d[:, None])
    quad = float(r @ rd - (utr @ np.linalg.solve(small, utr) if u.shape[1] else 0.0))
    dof = max(n - p, 1)
    chi2 = quad / dof
    b = max(1.0, chi2) if birge else 1.0
    g = a @ u
    cov_model = g @ g.T
    if shift is not None:
        sh = np.asarray(shift, np.float64).reshape(p, -1)
        cov_model = cov_model + sh @ sh.T
    cov_noise = b * jtj_inv
    return Covariance(cov_noise + cov_model, cov_noise, cov_model, chi2, b, dof)
