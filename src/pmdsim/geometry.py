"""Small vector helpers (float64, vectors in the last axis of 3)."""

from __future__ import annotations

import numpy as np


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis; zero vectors stay zero (no NaN)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis."""
    return np.einsum("...k,...k->...", a, b)


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over a last axis of length 3, written out: the numbers of
    ``np.sum(a * b, -1)`` (the same order of additions; :func:`dot`'s ``einsum`` rounds
    differently) at the speed of ``einsum``, not of NumPy's reduction over a short axis."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def reflect(i: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction of ``i`` (pointing away from the surface) about the normal ``n``."""
    return 2.0 * dot(i, n)[..., None] * n - i
