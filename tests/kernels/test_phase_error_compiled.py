"""The phase error of whole-camera arrays in one compiled pass (replicates and embedded
rules, :func:`pmdsim.render.results._phase_error_compiled`) against the NumPy expressions
of :func:`pmdsim.render.results.phase_error`: the same bytes, with zero, NaN and infinite
sums and errors among them (the embedded statement to a few ulp: NumPy's complex product
may round through an FMA), and per-fringe convergence factors on either side of 1."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.render import results


def _inputs(shape):
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
    return sums, err


def _both(monkeypatch, sums, err, kind, convergence=None):
    with np.errstate(all="ignore"):
        compiled = results.phase_error(sums, err, kind, convergence)
        monkeypatch.setattr(results, "_COMPILED_MIN", sums.size + 1)
        plain = results.phase_error(sums, err, kind, convergence)
    return compiled, plain


@pytest.mark.parametrize("shape", [(2, 3, 96, 1024), (300, 257)])
def test_compiled_replicates_statement_has_the_numpy_bytes(shape, monkeypatch):
    sums, err = _inputs(shape)
    compiled, plain = _both(monkeypatch, sums, err, "replicates")
    assert compiled.dtype == plain.dtype and compiled.shape == plain.shape
    assert compiled.tobytes() == plain.tobytes()
    assert np.isnan(compiled.reshape(-1)[:9]).all()
    assert compiled.reshape(-1)[10] == results.ROUNDOFF_PHASE


@pytest.mark.parametrize("convergence", [
    None,
    np.array([[0.3, 1.7, np.nan], [0.05, 1.0, 0.99]]),  # per fringe: fast, slow, unknown
    np.array([[0.4], [2.0]]),                              # broadcast over the widths
])
def test_compiled_embedded_statement_has_the_numpy_bytes(convergence, monkeypatch):
    sums, err = _inputs((2, 3, 96, 1024))
    err = err * np.exp(1j * 0.7) * np.where(np.arange(1024) % 2, 1.0, -1.0)  # signed dS
    with np.errstate(all="ignore"):
        unscaled = results.phase_error(sums, err, "embedded")  # compiled, no factors
    compiled, plain = _both(monkeypatch, sums, err, "embedded", convergence)
    assert compiled.dtype == plain.dtype and compiled.shape == plain.shape
    # NumPy's complex product may use an FMA (SIMD loops of some CPUs), the kernel does
    # not: Im(dS conj S) differs by an ulp of its products, the statement (which also
    # holds 0.1 |dS| / |S| >= 0.1 of that term's size) by far less than 1e-13 of itself
    assert np.array_equal(np.isnan(compiled), np.isnan(plain))
    assert np.array_equal(np.isinf(compiled), np.isinf(plain))
    fin = np.isfinite(plain)
    assert np.allclose(compiled[fin], plain[fin], rtol=1e-13, atol=0)
    assert (compiled == plain).mean() > 0.5
    assert np.isnan(compiled.reshape(-1)[:9]).all()
    if convergence is not None and convergence.shape[1] == 3:  # the factor scales fringe (0, 0)
        q = convergence[0, 0]
        ok = np.isfinite(unscaled[0, 0]) & (unscaled[0, 0] > results.ROUNDOFF_PHASE / q)
        assert ok.sum() > 1000
        ratio = compiled[0, 0][ok] / unscaled[0, 0][ok]
        assert np.all((ratio > q) & (ratio < results.CONVERGENCE_SAFETY * q * (1 + 1e-12)))
        assert compiled[0, 1].tobytes() == unscaled[0, 1].tobytes()  # q > 1: unscaled
