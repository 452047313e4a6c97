"""Real instrument files (issue 39) and bounded, well-named reading (issue 38 items 1, 4).

``tests/data/instrument-samples`` holds thirteen files measured on real instruments, from
SurfaceTopography's test suite (MIT, its notice beside them). Each must read with the grid,
physical size, unit and RMS height (before and after removing the curvature) that
SurfaceTopography's own tests (``test/IO/test_*.py``) state for it, where they state one,
and pointwise as Gwyddion (gwyconvert, a test dependency: an independent reader) reads it.
The bombs are small files written here that declare huge grids or parts that unpack huge.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pmdsim.config import InputError
from pmdsim.topofile import MAX_UNPACKED_BYTES, read_topography

DATA = Path(__file__).parents[1] / "data" / "instrument-samples"

pytest.importorskip("SurfaceTopography")

# file: (nx, ny, size x, size y, unit of the sizes and RMS, RMS height, RMS after removing
# the curvature or None), as SurfaceTopography's tests state them (its unit: the file's);
# None where they state nothing (then the value Gwyddion reads is checked instead).
STATED = {
    "plu-1.plu": (768, 576, 1274.880066, 956.160049, "um", 2.834391, 0.01818),
    "metropro-1.dat": (640, 480, 0.0007028812979115173, 0.000527160973433638, "m",
                       7.528822204734589e-08, 3.911386124282179e-09),
    "al3d-1.al3d": (200, 296, 8.76054e-05, 0.000129655992, "m", 7.688266102603082e-06, None),
    "x3p-2.x3p": (650, 650, 8.29767313942749e-05, 0.0002044783737930349, "m",
                  7.728033273597876e-08, None),
    "frt-2.frt": (150, 300, 0.03, 0.06, "m", 8.826763181113768e-06, 8.688677385181484e-06),
    "sur-3.sur": (512, 512, 0.151319552, 0.151319552, "m", 0.0011131994265859693, None),
    "opd-1.opd": (640, 480, 0.125909140, 0.094431855, "mm", None, None),
    "tmd-1.tmd": (300, 300, 18.9566, 18.9566, "mm", None, None),
    "sdf-1.sdf": (7, 4, 7.0, 4.0, "um", None, None),
    "mi-1.mi": (256, 256, 20.0, 20.0, "um", None, None),
    "nms-1.nms": (512, 512, 160.0, 160.0, "um", None, None),
    "sur-2.sur": (563, 484, None, None, "mm", None, None),
    "di-3.di": (256, 256, None, None, "nm", None, None),
}
# points not measured, as SurfaceTopography's tests state them (sur) or Gwyddion's mask has
NOT_MEASURED = {"sur-2.sur": 117, "sur-3.sur": 233009, "frt-2.frt": 12314, "opd-1.opd": 116}
UNIT_MM = {"m": 1e3, "mm": 1.0, "um": 1e-3, "nm": 1e-6}


def _rms(z, ok):
    return float(np.sqrt(np.mean((z[ok] - z[ok].mean()) ** 2)))


def _curvature_removed(z, ok, dx, dy):
    """RMS about the least-squares quadric in x and y (SurfaceTopography's 'curvature'
    detrending of a uniform map: 1, x, y, x^2, y^2, x y) of the measured points."""
    ny, nx = z.shape
    y, x = np.mgrid[0:ny, 0:nx]
    x, y = x * dx, y * dy
    a = np.stack([np.ones(ok.sum()), x[ok], y[ok], x[ok] ** 2, y[ok] ** 2, x[ok] * y[ok]], -1)
    c, *_ = np.linalg.lstsq(a, z[ok], rcond=None)
    return float(np.sqrt(np.mean((z[ok] - a @ c) ** 2)))


def _measured(name):
    """The measured points: a filled point differs between the two fills."""
    return (read_topography(DATA / name, fill="nearest").heights
            == read_topography(DATA / name, fill="mean").heights)


def _gwyddion(path, tmp_path):
    conv = pytest.importorskip("gwyddionpy_converter")
    gwyfile = pytest.importorskip("gwyfile")
    out = tmp_path / (path.name + ".gwy")
    res = subprocess.run([str(conv.binary_path()), str(path), str(out)], capture_output=True,
                         text=True, timeout=120, check=False)
    if res.returncode:
        return None  # this Gwyddion build has no module for the format (.x3p, .nms)
    field = gwyfile.load(str(out))["/0/data"]
    return np.asarray(field.data), field.xreal, field.yreal


def test_the_samples_and_their_notice_are_here():
    names = {p.name for p in DATA.iterdir()}
    assert set(STATED) <= names and "LICENSE-SurfaceTopography.md" in names
    assert "MIT license" in (DATA / "LICENSE-SurfaceTopography.md").read_text()


@pytest.mark.parametrize("name", sorted(STATED))
def test_each_real_file_reads_as_its_tests_state(name, tmp_path):
    nx, ny, sx, sy, unit, rms, rms_curv = STATED[name]
    t = read_topography(DATA / name, fill="mean")
    mm = UNIT_MM[unit]
    assert t.heights.shape == (ny, nx), t.heights.shape
    if sx is not None:
        assert t.size_mm == pytest.approx((sx * mm, sy * mm), rel=1e-4 if name == "tmd-1.tmd"
                                          else 1e-6)
    assert t.not_measured == NOT_MEASURED.get(name, 0) == t.invalid
    ok = _measured(name)
    if t.not_measured:
        with pytest.raises(InputError, match=rf"{t.not_measured} points not measured"):
            read_topography(DATA / name)
    if rms is not None:
        assert _rms(t.heights, ok) == pytest.approx(rms * mm, rel=1e-6)
    if rms_curv is not None:
        assert _curvature_removed(t.heights, ok, t.dx, t.dy) == pytest.approx(rms_curv * mm,
                                                                              rel=1e-4)


@pytest.mark.parametrize("name", sorted(STATED))
def test_each_real_file_reads_pointwise_as_gwyddion_reads_it(name, tmp_path):
    """Gwyddion's own file modules (an independent reader): the same heights point by point
    at the measured points (so the same orientation and unit) and the same physical size,
    where its build reads the format (not .x3p, .nms here). sur-3.sur: up to a constant
    (Gwyddion's z offset)."""
    read = _gwyddion(DATA / name, tmp_path)
    if read is None:
        pytest.skip(f"Gwyddion reads no {name}")
    gz, xreal, yreal = read
    t = read_topography(DATA / name, fill="nearest")
    assert t.size_mm == pytest.approx((xreal * 1e3, yreal * 1e3), rel=1e-9)  # m -> mm
    measured = _measured(name)
    assert gz.shape == t.heights.shape
    ours, theirs = t.heights[measured], gz[measured] * 1e3
    if name == "sur-3.sur":  # Gwyddion adds a z offset of -3.414 mm that SurfaceTopography and
        ours, theirs = ours - ours.mean(), theirs - theirs.mean()  # surfalize do not
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-12 * np.ptp(theirs))


