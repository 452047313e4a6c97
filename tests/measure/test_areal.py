"""Areal parameters and PSDs of error maps (pmdsim.measure.areal) against closed forms, a
slow reference, their own stated errors, surfalize and SurfaceTopography."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from pmdsim.measure import areal

DATA = Path(__file__).parents[1] / "data" / "instrument-samples"
EXAMPLE = Path(__file__).parents[2] / "examples" / "measured_topography.x3p"

# unequal steps and sizes: a swapped axis fails
NY, NX, DX, DY = 96, 128, 0.5, 0.4


def _grid(nx=NX, ny=NY, dx=DX, dy=DY):
    return np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dy)


def _sinusoids(comps, nx=NX, ny=NY, dx=DX, dy=DY):
    x, y = _grid(nx, ny, dx, dy)
    return sum(a * np.cos(2 * np.pi * (fx * x + fy * y) + p) for a, fx, fy, p in comps)


# periodic on the grid: whole cycles over (NX DX, NY DY) = (64, 38.4) mm, each >= 13 nodes
# per period along x and y (forward differences: sinc(pi dx / p) of the slope, < 1 % off)
LX, LY = NX * DX, NY * DY
COMPS = [(3.0, 5 / LX, 2 / LY, 0.3), (1.5, 1 / LX, 2 / LY, 1.1), (0.7, 9 / LX, 0.0, 2.0)]


def test_sinusoids_closed_form():
    z = _sinusoids(COMPS)
    ap = areal.areal_parameters(z, DX, DY)
    sq = math.sqrt(sum(a * a / 2 for a, *_ in COMPS))
    sdq = math.sqrt(sum(a * a / 2 * (2 * np.pi) ** 2 * (fx * fx + fy * fy) for a, fx, fy, _ in COMPS))
    assert ap["sq"] == pytest.approx(sq, rel=1e-12)
    assert ap["sdq"] == pytest.approx(sdq, rel=0.01)
    assert ap["n"] == NX * NY
    # one sinusoid: Sa = 2A/pi, Sz = 2A, Ssk = 0, Sku = 3/2
    one = _sinusoids([(2.0, 4 / LX, 0.0, 0.0)])
    a1 = areal.areal_parameters(one, DX, DY)
    assert a1["sa"] == pytest.approx(4 / np.pi, rel=0.01)
    assert a1["sz"] == pytest.approx(4.0, rel=0.01)
    assert abs(a1["ssk"]) < 1e-9 and a1["sku"] == pytest.approx(1.5, rel=1e-9)
    # PSD: each component's power A^2/2 in its radial bin, at +-f in the 2-D PSD, and
    # the power adds up to Sq^2 (no window: the map is periodic)
    p = areal.power_spectrum(z, DX, DY, window_kind="none")
    df = p.frequency[0]
    assert df == pytest.approx(max(1 / LX, 1 / LY))
    for a, fx, fy, _ in COMPS:
        k = int(np.ceil(math.hypot(fx, fy) / df - 0.5)) - 1
        assert p.psd_radial[k] * df == pytest.approx(a * a / 2, rel=1e-9)
        j, i = np.argmin(np.abs(p.fy - fy)), np.argmin(np.abs(p.fx - fx))
        assert p.psd_2d[j, i] / (LX * LY) == pytest.approx(a * a / 4, rel=1e-9)
    assert p.mean_square == pytest.approx(sq * sq, rel=1e-12)
    assert sum(r * r for r in p.band_rms.values()) == pytest.approx(sq * sq, rel=1e-12)


def test_sinusoids_on_a_disc_windowed():
    """Masked (a disc) and not periodic: the tapered window keeps each component's power
    within 8 bins of it to 1 %, whatever its frequency."""
    ny, nx = 160, 192
    comps = [(3.0, 0.12, 0.05, 0.3), (1.5, 0.02, 0.30, 1.1), (0.7, 0.55, 0.0, 2.0)]
    z = _sinusoids(comps, nx, ny)
    x, y = _grid(nx, ny)
    disc = np.hypot(x - x.mean(), y - y.mean()) < 30
    p = areal.power_spectrum(np.where(disc, z, np.nan), DX, DY)
    fx, fy = np.meshgrid(p.fx, p.fy)
    cell = (p.fx[1] - p.fx[0]) * (p.fy[1] - p.fy[0])
    for a, cx, cy, _ in comps:
        near = (np.hypot(fx - cx, fy - cy) < 8 * p.frequency[0]) | (np.hypot(fx + cx, fy + cy)
                                                                   < 8 * p.frequency[0])
        assert p.psd_2d[near].sum() * cell == pytest.approx(a * a / 2, rel=0.01)
    w = areal.window(disc, DX, DY)
    assert np.all(w[~disc] == 0) and w.max() == pytest.approx(1.0)
    assert areal.window(disc, DX, DY, "none")[disc].min() == 1.0
    # the "hann" window on a disc is the rotationally symmetric (1 + cos(pi r / R)) / 2
    hann = areal.window(disc, DX, DY, "hann")
    r = np.hypot(x - x.mean(), y - y.mean())
    inner = disc & (r < 25)
    expect = (1 + np.cos(np.pi * r[inner] / 30)) / 2  # the distance to the edge is 30 - r
    assert np.max(np.abs(hann[inner] - expect)) < 0.03


def _k_correlation(nx, ny, dx, dy, c0, f0, hurst, f_cut, seed):
    """A periodic K-correlation (self-affine with roll-off f0, cut off above f_cut) map whose
    periodogram is exactly its PSD: unit-modulus Hermitian random phases x sqrt(C)."""
    fx, fy = np.fft.fftfreq(nx, dx), np.fft.fftfreq(ny, dy)
    fr = np.hypot(fx[None, :], fy[:, None])
    c = c0 / (1 + (fr / f0) ** 2) ** (1 + hurst)
    c[0, 0] = 0.0
    c[fr > f_cut] = 0.0
    w = np.fft.fft2(np.random.default_rng(seed).standard_normal((ny, nx)))
    z = np.fft.ifft2(w / np.abs(w) * np.sqrt(c * nx * ny / (dx * dy))).real
    return z, c, fr


def test_k_correlation_closed_form():
    nx, ny, dx, dy = 320, 256, 0.5, 0.4
    c0, f0, hurst = 2.0, 0.08, 0.8
    f_cut = 0.25 * min(0.5 / dx, 0.5 / dy)
    z, c, fr = _k_correlation(nx, ny, dx, dy, c0, f0, hurst, f_cut, seed=3)
    area = nx * dx * ny * dy
    sq = math.sqrt(c.sum() / area)  # = sqrt of the integral of C over the grid's frequencies
    sdq = math.sqrt(((2 * np.pi * fr) ** 2 * c).sum() / area)
    ap = areal.areal_parameters(z, dx, dy)
    assert ap["sq"] == pytest.approx(sq, rel=1e-9)
    assert ap["sa"] == pytest.approx(math.sqrt(2 / math.pi) * sq, rel=0.01)  # Gaussian
    assert ap["sdq"] == pytest.approx(sdq, rel=0.01)
    p = areal.power_spectrum(z, dx, dy, window_kind="none")
    k = np.ceil(fr / p.frequency[0] - 0.5).astype(int)
    closed = np.array([c[k == j].mean() for j in range(1, p.frequency.size + 1)])
    below = p.frequency < 0.95 * f_cut
    np.testing.assert_allclose(p.psd_iso[below], closed[below], rtol=0.01)
    assert np.sum(p.psd_radial) * p.frequency[0] == pytest.approx(
        sum(c[(k >= 1) & (k <= p.frequency.size)]) / area, rel=1e-9)


def _slow_areal(z, dx, dy):
    """The definitions node by node (a slow reference for masked maps)."""
    vals = [v for v in z.ravel() if np.isfinite(v)]
    m = sum(vals) / len(vals)
    d = [v - m for v in vals]
    m2 = sum(t * t for t in d) / len(d)
    gx, gy = [], []
    h, w = z.shape
    for r in range(h):
        for c in range(w):
            if c + 1 < w and np.isfinite(z[r, c]) and np.isfinite(z[r, c + 1]):
                gx.append((z[r, c + 1] - z[r, c]) / dx)
            if r + 1 < h and np.isfinite(z[r, c]) and np.isfinite(z[r + 1, c]):
                gy.append((z[r + 1, c] - z[r, c]) / dy)
    return {"sq": math.sqrt(m2), "sa": sum(abs(t) for t in d) / len(d),
            "sz": max(vals) - min(vals), "ssk": sum(t**3 for t in d) / len(d) / m2**1.5,
            "sku": sum(t**4 for t in d) / len(d) / m2**2,
            "sdq": math.sqrt(sum(g * g for g in gx) / len(gx) + sum(g * g for g in gy) / len(gy))}


def test_masked_map_against_slow_reference():
    rng = np.random.default_rng(1)
    z = rng.standard_normal((23, 31)) + np.linspace(0, 3, 31)[None, :] ** 2
    x, y = _grid(31, 23, 0.3, 0.7)
    ring = (np.hypot(x - 4.5, y - 8) < 8) & (np.hypot(x - 4.5, y - 8) > 2)
    ring[5, 10] = False  # a dropped node
    zm = np.where(ring, z, np.nan)
    ap = areal.areal_parameters(zm, 0.3, 0.7)
    slow = _slow_areal(zm, 0.3, 0.7)
    for k, v in slow.items():
        assert ap[k] == pytest.approx(v, rel=1e-12), k
    assert ap["n"] == int(ring.sum())
    # a mask is the same as NaN
    assert areal.areal_parameters(z, 0.3, 0.7, mask=ring) == ap
    # the window tapers to the ring's edges, not around the dropped node
    w = areal.window(ring, 0.3, 0.7)
    assert w[~ring].max() == 0 and w[ring].min() > 0
    full = ring.copy()
    full[5, 10] = True
    np.testing.assert_array_equal(w[ring], areal.window(full, 0.3, 0.7)[ring])


def test_errors_bound_every_perturbation():
    """Any map within the stated node errors moves every parameter, PSD value and band RMS by
    no more than its stated error (random signs, smooth signs, all +)."""
    rng = np.random.default_rng(7)
    ny, nx, dx, dy = 40, 56, 0.5, 0.35
    x, y = _grid(nx, ny, dx, dy)
    z = np.sin(x / 3) * np.cos(y / 2) + 0.3 * rng.standard_normal((ny, nx))
    mask = np.hypot(x - 14, y - 7) < 9
    z = np.where(mask, z, np.nan)
    e = 0.02 + 0.03 * rng.random((ny, nx))
    ap = areal.areal_parameters(z, dx, dy, error=e)
    p = areal.power_spectrum(z, dx, dy, error=e)
    patterns = [rng.choice([-1.0, 1.0], size=z.shape) for _ in range(20)]
    patterns += [np.sign(np.sin(x / 2 + y)), np.ones_like(z), -np.ones_like(z)]
    patterns += [rng.uniform(-1, 1, z.shape) for _ in range(5)]
    for s in patterns:
        zz = z + s * e
        a2 = areal.areal_parameters(zz, dx, dy)
        for k in areal.AREAL:
            # Ssk and Sku: first order; second order is (e / Sq)^2 of the first: 10 % room
            room = 1.1 if k in ("ssk", "sku") else 1.0 + 1e-12
            assert abs(a2[k] - ap[k]) <= room * ap[f"{k}_err"], k
        p2 = areal.power_spectrum(zz, dx, dy, bands=p.bands)
        assert np.all(np.abs(p2.psd_2d - p.psd_2d) <= p.psd_2d_err * (1 + 1e-9) + 1e-15)
        assert np.all(np.abs(p2.psd_iso - p.psd_iso) <= p.psd_iso_err * (1 + 1e-9) + 1e-15)
        assert np.all(np.abs(p2.psd_radial - p.psd_radial) <= p.psd_radial_err * (1 + 1e-9) + 1e-15)
        for b in p.bands:
            assert abs(p2.band_rms[b] - p.band_rms[b]) <= p.band_rms_err[b] * (1 + 1e-9)
    # not needlessly loose: the band RMS's error is at most the window-weighted RMS of e'
    w = areal.window(np.isfinite(z), dx, dy)
    shift = np.sum(w * e) / w.sum()
    total = math.sqrt(np.sum((w * (e + shift)) ** 2 * np.isfinite(z)) / np.sum(w * w))
    assert max(p.band_rms_err.values()) <= total * (1 + 1e-12)
    # Sq's error is the run's RMS rule (the interval), never more than the RMS of e
    assert ap["sq_err"] <= math.sqrt(np.mean(e[np.isfinite(z)] ** 2))
    # no error given: no error keys
    assert "sq_err" not in areal.areal_parameters(z, dx, dy)
    assert areal.power_spectrum(z, dx, dy).psd_2d_err is None


def test_error_maps_bound_their_own_moves_and_are_tighter():
    """With the signed error maps (the map moved by +-its numerical error), any map moved
    by a fraction of either changes every PSD value and band RMS by no more than the
    stated error, which is below the any-sign bound where the error map is smooth."""
    ny, nx, dx, dy = 40, 56, 0.5, 0.35
    x, y = _grid(nx, ny, dx, dy)
    rng = np.random.default_rng(11)
    z = np.sin(x / 3) * np.cos(y / 2) + 0.05 * rng.standard_normal((ny, nx))
    mask = (x > 2) & (y < 12)
    z = np.where(mask, z, np.nan)
    up = 0.04 * np.cos(x / 9 + 0.3) * (1 + y / 20)  # a smooth error map and its opposite,
    down = -0.9 * up + 0.002 * np.sin(y)               # not exactly (a non-linear map)
    e = np.fmax(np.abs(up), np.abs(down))
    p = areal.power_spectrum(z, dx, dy, error=e, error_maps=[up, down])
    loose = areal.power_spectrum(z, dx, dy, error=e)
    for c, m in ((1.0, up), (0.5, up), (1.0, down), (-0.3, down)):
        p2 = areal.power_spectrum(z + c * m, dx, dy, bands=p.bands)
        assert np.all(np.abs(p2.psd_2d - p.psd_2d) <= p.psd_2d_err * (1 + 1e-9) + 1e-15)
        assert np.all(np.abs(p2.psd_radial - p.psd_radial) <= p.psd_radial_err * (1 + 1e-9) + 1e-15)
        for b in p.bands:
            assert abs(p2.band_rms[b] - p.band_rms[b]) <= p.band_rms_err[b] * (1 + 1e-9)
    # Sdq: each difference known to its own change, far tighter than any signs (smooth maps)
    ap = areal.areal_parameters(z, dx, dy, error_maps=[up, down])
    ap_loose = areal.areal_parameters(z, dx, dy, error=e)
    for c, m in ((1.0, up), (0.5, up), (1.0, down), (-0.3, down)):
        assert abs(areal.areal_parameters(z + c * m, dx, dy)["sdq"] - ap["sdq"]) <= ap["sdq_err"]
    assert ap["sdq_err"] < 0.2 * ap_loose["sdq_err"]
    assert ap["sq_err"] == ap_loose["sq_err"]  # node errors: the maps' largest magnitude
    assert np.all(p.psd_radial_err <= loose.psd_radial_err * (1 + 1e-12))
    assert p.band_rms_err["high"] < 0.1 * loose.band_rms_err["high"]
    with pytest.raises(ValueError, match="error_maps: shape"):
        areal.power_spectrum(z, dx, dy, error_maps=[np.zeros((3, 3))])


def test_bad_input():
    with pytest.raises(ValueError, match="2-D"):
        areal.areal_parameters(np.zeros(5), 1.0, 1.0)
    with pytest.raises(ValueError, match="error: shape"):
        areal.areal_parameters(np.zeros((4, 5)), 1.0, 1.0, error=np.zeros((5, 4)))
    with pytest.raises(ValueError, match="window"):
        areal.power_spectrum(np.zeros((4, 5)), 1.0, 1.0, window_kind="kaiser")
    with pytest.raises(ValueError, match="no valid node"):
        areal.power_spectrum(np.full((4, 5), np.nan), 1.0, 1.0)
    with pytest.raises(ValueError, match="form band"):
        areal.default_bands(np.ones((8, 8), bool), 1.0, 1.0, form_period_mm=1.0, high_period_mm=4.0)
    # a region of a few steps: the defaults cross, the mid band is empty
    tiny = areal.default_bands(np.ones((3, 4), bool), 1.0, 1.0)
    assert tiny["form"][1] == tiny["mid"][0] == tiny["mid"][1] == tiny["high"][0] == 0.25
    empty = areal.areal_parameters(np.full((3, 3), np.nan), 1.0, 1.0)
    assert empty["n"] == 0 and math.isnan(empty["sq"])
    s = areal.summary(np.full((3, 3), np.nan), 1.0, 1.0, "nm")
    assert s["n"] == 0 and s["sq"] is None and "psd" not in s


# ------------------------------------------------------------------ the libraries, real files
REAL = [DATA / "x3p-2.x3p", DATA / "sur-2.sur", EXAMPLE]


def _load(path):
    surfalize = pytest.importorskip("surfalize")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = surfalize.Surface.load(path)
    return s, np.array(s.data, np.float64), float(s.step_x), float(s.step_y)


@pytest.mark.parametrize("path", REAL, ids=lambda p: p.name)
def test_areal_matches_surfalize_on_real_files(path):
    """Sq, Sa, Sz, Ssk, Sku (and Sdq on complete maps) as surfalize computes them, to 1e-6
    (x3p-2: dx != dy; sur-2: 117 unmeasured points, surfalize masks them)."""
    surfalize = pytest.importorskip("surfalize")
    s, z, dx, dy = _load(path)
    ok = np.isfinite(z)
    ap = areal.areal_parameters(z, dx, dy)
    names = ("Sq", "Sa", "Sz", "Ssk", "Sku", "Sdq")
    if not ok.all():  # surfalize's Sdq needs a complete map
        s = surfalize.Surface(np.where(ok, z, 0.0), dx, dy, mask=~ok)
        names = names[:-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in names:
            assert ap[name.lower()] == pytest.approx(getattr(s, name)(), rel=1e-6), name


@pytest.mark.parametrize("path", REAL, ids=lambda p: p.name)
def test_psd_matches_surface_topography_on_real_files(path):
    """The 2-D PSD and its radial average as SurfaceTopography's power_spectrum_from_area
    computes them (for the same windowed map; wavevectors q = 2 pi f), to 1e-6."""
    st = pytest.importorskip("SurfaceTopography")
    _, z, dx, dy = _load(path)
    ok = np.isfinite(z)
    ny, nx = z.shape
    for kind in ("tukey", "none"):
        p = areal.power_spectrum(z, dx, dy, window_kind=kind)
        w = areal.window(ok, dx, dy, kind)
        zc = np.where(ok, (z - np.sum(w[ok] * z[ok]) / w.sum()) * w, 0.0)
        topo = st.Topography(zc.T, (nx * dx, ny * dy), periodic=False)  # SurfaceTopography: (x, y)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, c_iso, c_map = topo.power_spectrum_from_area(
                window="None", collocation=2 * np.pi * p.edges, return_map=True, reliable=False)
        scale = nx * ny / np.sum(w * w)  # its normalisation: the mean square of a full window
        mine = np.fft.ifftshift(p.psd_2d).T
        np.testing.assert_allclose(c_map * scale, mine, rtol=1e-6, atol=1e-12 * mine.max())
        # radial bins, except those with a frequency on a bin edge (dx/dy rational)
        fr = np.hypot(*np.meshgrid(np.fft.fftfreq(nx, dx), np.fft.fftfreq(ny, dy)))
        t = fr / p.frequency[0] - 0.5
        on_edge = np.abs(t - np.rint(t)) < 1e-9
        bad = np.unique(np.rint(t[on_edge]).astype(int))
        keep = np.ones(p.frequency.size, bool)
        keep[bad[(bad >= 0) & (bad < keep.size)]] = False
        keep[bad[(bad >= 1) & (bad <= keep.size)] - 1] = False
        c_iso = np.ma.filled(c_iso, np.nan) * scale
        np.testing.assert_allclose(c_iso[keep], p.psd_iso[keep], rtol=1e-6)
        assert keep.sum() > 0.5 * keep.size


def test_a_floor_beside_the_error_maps_covers_any_signs_of_it():
    """``floor`` (node errors of any signs, e.g. a solver's tolerance) beside the signed
    error maps: a map moved by a fraction of a map plus any signs of the floor (alternating
    from node to node: its power at the highest frequencies, which the smooth maps lack)
    changes Ssk, Sku (first order: 10 % room), Sdq, every PSD value and band RMS by no more
    than the stated errors; without the floor the alternating part is not covered."""
    ny, nx, dx, dy = 36, 50, 0.4, 0.55  # dx != dy
    x, y = _grid(nx, ny, dx, dy)
    rng = np.random.default_rng(5)
    z = np.sin(x / 2.5 + 0.4) * np.cos(y / 3) + 0.3 * x / x.max() \
        + 0.03 * rng.standard_normal((ny, nx))
    z = np.where((x - 10) ** 2 / 90 + (y - 9) ** 2 / 60 < 1, z, np.nan)  # an ellipse
    up = 0.02 * np.cos(x / 7 + 0.3) * (1 + y / 25)
    floor = np.full_like(z, 0.015)
    checker = np.where((np.indices(z.shape).sum(axis=0) % 2) == 0, 1.0, -1.0)
    kw = {"error_maps": [up, -up], "floor": floor}
    ap = areal.areal_parameters(z, dx, dy, **kw)
    p = areal.power_spectrum(z, dx, dy, **kw)
    moves = [c * up + s * floor for c in (1.0, -0.6) for s in (checker, -checker, rng.choice(
        [-1.0, 1.0], z.shape))]
    for m in moves:
        a2 = areal.areal_parameters(z + m, dx, dy)
        for k in ("ssk", "sku", "sdq"):
            room = 1.1 if k != "sdq" else 1.0 + 1e-12
            assert abs(a2[k] - ap[k]) <= room * ap[f"{k}_err"], k
        p2 = areal.power_spectrum(z + m, dx, dy, bands=p.bands)
        assert np.all(np.abs(p2.psd_radial - p.psd_radial) <= p.psd_radial_err * (1 + 1e-9) + 1e-15)
        for b in p.bands:
            assert abs(p2.band_rms[b] - p.band_rms[b]) <= p.band_rms_err[b] * (1 + 1e-9)
    # the checkerboard's power sits in the high band: the maps alone do not cover it (a
    # smooth map, whose own high band is small)
    smooth = np.where(np.isfinite(z), np.sin(x / 2.5 + 0.4) * np.cos(y / 3), np.nan)
    p0 = areal.power_spectrum(smooth, dx, dy, bands=p.bands)
    bare = areal.power_spectrum(smooth, dx, dy, error_maps=[up, -up], bands=p.bands)
    p2 = areal.power_spectrum(smooth + up + floor * checker, dx, dy, bands=p.bands)
    assert abs(p2.band_rms["high"] - p0.band_rms["high"]) > bare.band_rms_err["high"]


def test_an_error_map_and_its_negative_give_one_spectrum():
    """The PSD's errors from a signed pattern and its opposite (what a run passes) are those
    of the pattern alone, to the bit (its negative's spectrum is the same: one FFT), and a
    third, different map still counts (dx != dy, a masked corner)."""
    rng = np.random.default_rng(41)
    z = rng.normal(size=(40, 56))
    z[:6, :9] = np.nan
    p = 1e-3 * rng.normal(size=z.shape)
    q = 3e-3 * rng.normal(size=z.shape)
    one = areal.power_spectrum(z, 0.5, 0.7, error_maps=[p])
    both = areal.power_spectrum(z, 0.5, 0.7, error_maps=[p, -p])
    for name in ("psd_2d_err", "psd_radial_err", "psd_iso_err"):
        assert np.array_equal(getattr(one, name), getattr(both, name), equal_nan=True)
    assert one.band_rms_err == both.band_rms_err
    three = areal.power_spectrum(z, 0.5, 0.7, error_maps=[p, -p, q])
    assert np.nanmax(three.psd_radial_err - both.psd_radial_err) > 0
