"""The user's own files (pmdsim.config.files): every malformed file is a field-named error
that names the file and what is wrong, never a traceback; valid files read back exactly
what NumPy wrote (the independent reference: numpy.save / numpy.savetxt / tifffile)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from typer.testing import CliRunner

from conftest import base_dict, merge
from pmdsim.config import ConfigError, InputError
from pmdsim.config.files import (FileInputError, MissingFileError, read_flatness_map,
                                 read_height_map, read_response_lut, read_slope_table, read_variation_map,
                                 register_height_map_reader,
                                 HEIGHT_MAP_READERS)


FIELD = "some.field"
HYP = settings(max_examples=60, deadline=None, derandomize=True,
               suppress_health_check=[HealthCheck.function_scoped_fixture,
                                      HealthCheck.too_slow])


def _named(err: Exception, path, field: str = FIELD) -> None:
    msg = str(err)
    assert msg.startswith(field + ":"), msg
    assert str(path) in msg, msg
    assert isinstance(err, InputError) and isinstance(err, ConfigError)


# ----------------------------------------------------------------------------- the LUT
LUT_CASES = {
    "semicolons": ("0;0.1\n0.5;0.3\n1;1\n", None),  # valid: read as a table
    "header_only": ("drive,luminance\n", "no rows of numbers"),
    "one_row": ("0,1\n", "at least 2 rows"),
    "one_column": ("0\n0.5\n1\n", "2 columns"),
    "decreasing_drive": ("0,0\n1,0.5\n0.5,1\n", "drive must increase"),
    "decreasing_luminance": ("0,0\n0.5,0.7\n1,0.5\n", "must not decrease"),
    "bad_row": ("drive,lum\n0,0\n0.5,abc\n1,1\n", "line 3 is not a row of numbers"),
    "ragged": ("0,0\n0.5\n1,1\n", "different lengths"),
    "nan": ("0,0\n0.5,nan\n1,1\n", "non-finite"),
    "inf": ("0,0\n0.5,inf\n1,1\n", "non-finite"),
    "constant": ("0,0.5\n0.5,0.5\n1,0.5\n", "constant"),
    "negative_drive": ("-1,0\n0.5,0.5\n1,1\n", ">= 0"),
}


@pytest.mark.parametrize("name", list(LUT_CASES))
def test_lut_cases(tmp_path, name):
    text, problem = LUT_CASES[name]
    path = tmp_path / f"{name}.csv"
    path.write_text(text)
    if problem is None:
        d, lum = read_response_lut(path, FIELD)
        np.testing.assert_allclose(d, [0, 0.5, 1])
        np.testing.assert_allclose(lum, [0, 0.2 / 0.9, 1])
        return
    with pytest.raises(FileInputError, match=problem) as info:
        read_response_lut(path, FIELD)
    _named(info.value, path)


def test_missing_binary_and_empty_files_name_the_field(tmp_path):
    with pytest.raises(MissingFileError, match="file not found") as info:
        read_response_lut(tmp_path / "nope.csv", FIELD)
    _named(info.value, tmp_path / "nope.csv")
    assert isinstance(info.value, FileNotFoundError)
    binary = tmp_path / "lut.csv"
    binary.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(FileInputError, match="binary") as info:
        read_response_lut(binary, FIELD)
    empty = tmp_path / "e.npy"
    empty.write_bytes(b"")
    with pytest.raises(FileInputError, match="empty") as info:
        read_height_map(empty, FIELD)
    _named(info.value, empty)
    with pytest.raises(FileInputError, match="not a file"):
        read_height_map(tmp_path, FIELD)


def test_a_lut_reads_back_the_table_that_was_written(tmp_path):
    """Drive in 0..255 with a header and a comment: scaled to [0, 1], luminance to [0, 1]."""
    drive = np.array([0.0, 17.0, 80.0, 255.0])
    lum = np.array([0.3, 0.9, 10.0, 200.3])
    path = tmp_path / "lut.csv"
    np.savetxt(path, np.c_[drive, lum], delimiter=",", header="drive,luminance")
    d, r = read_response_lut(path, FIELD)
    np.testing.assert_allclose(d, drive / 255.0)
    np.testing.assert_allclose(r, (lum - 0.3) / 200.0)


# ----------------------------------------------------------------------------- grids
def _npy_bytes(a) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=True)
    return buf.getvalue()


GRID_CASES = {
    "nan.npy": (lambda: _npy_bytes(np.array([[1.0, np.nan, 2, 3]] * 4)), "non-finite"),
    "one.npy": (lambda: _npy_bytes(np.ones((1, 1))), "at least"),
    "cube.npy": (lambda: _npy_bytes(np.ones((3, 4, 5))), "2-D"),
    "truncated.npy": (lambda: _npy_bytes(np.ones((8, 8)))[:100], "truncated"),
    "garbage.npy": (lambda: b"not an npy file at all" * 10, "npy"),
    "object.npy": (lambda: _npy_bytes(np.array([[1, "a"], [2, None]], dtype=object)), "Python objects"),
    "structured.npy": (lambda: _npy_bytes(np.zeros((5, 5), dtype=[("a", "f8"), ("b", "i4")])), "plain float"),
    "complex.npy": (lambda: _npy_bytes(np.ones((5, 5)) * (1 + 2j)), "complex"),
    "text.csv": (lambda: b"1,2,3\n4,five,6\n7,8,9\n", "line 2"),
    "ragged.csv": (lambda: b"1,2,3\n4,5\n7,8,9\n", "different lengths"),
    "binary.csv": (lambda: bytes(range(256)), "binary"),
    "int.tif": (None, "float"),
    "truncated.tif": (None, "TIFF"),
    "heights.xyz": (lambda: b"1 2 3\n", "unknown format"),
}


def _write_case(tmp_path, name):
    make, problem = GRID_CASES[name]
    path = tmp_path / name
    if name == "int.tif":
        import tifffile

        tifffile.imwrite(path, np.arange(64, dtype=np.uint16).reshape(8, 8))
    elif name == "truncated.tif":
        import tifffile

        tifffile.imwrite(tmp_path / "full.tif", np.ones((64, 64), np.float32))
        path.write_bytes((tmp_path / "full.tif").read_bytes()[:2000])
    else:
        path.write_bytes(make())
    return path, problem


@pytest.mark.parametrize("name", list(GRID_CASES))
@pytest.mark.parametrize("reader", [read_height_map, read_flatness_map])
def test_bad_grids_name_the_field_the_file_and_the_problem(tmp_path, name, reader):
    path, problem = _write_case(tmp_path, name)
    if reader is read_flatness_map and name == "one.npy":
        problem = "at least 2 x 2"
    with pytest.raises(FileInputError, match=problem) as info:
        reader(path, FIELD)
    _named(info.value, path)


def test_grids_read_back_what_numpy_and_tifffile_wrote(tmp_path):
    """dx != dy shaped grid (5 rows, 7 columns): no transposition in any format."""
    import tifffile

    z = np.arange(35, dtype=np.float64).reshape(5, 7) * 0.25 - 3.0
    np.save(tmp_path / "z.npy", z)
    np.savetxt(tmp_path / "z.csv", z, delimiter=",", header="heights")
    np.savetxt(tmp_path / "z.txt", z)
    tifffile.imwrite(tmp_path / "z.tif", z.astype(np.float32))
    for name in ("z.npy", "z.csv", "z.txt", "z.tif"):
        np.testing.assert_array_equal(read_height_map(tmp_path / name, FIELD), z)


def test_a_registered_reader_plugs_in_and_its_failures_are_named(tmp_path):
    def reader(path, field):
        text = path.read_text()
        if text.startswith("bad"):
            raise RuntimeError("instrument file broken")
        return np.full((4, 6), float(text))

    register_height_map_reader(".fake", reader)
    try:
        (tmp_path / "a.fake").write_text("2.5")
        assert read_height_map(tmp_path / "a.fake", FIELD).shape == (4, 6)
        (tmp_path / "b.fake").write_text("bad")
        with pytest.raises(FileInputError, match="instrument file broken") as info:
            read_height_map(tmp_path / "b.fake", FIELD)
        _named(info.value, tmp_path / "b.fake")
    finally:
        HEIGHT_MAP_READERS.pop(".fake")


# ----------------------------------------------------------------------------- BRDF maps
def test_variation_maps(tmp_path):
    a = np.linspace(0.01, 0.05, 12).reshape(3, 4)
    np.savez(tmp_path / "ok.npz", alpha_radial=a, rho_s_scale=np.ones((3, 4)))
    got = read_variation_map(tmp_path / "ok.npz", None, FIELD)
    np.testing.assert_array_equal(got["alpha_radial"], a)
    (tmp_path / "corrupt.npz").write_bytes((tmp_path / "ok.npz").read_bytes()[:150])
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 junk" * 20)
    np.savez(tmp_path / "shapes.npz", alpha_radial=a, rho_s_scale=np.ones((4, 3)))
    np.savez(tmp_path / "other.npz", heights=a)
    np.savez(tmp_path / "big.npz", alpha_radial=a * 100)
    np.savez(tmp_path / "obj.npz", alpha_radial=np.array([[1, None], [2, 3]], dtype=object))
    for name, problem in (("corrupt.npz", "npz"), ("junk.npz", "npz"),
                          ("shapes.npz", "differ in shape"), ("other.npz", "none of the arrays"),
                          ("big.npz", "<= 2"), ("obj.npz", "objects")):
        with pytest.raises(FileInputError, match=problem) as info:
            read_variation_map(tmp_path / name, None, FIELD)
        _named(info.value, tmp_path / name)
    np.save(tmp_path / "one.npy", a)
    with pytest.raises(FileInputError, match="quantity"):
        read_variation_map(tmp_path / "one.npy", None, FIELD)
    np.testing.assert_array_equal(
        read_variation_map(tmp_path / "one.npy", "alpha_tangential", FIELD)["alpha_tangential"], a)


# ----------------------------------------------------------------------------- properties
LOADERS = {
    "lut.csv": lambda p: read_response_lut(p, FIELD),
    "flat.csv": lambda p: read_flatness_map(p, FIELD),
    "flat.npy": lambda p: read_flatness_map(p, FIELD),
    "height.npy": lambda p: read_height_map(p, FIELD),
    "height.csv": lambda p: read_height_map(p, FIELD),
    "height.tif": lambda p: read_height_map(p, FIELD),
    "brdf.npz": lambda p: read_variation_map(p, None, FIELD),
    "brdf.npy": lambda p: read_variation_map(p, "rho_s_scale", FIELD),
    "slopes.npz": lambda p: read_slope_table(p, FIELD),
}

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                    st.sampled_from([0.0, -0.0, 1e308, -1e308, 5e-324, math.nan]))
cells = st.one_of(numbers.map(repr), st.text(max_size=6), st.sampled_from(["", " ", "#", "1e999"]))
rows = st.lists(st.lists(cells, max_size=5), max_size=8)
separators = st.sampled_from([",", ";", "\t", " ", ", "])
arrays = hnp.arrays(
    dtype=st.sampled_from([np.float64, np.float32, np.int16, np.uint8, np.complex64, np.bool_,
                           np.dtype("U3"), np.dtype([("a", "f4"), ("b", "i2")])]),
    shape=hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=6))


def _bytes_of(kind: str, data) -> bytes:
    import io

    if kind == "text":
        rows_, sep = data
        return "\n".join(sep.join(r) for r in rows_).encode()
    if kind == "raw":
        return data
    if kind == "npy":
        return _npy_bytes(data)
    if kind == "npz":
        buf = io.BytesIO()
        np.savez(buf, alpha_radial=data, rho_s_scale=data)
        return buf.getvalue()
    import tifffile  # "tif"

    buf = io.BytesIO()
    tifffile.imwrite(buf, data)
    return buf.getvalue()


files_ = st.one_of(
    st.tuples(st.just("text"), st.tuples(rows, separators)),
    st.tuples(st.just("raw"), st.binary(max_size=300)),
    st.tuples(st.just("npy"), arrays),
    st.tuples(st.just("npz"), arrays),
    st.tuples(st.just("tif"), hnp.arrays(st.sampled_from([np.float32, np.float64, np.uint16]),
                                         hnp.array_shapes(min_dims=2, max_dims=3, max_side=6))),
)


@pytest.mark.parametrize("target", list(LOADERS))
@HYP
@given(case=files_, cut=st.one_of(st.none(), st.integers(0, 400)))
def test_any_file_gives_a_valid_result_or_a_field_named_error(tmp_path, target, case, cut):
    """Malformed files, extreme and non-finite values, wrong shapes and dtypes, truncated
    at any byte: either a finite grid/table of the promised shape or a FileInputError
    naming the field and the file; no other exception."""
    kind, data = case
    try:
        raw = _bytes_of(kind, data)
    except (ValueError, TypeError, struct.error):
        return  # the writer itself refuses: nothing to read
    if cut is not None:
        raw = raw[:cut]
    path = tmp_path / target
    path.write_bytes(raw)
    try:
        out = LOADERS[target](path)
    except FileInputError as err:
        _named(err, path)
        return
    grids = out.values() if isinstance(out, dict) else (out if isinstance(out, tuple) else [out])
    for g in grids:
        assert isinstance(g, np.ndarray) and g.dtype == np.float64 and np.isfinite(g).all()
        assert g.ndim in (1, 2)


# ----------------------------------------------------------------------------- the CLI
def toml_text(data: dict, prefix: str = "") -> str:
    """TOML of a nested mapping (values as JSON, which TOML reads for these types)."""
    import json

    plain = [f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict)]
    out = ([f"[{prefix}]"] if prefix and plain else []) + plain
    for k, v in data.items():
        if isinstance(v, dict):
            out.append(toml_text(v, f"{prefix}.{k}" if prefix else k))
    return "\n".join(out) + "\n"


def write_config(tmp_path, changes) -> str:
    path = tmp_path / "run.toml"
    path.write_text(toml_text(merge(base_dict(), changes)))
    return str(path)


CLI_CASES = {
    "lut_missing": ({"monitor": {"response_lut": "missing.csv"}}, None, "monitor.response_lut"),
    "lut_header_only": ({"monitor": {"response_lut": "lut.csv"}}, ("lut.csv", b"drive,lum\n"),
                        "monitor.response_lut"),
    "lut_binary": ({"monitor": {"response_lut": "lut.csv"}}, ("lut.csv", bytes(range(256))),
                   "monitor.response_lut"),
    "flatness_nan": ({"monitor": {"flatness_map": "f.npy"}},
                     ("f.npy", "nan"), "monitor.flatness_map"),
    "flatness_tif": ({"monitor": {"flatness_map": "f.tif"}}, ("f.tif", b"II*\x00garbage"),
                     "monitor.flatness_map"),
    "height_zero_bytes": ({"surface": {"__replace__": {"type": "height_map", "file": "h.npy",
                                                        "spacing_mm": [1.0, 1.0]}}},
                          ("h.npy", b""), "surface.file"),
    "height_header_csv": ({"surface": {"__replace__": {"type": "height_map", "file": "h.csv",
                                                        "spacing_mm": [1.0, 1.0]}}},
                          ("h.csv", b"x,y,z\n1,2\n"), "surface.file"),
    "variation_corrupt": ({"brdf": {"variation": {"file": "v.npz", "spacing_mm": [1.0, 1.0]}}},
                          ("v.npz", b"PK\x03\x04" + b"\x00" * 40), "brdf.variation.file"),
}


@pytest.mark.parametrize("name", list(CLI_CASES))
def test_bad_user_files_are_exit_2_naming_field_and_file(tmp_path, name):
    changes, content, field = CLI_CASES[name]
    if content is not None:
        fname, data = content
        if data == "nan":
            np.save(tmp_path / fname, np.array([[0.0, np.nan], [0.0, 0.0]]))
        else:
            (tmp_path / fname).write_bytes(data)
    cfg = write_config(tmp_path, changes)
    out = tmp_path / "out"
    result = CliRunner().invoke(app_(), ["simulate", cfg, "-o", str(out)])
    assert result.exit_code == 2, result.output
    assert field in result.output and "Traceback" not in result.output
    assert not out.exists()


def app_():
    from pmdsim.cli import app

    return app


def test_slope_tables(tmp_path):
    counts = np.arange(12.0).reshape(3, 4)
    ex, ey = np.linspace(-0.1, 0.1, 4), np.linspace(-0.2, 0.3, 5)
    np.savez(tmp_path / "ok.npz", counts=counts, edges_x=ex, edges_y=ey)
    got = read_slope_table(tmp_path / "ok.npz", FIELD)
    np.testing.assert_array_equal(got["counts"], counts)
    np.testing.assert_array_equal(got["edges_y"], ey)
    np.savez(tmp_path / "swapped.npz", counts=counts, edges_x=ey, edges_y=ex)
    np.savez(tmp_path / "neg.npz", counts=-counts, edges_x=ex, edges_y=ey)
    np.savez(tmp_path / "order.npz", counts=counts, edges_x=ex[::-1], edges_y=ey)
    np.savez(tmp_path / "noedges.npz", counts=counts)
    (tmp_path / "trunc.npz").write_bytes((tmp_path / "ok.npz").read_bytes()[:200])
    for name, problem in (("swapped.npz", "edges_x must hold 4"), ("neg.npz", ">= 0"),
                          ("order.npz", "increase"), ("noedges.npz", "edges_x"),
                          ("trunc.npz", "npz")):
        with pytest.raises(FileInputError, match=problem) as info:
            read_slope_table(tmp_path / name, FIELD)
        _named(info.value, tmp_path / name)