def test_nms_spacing_is_nanometres_where_surfacetopography_reads_millimetres():
    """The file that shows why pmdsim reads .nms itself: a 512 x 512 confocal map whose
    header holds the spacing 312.5 (nm: a 160 um field; surfalize reads it so), which
    SurfaceTopography 1.27 takes as mm (a 160 m field); its heights agree with ours."""
    from SurfaceTopography.IO import open_topography

    ours = read_topography(DATA / "nms-1.nms")
    theirs = open_topography(str(DATA / "nms-1.nms"), format="nms").topography()
    assert ours.size_mm == pytest.approx((0.16, 0.16), rel=1e-6)
    assert theirs.unit in ("\u00b5m", "um") and theirs.physical_sizes[0] == pytest.approx(1.6e8,
                                                                                        rel=1e-6)
    np.testing.assert_allclose(ours.heights, np.asarray(theirs.heights()).T * 1e-3, rtol=1e-12)
    surfalize = pytest.importorskip("surfalize")
    s = surfalize.Surface.load(DATA / "nms-1.nms")
    assert s.step_x * 1e-3 == pytest.approx(ours.dx, rel=1e-9)


def test_where_surfalize_misreads_the_real_files():
    """Why surfalize (today's GPL backend) is not used: on the real files it reads MetroPro
    heights 8 x too large and .tmd lengths in um where Gwyddion and SurfaceTopography have
    mm, and fails on .opd. If surfalize is fixed, this fails."""
    surfalize = pytest.importorskip("surfalize")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dat = surfalize.Surface.load(DATA / "metropro-1.dat")
        tmd = surfalize.Surface.load(DATA / "tmd-1.tmd")
        with pytest.raises(Exception):  # noqa: B017 - any failure
            surfalize.Surface.load(DATA / "opd-1.opd")
    ours = read_topography(DATA / "metropro-1.dat")
    rms = np.std(np.asarray(dat.data)) * 1e-3
    assert rms / np.std(ours.heights) == pytest.approx(8.0, rel=1e-3)
    assert tmd.step_x == pytest.approx(read_topography(DATA / "tmd-1.tmd").dx, rel=1e-6)  # um=mm


