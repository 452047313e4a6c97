"""Measured topographies in (``pmdsim.topofile``) and topography to BRDF parameters
(``pmdsim.brdf.topography``): files written by independent writers, values and spacings
(dx != dy); slope-density alphas and K-correlation parameters of synthetic surfaces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdsim.config import ConfigError, InputError
from pmdsim.topofile import read_topography
from pmdsim.brdf.psd import (KCorrelation, fit_k_correlation, periodogram, synthesize,
                             window_fraction)
from pmdsim.brdf.topography import analyse, regime, slope_table, to_local

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


@pytest.mark.filterwarnings("ignore:The surface has different pixel size")
@pytest.mark.parametrize("suffix", [".sur", ".al3d", ".sflz", ".sdf"])
def test_files_written_by_surfalize_read_with_values_orientation_and_spacing(tmp_path, suffix):
    """Files written by surfalize (an independent writer: pmdsim reads them through
    SurfaceTopography; .sflz, surfalize's own, through surfalize) from an asymmetric grid
    with dx != dy: the heights (um -> mm, rows along y) and the spacing come back; a swapped
    axis or a unit slip fails. .sur/.al3d store float32 or scaled integers (about 1e-7 of
    the range). Not .tmd: surfalize writes its lengths in um, where the real file
    (test_instrument_samples.py) and Gwyddion have mm."""
    surfalize = pytest.importorskip("surfalize")
    pytest.importorskip("SurfaceTopography")
    z = _grid()
    path = tmp_path / f"part{suffix}"
    surfalize.Surface(z * 1e3, DX * 1e3, DY * 1e3).save(path)
    t = read_topography(path)
    assert t.heights.shape == z.shape
    assert t.reader.startswith("surfalize" if suffix == ".sflz" else "SurfaceTopography")
    if suffix == ".sur":  # surfalize's writer stores an offset that SurfaceTopography reads
        z = z - z.mean()  # differently (on the real .sur files it agrees with Gwyddion)
        t = read_topography(path, level="mean")
    np.testing.assert_allclose(t.heights, z, rtol=0, atol=1e-7 * np.ptp(z))
    assert (t.dx, t.dy) == pytest.approx((DX, DY), rel=1e-7)


def test_ascii_sdf_by_the_standard_reads(tmp_path):
    """An ISO 25178-71 ASCII SDF file written here from the standard's layout (not by
    surfalize) reads with the scales of its header: x, y in m per point, z in m per unit."""
    pytest.importorskip("SurfaceTopography")
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
    with pytest.raises(ConfigError, match=r"brdf\.file: .*junk\.x3p \(X3P\): is not a ZIP"):
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

    h = synthesize(gauss_psd, (768, 1024), dx, dy, seed=3)
    a = analyse(h, dx, dy)
    ax, ay = 2 * sigma / lx, 2 * sigma / ly
    assert a.alpha_tangential == pytest.approx(ax, rel=0.02)
    assert a.alpha_radial == pytest.approx(ay, rel=0.02)
    table = slope_table(h, dx, dy, bins=128)
    assert table.equivalent_alphas[0] == pytest.approx(ax, rel=0.02)
    assert table.equivalent_alphas[1] == pytest.approx(ay, rel=0.02)
    # the map with its radial axis along x is the transposed one
    ht, dxt, dyt = to_local(h, dx, dy, "x")
    assert analyse(ht, dxt, dyt).alpha_radial == pytest.approx(ax, rel=0.02)


def test_k_correlation_parameters_recovered_within_5_percent():
    """Whittle fit of an anisotropic K-correlation surface (bx != by, dx != dy): every
    parameter within 5 % and within 4 of its own standard errors."""
    dx, dy = 0.5e-3, 0.3e-3
    kc = KCorrelation(3e-6, 2 * math.pi * 1.5 * dx, 2 * math.pi * 1.2 * dy, 2.4)
    h = synthesize(kc, (384, 512), dx, dy, seed=11)
    fx, fy, s = periodogram(h, dx, dy, "none")
    assert s.sum() * (fx[1] - fx[0]) * (fy[1] - fy[0]) == pytest.approx(h.var(), rel=1e-10)
    fit = fit_k_correlation(fx, fy, s)
    got = np.array([fit.model.sigma, fit.model.bx, fit.model.by, fit.model.c])
    want = np.array([kc.sigma, kc.bx, kc.by, kc.c])
    rel = got / want - 1
    assert np.all(np.abs(rel) < 0.05), rel
    assert np.all(np.abs(rel) < 4 * np.array(fit.rel_err)), (rel, fit.rel_err)
    # the Hann-windowed periodogram (for measured maps) agrees within its standard errors
    fxh, fyh, sh = periodogram(h, dx, dy, "hann")
    fh = fit_k_correlation(fxh, fyh, sh, effective_fraction=window_fraction("hann"))
    relh = np.array([fh.model.sigma, fh.model.bx, fh.model.by, fh.model.c]) / want - 1
    assert np.all(np.abs(relh) < 4 * np.array(fh.rel_err)), (relh, fh.rel_err)


def test_regime_follows_the_rayleigh_parameter():
    assert regime(0.07)[0] == "smooth" and regime(0.07)[2] == "rayleigh_rice"
    assert regime(0.9)[0] == "intermediate" and regime(0.9)[2] == "rayleigh_rice"
    assert regime(1.2)[2] == "slope_density"
    assert regime(3.0)[0] == "geometric"


def _smooth_x3p(path, sigma=3e-6):
    """A smooth K-correlation patch (dx != dy, lx != ly) written by x3pio."""
    kc = KCorrelation(sigma, 2 * math.pi * 6e-3, 2 * math.pi * 2e-3, 2.3)
    h = synthesize(kc, (96, 128), 0.8e-3, 0.5e-3, seed=5)
    x3pio.write(path, h * 1e-3, x_scale=0.8e-6, y_scale=0.5e-6)
    return h


def test_topography_model_picks_halo_or_slope_density_by_the_rayleigh_parameter(tmp_path):
    """[brdf] model = "topography": a 3 nm finish is smooth (peak + halo, specular share
    exp(-g^2)); the same map scaled to 300 nm is geometric (its slope density, alphas as
    the analysis's, tangential on local x); regime = "geometric" forces the density."""
    from pmdsim.brdf import brdf_from_config, equivalent_alphas
    from pmdsim.brdf.rayleigh_rice import SpecularHaloBRDF
    from pmdsim.brdf.slope_density import SlopeDensityBRDF
    from pmdsim.config import TopographyConfig

    h = _smooth_x3p(tmp_path / "s.x3p")
    cfg = TopographyConfig(file=str(tmp_path / "s.x3p"), incidence_deg=25.0, fill="error", level="none")
    b = brdf_from_config(cfg)
    assert isinstance(b, SpecularHaloBRDF) and b.name == "topography"
    g = 4 * math.pi * h.std() * math.cos(math.radians(25)) / 545e-6
    assert b.specular_reflectance == pytest.approx(cfg.rho_s * math.exp(-g * g), rel=1e-9)
    x3pio.write(tmp_path / "r.x3p", h * 100 * 1e-3, x_scale=0.8e-6, y_scale=0.5e-6)
    rough = TopographyConfig(file=str(tmp_path / "r.x3p"), level="none")
    b = brdf_from_config(rough)
    assert isinstance(b, SlopeDensityBRDF)
    a = analyse(h * 100, 0.8e-3, 0.5e-3)
    ax, ay = equivalent_alphas(rough)
    assert ax == pytest.approx(a.alpha_tangential, rel=0.03) and ay == pytest.approx(a.alpha_radial, rel=0.03)
    assert ax < ay  # lx > ly: steeper radially
    forced = brdf_from_config(cfg.model_copy(update={"regime": "geometric"}))
    assert isinstance(forced, SlopeDensityBRDF)


def test_texture_from_file_command(tmp_path):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    _smooth_x3p(tmp_path / "s.x3p")
    runner = CliRunner()
    res = runner.invoke(app, ["texture", "--from", str(tmp_path / "s.x3p"), "--incidence-deg", "25",
                              "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "smooth" in res.output and "Sdq" in res.output
    for f in ("topography.json", "topography.txt", "topography.png"):
        assert (tmp_path / "out" / f).is_file()
    res = runner.invoke(app, ["texture", "--from", str(tmp_path / "missing.x3p")])
    assert res.exit_code == 2 and "--from" in res.output and "missing.x3p" in res.output
    res = runner.invoke(app, ["texture"])
    assert res.exit_code == 2 and "--from" in res.output
