"""The replicates' phase error of whole-camera arrays in one compiled pass
(:func:`pmdsim.render.results._phase_error_compiled`) against the NumPy expressions of
:func:`pmdsim.render.results.phase_error`: the same bytes, with zero, NaN and infinite
sums and errors among them."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.render import results


@pytest.mark.parametrize("shape", [(2, 3, 96, 1024), (300, 257)])
def test_compiled_replicates_statement_has_the_numpy_bytes(shape, monkeypatch):
    rng = np.random.default_rng(11)
    sums = rng.standard_normal(shape) + 1j * rng.standard_normal(shape) * 0.3
    err = 1e-3 * np.abs(rng.standard_normal(shape)) + 2e-3j * np.abs(rng.standard_normal(shape))
    flat_s, flat_e = sums.reshape(-1), err.reshape(-1)
    flat_s[:5] = 0.0
    flat_s[5:9] = np.nan
    flat_s[9] = 1e-300 + 1e-300j  # |S|^2 underflows where |S| does not
    flat_e[10:14] = 0.0
    flat_e[14] = np.inf
    flat_s[15] = -0.0 - 0.0j
    assert sums.size >= results._COMPILED_MIN
    with np.errstate(all="ignore"):
        compiled = results.phase_error(sums, err, "replicates")
        monkeypatch.setattr(results, "_COMPILED_MIN", sums.size + 1)
        plain = results.phase_error(sums, err, "replicates")
    assert compiled.dtype == plain.dtype and compiled.shape == plain.shape
    assert compiled.tobytes() == plain.tobytes()
    assert np.isnan(compiled.reshape(-1)[:9]).all()
    assert compiled.reshape(-1)[10] == results.ROUNDOFF_PHASE
