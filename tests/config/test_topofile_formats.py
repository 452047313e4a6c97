"""Sensofar .plu, Keyence .vk4/.vk3 and Zygo .datx in (``pmdsim.topofile``, issues 20, 39).

The files are written here after the layouts independent open readers document
(``topofile_writers.py``: Gwyddion's sensofar.c and keyence.c, SurfaceTopography's PLU.py,
VK.py and DATX.py, prysm's io.py), with asymmetric heights, dx != dy and points not
measured; .plu and .vk4/.vk3 are also read by Gwyddion itself (its gwyconvert, a test
dependency), .datx by prysm's reader, to show the files follow the layout those readers
read. Checked: heights and
their unit, orientation (rows along y), spacing, points not measured, and that truncated
or garbled files are refused with an error naming the field and the file (exit 2). They
are read through SurfaceTopography (issue 39); the real instrument files are in
test_instrument_samples.py."""

from __future__ import annotations

import subprocess
import warnings

import numpy as np
import pytest
from topofile_writers import (
    DATX_UNITS,
    PLU_NOT_MEASURED,
    write_datx,
    write_plu,
    write_plux,
    write_vk4,
)

from pmdsim.config import InputError
from pmdsim.topofile import (
    NOT_READ,
    OWN_SUFFIXES,
    ST_FORMATS,
    SURFALIZE_SUFFIXES,
    read_topography,
)

pytest.importorskip("SurfaceTopography")

DX_UM, DY_UM = 0.4, 0.7  # dx != dy: a swapped axis fails


def _z_um(ny=5, nx=7):
    y, x = np.mgrid[0:ny, 0:nx]
    return 0.3 * x - 0.2 * y + 0.05 * x * y + np.sin(x)  # asymmetric in x and y


def _gwyddion(path, tmp_path):
    """(heights in m, x real size, y real size, mask or None) of the first channel, as
    Gwyddion's own file module reads ``path`` (gwyconvert -> .gwy -> gwyfile)."""
    conv = pytest.importorskip("gwyddionpy_converter")
    gwyfile = pytest.importorskip("gwyfile")
    out = tmp_path / (path.name + ".gwy")
    res = subprocess.run([str(conv.binary_path()), str(path), str(out)], capture_output=True,
                         text=True, timeout=120, check=False)
    assert res.returncode == 0, res.stderr
    obj = gwyfile.load(str(out))
    field = obj["/0/data"]
    mask = obj["/0/mask"].data if "/0/mask" in obj else None
    return np.asarray(field.data), field.xreal, field.yreal, mask


# --- Sensofar .plu ---------------------------------------------------------------------

def test_plu_reads_heights_spacing_and_points_not_measured(tmp_path):
    z = _z_um().astype(np.float32)
    z[3, 4] = PLU_NOT_MEASURED
    path = tmp_path / "part.plu"
    write_plu(path, z, DX_UM, DY_UM)
    with pytest.raises(InputError, match=r"1 points not measured"):
        read_topography(path)
    t = read_topography(path, fill="mean")
    assert t.heights.shape == (5, 7) and t.invalid == 1 and t.reader.startswith("SurfaceTop")
    ok = z != PLU_NOT_MEASURED
    np.testing.assert_allclose(t.heights[ok], z[ok].astype(float) * 1e-3, rtol=0, atol=1e-15)
    assert t.heights[3, 4] == pytest.approx(np.mean(z[ok]) * 1e-3, rel=1e-6)
    assert (t.dx, t.dy) == pytest.approx((DX_UM * 1e-3, DY_UM * 1e-3), rel=1e-6)


def test_plu_file_is_read_alike_by_gwyddion_and_misread_by_surfalize(tmp_path):
    """Gwyddion's sensofar module reads the same heights, mask and spacing from the file;
    surfalize 0.19.2 returns it shifted by two values (the grid's size as two tiny
    heights), one reason pmdsim does not read through surfalize."""
    z = _z_um().astype(np.float32)
    z[1, 5] = PLU_NOT_MEASURED
    path = tmp_path / "part.plu"
    write_plu(path, z, DX_UM, DY_UM)
    ours = read_topography(path, fill="mean")
    gz, xreal, yreal, mask = _gwyddion(path, tmp_path)
    ok = z != PLU_NOT_MEASURED
    assert gz.shape == (5, 7) and mask is not None and mask[1, 5] == 1 and not mask[ok].any()
    np.testing.assert_allclose(gz[ok] * 1e3, ours.heights[ok], rtol=1e-6)  # m -> mm
    assert (xreal / 7 * 1e3, yreal / 5 * 1e3) == pytest.approx((ours.dx, ours.dy), rel=1e-6)
    surfalize = pytest.importorskip("surfalize")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        misread = np.asarray(surfalize.Surface.load(path).data).ravel()
    np.testing.assert_allclose(misread[2:][ok.ravel()[:-2]], z.ravel()[:-2][ok.ravel()[:-2]],
                               rtol=1e-6)
    assert abs(misread[0]) < 1e-30 and abs(misread[1]) < 1e-30  # 5 and 7 as float32 bits


