"""Vectorisable elementary functions for the hot loops.

Without Intel SVML, LLVM cannot vectorise calls to libm's ``exp``/``sin``/``cos``; a loop
containing one runs scalar. These polynomial versions are plain arithmetic, so the loops that
use them vectorise (AVX2/AVX-512). Their accuracy is tested against NumPy
(``tests/kernels/test_kernels.py``): ``exp_neg`` has a relative error below 1e-11 on [-64, 0],
``sincos`` an absolute error below 1e-13 for |x| <= 100, growing as about 1e-16 |x|
beyond (argument-reduction rounding; 9e-13 at |x| = 1e4), below the rounding error of the
argument k * u itself.
"""

from __future__ import annotations

import numpy as np

from ._jit import fastjit

_PI_HI = 3.14159265358979311600e00
_PI_LO = 1.22464679914735320717e-16
_INV_PI = 0.318309886183790671538


@fastjit(inline="always")
def exp_neg(x):
    """exp(x) for x <= 0; arguments below -64 are clamped (exp(-64) ~ 1.6e-28).

    Evaluates a degree-12 Taylor polynomial at x/128 and squares the result seven times.
    """
    y = max(x, -64.0) * (1.0 / 128.0)
    p = 1.0 / 479001600.0
    p = p * y + 1.0 / 39916800.0
    p = p * y + 1.0 / 3628800.0
    p = p * y + 1.0 / 362880.0
    p = p * y + 1.0 / 40320.0
    p = p * y + 1.0 / 5040.0
    p = p * y + 1.0 / 720.0
    p = p * y + 1.0 / 120.0
    p = p * y + 1.0 / 24.0
    p = p * y + 1.0 / 6.0
    p = p * y + 0.5
    p = p * y + 1.0
    p = p * y + 1.0
    for _ in range(7):
        p = p * p
    return p


@fastjit(inline="always")
def sincos(x):
    """(sin x, cos x): reduction by multiples of pi, Taylor polynomials on [-pi/2, pi/2]."""
    q = np.rint(x * _INV_PI)
    r = (x - q * _PI_HI) - q * _PI_LO
    z = r * r
    s = 1.0 / 355687428096000.0
    s = s * z - 1.0 / 1307674368000.0
    s = s * z + 1.0 / 6227020800.0
    s = s * z - 1.0 / 39916800.0
    s = s * z + 1.0 / 362880.0
    s = s * z - 1.0 / 5040.0
    s = s * z + 1.0 / 120.0
    s = s * z - 1.0 / 6.0
    s = r + r * z * s
    c = 1.0 / 6402373705728000.0
    c = c * z - 1.0 / 20922789888000.0
    c = c * z + 1.0 / 87178291200.0
    c = c * z - 1.0 / 479001600.0
    c = c * z + 1.0 / 3628800.0
    c = c * z - 1.0 / 40320.0
    c = c * z + 1.0 / 720.0
    c = c * z - 1.0 / 24.0
    c = c * z + 0.5
    c = 1.0 - z * c
    sign = 1.0 - 2.0 * (q - 2.0 * np.floor(0.5 * q))
    return s * sign, c * sign
