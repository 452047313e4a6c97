"""Compiled numeric kernels: vision rays (``primary``), scattered bundles and pattern sums
(``bundle``), the fringes' per-tile finishing and error sums (``fringe_finish``), phase
decoding (``decode``), reconstruction (``reconstruct``), sag surfaces (``surface``),
mantissa rounding for storage (``bits``), the exposure and integer images of camera
values (``images``), the window of a large sample's order statistics (``select``),
polynomial exp/sin/cos (``fastmath``); every
Numba option in ``_jit``.

Modules here import nothing from the rest of :mod:`pmdsim`; they take and return plain
NumPy arrays. Public, validated entry points live one layer up (``pmdsim.render``,
``pmdsim.decode``, ...). Every kernel has a slow NumPy reference in ``tests/naive.py`` or
``tests/naive_decode.py`` and a test comparing the two.
"""

from . import _jit  # noqa: F401  (first: sets Numba's CPU features before Numba loads)
