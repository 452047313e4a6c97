"""The gamma aliasing of phase shifting, derived instead of windowed (issue 9).

``test_decode.py`` asserted that gamma 2.2 leaves a phase error between 3 and 30 mrad with
K = 4 shifts and below 3 mrad with K = 5 (a window copied from a run). Here the error is
derived: the displayed profile ((1 + cos x) / 2)^gamma has cosine coefficients a_m (FFT of
the profile: the series converges like m^(-1 - 2 gamma)); K equal shifts keep the harmonics
m = 1 (mod K) with e^{i m phi} and m = -1 (mod K) with e^{-i m phi}, so the decoded phase is

    phi + arg(sum_{m = 1 mod K} a_m e^{i (m - 1) phi} + sum_{m = -1 mod K} a_m e^{-i (m + 1) phi}).

The decoder must reproduce this error phase by phase (1e-9 rad).
"""

from __future__ import annotations


import numpy as np
import pytest

from naive_decode import gamma_cosine_coefficients as _cosine_coefficients
from naive_decode import gamma_phase_error as _derived_error
from pmdsim.measure.decode import phase_shift
from pmdsim.measure.deviation import wrap


@pytest.mark.parametrize("k", [3, 4, 5, 8])
def test_gamma_phase_error_equals_the_aliased_harmonics(k):
    """Decoded phase of a gamma 2.2 fringe (black 0.05, white 0.95) minus the true phase
    equals the derived aliasing error at every phase, for K = 3, 4, 5, 8. Guards against a
    decoder with the shifts' sign or order wrong (the error would be the conjugate pattern
    plus 2 phi), a wrong shift table (delta_k = 2 pi k / (K - 1)), an offset leaking in."""
    phi = 2 * np.pi * np.arange(50) / 50
    delta = 2 * np.pi * np.arange(k) / k
    s = 0.5 + 0.5 * np.cos(phi[None] + delta[:, None])
    frames = 0.05 + 0.9 * s**2.2
    res = phase_shift(frames[:, None, :])
    err = wrap(res.wrapped_phase[0] - phi)
    np.testing.assert_allclose(err, _derived_error(phi, 2.2, k), rtol=0, atol=1e-9)


def test_gamma_window_of_the_physics_note_is_derived():
    """The physics note's claim (K = 4 about 10 mrad, K >= 5 near a milliradian) from the
    derivation alone: max |error| over the phase for gamma 2.2. The numbers come out as
    10.6 mrad (K = 4), 1.3 mrad (K = 5), 0.30 / 0.04 mrad for K = 6 / 8, and 291 mrad for
    K = 3 (the strong second harmonic aliases: m = 2 = -1 mod 3)."""
    phi = np.linspace(-np.pi, np.pi, 2001)
    worst = {k: float(np.abs(_derived_error(phi, 2.2, k)).max()) for k in (3, 4, 5, 6, 8)}
    assert 5e-3 < worst[4] < 15e-3
    assert 0.5e-3 < worst[5] < 3e-3 and worst[4] > 4 * worst[5]
    assert worst[3] > 0.1
    assert worst[3] > worst[4] > worst[6] > worst[8]
    # linear display: nothing to alias
    assert float(np.abs(_derived_error(phi, 1.0, 4)).max()) < 1e-12
    # the series: a_1 of ((1 + cos x) / 2)^1 is 1/2, a_2 of its square 1/8
    assert _cosine_coefficients(1.0)[1] == pytest.approx(0.5, abs=1e-15)
    assert _cosine_coefficients(2.0)[2] == pytest.approx(0.125, abs=1e-15)
