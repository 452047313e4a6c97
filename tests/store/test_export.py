"""pmdsim export: X3P read back by an independent reader (zip + XML + raw little-endian
doubles, as ISO 25178-72 lays them out), CSV and xyz with units in the header."""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from typer.testing import CliRunner

from pmdsim.cli import app

pytest.importorskip("x3pio")


def _strip(tag):
    return tag.rsplit("}", 1)[-1]


def _find(root, path):
    node = root
    for part in path.split("/"):
        node = next(c for c in node if _strip(c.tag) == part)
    return node


def read_x3p_independently(path):
    """(z (SizeY, SizeX) in metres, dx, dy, x offset, y offset) from the archive itself."""
    with zipfile.ZipFile(path) as zf:
        xml = zf.read("main.xml")
        md5 = zf.read("md5checksum.hex").decode().split()[0]
        assert md5.lower() == hashlib.md5(xml).hexdigest()  # the checksum of main.xml
        root = ET.fromstring(xml)
        axes = _find(root, "Record1/Axes")
        cx, cy, cz = (_find(axes, a) for a in ("CX", "CY", "CZ"))
        assert _find(cx, "AxisType").text == "I" and _find(cz, "AxisType").text == "A"
        assert _find(cz, "DataType").text == "D"  # float64
        dim = _find(root, "Record3/MatrixDimension")
        nx, ny, nz = (int(_find(dim, s).text) for s in ("SizeX", "SizeY", "SizeZ"))
        link = _find(root, "Record3/DataLink/PointDataLink").text
        z = np.frombuffer(zf.read(link), "<f8").reshape(nz, ny, nx)[0]  # X fastest, then Y
    off = lambda ax: float(_find(ax, "Offset").text) if any(_strip(c.tag) == "Offset" for c in ax) else 0.0  # noqa: E731
    return z, float(_find(cx, "Increment").text), float(_find(cy, "Increment").text), off(cx), off(cy)


def _fake_run(tmp_path, x, y, maps):
    import xarray as xr

    dims = ("surface_y", "surface_x")
    ds = xr.Dataset({k: (dims, v, {"description": f"test {k}"}) for k, v in maps.items()},
                    coords={"surface_x": ("surface_x", x, {"units": "mm"}),
                            "surface_y": ("surface_y", y, {"units": "mm"})},
                    attrs={"title": "pmdsim run export-test", "created_utc": "2026-01-02T03:04:05+00:00"})
    run = tmp_path / "run"
    run.mkdir()
    ds.to_zarr(run / "run.zarr", consolidated=False)
    (run / "pmdsim-run.json").write_text('{"format": "pmdsim-run/1"}\n')  # written last: complete
    return run


def _maps():
    rng = np.random.default_rng(5)
    x = 1.5 + 0.25 * np.arange(11)        # dx = 0.25 mm
    y = -2.0 + 0.4 * np.arange(7)         # dy = 0.4 mm: a swapped axis fails
    h = rng.normal(0, 30.0, (7, 11))
    h[0, :3] = np.nan                      # not measured
    sx = rng.normal(0, 5.0, (7, 11))
    sx[np.isnan(h)] = np.nan
    return x, y, {"height_error_nm": h, "slope_error_x_urad": sx}


def test_x3p_round_trip_through_an_independent_reader(tmp_path):
    x, y, maps = _maps()
    run = _fake_run(tmp_path, x, y, maps)
    res = CliRunner().invoke(app, ["export", str(run), "--format", "x3p", "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    z, dx, dy, x0, y0 = read_x3p_independently(tmp_path / "out" / "height_error.x3p")
    assert z.shape == (7, 11)
    assert dx == pytest.approx(0.25e-3, rel=1e-12) and dy == pytest.approx(0.4e-3, rel=1e-12)
    np.testing.assert_array_equal(np.isnan(z), np.isnan(maps["height_error_nm"]))
    ok = np.isfinite(z)
    np.testing.assert_allclose(z[ok], maps["height_error_nm"][ok] * 1e-9, rtol=1e-12)
    # a slope is no length: not written as X3P (every reader labels z metres), said so
    assert not (tmp_path / "out" / "slope_error_x.x3p").exists()
    assert "slope_error_x_urad" in res.output and "--format csv" in res.output
    # and the library that wrote it reads the same heights
    import x3pio

    f = x3pio.read(tmp_path / "out" / "height_error.x3p")
    np.testing.assert_allclose(np.asarray(f.layers[0].z)[ok], z[ok], rtol=1e-12)
    # same run, same bytes; an existing file is refused without --overwrite
    first = (tmp_path / "out" / "height_error.x3p").read_bytes()
    res = CliRunner().invoke(app, ["export", str(run), "--format", "x3p", "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and "overwrite" in res.output
    res = CliRunner().invoke(app, ["export", str(run), "--format", "x3p", "-o", str(tmp_path / "out"),
                                   "--overwrite"])
    assert res.exit_code == 0 and (tmp_path / "out" / "height_error.x3p").read_bytes() == first


def test_csv_and_xyz_have_units_in_the_header(tmp_path):
    x, y, maps = _maps()
    run = _fake_run(tmp_path, x, y, maps)
    for fmt in ("csv", "xyz"):
        res = CliRunner().invoke(app, ["export", str(run), "--format", fmt])
        assert res.exit_code == 0, res.output
    lines = (run / "export" / "surface.csv").read_text().splitlines()
    head = next(line for line in lines if not line.startswith("#"))
    assert head == "x_mm,y_mm,height_error_nm,slope_error_x_urad"
    import csv

    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    data = {k: np.array([float(r[k]) for r in rows]) for k in ("x_mm", "y_mm", "height_error_nm")}
    xx, yy = np.meshgrid(x, y)
    ok = np.isfinite(maps["height_error_nm"])
    assert len(rows) == ok.sum()
    np.testing.assert_allclose(data["x_mm"], xx[ok])
    np.testing.assert_allclose(data["y_mm"], yy[ok])
    np.testing.assert_allclose(data["height_error_nm"], maps["height_error_nm"][ok], rtol=1e-9)
    text = (run / "export" / "height_error.xyz").read_text()
    assert "# x [mm] y [mm] z [nm]" in text
    xyz = np.loadtxt(run / "export" / "height_error.xyz")
    np.testing.assert_allclose(xyz, np.stack([xx[ok], yy[ok], maps["height_error_nm"][ok]], 1), rtol=1e-9)


def test_bad_input(tmp_path):
    res = CliRunner().invoke(app, ["export", str(tmp_path), "--format", "x3p"])
    assert res.exit_code == 2 and "not a pmdsim run" in res.output
    x, y, maps = _maps()
    run = _fake_run(tmp_path, x, y, maps)
    res = CliRunner().invoke(app, ["export", str(run), "--format", "stl"])
    assert res.exit_code == 2 and "--format" in res.output
