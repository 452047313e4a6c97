"""Measured topographies in (``pmdsim.topofile``) and topography to BRDF parameters
(``pmdsim.brdf.topography``): files written by independent writers, values and spacings
(dx != dy); slope-density alphas and K-correlation parameters of synthetic surfaces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdsim.brdf import topography as tp
from pmdsim.config import ConfigError, InputError
from pmdsim.topofile import read_topography

x3pio = pytest.importorskip("x3pio")

DX, DY = 0.4e-3, 0.7e-3  # mm: dx != dy


def _grid(ny=9, nx=13):
    y, x = np.mgrid[0:ny, 0:nx]
    return 1e-6 * (3.0 * x - 2.0 * y + 0.5 * x * y + np.sin(x))  # mm, asymmetric in x/y


def test_x3p_written_by_surfalize_reads_with_values_and_spacing(tmp_path):
    """surfalize writes the X3P (its own ISO 25178-72 writer), x3pio reads it."""
    surfalize = pytest.importorskip("surfalize")
    z = _grid()
    path = tmp_path / "part.x3p"
    surfalize.Surface(z * 1e3, DX * 1e3, DY * 1e3).save(path)  # surfalize works in um
    t = read_topography(path)
    assert t.heights.shape == z.shape  # rows along y
    np.testing.assert_allclose(t.heights, z, rtol=0, atol=1e-15)
    assert (t.dx, t.dy) == pytest.approx((DX, DY), rel=1e-12)
    assert t.reader.startswith("x3pio")


def test_ascii_sdf_by_the_standard_reads_through_surfalize(tmp_path):
    """An ISO 25178-71 ASCII SDF file written here from the standard's layout (not by
    surfalize) reads with the scales of its header: x, y in m per point, z in m per unit."""
    pytest.importorskip("surfalize")
    counts = np.arange(12, dtype=float).reshape(3, 4) * 7 - 20  # (profiles = y, points = x)
    head = ["aISO-1.0", "ManufacID   = pmdsimtest", "CreateDate  = 011220261200",
            "ModDate     = 011220261200", "NumPoints   = 4", "NumProfiles = 3",
            "Xscale      = 4.0E-07", "Yscale      = 7.0E-07", "Zscale      = 1.0E-09",
            "Zresolution = -1", "Compression = 0", "DataType    = 7", "CheckType   = 0", "*"]
    body = "\n".join(" ".join(f"{v:g}" for v in row) for row in counts)
    path = tmp_path / "part.sdf"
    path.write_text("\n".join(head) + "\n" + body + "\n*\n*\n")
    t = read_topography(path, min_points=3)
    np.testing.assert_allclose(t.heights, counts * 1e-6, rtol=1e-12)  # nm -> mm
    assert (t.dx, t.dy) == pytest.approx((DX, DY), rel=1e-12)


def test_levelling_outliers_and_fill(tmp_path):
    z = _grid(20, 24)
    tilt = 2e-5 * np.arange(24)[None, :] - 1e-5 * np.arange(20)[:, None] + 3e-4
    bad = z + tilt
    bad[3, 5] = np.nan
    bad[10, 7] += 1e-2  # a spike
    path = tmp_path / "nan.x3p"
    x3pio.write(path, bad * 1e-3, x_scale=DX * 1e-3, y_scale=DY * 1e-3)
    with pytest.raises(InputError, match=r"brdf\.file.*nan\.x3p.*1 points not measured"):
        read_topography(path, "brdf.file")
    t = read_topography(path, level="plane", fill="nearest", outlier_sigma=6)
    assert t.invalid == 2
    assert np.isfinite(t.heights).all()
    # the plane of the valid points is gone: what is left is the grid minus its own plane
    ny, nx = z.shape
    yy, xx = np.mgrid[0:ny, 0:nx]
    ok = np.ones_like(z, bool)
    ok[3, 5] = ok[10, 7] = False
    a = np.stack([np.ones(ok.sum()), xx[ok], yy[ok]], -1)
    c, *_ = np.linalg.lstsq(a, z[ok], rcond=None)
    ref = z - (c[0] + c[1] * xx + c[2] * yy)
    np.testing.assert_allclose(t.heights[ok], ref[ok], atol=1e-12)
    assert t.heights[10, 7] in (t.heights[9, 7], t.heights[11, 7], t.heights[10, 6], t.heights[10, 8])


def test_read_errors_name_field_and_file(tmp_path):
    with pytest.raises(InputError, match=r"surface\.file.*not found.*nope\.x3p"):
        read_topography(tmp_path / "nope.x3p")
    junk = tmp_path / "junk.x3p"
    junk.write_bytes(b"not a zip archive")
    with pytest.raises(ConfigError, match=r"brdf\.file: cannot read .*junk\.x3p"):
        read_topography(junk, "brdf.file")
    npy = tmp_path / "m.npy"
    np.save(npy, _grid())
    with pytest.raises(InputError, match=r"brdf\.file.*spacing_mm"):
        read_topography(npy, "brdf.file")
    odd = tmp_path / "m.xyzzy"
    odd.write_text("1")
    with pytest.raises(InputError, match=r"unknown topography format '\.xyzzy'"):
        read_topography(odd)


def test_height_map_surface_reads_x3p_spacing_from_the_file(tmp_path):
    """[surface] type = "height_map" with an X3P: spacing from the file (dx != dy), sag equal
    to the stored heights at the grid nodes."""
    from pmdsim.config import parse_config
    from pmdsim.scene.surfaces import surface_from_config

    z = _grid(12, 16) * 50
    path = tmp_path / "map.x3p"
    x3pio.write(path, z * 1e-3, x_scale=0.5e-3, y_scale=0.8e-3)  # 0.5 mm x 0.8 mm steps
    from conftest import make_config

    cfg = make_config().model_dump()
    cfg["surface"] = dict(type="height_map", file=str(path))
    s = surface_from_config(parse_config(cfg).surface)
    assert s.map_spacing == pytest.approx((0.5, 0.8))
    ny, nx = z.shape
    x0, y0 = s.map_origin
    np.testing.assert_allclose(s.sag(np.array([x0 + 3 * 0.5]), np.array([y0 + 7 * 0.8]))[0], z[7, 3],
                               atol=1e-12)
    cfg["surface"] = dict(type="height_map", file=str(tmp_path / "map.npy"))
    np.save(tmp_path / "map.npy", z)
    with pytest.raises(ConfigError, match="surface.spacing_mm"):
        surface_from_config(parse_config(cfg).surface)


# --------------------------------------------------------------------------- to the BRDF
def test_slope_density_recovers_gaussian_alphas_per_axis():
    """A Gaussian surface of Gaussian autocorrelation (lx != ly, dx != dy): RMS slope
    sqrt(2) sigma / l per axis, so alpha = 2 sigma / l; recovered within 2 % and not swapped."""
    sigma, lx, ly = 2e-5, 6e-3, 3e-3  # mm: 12 dx, 10 dy (central differences lose < 1 %)
    dx, dy = 0.5e-3, 0.3e-3

    def gauss_psd(fx, fy):
        return sigma**2 * math.pi * lx * ly * np.exp(-(math.pi * lx * fx) ** 2 - (math.pi * ly * fy) ** 2)

    h = tp.synthesize(gauss_psd, (768, 1024), dx, dy, seed=3)
    a = tp.analyse(h, dx, dy)
    ax, ay = 2 * sigma / lx, 2 * sigma / ly
    assert a.alpha_tangential == pytest.approx(ax, rel=0.02)
    assert a.alpha_radial == pytest.approx(ay, rel=0.02)
    table = tp.slope_table(h, dx, dy, bins=128)
    assert table.equivalent_alphas[0] == pytest.approx(ax, rel=0.02)
    assert table.equivalent_alphas[1] == pytest.approx(ay, rel=0.02)
    # the map with its radial axis along x is the transposed one
    ht, dxt, dyt = tp.to_local(h, dx, dy, "x")
    assert tp.analyse(ht, dxt, dyt).alpha_radial == pytest.approx(ax, rel=0.02)


def test_k_correlation_parameters_recovered_within_5_percent():
    """Whittle fit of an anisotropic K-correlation surface (bx != by, dx != dy): every
    parameter within 5 % and within 4 of its own standard errors."""
    dx, dy = 0.5e-3, 0.3e-3
    kc = tp.KCorrelation(3e-6, 2 * math.pi * 1.5 * dx, 2 * math.pi * 1.2 * dy, 2.4)
    h = tp.synthesize(kc, (384, 512), dx, dy, seed=11)
    fx, fy, s = tp.periodogram(h, dx, dy, "none")
    assert s.sum() * (fx[1] - fx[0]) * (fy[1] - fy[0]) == pytest.approx(h.var(), rel=1e-10)
    fit = tp.fit_k_correlation(fx, fy, s)
    got = np.array([fit.model.sigma, fit.model.bx, fit.model.by, fit.model.c])
    want = np.array([kc.sigma, kc.bx, kc.by, kc.c])
    rel = got / want - 1
    assert np.all(np.abs(rel) < 0.05), rel
    assert np.all(np.abs(rel) < 4 * np.array(fit.rel_err)), (rel, fit.rel_err)
    # the Hann-windowed periodogram (for measured maps) agrees within its standard errors
    fxh, fyh, sh = tp.periodogram(h, dx, dy, "hann")
    fh = tp.fit_k_correlation(fxh, fyh, sh, effective_fraction=tp.window_fraction("hann"))
    relh = np.array([fh.model.sigma, fh.model.bx, fh.model.by, fh.model.c]) / want - 1
    assert np.all(np.abs(relh) < 4 * np.array(fh.rel_err)), (relh, fh.rel_err)


def test_regime_follows_the_rayleigh_parameter():
    assert tp.regime(0.07)[0] == "smooth" and tp.regime(0.07)[2] == "rayleigh_rice"
    assert tp.regime(0.9)[0] == "intermediate" and tp.regime(0.9)[2] == "rayleigh_rice"
    assert tp.regime(1.2)[2] == "slope_density"
    assert tp.regime(3.0)[0] == "geometric"