@pytest.mark.parametrize("suffix", [".spm"])
def test_nanoscope_under_its_other_suffix(tmp_path, suffix):
    path = tmp_path / f"scan{suffix}"
    shutil.copy(DATA / "di-3.di", path)
    np.testing.assert_array_equal(read_topography(path).heights,
                                  read_topography(DATA / "di-3.di").heights)


@pytest.mark.parametrize("name", sorted(STATED))
def test_texture_from_each_real_file(name, tmp_path):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    res = CliRunner().invoke(app, ["texture", "--from", str(DATA / name), "--no-figure",
                                   "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "o" / "topography.json").exists()
    n = NOT_MEASURED.get(name, 0)
    assert f"filled {n} of {STATED[name][0] * STATED[name][1]} points" in res.output, res.output


# --- bombs: small files that declare huge grids or unpack huge (issue 38, item 1) -------

HUGE = 20000  # 20000 x 20000 = 4e8 points > 2^28


def _x3p_bomb(path):
    xml = ("<?xml version='1.0'?><p:ISO5436_2 xmlns:p='http://www.opengps.eu/2008/ISO5436_2'>"
           f"<Record3><MatrixDimension><SizeX>{HUGE}</SizeX><SizeY>{HUGE}</SizeY><SizeZ>1</SizeZ>"
           "</MatrixDimension></Record3></p:ISO5436_2>")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("main.xml", xml)
        z.writestr("bindata/data.bin", bytes(4096))


def _plux_bomb(path):
    from topofile_writers import write_plux

    write_plux(path, np.zeros((2, 2), np.float32), 1.0, 1.0, stated_shape=(HUGE, HUGE))


def _datx_bomb(path):
    h5py = pytest.importorskip("h5py")
    from topofile_writers import write_datx

    write_datx(path, np.zeros((2, 2)), 1e-6, 1e-6)
    with h5py.File(path, "a") as h5:  # the surface replaced by an unwritten gzip dataset
        name = next(iter(h5["Data/Surface"]))
        attrs = dict(h5[f"Data/Surface/{name}"].attrs)
        del h5[f"Data/Surface/{name}"]
        ds = h5.create_dataset(f"Data/Surface/{name}", (HUGE, HUGE), "f4", chunks=(1000, 1000),
                               compression="gzip")
        for k, v in attrs.items():
            ds.attrs[k] = v


def _sflz_bomb(path, *, unpacks=False):
    surfalize = pytest.importorskip("surfalize")
    surfalize.Surface(np.arange(35.0).reshape(5, 7), 1.0, 1.0).save(path)
    data = bytearray(path.read_bytes())
    name = b"topography"
    at = data.index(name) + len(name) + 1  # is_height, then width, height (uint32)
    if unpacks:  # the layer's compressed data replaced by 64 MB of zeros, deflated
        import zlib

        size_at = at + 4 + 4 + 1 + 4 + 1 + 1 + 8 + 8
        (size,) = struct.unpack_from("<I", data, size_at)
        blob = zlib.compress(bytes(64 * 2**20), 9)
        data[size_at:size_at + 4 + size] = struct.pack("<I", len(blob)) + blob
    else:
        struct.pack_into("<II", data, at, HUGE, HUGE)
    path.write_bytes(bytes(data))


def _plu_bomb(path):
    from topofile_writers import write_plu

    write_plu(path, np.zeros((4, 4)), 1.0, 1.0)
    data = bytearray(path.read_bytes())
    struct.pack_into("<II", data, 500, HUGE, HUGE)
    path.write_bytes(bytes(data))


def _nms_bomb(path):
    data = bytearray((DATA / "nms-1.nms").read_bytes()[:4000])
    struct.pack_into("<2I", data, 1368, HUGE, HUGE)
    path.write_bytes(bytes(data))


def _sur_bomb(path):  # nx, ny (int32) at bytes 108, 112 of Digital Surf's 512-byte header
    data = bytearray((DATA / "sur-2.sur").read_bytes()[:4096])
    struct.pack_into("<iiI", data, 108, HUGE, HUGE, HUGE * HUGE % 2**32)
    path.write_bytes(bytes(data))


def _sdf_bomb(path):  # ISO 25178-71 ASCII: the grid in its header, then two numbers
    text = (DATA / "sdf-1.sdf").read_text()
    text = text.replace("NumPoints = 7", f"NumPoints = {HUGE}")
    text = text.replace("NumProfiles = 4", f"NumProfiles = {HUGE}")
    assert text.count(str(HUGE)) == 2
    path.write_text(text)


DECLARES = r"declares a grid of 20000 x 20000 = 400,000,000 points, more than the 268,435,456"


@pytest.mark.parametrize("suffix,write,match", [
    (".x3p", _x3p_bomb, DECLARES), (".plux", _plux_bomb, DECLARES),
    (".datx", _datx_bomb, DECLARES), (".sflz", _sflz_bomb, DECLARES),
    (".nms", _nms_bomb, DECLARES), (".sur", _sur_bomb, DECLARES + "|truncated"),
    (".sdf", _sdf_bomb, DECLARES + "|truncated"),
    # SurfaceTopography's .plu reader checks the declared grid against the file's size itself
    (".plu", _plu_bomb, r"cannot read it \(CorruptFile: .*truncated"),
])
def test_a_declared_huge_grid_is_refused_before_reading(tmp_path, suffix, write, match):
    import resource

    path = tmp_path / f"bomb{suffix}"
    write(path)
    assert path.stat().st_size < 2 * 2**20
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(InputError, match=rf"brdf\.file: .*bomb\{suffix}.*({match})"):
        read_topography(path, "brdf.file")
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before  # kB
    assert grown < 200 * 1024, f"{grown} kB taken to refuse it"


def test_a_zip_part_that_unpacks_huge_is_refused_before_reading(tmp_path):
    """The unpacked size the ZIP directory states (zipfile stops there) above the limit."""
    from topofile_writers import write_plux

    path = tmp_path / "bomb.plux"
    write_plux(path, np.zeros((3, 3), np.float32), 1.0, 1.0)
    data = bytearray(path.read_bytes())
    central = data.index(b"PK\x01\x02" + data[data.index(b"PK\x01\x02") + 4:][:0])
    while central >= 0:  # every central directory entry: uncompressed size at +24
        struct.pack_into("<I", data, central + 24, 0xF000_0000)
        central = data.find(b"PK\x01\x02", central + 4)
    path.write_bytes(bytes(data))
    assert 0xF000_0000 > MAX_UNPACKED_BYTES
    with pytest.raises(InputError, match=r"surface\.file: .*bomb\.plux.*unpacks to 3\.75 GB"):
        read_topography(path)


def test_an_x3p_part_that_unpacks_beyond_its_declared_grid_is_refused(tmp_path):
    """A 10 x 10 X3P whose data part the ZIP directory says unpacks to 1 GB (under the
    2 GB bound, far over what 100 heights fill): refused before x3pio reads it."""
    x3pio = pytest.importorskip("x3pio")
    path = tmp_path / "bomb.x3p"
    x3pio.write(path, np.zeros((10, 10)), x_scale=1e-6, y_scale=2e-6)
    data = bytearray(path.read_bytes())
    at = data.find(b"PK\x01\x02")
    patched = 0
    while at >= 0:
        (length,) = struct.unpack_from("<H", data, at + 28)
        if not data[at + 46:at + 46 + length].endswith(b"main.xml"):
            struct.pack_into("<I", data, at + 24, 2**30)
            patched += 1
        at = data.find(b"PK\x01\x02", at + 4)
    assert patched
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"bomb\.x3p \(X3P\): its part .* unpacks to "
                       r"1,073,741,824 bytes, more than the 10 x 10 heights main\.xml declares"):
        read_topography(path)


def test_an_sflz_layer_that_unpacks_beyond_its_grid_is_refused(tmp_path):
    path = tmp_path / "bomb.sflz"
    _sflz_bomb(path, unpacks=True)
    with pytest.raises(InputError, match=r"bomb\.sflz.*a layer of 7 x 5 declares .* unpacks to "
                       "more: garbled"):
        read_topography(path)


# --- not a file (issue 38, item 4) -----------------------------------------------------

def _loop(tmp_path):
    a, b = tmp_path / "a.x3p", tmp_path / "b.x3p"
    os.symlink(b, a)
    os.symlink(a, b)
    return a


@pytest.mark.parametrize("make,match", [
    (lambda p: (p / "scan.x3p").mkdir() or p / "scan.x3p",
     r"is a folder, not a file; name the measurement file inside it"),
    (lambda p: os.mkfifo(p / "pipe.sur") or p / "pipe.sur",
     r"is a named pipe \(FIFO\), not a file; save the measurement to a file"),
    (lambda p: Path("/dev/zero"), None),
    (_loop, r"is a symbolic link loop"),
    (lambda p: os.symlink(p / "gone.plu", p / "l.plu") or p / "l.plu",
     r"symbolic link to .*gone\.plu.*which does not exist"),
])
def test_not_a_file_gets_its_own_message(tmp_path, make, match):
    path = make(tmp_path)
    with pytest.raises(InputError) as info:
        read_topography(path, "brdf.file")
    msg = str(info.value)
    assert msg.startswith("brdf.file: ") and str(path) in msg and "not found" not in msg, msg
    if match is not None:
        assert __import__("re").search(match, msg), msg


def test_dev_zero_as_a_device_and_through_the_command_line(tmp_path):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    zero = tmp_path / "zero.npy"
    os.symlink("/dev/zero", zero)
    with pytest.raises(InputError, match=r"zero\.npy: is a character device, not a file"):
        read_topography(zero, spacing_mm=(1, 1))
    (tmp_path / "d.x3p").mkdir()
    res = CliRunner().invoke(app, ["texture", "--from", str(tmp_path / "d.x3p")])
    assert res.exit_code == 2 and "--from: " in res.output and "is a folder" in res.output
    assert "not found" not in res.output


def test_the_other_user_files_get_the_same_messages(tmp_path):
    """Every loader of config/files.py checks the path the same way, before opening it."""
    from pmdsim.config.files import read_response_lut

    os.mkfifo(tmp_path / "lut.csv")
    with pytest.raises(InputError, match=r"monitor\.response_lut: .*lut\.csv: is a named pipe"):
        read_response_lut(tmp_path / "lut.csv")  # would block if it were opened


def test_texture_report_says_how_many_nan_and_inf_points_it_filled(tmp_path):
    import json

    from typer.testing import CliRunner

    from pmdsim.cli import app

    y, x = np.mgrid[0:24, 0:32]
    h = 0.02 * np.sin(2 * np.pi * x / 8) + 0.003 * y
    h[3, 4], h[10, 20], h[0, 31] = np.nan, np.inf, -np.inf
    np.save(tmp_path / "h.npy", h)
    res = CliRunner().invoke(app, ["texture", "--from", str(tmp_path / "h.npy"), "--spacing-um",
                                   "1", "2", "--no-figure", "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert "filled 3 of 768 points (nearest): 3 not measured (NaN/inf" in res.output
    js = json.loads((tmp_path / "o" / "topography.json").read_text())
    assert js["invalid_points"] == js["not_measured_points"] == 3
    assert "filled 3 of 768" in (tmp_path / "o" / "topography.txt").read_text()