def test_plu_without_the_grid_size_or_of_another_kind_is_refused(tmp_path):
    z = _z_um().astype(np.float32)
    path = tmp_path / "shifted.plu"
    write_plu(path, z, DX_UM, DY_UM, with_grid_size=False)  # the layout surfalize reads
    # SurfaceTopography takes the first heights for the grid's size: an empty grid, refused
    with pytest.raises(InputError, match=r"brdf\.file: .*shifted\.plu.*declares a grid of"):
        read_topography(path, "brdf.file")
    write_plu(path, z, DX_UM, DY_UM, measurement_type=1)
    with pytest.raises(InputError, match=r"surface\.file: .*shifted\.plu \(Sensofar PLU\): not "
                       r"read \(.*`type` has invalid value '1'.*expected value is '3'"):
        read_topography(path)


def test_plux_reads_heights_spacing_and_points_not_measured(tmp_path):
    """Sensofar's newer .plux (ZIP) on a file written after SurfaceTopography's layout; a
    layer whose size disagrees with index.xml is refused."""
    z = _z_um().astype(np.float32)
    z[2, 3] = np.nan
    path = tmp_path / "part.plux"
    write_plux(path, z, DX_UM, DY_UM)
    t = read_topography(path, fill="nearest")
    ok = np.isfinite(z)
    assert t.heights.shape == (5, 7) and t.invalid == 1 and t.reader.startswith("SurfaceTop")
    np.testing.assert_allclose(t.heights[ok], z[ok].astype(float) * 1e-3, rtol=0, atol=1e-15)
    assert (t.dx, t.dy) == pytest.approx((DX_UM * 1e-3, DY_UM * 1e-3), rel=1e-12)
    write_plux(path, np.vstack([z, z[:1]]), DX_UM, DY_UM, stated_shape=(5, 7))
    with pytest.raises(InputError, match=r"LAYER_0\.raw holds 168 bytes, index\.xml states 5 x 7"):
        read_topography(path)


# --- Keyence .vk4 / .vk3 -----------------------------------------------------------------

@pytest.mark.parametrize("version,bits", [(4, 32), (4, 16), (3, 32)])
def test_vk_reads_heights_in_picometres_and_spacing(tmp_path, version, bits):
    """Heights are counts x z length per digit (pm), spacing x/y length per pixel (pm),
    read through SurfaceTopography; Gwyddion reads the same."""
    y, x = np.mgrid[0:5, 0:7]
    counts = 1000 + 37 * x + 11 * y * y + x * y
    path = tmp_path / f"part.vk{version}"
    write_vk4(path, counts, 400_000, 700_000, 1250, bit_depth=bits, version=version)
    t = read_topography(path)
    assert t.heights.shape == (5, 7) and t.reader.startswith("SurfaceTop")
    np.testing.assert_allclose(t.heights, counts * 1250e-9, rtol=1e-12)  # pm -> mm
    assert (t.dx, t.dy) == pytest.approx((DX_UM * 1e-3, DY_UM * 1e-3), rel=1e-12)
    gz, xreal, yreal, _ = _gwyddion(path, tmp_path)
    np.testing.assert_allclose(gz * 1e3, t.heights, rtol=1e-12)
    # Gwyddion's real size is (n - 1) x the spacing ("from comparison with original software")
    assert (xreal / 6 * 1e3, yreal / 4 * 1e3) == pytest.approx((t.dx, t.dy), rel=1e-12)


# --- Zygo .datx ------------------------------------------------------------------------

@pytest.mark.parametrize("unit,metadata,unit_attr", [("NanoMeters", True, None),
                                                    ("MicroMeters", True, "\u00b5m")])
