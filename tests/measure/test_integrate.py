"""Slope integration (measure/integrate.py) against analytic surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.measure.integrate import (
    frankot_chellappa,
    grid_coordinates,
    height_stats,
    legendre_terms,
    modal_fit,
    remove_terms,
    southwell,
    zernike,
    zernike_noll_index,
)

H = 0.5  # mm


def quad(x, y):
    return 1e-3 * (0.3 * x * x + 0.7 * x * y - 0.2 * y * y) + 0.01 * x - 0.02 * y


def quad_grad(x, y):
    return 1e-3 * (0.6 * x + 0.7 * y) + 0.01, 1e-3 * (0.7 * x - 0.4 * y) - 0.02


def ripple(x, y):
    return 1e-4 * np.sin(2 * np.pi * x / 7 + 0.3) * np.cos(2 * np.pi * y / 9)


def ripple_grad(x, y):
    a = 2 * np.pi / 7
    b = 2 * np.pi / 9
    return (
        1e-4 * a * np.cos(a * x + 0.3) * np.cos(b * y),
        -1e-4 * b * np.sin(a * x + 0.3) * np.sin(b * y),
    )


def masks(x, y):
    r = np.hypot(x, y)
    return {
        "rectangle": np.ones_like(x, bool),
        "circle": r < 9.0,
        "annulus": (r < 9.0) & (r > 3.5),
        "inner_rectangle": (np.abs(x) < 8.0) & (np.abs(y) < 5.0),
    }


@pytest.mark.parametrize("order", [2, 4])
@pytest.mark.parametrize("kind", ["rectangle", "circle", "annulus", "inner_rectangle"])
def test_southwell_exact_on_quadratics(kind, order):
    x, y = grid_coordinates((41, 45), H)
    m = masks(x, y)[kind]
    sx, sy = quad_grad(x, y)
    truth = remove_terms(quad(x, y), m, x, y, "piston")
    solvers = ["dct", "pcg", "direct", "amg"] if kind == "rectangle" else ["pcg", "direct", "amg"]
    for solver in solvers:
        z = southwell(sx, sy, H, None if kind == "rectangle" else m, order=order, solver=solver)
        assert np.array_equal(np.isfinite(z), m)
        err = np.nanmax(np.abs(z - truth)) / np.nanmax(np.abs(truth))
        assert err < 1e-9, (solver, err)


@pytest.mark.parametrize("kind", ["rectangle", "circle", "annulus"])
def test_southwell_grid_refinement_ripple(kind):
    """Classic Southwell converges at second order, the corrected scheme at fourth."""
    errs = {2: [], 4: []}
    for h in (0.5, 0.25, 0.125):
        n = int(round(20 / h)) + 1
        x, y = grid_coordinates((n, n), h)
        m = masks(x, y)[kind]
        sx, sy = ripple_grad(x, y)
        truth = remove_terms(ripple(x, y), m, x, y, "piston")
        for order in (2, 4):
            z = southwell(np.where(m, sx, np.nan), sy, h, m, order=order)
            errs[order].append(np.sqrt(np.nanmean((z - truth) ** 2)))
    r2 = np.log2(np.array(errs[2][:-1]) / np.array(errs[2][1:]))
    r4 = np.log2(np.array(errs[4][:-1]) / np.array(errs[4][1:]))
    assert np.all((r2 > 1.85) & (r2 < 2.15)), r2
    assert np.all(r4 > 3.5), r4
    assert errs[4][0] < errs[2][0] / 10


def test_southwell_islands_piston_per_part():
    x, y = grid_coordinates((31, 61), H)
    m = (np.hypot(x + 8, y) < 6) | (np.hypot(x - 8, y) < 6)
    sx, sy = quad_grad(x, y)
    z = southwell(sx, sy, H, m)
    left = m & (x < 0)
    for part in (left, m & (x > 0)):
        t = quad(x, y)[part]
        np.testing.assert_allclose(z[part], t - t.mean(), atol=1e-12 * np.abs(t).max())


def test_southwell_nan_slopes_are_masked():
    x, y = grid_coordinates((21, 21), H)
    sx, sy = quad_grad(x, y)
    sx[3, 4] = np.nan
    z = southwell(sx, sy, H)
    assert np.isnan(z[3, 4]) and np.isfinite(z).sum() == 21 * 21 - 1


def test_southwell_rejects_bad_input():
    with pytest.raises(ValueError, match="order"):
        southwell(np.zeros((4, 4)), np.zeros((4, 4)), 1.0, order=3)
    with pytest.raises(ValueError, match="dct"):
        southwell(np.zeros((4, 4)), np.zeros((4, 4)), 1.0, np.eye(4, dtype=bool), solver="dct")
    with pytest.raises(ValueError, match="shape"):
        southwell(np.zeros((4, 4)), np.zeros((4, 5)), 1.0)


@pytest.mark.parametrize("order", [2, 4])
def test_southwell_rhs_kernel_matches_numpy_reference(order):
    """The compiled right-hand side (kernels.reconstruct.southwell_rhs) against the NumPy
    reference on masks with every neighbour case: islands, one-node-wide lines, single
    nodes, edges; unequal steps."""
    from naive_integrate import southwell_rhs as naive_rhs

    from pmdsim.measure.integrate import _southwell_rhs

    rng = np.random.default_rng(7)
    m = rng.random((37, 53)) < 0.8
    m[5, :] = True
    m[:, 9] = False
    m[20:23, 30] = True
    sx, sy = rng.standard_normal((2, 37, 53))
    got = _southwell_rhs(np.where(m, sx, 0.0), np.where(m, sy, 0.0), m, 0.3, 0.45, order)
    want = naive_rhs(sx, sy, m, 0.3, 0.45, order)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


def test_southwell_reuses_the_operator_of_a_mask():
    """Calls with the same mask share one factorisation / hierarchy (and still answer each
    call's own slopes exactly); a different mask gets its own."""
    from pmdsim.measure import poisson

    poisson.clear_operator_cache()
    x, y = grid_coordinates((41, 45), H)
    circle = masks(x, y)["circle"]
    annulus = masks(x, y)["annulus"]
    for k, solver in enumerate(("direct", "amg", "pcg")):
        for scale in (1.0, -2.5):
            sx, sy = quad_grad(scale * x, scale * y)
            truth = remove_terms(quad(scale * x, scale * y) / scale, circle, x, y, "piston")
            guess = truth + 1e-6 * x if solver != "direct" else None  # a warm start
            z = southwell(sx, sy, H, circle, solver=solver, x0=guess)
            assert np.nanmax(np.abs(z - truth)) < 1e-9 * np.nanmax(np.abs(truth))
        assert len(poisson._OPERATORS) == min(k + 1, 2)
    southwell(sx, sy, H, annulus, solver="direct")
    assert len(poisson._OPERATORS) == 2  # the latest two are kept
    poisson.clear_operator_cache()


# Documented edge error of Frankot-Chellappa on the mirror-extended field (docs/reconstruction.md):
# max |error| <= 0.25 h max|edge-normal slope|, falling with h.
@pytest.mark.parametrize("surface", ["quad", "ripple"])
def test_frankot_chellappa_edge_error(surface):
    f, g = (quad, quad_grad) if surface == "quad" else (ripple, ripple_grad)
    prev = np.inf
    for h in (0.5, 0.25):
        n = int(round(20 / h)) + 1
        x, y = grid_coordinates((n, n), h)
        sx, sy = g(x, y)
        m = np.ones_like(x, bool)
        truth = remove_terms(f(x, y), m, x, y)
        err = np.abs(frankot_chellappa(sx, sy, h) - truth).max()
        edge_slope = max(np.abs(sx[:, [0, -1]]).max(), np.abs(sy[[0, -1], :]).max())
        assert err <= 0.25 * h * edge_slope, (err, h * edge_slope)
        assert err < prev
        prev = err


def test_frankot_chellappa_periodic_is_spectral():
    """On a field periodic over the grid the plain FFT method is exact."""
    n = 64
    h = 0.25
    x, y = grid_coordinates((n, n), h)
    L = n * h
    z = 1e-4 * np.sin(2 * np.pi * 3 * x / L + 0.2) * np.cos(2 * np.pi * 2 * y / L)
    sx = 1e-4 * 2 * np.pi * 3 / L * np.cos(2 * np.pi * 3 * x / L + 0.2) * np.cos(2 * np.pi * 2 * y / L)
    sy = -1e-4 * 2 * np.pi * 2 / L * np.sin(2 * np.pi * 3 * x / L + 0.2) * np.sin(2 * np.pi * 2 * y / L)
    m = np.ones_like(x, bool)
    out = frankot_chellappa(sx, sy, h, extend="none")
    np.testing.assert_allclose(out, remove_terms(z, m, x, y), atol=1e-15)


def test_zernike_index_and_normalisation():
    assert [zernike_noll_index(j) for j in range(1, 12)] == [
        (0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2), (3, -1), (3, 1), (3, -3), (3, 3), (4, 0)
    ]
    # orthonormality (RMS 1) by Gauss-Legendre x trapezoid quadrature on the unit disc
    rg, wg = np.polynomial.legendre.leggauss(40)
    r = 0.5 * (rg + 1)
    wr = 0.5 * wg * r
    th = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    rr, tt = np.meshgrid(r, th)
    w = np.broadcast_to(wr, rr.shape) * (2 * np.pi / 80) / np.pi
    zs = [zernike(j, rr * np.cos(tt), rr * np.sin(tt))[0] for j in range(1, 22)]
    gram = np.array([[np.sum(w * a * b) for b in zs] for a in zs])
    np.testing.assert_allclose(gram, np.eye(21), atol=1e-12)


def test_zernike_gradient_matches_numerical():
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-0.7, 0.7, (2, 50))
    x[0], y[0] = 0.0, 0.0  # the centre too
    e = 1e-6
    for j in range(1, 29):
        _, gx, gy = zernike(j, x, y)
        nx = (zernike(j, x + e, y)[0] - zernike(j, x - e, y)[0]) / (2 * e)
        ny = (zernike(j, x, y + e)[0] - zernike(j, x, y - e)[0]) / (2 * e)
        np.testing.assert_allclose(gx, nx, atol=1e-7)
        np.testing.assert_allclose(gy, ny, atol=1e-7)


