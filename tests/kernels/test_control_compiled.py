"""The nearest monitor's control variate's whole-camera steps in compiled passes
(:meth:`pmdsim.render.control_variate._Layout.sums_of_columns`, :func:`pmdsim.render.control_variate.
_half_widths`) against the NumPy expressions they replace: the same bytes (signed zeros
included; of a NaN only that it is one: x86's 0 * inf and sqrt(-1) are a NaN of the other
sign than NumPy's loops give), with zeros, infinities and NaN among the inputs, float32 and
float64 columns."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.render import control_variate as control


def _same(a, b) -> bool:
    """The same complex values, bit for bit (signed zeros), NaN where the other is NaN."""
    a, b = np.asarray(a).reshape(-1), np.asarray(b).reshape(-1)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    parts = []
    for x, y in ((a.real, b.real), (a.imag, b.imag)):
        nan = np.isnan(x)
        if not np.array_equal(nan, np.isnan(y)):
            return False
        parts.append(np.array_equal(x[~nan].view(np.uint64), y[~nan].view(np.uint64)))
    return all(parts)


def _columns(dtype, shape=(37, 53, 9)):
    rng = np.random.default_rng(5)
    t = (rng.standard_normal(shape) * 10.0 ** rng.integers(-8, 3, shape)).astype(dtype)
    flat = t.reshape(-1, shape[-1])
    special = [0.0, -0.0, np.inf, -np.inf, np.nan, 1e-310, -1e-310]
    for k, (a, b) in enumerate((a, b) for a in special for b in special):
        flat[k, 3], flat[k, 4] = a, b  # every pair on a fringe's two columns
    return t


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_sums_of_columns_are_numpys_complex_sums(dtype):
    t = _columns(dtype)
    lay = control._Layout(("x", "y"), (50.0, 400.0), np.arange(4) * np.pi / 2, True, None,
                          t.shape[-1])
    cols = [1, 3, 5, 7]  # (x, 50), (x, 400), (y, 50), (y, 400): unequal offsets
    with np.errstate(all="ignore"):
        got = lay.sums_of_columns(t, cols)
        t64 = t.astype(np.float64)
        want = np.stack([t64[..., c] + 1j * t64[..., c + 1] for c in cols]).reshape(got.shape)
    assert got.dtype == np.complex128 and _same(got, want)
    # the tables' own layout gives fringe_sums (a float64 table as the renders make it)
    if dtype == np.float64:
        lay.fringes = [(di, wi, c, c) for (di, wi), c in zip(
            [(0, 0), (0, 1), (1, 0), (1, 1)], cols)]
        assert _same(lay.fringe_sums(t), want)


def test_half_widths_are_numpys_expression():
    rng = np.random.default_rng(8)
    shape = (2, 3, 41, 67)
    m2_re = rng.random(shape) * 10.0 ** rng.integers(-30, 2, shape)
    m2_im = rng.random(shape) * 10.0 ** rng.integers(-30, 2, shape)
    fr, fi = m2_re.reshape(-1), m2_im.reshape(-1)
    fr[:6] = [0.0, -0.0, np.inf, np.nan, -1e-300, 5e-324]
    fi[:6] = [np.inf, 0.0, -0.0, 2.0, np.nan, -1.0]
    half = float(2.3646242515927844 / np.sqrt(7 * 8))
    with np.errstate(all="ignore"):
        got = control._half_widths(m2_re, m2_im, half)
        want = half * np.sqrt(m2_re) + 1j * half * np.sqrt(m2_im)
    assert got.shape == want.shape and _same(got, want)
    assert np.isnan(got.reshape(-1)[[3, 4]].real).all()  # sqrt(NaN), sqrt(-1e-300)