def test_datx_reads_heights_units_spacing_and_no_data(tmp_path, unit, metadata, unit_attr):
    pytest.importorskip("h5py")
    z_um = _z_um()
    z = z_um * 1e-6 / DATX_UNITS[unit]
    no_data = np.finfo(np.float64).max if metadata else -9999.0
    z[1, 2], z[4, 0] = no_data, np.nan
    path = tmp_path / "part.datx"
    write_datx(path, z, DX_UM * 1e-6, DY_UM * 1e-6, unit=unit, no_data=no_data,
               metadata=metadata, unit_attr=unit_attr)
    t = read_topography(path, fill="nearest")
    assert t.heights.shape == (5, 7) and t.invalid == 2 and t.reader.startswith("SurfaceTop")
    ok = np.ones_like(z, bool)
    ok[1, 2] = ok[4, 0] = False
    np.testing.assert_allclose(t.heights[ok], z_um[ok] * 1e-3, rtol=1e-12)
    assert (t.dx, t.dy) == pytest.approx((DX_UM * 1e-3, DY_UM * 1e-3), rel=1e-12)


def test_datx_file_is_read_alike_by_prysm(tmp_path):
    """prysm's read_zygo_datx (MIT, an independent reader) finds the same heights (nm), the
    same points not measured and the lateral resolution in the file pmdsim reads."""
    pytest.importorskip("h5py")
    prysm_io = pytest.importorskip("prysm.io")
    z = _z_um() * 1e3
    z[2, 5] = np.finfo(np.float64).max
    path = tmp_path / "part.datx"
    write_datx(path, z, DX_UM * 1e-6, DY_UM * 1e-6)
    ours = read_topography(path, fill="mean")
    theirs = prysm_io.read_zygo_datx(path)
    phase = np.asarray(theirs["phase"])
    assert phase.shape == ours.heights.shape and np.isnan(phase[2, 5])
    ok = np.isfinite(phase)
    assert ok.sum() == phase.size - 1 and ours.invalid == 1
    np.testing.assert_allclose(phase[ok] * 1e-6, ours.heights[ok], rtol=1e-12)  # nm -> mm
    assert theirs["meta"]["Lateral Resolution"] * 1e3 == pytest.approx(ours.dx, rel=1e-12)


def test_instrument_file_without_surfacetopography_says_what_to_install(tmp_path, monkeypatch):
    import sys

    path = tmp_path / "part.datx"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(64))
    monkeypatch.setitem(sys.modules, "SurfaceTopography", None)
    with pytest.raises(InputError, match=r"surface\.file: .*part\.datx.*needs "
                       r"SurfaceTopography \(MIT\): pip install 'pmdsim\[instruments\]'"):
        read_topography(path)


@pytest.mark.parametrize("change,match", [
    ({"unit": "Fringes"}, r"not read \(.*Unknown unit 'Fringes'"),
    ({"unit_attr": "MicroMeters"}, r"not read \(.*conflicting height units"),
    ({"lateral_category": "PixelCat"}, r"not read \(.*LateralCat"),
    ({"z_category": "IntensityCat"}, r"not read \(.*HeightCat"),
    ({"metadata": False}, r"cannot read it .*MetaData"),
])
def test_datx_refuses_what_it_cannot_read_as_heights(tmp_path, change, match):
    pytest.importorskip("h5py")
    path = tmp_path / "odd.datx"
    write_datx(path, _z_um(), DX_UM * 1e-6, DY_UM * 1e-6, **change)
    with pytest.raises(InputError, match=r"brdf\.file: .*odd\.datx \(Zygo DATX\): " + match):
        read_topography(path, "brdf.file")


# --- Gwyddion .gwy ----------------------------------------------------------------------

def test_gwy_written_by_gwyfile_reads_with_units_spacing_and_mask(tmp_path):
    """A .gwy file written by gwyfile (Gwyddion's format, an independent writer): heights in
    the z unit (um here), the real sizes, and the mask's points as not measured."""
    objects = pytest.importorskip("gwyfile.objects")
    z = _z_um()
    y, x = np.mgrid[0:5, 0:7]
    unit = objects.GwySIUnit
    field = objects.GwyDataField(z, xreal=7 * DX_UM * 1e-6, yreal=5 * DY_UM * 1e-6,
                                 si_unit_xy=unit(unitstr="m"), si_unit_z=unit(unitstr="um"))
    container = objects.GwyContainer()
    container["/0/data"] = field
    container["/0/data/title"] = "Height"
    container["/0/mask"] = objects.GwyDataField(((x == 3) & (y == 2)) * 1.0, xreal=1.0,
                                                yreal=1.0)
    path = tmp_path / "part.gwy"
    container.tofile(str(path))
    t = read_topography(path, fill="mean")
    assert t.heights.shape == (5, 7) and t.not_measured == 1 and t.reader.startswith("Surface")
    ok = ~((x == 3) & (y == 2))
    np.testing.assert_allclose(t.heights[ok], z[ok] * 1e-3, rtol=1e-12)
    assert (t.dx, t.dy) == pytest.approx((DX_UM * 1e-3, DY_UM * 1e-3), rel=1e-12)