def test_modal_fit_recovers_coefficients():
    x, y = grid_coordinates((61, 61), 0.5)
    rad = 15.0
    m = np.hypot(x, y) <= rad
    true = np.zeros(22)
    true[[1, 2, 3, 4, 6, 10, 21]] = [2e-3, -1e-3, 5e-4, 3e-4, -2e-4, 1e-4, 5e-5]
    z = np.zeros_like(x)
    sx = np.zeros_like(x)
    sy = np.zeros_like(x)
    for k, c in enumerate(true):
        a, b, d = zernike(k + 1, x / rad, y / rad)
        z += c * a
        sx += c * b / rad
        sy += c * d / rad
    fit = modal_fit(sx, sy, 0.5, m, basis="zernike", n_terms=22, radius_mm=rad)
    np.testing.assert_allclose(fit.coefficients[1:], true[1:], atol=1e-15)
    np.testing.assert_allclose(fit.height[m], (z - z[m].mean())[m], atol=1e-14)
    # Legendre on a rectangle: a cubic is represented exactly
    xr, yr = grid_coordinates((31, 41), 0.5)
    zc = 1e-4 * (xr**3 - 2 * xr * yr + yr**2)
    sxc, syc = 1e-4 * (3 * xr**2 - 2 * yr), 1e-4 * (-2 * xr + 2 * yr)
    fl = modal_fit(sxc, syc, 0.5, basis="legendre", n_terms=10)
    full = np.ones_like(xr, bool)
    np.testing.assert_allclose(fl.height, remove_terms(zc, full, xr, yr), atol=1e-14)
    assert legendre_terms(6) == [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    assert fl.names[:3] == ("L00", "L10", "L01") and fl.residual_rms < 1e-15


def test_remove_terms_and_stats():
    x, y = grid_coordinates((41, 41), 0.5)
    m = np.hypot(x, y) < 9
    base = 1e-6 * np.cos(x) * np.sin(1.3 * y)
    low = 0.3 + 1e-3 * x - 2e-3 * y + 4e-4 * (x * x + y * y)
    ref = remove_terms(base, m, x, y, "power")
    np.testing.assert_allclose(remove_terms(base + low, m, x, y, "power"), ref, atol=1e-12)
    assert np.nanstd(remove_terms(base + low, m, x, y, "tilt")) > 100 * np.nanstd(ref)
    s = height_stats(ref)
    v = ref[m] - ref[m].mean()
    assert s.n == m.sum() and np.isclose(s.rms, np.sqrt(np.mean(v**2)))
    assert np.isclose(s.pv, v.max() - v.min()) and np.isclose(s.p95, np.percentile(np.abs(v), 95))


def test_dct_solve_with_a_tridiagonal_axis():
    """A large grid of awkward lengths (263 and 307 are prime) takes the DCT + tridiagonal
    path: it agrees with the 2-D DCT solve and integrates a quadratic exactly."""
    import scipy.fft

    from pmdsim.measure.poisson import _dct_eigenvalues, _dct_poisson, _neumann_tridiagonal_solve

    rng = np.random.default_rng(2)
    rhs = rng.standard_normal((263, 307))
    rhs -= rhs.mean()
    c = scipy.fft.dctn(rhs, type=2, norm="ortho") / _dct_eigenvalues(rhs.shape)
    c[0, 0] = 0.0
    want = scipy.fft.idctn(c, type=2, norm="ortho")
    got = _dct_poisson(rhs)
    assert np.abs(got - want).max() < 1e-10 * np.abs(want).max()
    # the tridiagonal sweep against dense solves of shifted Neumann systems
    n = 9
    t = np.diag(np.r_[1.0, 2.0 * np.ones(n - 2), 1.0]) - np.eye(n, k=1) - np.eye(n, k=-1)
    b = rng.standard_normal((2, n))
    shifts = np.array([0.37, 1e-4])
    out = _neumann_tridiagonal_solve(b, shifts)
    for k in range(2):
        np.testing.assert_allclose(out[k], np.linalg.solve(t + shifts[k] * np.eye(n), b[k]), rtol=1e-10)
    x, y = grid_coordinates(rhs.shape, H)
    sx, sy = quad_grad(x, y)
    z = southwell(sx, sy, H, solver="dct")
    truth = remove_terms(quad(x, y), np.ones(rhs.shape, bool), x, y, "piston")
    assert np.abs(z - truth).max() < 1e-9 * np.abs(truth).max()


def test_southwell_on_an_empty_mask_is_all_nan():
    for solver in ("auto", "pcg", "direct", "amg"):
        z = southwell(np.zeros((6, 7)), np.zeros((6, 7)), H, np.zeros((6, 7), bool), solver=solver)
        assert z.shape == (6, 7) and np.isnan(z).all()
