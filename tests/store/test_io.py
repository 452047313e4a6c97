"""Image scaling, image files (TIFF, PNG) and atomic run folders (:mod:`pmdsim.io`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pmdsim.store.folder import atomic_run_dir, is_run_dir
from pmdsim.store.images import (IMAGE_SUFFIX, exposure_factor, read_image, to_integer_image,
                                 write_image)
from pmdsim.store.manifest import write_manifest



def test_exposure_factor_is_run_wide_and_ignores_nan():
    a = np.array([[1.0, np.nan], [2.0, 0.5]], np.float32)
    b = np.array([4.0, np.nan, -1.0])
    assert exposure_factor([a, b]) == pytest.approx(0.95 * 65535 / 4.0)
    assert exposure_factor([a], bit_depth=8, headroom=1.0) == pytest.approx(255 / 2.0)
    assert exposure_factor([np.full(3, np.nan), np.zeros(2)]) == 1.0
    assert exposure_factor([]) == 1.0
    with pytest.raises(ValueError, match="bit_depth"):
        exposure_factor([a], bit_depth=12)


def test_to_integer_image_rounds_clips_and_zeroes_nan():
    v = np.array([[np.nan, -1.0, 0.2, 0.7], [1.0, 2.0, np.inf, 0.5]])
    img = to_integer_image(v, exposure=100.0, bit_depth=8)
    assert img.dtype == np.uint8
    np.testing.assert_array_equal(img, [[0, 0, 20, 70], [100, 200, 0, 50]])
    img16 = to_integer_image(v, exposure=1e5, bit_depth=16)
    assert img16.dtype == np.uint16 and img16[1, 0] == 65535 and img16[0, 2] == 20000


def test_compiled_image_passes_match_numpy():
    """The compiled exposure peak and integer conversion against the NumPy expressions they
    replace (float32 and float64 camera values, NaN, +-inf, negatives, exact halves for
    rint's ties to even, values past full scale, a 2-D non-square image)."""
    rng = np.random.default_rng(22)
    for dtype in (np.float32, np.float64):
        v = (rng.uniform(-0.2, 1.3, (37, 53)) * 1000).astype(dtype)
        v[0, :6] = [np.nan, np.inf, -np.inf, 0.5, 1.5, 2.5]
        v[1, 0] = 70000.0
        finite = np.isfinite(v)
        peak = float(v[finite].max())
        assert exposure_factor([v], headroom=1.0) == 65535 / peak
        for exposure, depth in ((1.0, 16), (0.37, 8), (61.0, 16)):
            want = np.multiply(v, exposure, dtype=np.float64)
            want[~np.isfinite(want)] = 0.0
            want = np.rint(np.clip(want, 0.0, 2**depth - 1)).astype(
                np.uint16 if depth == 16 else np.uint8)
            got = to_integer_image(v, exposure, depth)
            assert got.dtype == want.dtype and got.shape == v.shape
            np.testing.assert_array_equal(got, want)
    # ties to even at the exposure 1: 0.5 -> 0, 1.5 -> 2, 2.5 -> 2
    assert to_integer_image(np.array([0.5, 1.5, 2.5]), 1.0).tolist() == [0, 2, 2]
    # integer values and non-contiguous views convert as floats do
    ints = np.arange(12).reshape(3, 4)
    np.testing.assert_array_equal(to_integer_image(ints[:, ::2], 2.0, 8), ints[:, ::2] * 2)
    assert exposure_factor([ints]) == 0.95 * 65535 / 11


def test_lit_images_stop_at_the_first_positive_value():
    """The rendered-images check (any value > 0, NaN never) against numpy.any, and the
    run's error for black fringes (float32 stacks of the render's shape, a last-pixel light)."""
    from pmdsim.config import ConfigError
    from pmdsim.kernels.images import any_positive
    from pmdsim.studies.coverage import check_rendered

    for a in (np.full(7, np.nan), np.zeros(5), -np.ones(3), np.array([np.nan, -1.0, 0.0, 2e-45]),
              np.array([0.0, np.inf]), np.array([-np.inf, np.nan])):
        for dtype in (np.float32, np.float64):
            b = a.astype(dtype)
            assert any_positive(b) == bool(np.any(b > 0))
    black = np.zeros((2, 3, 4, 5, 6), np.float32)
    black[0, 0, 0, 0, :2] = np.nan
    with pytest.raises(ConfigError, match="every fringe image is black"):
        check_rendered(black)
    black[1, 2, 3, 4, 5] = 1e-6
    check_rendered(black)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("fmt", ["tiff", "png"])
def test_image_files_round_trip(tmp_path, fmt, dtype):
    rng = np.random.default_rng(1)
    img = rng.integers(0, np.iinfo(dtype).max, size=(7, 11), endpoint=True).astype(dtype)
    path = write_image(tmp_path / f"sub/img{IMAGE_SUFFIX[fmt]}", img, fmt,
                           {"exposure": 2.5})
    back = read_image(path)
    assert back.dtype == dtype
    np.testing.assert_array_equal(back, img)


def test_png_is_readable_by_pillow(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    img = (np.arange(12 * 5, dtype=np.uint16).reshape(5, 12) * 1000).astype(np.uint16)
    path = write_image(tmp_path / "a.png", img, "png")
    with Image.open(path) as im:
        assert im.size == (12, 5)
        np.testing.assert_array_equal(np.asarray(im).astype(np.uint16), img)
    img8 = img.astype(np.uint8)
    with Image.open(write_image(tmp_path / "b.png", img8, "png")) as im:
        assert im.mode == "L"
        np.testing.assert_array_equal(np.asarray(im), img8)


def test_write_image_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="image_format"):
        write_image(tmp_path / "x.bmp", np.zeros((2, 2), np.uint8), "bmp")
    with pytest.raises(ValueError, match="uint8/uint16"):
        write_image(tmp_path / "x.png", np.zeros((2, 2), np.float32), "png")


def _finish(folder):
    (folder / "data.txt").write_text("payload")
    write_manifest(folder, {"ok": True})


def test_atomic_run_dir_success(tmp_path):
    out = tmp_path / "run"
    with atomic_run_dir(out) as tmp:
        assert tmp.name.startswith("run.tmp-") and tmp.parent == out.parent
        assert not out.exists()
        _finish(tmp)
    assert is_run_dir(out) and (out / "data.txt").read_text() == "payload"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_atomic_run_dir_failure_removes_temp(tmp_path):
    out = tmp_path / "nested" / "run"
    with pytest.raises(KeyError):
        with atomic_run_dir(out) as tmp:
            _finish(tmp)
            raise KeyError("boom")
    assert not out.exists() and list(out.parent.iterdir()) == []


def test_atomic_run_dir_overwrite_rules(tmp_path):
    out = tmp_path / "run"
    with atomic_run_dir(out) as tmp:
        _finish(tmp)
    with pytest.raises(FileExistsError, match="--overwrite"):
        with atomic_run_dir(out):
            pytest.fail("must not start")
    with atomic_run_dir(out, overwrite=True) as tmp:
        (tmp / "new.txt").write_text("second")
        write_manifest(tmp, {"ok": 2})
    assert (out / "new.txt").exists() and not (out / "data.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]

    # An empty folder may be replaced; a non-run folder or a file never.
    empty = tmp_path / "empty"
    empty.mkdir()
    with atomic_run_dir(empty, overwrite=True) as tmp:
        _finish(tmp)
    assert is_run_dir(empty)
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("keep")
    with pytest.raises(FileExistsError, match="not a pmdsim run folder"):
        with atomic_run_dir(other, overwrite=True):
            pass
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(FileExistsError, match="not a folder"):
        with atomic_run_dir(afile, overwrite=True):
            pass
    assert (other / "keep.txt").exists() and afile.read_text() == "x"


def test_float32_parts_of_complex_sums_match_numpy():
    """The dataset's float32 real and imaginary parts of the complex sums (one compiled
    pass) against NumPy's astype: rounding to nearest, NaN, inf, subnormal and overflowing
    values, a (2, 3, H, W) stack with H != W; complex64 takes NumPy's own path."""
    from pmdsim.store.schema import complex_parts_float32

    rng = np.random.default_rng(12)
    z = (rng.normal(size=(2, 3, 5, 7)) * 10.0 ** rng.uniform(-50, 50, (2, 3, 5, 7))
         + 1j * rng.normal(size=(2, 3, 5, 7)) * 10.0 ** rng.uniform(-50, 50, (2, 3, 5, 7)))
    z[0, 0, 0, :3] = [np.nan, complex(np.inf, -np.inf), complex(1e-46, 3e39)]
    re, im = complex_parts_float32(z)
    with np.errstate(over="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "overflow encountered in cast"
        want_re, want_im = z.real.astype(np.float32), z.imag.astype(np.float32)
        z64 = z.astype(np.complex64)
    assert re.dtype == im.dtype == np.float32 and re.shape == z.shape
    np.testing.assert_array_equal(re, want_re)
    np.testing.assert_array_equal(im, want_im)
    re64, _ = complex_parts_float32(z64)
    np.testing.assert_array_equal(re64, z64.real)
