"""The linear solvers of the Southwell normal equations (:func:`pmdsim.measure.integrate.southwell`):
the exact DCT solve of the Neumann Laplacian on full rectangles, and for masked grids
conjugate gradients preconditioned by it, SciPy's sparse LU or PyAMG's multigrid, with
the latest two operators kept (:func:`clear_operator_cache`)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.sparse as sp
import scipy.sparse.csgraph
import scipy.sparse.linalg


def _dct_poisson(rhs):
    """Solve L z = rhs for the Neumann grid Laplacian L = Dx^T Dx + Dy^T Dy (forward
    differences, unit step) on a full rectangle; the zero-mean solution.

    Both axes by DCT-II when their lengths have small prime factors (or the grid is small);
    otherwise (a DCT of a length like 1226 = 2 x 613 takes 3x longer) DCT along the axis
    with the smaller largest prime factor only and, for each of its modes k, the tridiagonal
    system (T + lambda_k I) y = c_k along the other axis
    (:func:`_neumann_tridiagonal_solve`; mode 0 by a 1-D DCT).
    The two agree to ~1e-11 relative (the Thomas sweep of the near-singular low modes)."""
    h, w = rhs.shape
    if all(scipy.fft.next_fast_len(n, real=True) == n for n in (h, w)) or min(h, w) < 3 or h * w < 65_536:
        c = scipy.fft.dctn(rhs, type=2, norm="ortho", workers=-1)
        c /= _dct_eigenvalues(rhs.shape)
        c[0, 0] = 0.0
        return scipy.fft.idctn(c, type=2, norm="ortho", workers=-1)
    # the DCT axis: the length with the smaller largest prime factor; the other is solved directly
    axis = 0 if _largest_prime_factor(h) <= _largest_prime_factor(w) else 1
    c = scipy.fft.dct(rhs, type=2, norm="ortho", axis=axis, workers=-1)
    c = np.ascontiguousarray(c if axis == 0 else c.T)  # (modes, positions)
    k = c.shape[0]
    lam = 2.0 - 2.0 * np.cos(np.pi * np.arange(k) / k)
    y = np.zeros_like(c)
    y[1:] = _neumann_tridiagonal_solve(c[1:], lam[1:])
    # mode 0: the singular 1-D Neumann problem, its zero-mean solution
    n = c.shape[1]
    c0 = scipy.fft.dct(c[0], type=2, norm="ortho")
    lam1 = 2.0 - 2.0 * np.cos(np.pi * np.arange(n) / n)
    lam1[0] = 1.0
    c0 /= lam1
    c0[0] = 0.0
    y[0] = scipy.fft.idct(c0, type=2, norm="ortho")
    return scipy.fft.idct(y if axis == 0 else y.T, type=2, norm="ortho", axis=axis, workers=-1)


@dataclass(eq=False)
class _SouthwellOperator:
    """The normal matrix of the Southwell equations on one mask (the Neumann grid Laplacian
    of the measured nodes; independent of the slopes and of the grid step) and its solver:
    ``lu`` (SuperLU of the matrix with one node pinned per connected part), ``ml`` (the
    PyAMG hierarchy of the singular matrix) or ``box`` (for ``pcg``: the slices of the
    mask's bounding box and the shape of the DCT rectangle that holds it)."""

    lap: object
    ncomp: int
    labels: np.ndarray
    lu: object = None
    ml: object = None
    box: tuple = None


_OPERATORS: dict = {}  # (shape, kind, mask digest) -> _SouthwellOperator, the latest two


_OPERATORS_KEPT = 2


_OPERATORS_LOCK = threading.Lock()  # runs and sweep points may integrate in threads


def clear_operator_cache():
    """Forget the kept Southwell factorisations and AMG hierarchies (their memory)."""
    with _OPERATORS_LOCK:
        _OPERATORS.clear()


def _laplacian(m):
    """The Neumann grid Laplacian A^T A of the measured nodes' neighbour pairs (CSR)."""
    h, w = m.shape
    n = int(m.sum())
    idx = np.full((h, w), -1, np.int64)
    idx[m] = np.arange(n)
    px = m[:, :-1] & m[:, 1:]
    py = m[:-1, :] & m[1:, :]
    i0 = np.concatenate([idx[:, :-1][px], idx[:-1, :][py]])
    i1 = np.concatenate([idx[:, 1:][px], idx[1:, :][py]])
    deg = np.bincount(i0, minlength=n) + np.bincount(i1, minlength=n)
    rows = np.concatenate([i0, i1, np.arange(n)])
    cols = np.concatenate([i1, i0, np.arange(n)])
    vals = np.concatenate([-np.ones(2 * len(i0)), deg.astype(np.float64)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _operator(m, kind):
    import hashlib

    key = (m.shape, kind, hashlib.blake2b(np.packbits(m).tobytes(), digest_size=16).hexdigest())
    with _OPERATORS_LOCK:
        op = _OPERATORS.get(key)
    if op is not None:
        return op
    lap = _laplacian(m)
    ncomp, labels = scipy.sparse.csgraph.connected_components(lap, directed=False)
    op = _SouthwellOperator(lap, ncomp, labels)
    if kind == "pcg":
        rows = np.flatnonzero(m.any(axis=1))
        cols = np.flatnonzero(m.any(axis=0))
        box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
        # a DCT of a length with a large prime factor is several times slower: the
        # rectangle of the preconditioner only has to hold the mask
        shape = tuple(scipy.fft.next_fast_len(int(n), real=True)
                      for n in (rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))
        op.box = (box, shape)
    elif kind == "direct" or ncomp > 16:  # many islands: AMG's near-null space would be too wide
        # pin one node per connected part (piston is free; set afterwards): since the
        # right-hand side sums to zero over each part, the pinned node comes out 0 and
        # the others solve the singular system exactly
        first = np.unique(labels, return_index=True)[1]
        pin = np.zeros(lap.shape[0])
        pin[first] = 1.0
        op.lu = scipy.sparse.linalg.splu((lap + sp.diags(pin)).tocsc(), permc_spec="MMD_AT_PLUS_A")
    else:
        try:
            import pyamg
        except ImportError as e:  # pragma: no cover - pyamg is a dependency
            raise ImportError("solver='amg' needs PyAMG (pip install pyamg)") from e
        # the singular Neumann system itself (consistent: rhs sums to zero per part), with
        # the constants of each part as the near-null space; CG stays in the range
        near_null = np.zeros((lap.shape[0], ncomp))
        near_null[np.arange(lap.shape[0]), labels] = 1.0
        op.ml = pyamg.smoothed_aggregation_solver(lap, B=near_null, symmetry="hermitian", max_coarse=500)
    with _OPERATORS_LOCK:
        while len(_OPERATORS) >= _OPERATORS_KEPT:
            _OPERATORS.pop(next(iter(_OPERATORS)))
        _OPERATORS[key] = op
    return op


def _southwell_sparse(rhs, m, solver, x0=None, rtol=1e-11):
    op = _operator(m, solver)
    b = rhs[m]
    if op.lu is not None:
        z = op.lu.solve(b)
    else:
        guess = None
        if x0 is not None:
            guess = np.asarray(x0, np.float64)[m]
            if not np.isfinite(guess).all():
                guess = None
        norm_b = max(float(np.linalg.norm(b)), 1e-300)
        # the residual to reach: rtol of the first guess's residual (of b without one)
        target = rtol * (norm_b if guess is None else float(np.linalg.norm(b - op.lap @ guess)))
        if op.box is not None:
            z = _pcg(op, m, b, guess, target)
        else:
            # SciPy's CG with the AMG V-cycle as preconditioner: PyAMG's own CG warns
            # "Indefinite matrix detected" once the residual reaches round-off, and it turns
            # its warnings on itself at every call (a caller's filter cannot hold them)
            z, _ = scipy.sparse.linalg.cg(op.lap, b, x0=guess, rtol=target / norm_b,
                                          atol=0.0, maxiter=300,
                                          M=op.ml.aspreconditioner(cycle="V"))
        res = np.linalg.norm(op.lap @ z - b)
        if not res <= max(1e-8 * norm_b, 2.0 * target):  # not converged: the sure way
            return _southwell_sparse(rhs, m, "direct")
    out = np.zeros(m.shape)
    out[m] = z
    return out


def _pcg(op, m, b, x0, atol, maxiter=200):
    """CG on the masked Southwell system to a residual of ``atol``, preconditioned by the
    exact solve of the system on a rectangle holding the mask (:func:`_dct_poisson`) with
    the residual put on the mask's nodes and zeros around: a fictitious-domain
    preconditioner, symmetric and positive definite."""
    (box, shape) = op.box
    mb = m[box]
    h, w = mb.shape
    lam = _dct_eigenvalues(shape)
    pad = np.zeros(shape)
    inner = pad[:h, :w]

    def precondition(r):
        inner[mb] = r
        c = scipy.fft.dctn(pad, type=2, norm="ortho", workers=-1)
        c /= lam
        c[0, 0] = 0.0
        return scipy.fft.idctn(c, type=2, norm="ortho", workers=-1)[:h, :w][mb]

    n = len(b)
    prec = scipy.sparse.linalg.LinearOperator((n, n), matvec=precondition, dtype=np.float64)
    z, _ = scipy.sparse.linalg.cg(op.lap, b, x0=x0, rtol=0.0, atol=atol, maxiter=maxiter, M=prec)
    return z


def _neumann_tridiagonal_solve(rhs, shift):
    """Solve ``(T + shift[k] I) y_k = rhs[k]`` for every row k of ``rhs`` (K, n) (all shifts
    > 0), T the 1-D Neumann grid Laplacian of length n (diagonal 1, 2, ..., 2, 1;
    off-diagonals -1): the Thomas algorithm, one sweep for all rows at once (stable: the
    matrices are symmetric, positive definite and diagonally dominant)."""
    k, n = rhs.shape
    if n == 1:
        return rhs / shift[:, None]
    cp = np.empty((n, k))  # modified super-diagonal, position-major
    y = np.empty((n, k))
    r = rhs.T
    den = 1.0 + shift
    cp[0] = -1.0 / den
    y[0] = r[0] / den
    for i in range(1, n):
        den = (2.0 if i < n - 1 else 1.0) + shift + cp[i - 1]  # b - a cp[i-1], a = -1
        cp[i] = -1.0 / den
        y[i] = (r[i] + y[i - 1]) / den
    for i in range(n - 2, -1, -1):
        y[i] -= cp[i] * y[i + 1]
    return y.T


def _largest_prime_factor(n):
    p, largest = 2, 1
    while p * p <= n:
        while n % p == 0:
            n //= p
            largest = p
        p += 1
    return max(largest, n) if n > 1 else largest


def _dct_eigenvalues(shape):
    """Eigenvalues of the Neumann grid Laplacian of ``shape`` in the DCT-II basis ([0, 0]
    set to 1: the constant mode is dropped by the caller)."""
    h, w = shape
    lam = (2.0 - 2.0 * np.cos(np.pi * np.arange(h) / h))[:, None] + (2.0 - 2.0 * np.cos(np.pi * np.arange(w) / w))[None, :]
    lam[0, 0] = 1.0
    return lam
