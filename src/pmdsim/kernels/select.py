"""Compiled selection pass for order statistics of large samples.

:func:`window_values` gathers the values of a sample that lie in a closed window
``[low, high]`` and counts those below it, in one pass: when the window holds the order
statistics asked for, partitioning the few values inside it gives them exactly, instead of
partitioning the whole sample (:mod:`pmdsim.quantiles`). The NumPy reference is
``values[(values >= low) & (values <= high)]`` and ``count_nonzero(values < low)``;
``tests/test_quantiles.py`` compares them.
"""

from __future__ import annotations

from ._jit import jit


@jit
def window_values(values, low, high, out):
    """Gather into ``out`` the values ``v`` of ``values`` (1-D, float32 or float64) with
    ``low <= v <= high``, in order; returns ``(below, inside, nan)``: how many values are
    ``< low``, how many lie in the window, and whether a NaN was met. ``out[:inside]``
    holds the window's values only where ``inside < out.size`` (else ``out`` is too small
    and its content undefined). Without branches on the values (a window about a median
    would mispredict every other one): each value is written to the next free place and
    kept there only if it lies in the window."""
    below = 0
    inside = 0
    nan = False
    last = out.shape[0] - 1
    if last < 0:
        return 0, 0, False
    for i in range(values.shape[0]):
        v = values[i]
        out[min(inside, last)] = v
        below += v < low
        inside += (v >= low) & (v <= high)
        nan |= v != v
    return below, inside, nan
