"""Form removal (measure/form.py) against independent values: a sphere of known radius, a
direct least-squares fit of the residual, the published Fringe Zernike table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdsim.measure.form import (
    FormSpec,
    best_fit_sphere,
    fringe_index,
    remove_form,
    rim_mask,
    zernike_columns,
    zernike_value,
)
from pmdsim.measure.integrate import zernike_noll_index

# The first 37 Fringe (University of Arizona) Zernike polynomials as published (Wyant and
# Creath, "Basic wavefront aberration theory for optical metrology", Applied Optics and
# Optical Engineering XI, 1992, Table 2), unnormalised, in (rho, theta).
C, S = np.cos, np.sin
FRINGE_TABLE = [
    lambda r, t: np.ones_like(r),
    lambda r, t: r * C(t),
    lambda r, t: r * S(t),
    lambda r, t: 2 * r**2 - 1,
    lambda r, t: r**2 * C(2 * t),
    lambda r, t: r**2 * S(2 * t),
    lambda r, t: (3 * r**3 - 2 * r) * C(t),
    lambda r, t: (3 * r**3 - 2 * r) * S(t),
    lambda r, t: 6 * r**4 - 6 * r**2 + 1,
    lambda r, t: r**3 * C(3 * t),
    lambda r, t: r**3 * S(3 * t),
    lambda r, t: (4 * r**4 - 3 * r**2) * C(2 * t),
    lambda r, t: (4 * r**4 - 3 * r**2) * S(2 * t),
    lambda r, t: (10 * r**5 - 12 * r**3 + 3 * r) * C(t),
    lambda r, t: (10 * r**5 - 12 * r**3 + 3 * r) * S(t),
    lambda r, t: 20 * r**6 - 30 * r**4 + 12 * r**2 - 1,
    lambda r, t: r**4 * C(4 * t),
    lambda r, t: r**4 * S(4 * t),
    lambda r, t: (5 * r**5 - 4 * r**3) * C(3 * t),
    lambda r, t: (5 * r**5 - 4 * r**3) * S(3 * t),
    lambda r, t: (15 * r**6 - 20 * r**4 + 6 * r**2) * C(2 * t),
    lambda r, t: (15 * r**6 - 20 * r**4 + 6 * r**2) * S(2 * t),
    lambda r, t: (35 * r**7 - 60 * r**5 + 30 * r**3 - 4 * r) * C(t),
    lambda r, t: (35 * r**7 - 60 * r**5 + 30 * r**3 - 4 * r) * S(t),
    lambda r, t: 70 * r**8 - 140 * r**6 + 90 * r**4 - 20 * r**2 + 1,
    lambda r, t: r**5 * C(5 * t),
    lambda r, t: r**5 * S(5 * t),
    lambda r, t: (6 * r**6 - 5 * r**4) * C(4 * t),
    lambda r, t: (6 * r**6 - 5 * r**4) * S(4 * t),
    lambda r, t: (21 * r**7 - 30 * r**5 + 10 * r**3) * C(3 * t),
    lambda r, t: (21 * r**7 - 30 * r**5 + 10 * r**3) * S(3 * t),
    lambda r, t: (56 * r**8 - 105 * r**6 + 60 * r**4 - 10 * r**2) * C(2 * t),
    lambda r, t: (56 * r**8 - 105 * r**6 + 60 * r**4 - 10 * r**2) * S(2 * t),
    lambda r, t: (126 * r**9 - 280 * r**7 + 210 * r**5 - 60 * r**3 + 5 * r) * C(t),
    lambda r, t: (126 * r**9 - 280 * r**7 + 210 * r**5 - 60 * r**3 + 5 * r) * S(t),
    lambda r, t: 252 * r**10 - 630 * r**8 + 560 * r**6 - 210 * r**4 + 30 * r**2 - 1,
    lambda r, t: (924 * r**12 - 2772 * r**10 + 3150 * r**8 - 1680 * r**6 + 420 * r**4
                  - 42 * r**2 + 1),
]

# Noll's first 11 terms (Noll 1976, Table 1), normalised to unit RMS over the disc
NOLL_TABLE = [
    lambda r, t: np.ones_like(r),
    lambda r, t: 2 * r * C(t),
    lambda r, t: 2 * r * S(t),
    lambda r, t: math.sqrt(3) * (2 * r**2 - 1),
    lambda r, t: math.sqrt(6) * r**2 * S(2 * t),
    lambda r, t: math.sqrt(6) * r**2 * C(2 * t),
    lambda r, t: math.sqrt(8) * (3 * r**3 - 2 * r) * S(t),
    lambda r, t: math.sqrt(8) * (3 * r**3 - 2 * r) * C(t),
    lambda r, t: math.sqrt(8) * r**3 * S(3 * t),
    lambda r, t: math.sqrt(8) * r**3 * C(3 * t),
    lambda r, t: math.sqrt(5) * (6 * r**4 - 6 * r**2 + 1),
]


def _grid(dx=0.4, dy=0.3, radius=22.0, centre=(0.3, -0.2)):
    xs = np.arange(-23.0, 23.01, dx)
    ys = np.arange(-23.0, 23.01, dy) + 0.1
    x, y = np.meshgrid(xs, ys)
    return x, y, np.hypot(x - centre[0], y - centre[1]) <= radius


def test_fringe_order_matches_the_published_table():
    rng = np.random.default_rng(3)
    r = np.sqrt(rng.uniform(0, 1, 500))
    t = rng.uniform(-np.pi, np.pi, 500)
    u, v = r * np.cos(t), r * np.sin(t)
    idx, cols = zernike_columns("fringe", 37, u, v)
    assert [j for j, _, _ in idx] == list(range(1, 38))
    for j, f in enumerate(FRINGE_TABLE, start=1):
        np.testing.assert_allclose(cols[:, j - 1], f(r, t), atol=1e-11, err_msg=f"Fringe Z{j}")
    assert fringe_index(37) == (12, 0) and fringe_index(9) == (4, 0)
    idx, cols = zernike_columns("noll", 11, u, v)
    for j, f in enumerate(NOLL_TABLE, start=1):
        np.testing.assert_allclose(cols[:, j - 1], f(r, t), atol=1e-12, err_msg=f"Noll Z{j}")


@pytest.mark.parametrize("order", ["noll", "fringe"])
def test_zernike_columns_share_work_but_not_numbers(order):
    """The columns share rho, theta and the powers of rho between terms: each is still
    bit for bit the term evaluated alone (so the tables did not change), on a 2-D grid of
    points (columns last)."""
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-1, 1, (7, 9)), rng.uniform(-0.8, 1.1, (7, 9))
    idx, cols = zernike_columns(order, 37, u, v)
    assert cols.shape == (7, 9, 37)
    for k, (j, n, m) in enumerate(idx):
        assert (n, m) == (zernike_noll_index(j) if order == "noll" else fringe_index(j))
        alone = zernike_value(n, m, u, v, normalized=order == "noll")
        assert np.array_equal(cols[..., k], alone), f"{order} Z{j}"


def test_one_basis_for_both_tables_changes_no_number():
    """remove_form evaluates the Noll and Fringe tables on one shared basis of the disc's
    points (radial and angular factors once): every column is still bit for bit the term
    evaluated alone, in either order of use."""
    from pmdsim.measure.form import _Basis

    rng = np.random.default_rng(11)
    u, v = rng.uniform(-1, 1, 301), rng.uniform(-0.7, 0.9, 301)
    shared = _Basis(u, v)
    _, fringe = zernike_columns("fringe", 37, None, None, basis=shared)
    _, noll = zernike_columns("noll", 37, None, None, basis=shared)
    _, noll_alone = zernike_columns("noll", 37, u, v)
    _, fringe_alone = zernike_columns("fringe", 37, u, v)
    assert noll.tobytes() == noll_alone.tobytes()
    assert fringe.tobytes() == fringe_alone.tobytes()


def test_best_fit_sphere_recovers_a_radius_change():
    x, y, m = _grid()
    radius, change = 800.0, 0.8

    def sphere(rad, a=0.0, b=0.0, z0=0.0):
        return z0 + rad - np.sqrt(rad * rad - (x - a) ** 2 - (y - b) ** 2)

    true = sphere(radius)
    measured = sphere(radius + change, a=1.3, b=-0.7, z0=0.01)  # decentred, offset: tilt + piston
    res = remove_form(measured - true, m, x, y, FormSpec.of("sphere"), true_height=true)
    assert res.sphere["radius_true_mm"] == pytest.approx(radius, rel=1e-9)
    assert res.sphere["radius_change_mm"] == pytest.approx(change, rel=1e-6)
    assert np.nanmax(np.abs(res.residual)) < 1e-9  # mm: a sphere leaves nothing
    # a plane has no curvature; a convex sphere a negative radius
    assert abs(best_fit_sphere(x, y, 1e-3 * x - 2e-3 * y, m).curvature) < 1e-15  # 1/mm
    assert best_fit_sphere(x, y, -sphere(500.0), m).radius_mm == pytest.approx(-500.0, rel=1e-9)


@pytest.mark.parametrize("terms", ["tilt", "power", ("piston", "tilt", "astigmatism")])
def test_zernike_tables_after_removal_equal_a_direct_fit_of_the_residual(terms):
    x, y, m = _grid()
    rng = np.random.default_rng(7)
    c, rad = (0.3, -0.2), 22.0
    u, v = (x - c[0]) / rad, (y - c[1]) / rad
    r, t = np.hypot(u, v), np.arctan2(v, u)
    coef = rng.normal(0, 1e-5, 37)
    err = sum(k * f(r, t) for k, f in zip(coef, FRINGE_TABLE)) + 1e-6 * np.sin(3 * x) * np.cos(y)
    spec = FormSpec.of(terms, zernike=(9,), n_zernike=37)
    res = remove_form(err, m, x, y, spec, disc=(c, rad))
    keep = res.mask
    assert keep.sum() == m.sum()
    resid = res.residual[keep]
    # the residual is orthogonal to what was removed (least squares)
    removed_cols = [np.ones(keep.sum()), x[keep], y[keep]]
    if terms == "power":
        removed_cols.append(x[keep] ** 2 + y[keep] ** 2)
    for col in removed_cols:
        assert abs(col @ resid) < 1e-9 * np.linalg.norm(col) * np.linalg.norm(err[keep])
    # tables: a direct least-squares fit of the residual onto the published polynomials
    a_fringe = np.stack([f(r[keep], t[keep]) for f in FRINGE_TABLE], axis=1)
    direct = np.linalg.lstsq(a_fringe, resid, rcond=None)[0]
    got = np.array([row["coefficient"] for row in res.fringe])
    np.testing.assert_allclose(got, direct, atol=1e-10 * np.abs(coef).max())
    a_noll = np.stack([f(r[keep], t[keep]) for f in NOLL_TABLE], axis=1)
    _, full = zernike_columns("noll", 37, u[keep], v[keep])
    np.testing.assert_allclose(full[:, :11], a_noll, atol=1e-12)
    direct = np.linalg.lstsq(full, resid, rcond=None)[0]
    np.testing.assert_allclose([row["coefficient"] for row in res.noll], direct,
                               atol=1e-10 * np.abs(coef).max())
    # removed column: Z9 (Noll: spherical 4,0) and the named terms
    gone = {row["index"] for row in res.noll if row["removed"]}
    expect = {1, 2, 3, 9} | ({4} if terms == "power" else set()) | (
        {5, 6} if "astigmatism" in terms else set())
    assert gone == expect
    # Fringe Z16 is (6, 0), not removed; Fringe Z9 is (4, 0) = Noll Z11, not Noll Z9 (3, -3)
    fr = {row["index"]: row for row in res.fringe}
    assert not fr[9]["removed"] and fr[11]["removed"]  # Fringe Z11 = (3, -3) = Noll Z9
    assert abs(fr[11]["coefficient"]) < 0.01 * np.abs(coef).max()  # removed: (almost) nothing left


def test_rim_exclusion_with_unequal_spacing():
    x, y, m = _grid(dx=0.4, dy=0.25, radius=20.0, centre=(0.0, 0.1))
    r = np.hypot(x, y - 0.1)
    kept = rim_mask(m, (0.4, 0.25), rim_mm=2.0)
    assert kept.sum() < m.sum()
    # nothing within 2 mm of the rim, everything farther in kept (to half a step, 0.2 mm)
    assert r[kept].max() < 18.0 + 0.2 + 1e-9
    assert kept[m & (r < 18.0 - 0.2)].all()
    pct = rim_mask(m, (0.4, 0.25), rim_percent=10.0)  # 10 % of the 20 mm radius
    assert r[pct].max() < 18.0 + 0.2 + 1e-9 and pct[m & (r < 18.0 - 0.2 - 0.25)].all()
    spec = FormSpec.of("piston", rim_mm=2.0)
    res = remove_form(np.where(m, x * 1e-6, np.nan), m, x, y, spec)
    assert res.excluded_rim == int(m.sum() - kept.sum())
    assert np.isnan(res.residual[m & ~kept]).all()
    assert "rim band 2 mm" in res.removed


@pytest.mark.parametrize("block", [97, 1000, 4096])
def test_zernike_tables_in_blocks_equal_a_direct_fit(block):
    """The tables are fitted block by block (normal equations summed over blocks of points,
    no full matrix): the same coefficients as one least-squares fit of all points, for
    blocks that split the points unevenly (97: 11 blocks and a remainder), one block, and
    a block larger than the points; two tables of different orders and lengths at once,
    on an off-centre, unequally scaled set of points."""
    from pmdsim.measure.form import zernike_tables

    rng = np.random.default_rng(23)
    u, v = rng.uniform(-0.9, 0.7, 1000), rng.uniform(-0.6, 0.95, 1000)
    keep = np.hypot(u, v) <= 1.0
    u, v = u[keep], v[keep]
    b = np.sin(2.1 * u + 0.3) * np.cos(1.7 * v - 0.2) + 0.05 * rng.normal(size=u.size)
    noll, fringe = zernike_tables(b, u, v, (("noll", 22), ("fringe", 37)), removed=(1, 4),
                                  block=block)
    for order, n, table in (("noll", 22, noll), ("fringe", 37, fringe)):
        idx, a = zernike_columns(order, n, u, v)
        direct = np.linalg.lstsq(a, b, rcond=None)[0]
        assert [(row["index"], row["n"], row["m"]) for row in table] == idx
        np.testing.assert_allclose([row["coefficient"] for row in table], direct,
                                   rtol=0, atol=1e-11)
    assert [row["index"] for row in noll if row["removed"]] == [1, 4]
    # Fringe Z4 is (2, 0) = Noll Z4 (removed); Fringe Z1 piston = Noll Z1
    assert [row["index"] for row in fringe if row["removed"]] == [1, 4]
    # fewer points than terms: no table, the other still fitted
    few, more = zernike_tables(b[:20], u[:20], v[:20], (("noll", 37), ("noll", 6)), block=block)
    assert few == [] and len(more) == 6


# ------------------------------------------------------------ on a surface that is not a sphere
def _asphere(x, y):
    """An even asphere (mm): a conic (R 800 mm, k = -0.6) with a 4th-order term, decentred."""
    xc, yc = x - 0.7, y + 0.4
    r2 = xc * xc + yc * yc
    c, k = 1.0 / 800.0, -0.6
    return c * r2 / (1.0 + np.sqrt(1.0 - (1.0 + k) * c * c * r2)) + 3e-8 * r2 * r2


def _direct_sphere(x, y, z):
    """A least-squares sphere written here, independently of form.py: centre (a, b) in x, y,
    vertex height zv and signed radius R (> 0 concave towards +z, as form.py signs it), the
    branch through the vertex z = zv + rho^2 / (R + s sqrt(R^2 - rho^2)), rho^2 = (x-a)^2 +
    (y-b)^2, s = sign(R) (no cancellation); vertical residuals; started from a paraboloid
    fit. Returns (R, the fitted heights)."""
    from scipy.optimize import least_squares

    a_mat = np.stack([np.ones_like(x), x, y, x * x + y * y], axis=1)
    p = np.linalg.lstsq(a_mat, z, rcond=None)[0]
    rad0 = 1.0 / (2.0 * p[3])
    a0, b0 = -p[1] * rad0, -p[2] * rad0
    zv0 = p[0] - (a0 * a0 + b0 * b0) / (2.0 * rad0)

    def heights(q):
        a, b, zv, rad = q
        rho2 = (x - a) ** 2 + (y - b) ** 2
        return zv + rho2 / (rad + np.sign(rad) * np.sqrt(rad * rad - rho2))

    sol = least_squares(lambda q: heights(q) - z, [a0, b0, zv0, rad0], method="lm",
                        x_scale=[1.0, 1.0, 1e-3, 10.0], xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=5000)
    return sol.x[3], heights(sol.x)


@pytest.mark.parametrize("change_mm", [0.0, 0.4])
def test_best_fit_sphere_removal_on_an_asphere_equals_a_direct_fit(change_mm):
    """The true surface an asphere (not a sphere), the measured one that asphere plus a
    radius change, decentre, tilt, piston and 40 nm of coma: what is left after the
    best-fit-sphere removal equals (z_meas - S_meas) - (z_true - S_true) of spheres fitted
    here, and so do the radii. Catches a removal that fits only one of the surfaces, fits
    the error alone, takes the sphere of the truth for both, or drops z_true - S_true."""
    x, y, m = _grid()
    true = _asphere(x, y)
    rho2 = (x - 0.3) ** 2 + (y + 0.2) ** 2
    err = (change_mm * rho2 / (2 * 800.0**2)  # about a radius change of change_mm
           + 2e-5 * x - 1e-5 * y + 3e-4 + 4e-5 * (3 * (rho2 / 22**2) - 2) * (x - 0.3) / 22)
    res = remove_form(np.where(m, err, np.nan), m, x, y, FormSpec.of("sphere"), true_height=true)
    xm, ym = x[m], y[m]
    r_meas, s_meas = _direct_sphere(xm, ym, true[m] + err[m])
    r_true, s_true = _direct_sphere(xm, ym, true[m])
    want = (true[m] + err[m] - s_meas) - (true[m] - s_true)
    got = res.residual[m]
    assert res.mask.sum() == m.sum()
    # mm: 1e-3 nm against a residual of ~1e-5 mm (the two fits' least squares agree to all
    # digits; the flat minimum leaves their spheres ~3e-11 mm apart)
    assert np.abs(got - want).max() < 1e-9
    assert np.abs(want).max() > 5e-6
    assert res.sphere["radius_true_mm"] == pytest.approx(r_true, rel=1e-8)
    assert res.sphere["radius_measured_mm"] == pytest.approx(r_meas, rel=1e-8)
    assert res.sphere["radius_change_mm"] == pytest.approx(r_meas - r_true, abs=1e-6)
    # the asphere is no sphere: the true surface's own departure is large, so each
    # shortcut above would be far off
    naive = true[m] + err[m] - s_meas  # z_true - S_true dropped
    assert np.abs(naive - want).max() > 1e3 * 1e-9
    _, s_err = _direct_sphere(xm, ym, err[m] + 1e-3 * (xm * xm + ym * ym))  # the error alone
    assert np.abs((err[m] + 1e-3 * (xm * xm + ym * ym) - s_err) - want).max() > 1e3 * 1e-9


@pytest.mark.parametrize("level", ["piston", "tilt", "power", "astigmatism"])
def test_linear_removal_on_an_asphere_equals_a_direct_fit(level):
    """piston / tilt / power (x^2 + y^2) / astigmatism removal on an asphere's height error
    (the measured surface minus the true asphere: an error with power, astigmatism, coma and
    a fourth-order part): the residual equals a direct least-squares fit of the columns
    written here (np.linalg.lstsq), on a decentred disc with dx != dy."""
    x, y, m = _grid()
    true = _asphere(x, y)
    measured = _asphere(1.001 * x, 0.998 * y) + 1e-5 * x**2 * y / 22**2 + 2e-4 - 3e-6 * y
    err = measured - true
    res = remove_form(np.where(m, err, np.nan), m, x, y, FormSpec.of(level), true_height=true)
    xm, ym = x[m], y[m]
    cols = {"piston": [np.ones_like(xm)], "tilt": [np.ones_like(xm), xm, ym],
            "power": [np.ones_like(xm), xm, ym, xm**2 + ym**2],
            "astigmatism": [np.ones_like(xm), xm, ym, xm**2 + ym**2, xm**2 - ym**2, 2 * xm * ym]}[level]
    a = np.stack(cols, axis=1)
    want = err[m] - a @ np.linalg.lstsq(a, err[m], rcond=None)[0]
    assert np.abs(res.residual[m] - want).max() < 1e-9 * np.abs(err[m]).max()
    assert np.abs(want).max() > 1e-3 * np.abs(err[m]).max()  # something is left to compare


def test_surface_errors_remove_the_best_fit_sphere_of_an_aspheric_truth():
    """Through the run's path (measure.reconstruct.surface_errors, the true surface a conic
    scene surface, R 800 mm, k = -1: a paraboloid): the height error after ``remove =
    "sphere"`` equals the direct fit's (z_meas - S_meas) - (z_true - S_true), in nm: the
    true heights reach the removal (without them it fits a sphere to the error alone).
    (The nominal sphere in their place would be a second-order change only: for small
    errors the removal is nearly linear in them, whatever sphere it starts from.)"""
    from test_reconstruct import parse_config, scene_dict

    from pmdsim.measure.reconstruct import Reconstruction, surface_errors
    from pmdsim.scene.surfaces import surface_from_config

    ap = {"shape": "circular", "radius_mm": 20.0, "centre_mm": [1.0, -0.5]}
    truth = surface_from_config(parse_config(scene_dict({"type": "conic", "radius_mm": 800.0,
                                                         "conic": -1.0, "aperture": ap})).surface)
    xs = np.arange(-19.0, 21.01, 0.5)
    ys = np.arange(-20.5, 19.51, 0.4)
    x, y = np.meshgrid(xs, ys)
    z = truth.sag(x, y)[0]
    m = np.hypot(x - 1.0, y + 0.5) <= 20.0
    err = 1e-6 * (3 + 2 * x / 20 - (x * x + y * y) / 400) + 2e-5 * ((x - 1) / 20) ** 3
    nan = np.where(m, 1.0, np.nan)
    r2 = x * x + y * y
    nominal = r2 / (800.0 + np.sqrt(800.0**2 - r2))  # the nominal sphere, not the truth
    rec = Reconstruction(xs, ys, m, (z + err) * nan, nan, nan, nominal * nan, 1, (0.0,), True)
    e = surface_errors(rec, truth, "sphere", tables=False)
    _, s_meas = _direct_sphere(x[m], y[m], z[m] + err[m])
    _, s_true = _direct_sphere(x[m], y[m], z[m])
    want = ((z[m] + err[m] - s_meas) - (z[m] - s_true)) * 1e6  # nm
    assert np.abs(e.height_nm[m] - want).max() < 1e-3
    assert np.abs(want).max() > 1.0
    assert np.abs((z[m] - s_true) * 1e6).max() > 5.0  # the paraboloid is not a sphere