# --- bad files -------------------------------------------------------------------------

def _good(tmp_path, suffix):
    path = tmp_path / f"good{suffix}"
    if suffix == ".plu":
        write_plu(path, _z_um(), DX_UM, DY_UM)
    elif suffix == ".datx":
        write_datx(path, _z_um() * 1e3, DX_UM * 1e-6, DY_UM * 1e-6)
    elif suffix == ".plux":
        write_plux(path, _z_um(), DX_UM, DY_UM)
    else:
        write_vk4(path, 1000 + np.arange(35).reshape(5, 7), 400_000, 700_000, 1000,
                  version=int(suffix[-1]))
    return path.read_bytes()


def _damaged(data, how):
    n = len(data)
    return {"empty": b"", "head": data[:100], "middle": data[:n // 2], "tail": data[:n - 9],
            "garbled": data[:4] + bytes(b ^ 0x5A for b in data[4:520]) + data[520:]}[how]


@pytest.mark.parametrize("suffix", [".plu", ".vk4", ".vk3", ".datx", ".plux"])
@pytest.mark.parametrize("how", ["empty", "head", "middle", "tail", "garbled"])
def test_truncated_or_garbled_files_are_refused_naming_field_and_file(tmp_path, suffix, how):
    pytest.importorskip("h5py")
    path = tmp_path / f"bad-{how}{suffix}"
    path.write_bytes(_damaged(_good(tmp_path, suffix), how))
    if how == "tail" and suffix in (".vk4", ".vk3"):
        # the last 9 bytes are the lens name's characters, after the heights: read whole
        np.testing.assert_array_equal(read_topography(path).heights,
                                      read_topography(tmp_path / f"good{suffix}").heights)
        return
    with pytest.raises(InputError) as info:
        read_topography(path, "brdf.file")
    msg = str(info.value)
    assert msg.startswith("brdf.file: ") and path.name in msg, msg


@pytest.mark.parametrize("suffix", [".plu", ".vk4", ".datx"])
def test_cli_exits_2_on_a_damaged_file(tmp_path, suffix):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    path = tmp_path / f"cut{suffix}"
    path.write_bytes(_damaged(_good(tmp_path, suffix), "middle"))
    res = CliRunner().invoke(app, ["texture", "--from", str(path), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "--from" in res.output and path.name in res.output, res.output
    assert not (tmp_path / "o").exists()


def test_every_instrument_format_is_read_by_a_tested_reader_or_refused(tmp_path):
    """Every suffix SurfaceTopography reads is read (tested here, in test_topography.py or on
    a real file in test_instrument_samples.py) or refused with its reason, the field, the
    file and what to export; surfalize is used only for its own .sflz."""
    from SurfaceTopography.IO import readers

    from pmdsim.topofile import ARRAY_SUFFIXES, X3P_SUFFIXES

    read = set(ST_FORMATS) | set(X3P_SUFFIXES) | set(OWN_SUFFIXES) | set(SURFALIZE_SUFFIXES)
    assert read == {".plu", ".plux", ".opd", ".dat", ".datx", ".al3d", ".tmd", ".sdf", ".sur",
                    ".mi", ".frt", ".di", ".spm", ".vk4", ".vk3", ".gwy", ".x3p", ".nms",
                    ".sflz"}
    assert not set(NOT_READ) & (read | set(ARRAY_SUFFIXES))
    theirs = {"." + e.lower() for r in readers for e in (getattr(r, "_file_extensions", None) or ())}
    assert theirs - read - set(ARRAY_SUFFIXES) - set(NOT_READ) == set()
    for name in ("part.vk7", "part.vk6", "part.zon", "part.xyz"):
        (tmp_path / name).write_bytes(bytes(64))
        with pytest.raises(InputError) as info:
            read_topography(tmp_path / name, "brdf.file")
        msg = str(info.value)
        assert msg.startswith("brdf.file:") and name in msg and "not read" in msg, msg
        assert "X3P" in msg and NOT_READ[name[4:]] in msg
