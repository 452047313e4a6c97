"""The decoder's input checks (frames, widths, shifts, thresholds: errors name the argument)
and the plan of the temporal unwrapping of each method (:mod:`pmdsim.measure.decode`):
which width unwraps which, through which beats, and the unambiguous range."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


METHODS = ("hierarchical", "heterodyne", "number_theoretic")


def _check_frames(frames, name: str, ndim: int, layout: str) -> np.ndarray:
    arr = np.asarray(frames)
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have the layout {layout}, got shape {arr.shape}")
    if arr.dtype.kind in "ui":
        arr = arr.astype(np.float64 if arr.dtype.itemsize > 2 else np.float32)
    elif arr.dtype not in (np.float32, np.float64):
        raise ValueError(
            f"{name} must be a float32, float64 or integer array, got dtype {arr.dtype}"
        )
    if min(arr.shape) == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def _check_out_dtype(dtype) -> np.dtype:
    dt = np.dtype(dtype)
    if dt not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float32 or float64, got {dt}")
    return dt


def _check_positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


def _check_thresholds(min_amplitude, min_relative_amplitude, max_order_residual):
    a = float(min_amplitude)
    if not (math.isfinite(a) and a >= 0):
        raise ValueError(f"min_amplitude must be a finite number >= 0, got {min_amplitude!r}")
    rel = float(min_relative_amplitude)
    if not (math.isfinite(rel) and rel >= 0):
        raise ValueError(
            f"min_relative_amplitude must be a finite number >= 0, got {min_relative_amplitude!r}"
        )
    res = float(max_order_residual)
    if not (0 < res <= 0.5):
        raise ValueError(
            f"max_order_residual must lie in (0, 0.5] (0.5 = ambiguous order), "
            f"got {max_order_residual!r}"
        )
    return a, rel, res


def _check_shifts(shifts) -> int:
    """K from an integer K or from the K shift angles (which must be 2 pi k / K)."""
    if np.ndim(shifts) == 1:
        try:
            deltas = np.asarray(shifts, dtype=np.float64)
        except (TypeError, ValueError):
            deltas = np.full(1, np.nan)
        n = deltas.size
        expected = 2.0 * np.pi * np.arange(n) / n
        if n < 3 or not np.allclose(deltas, expected, rtol=0.0, atol=1e-9):
            raise ValueError(
                "shifts given as angles must be the K >= 3 equal shifts 2 pi k / K, "
                f"k = 0..K-1 (rad), got {np.asarray(shifts).tolist()}"
            )
        return n
    if isinstance(shifts, bool) or not isinstance(shifts, (int, np.integer)) or shifts < 3:
        raise ValueError(
            f"shifts must be an integer K >= 3 (number of phase shifts) or the K shift "
            f"angles 2 pi k / K, got {shifts!r}"
        )
    return int(shifts)


def _check_widths(widths) -> np.ndarray:
    try:
        w = np.atleast_1d(np.asarray(widths, dtype=np.float64))
    except (TypeError, ValueError):
        w = np.empty((0, 0))
    if w.ndim != 1 or w.size == 0:
        raise ValueError(
            f"widths must be a non-empty 1-D sequence of fringe widths (monitor px), got {widths!r}"
        )
    if not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError(f"widths must be positive finite monitor px, got {w.tolist()}")
    if np.unique(w).size != w.size:
        raise ValueError(f"widths must be distinct (each width unwraps the next), got {w.tolist()}")
    return w


@dataclass(frozen=True)
class _Plan:
    """Kernel arguments of one unwrapping method for given widths and extent."""

    method: str
    n_widths: int
    finest_index: int
    finest_width: float
    range_px: float
    window_lo: float
    rewrap_period: float = 0.0
    # chain methods
    coef: np.ndarray | None = None
    chain_w: np.ndarray | None = None
    # number-theoretic
    order: np.ndarray | None = None
    widths: np.ndarray | None = None
    step_factor: np.ndarray | None = None
    step_inverse: np.ndarray | None = None
    step_period: np.ndarray | None = None
    unit: float = 0.0


def _heterodyne_chain(w: np.ndarray):
    """Beat tree of widths ``w``: chain coefficients and wavelengths, coarse to fine."""
    idx = np.argsort(w)
    n = w.size
    lam = w[idx].copy()
    coef = np.eye(n)[idx]  # row i: phase of level-0 element i as a combination
    chain_coef = [coef[0].copy()]
    chain_w = [lam[0]]
    for _level in range(1, n):
        new_lam = np.empty(lam.size - 1)
        new_coef = np.empty((lam.size - 1, n))
        for i in range(lam.size - 1):
            a, b = lam[i], lam[i + 1]
            if abs(a - b) <= 1e-12 * max(a, b):
                raise ValueError(
                    f"widths {w.tolist()} give two equal wavelengths ({a:g} monitor px) in the "
                    "heterodyne beat tree, whose beat is constant; choose widths whose "
                    "successive beats differ, or use method='hierarchical'"
                )
            sign = 1.0 if a < b else -1.0
            new_lam[i] = a * b / abs(a - b)
            new_coef[i] = sign * (coef[i] - coef[i + 1])
        lam, coef = new_lam, new_coef
        if lam[0] <= chain_w[-1]:
            raise ValueError(
                f"widths {w.tolist()}: the heterodyne beat of wavelength {lam[0]:g} monitor px "
                f"is not longer than the width it must unwrap ({chain_w[-1]:g}); heterodyne "
                "needs widths within a factor < 2 of each other (e.g. [48, 54, 60]); "
                "otherwise use method='hierarchical'"
            )
        chain_coef.append(coef[0].copy())
        chain_w.append(lam[0])
    return np.array(chain_coef[::-1]), np.array(chain_w[::-1])


def _plan(widths, extent_px, method: str) -> _Plan:
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    w = _check_widths(widths)
    extent = _check_positive(extent_px, "extent_px")
    fine = int(np.argmin(w))

    def window(period):
        return 0.5 * (extent - period - 1.0)

    def rewrap(chain_w):
        ratio = chain_w[0] / chain_w[-1]
        return float(chain_w[0]) if abs(ratio - round(ratio)) <= 1e-9 * ratio else 0.0

    if method == "hierarchical":
        order = np.argsort(-w)
        if w[order[0]] < extent:
            raise ValueError(
                f"widths: hierarchical unwrapping needs the widest width >= extent_px so that its "
                f"phase is absolute, but max(widths) = {w.max():g} < extent_px = {extent:g}; "
                f"add a width of at least {extent:g} monitor px"
            )
        coef = np.eye(w.size)[order]
        return _Plan(method, w.size, fine, float(w[fine]), float(w.max()), window(w.max()),
                     rewrap(w[order]), coef=np.ascontiguousarray(coef), chain_w=w[order].copy())

    if w.size < 2:
        raise ValueError(f"widths: method={method!r} needs at least two widths, got {w.tolist()}")

    if method == "heterodyne":
        coef, chain_w = _heterodyne_chain(w)
        if chain_w[0] < extent:
            raise ValueError(
                f"widths {w.tolist()}: the longest heterodyne synthetic wavelength is "
                f"{chain_w[0]:g} monitor px < extent_px = {extent:g}; choose widths closer "
                "together (longer beats) or add a width"
            )
        return _Plan(method, w.size, fine, float(w[fine]), float(chain_w[0]), window(chain_w[0]),
                     rewrap(chain_w), coef=np.ascontiguousarray(coef), chain_w=chain_w)

    # number-theoretic
    rounded = np.round(w)
    if not np.all(np.abs(w - rounded) <= 1e-9 * w):
        raise ValueError(
            f"widths must be integer monitor px for method='number_theoretic', got {w.tolist()}"
        )
    ints = [int(x) for x in rounded]
    unit = math.gcd(*ints)
    factors = [x // unit for x in ints]
    for i in range(len(factors)):
        for j in range(i + 1, len(factors)):
            if math.gcd(factors[i], factors[j]) != 1:
                raise ValueError(
                    f"widths {ints}: with g = gcd = {unit}, widths/g = {factors} must be pairwise "
                    f"coprime for method='number_theoretic', but {factors[i]} and {factors[j]} "
                    f"share the factor {math.gcd(factors[i], factors[j])}; choose e.g. "
                    "[96, 128, 160] (g = 32, 3:4:5)"
                )
    period = unit * math.prod(factors)
    if period < extent:
        raise ValueError(
            f"widths {ints}: the number-theoretic unambiguous range lcm(widths) = {period} "
            f"monitor px < extent_px = {extent:g}; use larger or more coprime widths"
        )
    order = np.argsort(w)
    step_factor = np.zeros(w.size)
    step_inverse = np.zeros(w.size)
    step_period = np.zeros(w.size)
    prod = factors[order[0]]
    step_factor[0] = prod
    for s in range(1, w.size):
        b = factors[order[s]]
        step_factor[s] = b
        step_inverse[s] = pow(prod % b, -1, b) if b > 1 else 0
        step_period[s] = prod * unit
        prod *= b
    return _Plan(method, w.size, fine, float(w[fine]), float(period), window(period),
                 order=order.astype(np.int64), widths=w, step_factor=step_factor,
                 step_inverse=step_inverse, step_period=step_period, unit=float(unit))


def unambiguous_range_px(widths: Sequence[float], method: str = "hierarchical") -> float:
    """Longest monitor extent a set of widths can unwrap.

    Parameters
    ----------
    widths : sequence of float, monitor px
        Fringe widths (periods), any order.
    method : {"hierarchical", "heterodyne", "number_theoretic"}
        Unwrapping method.

    Returns
    -------
    range_px : float, monitor px
        ``max(widths)`` (hierarchical), the longest synthetic wavelength (heterodyne) or
        ``lcm(widths)`` (number-theoretic).

    Raises
    ------
    ValueError
        If the widths do not fit the method (see the module docstring).
    """
    return _plan(widths, 1.0, method).range_px
