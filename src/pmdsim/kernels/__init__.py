"""Compiled numeric kernels.

Modules here import nothing from the rest of :mod:`pmdsim`; they take and return plain
NumPy arrays. Public, validated entry points live one layer up (``pmdsim.render``,
``pmdsim.decode``, ...). Every kernel has a slow NumPy reference in ``tests/naive.py`` or
``tests/naive_decode.py`` and a test comparing the two.
"""

from . import _jit  # noqa: F401  (first: sets Numba's CPU features before Numba loads)
