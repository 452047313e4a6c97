"""Tests of pmdsim.decode: physics of phase shifting and unwrapping, flags, kernels vs NumPy."""

from __future__ import annotations

import numpy as np
import pytest

import naive_decode as naive
from pmdsim.measure import decode as dec
from pmdsim.measure.decode_plan import unambiguous_range_px
from pmdsim.measure.images import load_image_stack
from pmdsim.kernels import decode as kd

EXTENT = 1920
WIDTHS = {
    "hierarchical": [400, 3200, 50],  # deliberately unsorted
    "heterodyne": [54, 48, 60],  # beats 432, 540 -> 2160 >= 1920
    "number_theoretic": [128, 96, 160],  # g = 32, 4:3:5, lcm 1920
}
F = dec.DecodeFlag


def pattern(u, width, n_shifts, black=0.0, white=1.0, gamma=1.0, phase_error=0.0):
    """Frames (K, ...) of the conventions' fringe at monitor coordinates u (monitor px)."""
    delta = 2 * np.pi * np.arange(n_shifts) / n_shifts
    delta = delta.reshape((-1,) + (1,) * np.ndim(u))
    s = 0.5 + 0.5 * np.cos(2 * np.pi * np.asarray(u) / width + phase_error + delta)
    return black + (white - black) * s**gamma


def sequence(u, widths, n_shifts, **kw):
    """Frames (n_widths, K, ...) for the widths at monitor coordinates u."""
    return np.stack([pattern(u, w, n_shifts, **kw) for w in widths])


def monitor_row(rows=2, extent=EXTENT):
    """(rows, extent) monitor coordinates: every monitor pixel centre, as a camera would see."""
    return np.broadcast_to(np.arange(extent, dtype=np.float64), (rows, extent)).copy()


def wrap(phi):
    return np.angle(np.exp(1j * phi))


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("method", list(WIDTHS))
@pytest.mark.parametrize("n_shifts", [3, 4, 8])
def test_round_trip_recovers_phase_and_monitor_coordinate(method, n_shifts):
    widths = WIDTHS[method]
    u = monitor_row()
    frames = sequence(u, widths, n_shifts, black=0.1, white=0.9)
    res = dec.decode_sequence(frames, widths, n_shifts, EXTENT, method)
    for j, w in enumerate(widths):
        err = wrap(res.wrapped_phase[j] - 2 * np.pi * u / w)
        assert np.abs(err).max() < 1e-9
        assert np.all((res.wrapped_phase[j] > -np.pi) & (res.wrapped_phase[j] <= np.pi))
    w_fine = min(widths)
    assert res.finest_width_px == w_fine
    assert np.abs(res.absolute_phase - 2 * np.pi * u / w_fine).max() < 1e-9
    assert np.abs(res.monitor_coord_px - u).max() < 1e-6
    assert res.valid.all() and not res.flags.any()
    assert res.order_residual.max() < 1e-9
    np.testing.assert_allclose(
        dec.phase_to_monitor_px(res.absolute_phase, w_fine), res.monitor_coord_px, atol=1e-9
    )


def test_shifts_as_angles():
    u = monitor_row()
    widths = [50, 400, 3200]
    frames = sequence(u, widths, 5)
    res = dec.decode_sequence(frames, widths, 2 * np.pi * np.arange(5) / 5, EXTENT)
    assert np.abs(res.monitor_coord_px - u).max() < 1e-6


def test_vertical_direction_is_the_same_maths():
    """Direction y: phase runs along v (the rows); decoding does not care."""
    v = monitor_row(rows=3, extent=1080).T  # (1080, 3): v down the image
    widths = [40, 270, 1080]
    res = dec.decode_sequence(sequence(v, widths, 4), widths, 4, 1080)
    assert np.abs(res.monitor_coord_px - v).max() < 1e-6
    assert res.valid.all()


def test_sign_convention_cos_phi_plus_delta_decodes_to_plus_phi():
    phi = np.array([[0.7, -2.0, 3.0]])
    delta = 2 * np.pi * np.arange(5) / 5
    plus = 1.0 + 0.5 * np.cos(phi[None] + delta[:, None, None])
    minus = 1.0 + 0.5 * np.cos(phi[None] - delta[:, None, None])
    np.testing.assert_allclose(dec.phase_shift(plus).wrapped_phase, phi, atol=1e-12)
    np.testing.assert_allclose(dec.phase_shift(minus).wrapped_phase, -phi, atol=1e-12)
    # and the monitor coordinate increases with u
    u = np.array([[10.0, 20.0]])
    res = dec.decode_sequence(sequence(u, [50, 400, 3200], 4), [50, 400, 3200], 4, EXTENT)
    np.testing.assert_allclose(res.monitor_coord_px, u, atol=1e-9)


def test_phase_range_is_half_open_at_minus_pi():
    """phi = pi decodes to +pi (never -pi)."""
    delta = 2 * np.pi * np.arange(4) / 4
    frames = (1.0 + np.cos(np.pi + delta))[:, None, None]
    assert dec.phase_shift(frames).wrapped_phase[0, 0] == pytest.approx(np.pi, abs=1e-15)
    assert dec.phase_shift(frames).wrapped_phase[0, 0] > 0


def test_amplitude_offset_modulation_recovered():
    rng = np.random.default_rng(1)
    shape = (6, 7)
    a = rng.uniform(0.3, 2.0, shape)
    b = rng.uniform(0.05, 0.3, shape)
    phi = rng.uniform(-np.pi, np.pi, shape)
    delta = 2 * np.pi * np.arange(6) / 6
    frames = a + b * np.cos(phi + delta[:, None, None])
    res = dec.phase_shift(frames)
    np.testing.assert_allclose(res.amplitude, b, rtol=1e-12)
    np.testing.assert_allclose(res.offset, a, rtol=1e-12)
    np.testing.assert_allclose(res.modulation, b / a, rtol=1e-12)
    np.testing.assert_allclose(res.wrapped_phase, phi, atol=1e-12)
    assert res.valid.all()


def test_float32_frames_and_output():
    u = monitor_row()
    widths = [50, 400, 3200]
    frames = sequence(u, widths, 4, black=0.1, white=0.9).astype(np.float32)
    res = dec.decode_sequence(frames, widths, 4, EXTENT, dtype=np.float32)
    assert res.wrapped_phase.dtype == np.float32 and res.amplitude.dtype == np.float32
    assert res.absolute_phase.dtype == np.float64 and res.monitor_coord_px.dtype == np.float64
    assert np.abs(res.monitor_coord_px - u).max() < 1e-3  # float32 frames: ~1e-7 relative
    assert res.valid.all()
    # integer camera counts are accepted too
    counts = np.round(frames * 4000).astype(np.uint16)
    res16 = dec.decode_sequence(counts, widths, 4, EXTENT)
    assert np.abs(res16.monitor_coord_px - u).max() < 0.05


def test_inputs_are_not_modified():
    rng = np.random.default_rng(2)
    frames = rng.uniform(0, 1, (3, 4, 3, 5))
    frames[0, 1, 1, 1] = np.nan
    before = frames.copy()
    dec.decode_sequence(frames, [50, 400, 3200], 4, EXTENT)
    dec.phase_shift(frames[0])
    phases = rng.uniform(-np.pi, np.pi, (3, 3, 5))
    phases_before = phases.copy()
    dec.unwrap_phase(phases, [50, 400, 3200], EXTENT, amplitude=frames[:, 0])
    np.testing.assert_array_equal(frames, before)
    np.testing.assert_array_equal(phases, phases_before)


# --------------------------------------------------------------------------- noise and gamma


@pytest.mark.parametrize("n_shifts", [4, 8])
def test_phase_noise_matches_sqrt_2_over_k_sigma_over_b(n_shifts):
    rng = np.random.default_rng(12345)
    sigma, a, b = 0.01, 0.5, 0.4
    phi = rng.uniform(-np.pi, np.pi, (100, 1000))
    delta = 2 * np.pi * np.arange(n_shifts) / n_shifts
    frames = a + b * np.cos(phi + delta[:, None, None])
    frames += rng.normal(0.0, sigma, frames.shape)
    res = dec.phase_shift(frames)
    std = wrap(res.wrapped_phase - phi).std()
    expected = np.sqrt(2.0 / n_shifts) * sigma / b
    assert std == pytest.approx(expected, rel=0.1)


def test_gamma_harmonics_alias_more_with_four_than_five_shifts():
    """Gamma 2.2 harmonics m = qK +- 1 alias: K = 4 errs ~10 mrad, K = 5 ~1 mrad. The
    largest error over the 50 phases equals the one derived from the profile's Fourier
    series (``naive_decode.gamma_phase_error``), not a window copied from a run."""
    u = np.arange(400.0)[None]
    errors = {}
    for n_shifts in (4, 5):
        frames = pattern(u, 50, n_shifts, black=0.05, white=0.95, gamma=2.2)
        res = dec.phase_shift(frames)
        errors[n_shifts] = np.abs(wrap(res.wrapped_phase - 2 * np.pi * u / 50)).max()
        derived = np.abs(naive.gamma_phase_error(2 * np.pi * np.arange(50) / 50, 2.2, n_shifts))
        assert errors[n_shifts] == pytest.approx(derived.max(), abs=1e-9)
    assert errors[4] > 5 * errors[5]
    assert 3e-3 < errors[4] < 3e-2
    assert errors[5] < 3e-3


# --------------------------------------------------------------------------- flags


@pytest.mark.parametrize("method", list(WIDTHS))
def test_wrong_orders_are_always_flagged(method):
    """Inject a coarse phase error of up to 0.7 orders (uniform): every wrong order (error
    > 0.5) has a residual >= 0.3 and must be flagged; every unflagged pixel must be exact."""
    widths = WIDTHS[method]
    rng = np.random.default_rng(7)
    u = monitor_row(rows=20)
    phases = np.stack([wrap(2 * np.pi * u / w) for w in widths])
    w_sorted = sorted(widths)
    if method == "hierarchical":
        # error e (in orders of the finest width) on the next coarser width's phase
        j = widths.index(w_sorted[1])
        e = rng.uniform(-0.7, 0.7, u.shape)
        phases[j] = wrap(phases[j] + 2 * np.pi * e * w_sorted[0] / w_sorted[1])
    else:
        # error on the widest measured phase (60 or 160 px); it enters the order of its step
        # multiplied by 5 (beat ratio 2160/432, or 160/32 for number-theoretic)
        j = widths.index(w_sorted[-1])
        e = rng.uniform(-0.7, 0.7, u.shape)
        phases[j] = wrap(phases[j] + 2 * np.pi * e / 5)
    res = dec.unwrap_phase(phases, widths, EXTENT, method)
    wrong = np.abs(res.monitor_coord_px - u) > 1e-6
    flagged = (res.flags & F.ORDER_RESIDUAL) != 0
    assert wrong.sum() > 50  # the injection really produced wrong orders
    assert np.all(flagged[wrong])
    assert np.abs(res.monitor_coord_px - u)[~flagged].max() < 1e-6


@pytest.mark.parametrize("method", ["hierarchical", "heterodyne"])
def test_noisy_frames_wrong_orders_flagged(method):
    """Gaussian camera noise strong enough to break some orders: none slips through unflagged."""
    widths = WIDTHS[method]
    rng = np.random.default_rng(99)
    u = monitor_row(rows=20)
    sigma = {"hierarchical": 0.065, "heterodyne": 0.05}[method]
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    frames += rng.normal(0, sigma, frames.shape)
    res = dec.decode_sequence(frames, widths, 4, EXTENT, method)
    wrong = np.abs(res.monitor_coord_px - u) > min(widths) / 2
    assert wrong.sum() > 30  # the noise really breaks orders
    assert np.all(res.flags[wrong] & F.ORDER_RESIDUAL)
    assert not np.any(wrong & res.valid)


@pytest.mark.parametrize(
    "method, reversed_width",
    [("hierarchical", 50), ("number_theoretic", 96), ("heterodyne", 54), ("heterodyne", 60)],
)
def test_contrast_reversal_of_narrow_fringes_is_flagged(method, reversed_width):
    """Scattering can reverse the contrast (phase pi) of narrow fringes: the order becomes
    ambiguous (residual ~0.5) and must be flagged, not silently shifted."""
    widths = WIDTHS[method]
    u = monitor_row(rows=4)
    j = widths.index(reversed_width)
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    frames[j, :, 1:3, 500:900] = pattern(
        u[1:3, 500:900], reversed_width, 4, black=0.1, white=0.9, phase_error=np.pi
    )
    res = dec.decode_sequence(frames, widths, 4, EXTENT, method)
    block = np.zeros(u.shape, bool)
    block[1:3, 500:900] = True
    assert np.all(res.flags[block] & F.ORDER_RESIDUAL)
    assert res.valid[~block].all()


def test_heterodyne_contrast_reversal_of_finest_width_is_an_exact_alias():
    """Known limit (documented): for [48, 54, 60] a phase pi on the 48 px fringes is exactly
    the pattern at u + 1080 (= 22.5 * 48 = 20 * 54 = 18 * 60); no method can see it. It is
    flagged only where u + 1080 (mod 2160) is off the monitor."""
    widths = WIDTHS["heterodyne"]
    u = monitor_row(rows=1)
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    frames[widths.index(48)] = pattern(u, 48, 4, black=0.1, white=0.9, phase_error=np.pi)
    res = dec.decode_sequence(frames, widths, 4, EXTENT, "heterodyne")
    alias = np.mod(u + 1080 + 120.5, 2160) - 120.5  # wrapped into the window
    np.testing.assert_allclose(res.monitor_coord_px, alias, atol=1e-6)
    assert res.order_residual.max() < 1e-9
    np.testing.assert_array_equal(res.valid, (alias >= -0.5) & (alias < EXTENT - 0.5))
    assert 0 < res.valid.sum() < u.size


def test_phase_jump_on_coarse_width_is_flagged():
    widths = [50, 400, 3200]
    u = monitor_row(rows=4)
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    # a 0.3 rad jump of the 3200 px phase is 0.38 orders of the 400 px width
    frames[2, :, :2, 1000:] = pattern(u[:2, 1000:], 3200, 4, black=0.1, white=0.9, phase_error=0.3)
    res = dec.decode_sequence(frames, widths, 4, EXTENT)
    assert np.all(res.flags[:2, 1000:] & F.ORDER_RESIDUAL)
    assert np.all(res.order_residual[:2, 1000:] > 0.3)
    assert res.valid[2:].all() and res.valid[:, :1000].all()


def test_low_amplitude_pixels_flagged_relative_and_absolute():
    widths = [50, 400, 3200]
    u = monitor_row(rows=6)
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    dim = np.zeros(u.shape, bool)
    dim[2:4, 100:200] = True
    # almost no fringe contrast in the 50 px width there (scattering washes it out)
    frames[0][:, dim] = 0.5 + 0.01 * (frames[0][:, dim] - 0.5)
    res = dec.decode_sequence(frames, widths, 4, EXTENT)
    assert np.all(res.flags[dim] & F.LOW_AMPLITUDE)
    assert not np.any(res.flags[~dim] & F.LOW_AMPLITUDE)
    # absolute threshold: B = 0.4 everywhere else, 0.004 in the block
    res_abs = dec.decode_sequence(frames, widths, 4, EXTENT, min_amplitude=0.1,
                                  min_relative_amplitude=0.0)
    np.testing.assert_array_equal((res_abs.flags & F.LOW_AMPLITUDE) != 0, dim)
    res_none = dec.decode_sequence(frames, widths, 4, EXTENT, min_relative_amplitude=0.0)
    assert not np.any(res_none.flags & F.LOW_AMPLITUDE)
    # unwrap_phase flags it too, given the amplitude
    res_u = dec.unwrap_phase(res.wrapped_phase, widths, EXTENT, amplitude=res.amplitude)
    np.testing.assert_array_equal((res_u.flags & F.LOW_AMPLITUDE) != 0, dim)


@pytest.mark.parametrize("bad_value", [np.nan, np.inf])
def test_non_finite_pixels_flagged_not_crashing(bad_value):
    widths = [50, 400, 3200]
    u = monitor_row(rows=3)
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    frames[1, 2, 1, 17] = bad_value
    res = dec.decode_sequence(frames, widths, 4, EXTENT)
    assert res.flags[1, 17] == F.NAN_INPUT
    assert not res.valid[1, 17]
    for arr in (res.absolute_phase, res.monitor_coord_px, res.order_residual,
                res.wrapped_phase[1], res.amplitude[1], res.offset[1]):
        assert np.isnan(arr[1, 17])
    others = np.ones(u.shape, bool)
    others[1, 17] = False
    assert res.valid[others].all()
    assert np.abs(res.monitor_coord_px - u)[others].max() < 1e-6
    ps = dec.phase_shift(frames[1])
    assert not ps.valid[1, 17] and np.isnan(ps.wrapped_phase[1, 17]) and ps.valid[others].all()
    # NaN wrapped phase given to unwrap_phase
    phases = res.wrapped_phase.copy()
    phases[0, 0, 0] = np.nan
    assert dec.unwrap_phase(phases, widths, EXTENT).flags[0, 0] == F.NAN_INPUT


def test_out_of_range_flagged():
    """Pattern over 1920 px but a monitor of 1600 px: u >= 1599.5 is off the monitor."""
    widths = [50, 400, 3200]
    u = monitor_row(rows=2)
    res = dec.decode_sequence(sequence(u, widths, 4), widths, 4, 1600)
    off = u >= 1599.5
    np.testing.assert_array_equal(res.flags == F.OUT_OF_RANGE, off)
    assert np.abs(res.monitor_coord_px - u).max() < 1e-6  # still decoded, only flagged


def test_noise_at_monitor_edges_does_not_wrap():
    """Widest width == extent: the coarse position of the edge pixels is +-3 px noisy and
    crosses the cut at -0.5 / 1919.5, but the final (fine) position decides: pixels 0 and
    1919 decode to 0 and 1919, not to 1920 or -1."""
    widths = [48, 384, 1920]
    rng = np.random.default_rng(3)
    u = np.broadcast_to(np.array([0.0, 0.0, 1919.0, 1919.0]), (500, 4))
    frames = sequence(u, widths, 4, black=0.1, white=0.9)
    frames += rng.normal(0, 0.005, frames.shape)
    res = dec.decode_sequence(frames, widths, 4, 1920)
    coarse = dec.phase_shift(frames[2]).wrapped_phase * 1920 / (2 * np.pi)
    assert np.mean(np.abs(np.mod(coarse - u + 960, 1920) - 960) > 1) > 0.5  # really noisy
    assert np.abs(res.monitor_coord_px - u).max() < 0.35  # fine noise 0.07 px rms
    assert res.valid.all()


def test_valid_is_flags_zero_and_flag_bits():
    assert [int(f) for f in F] == [1, 2, 4, 8, 16]
    u = monitor_row()
    frames = sequence(u, [50, 400, 3200], 4)
    frames[0, 0, 0, 0] = np.nan
    res = dec.decode_sequence(frames, [50, 400, 3200], 4, EXTENT)
    np.testing.assert_array_equal(res.valid, res.flags == 0)
    assert res.flags.dtype == np.uint8


# --------------------------------------------------------------------------- arguments


def _frames(n=3, k=4):
    return np.ones((n, k, 2, 3))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(widths=[50, 400, 1000]), "widths.*extent_px"),  # widest < extent
        (dict(widths=[50, 400, 400]), "widths must be distinct"),
        (dict(widths=[50, 400, 3200], method="heterodyne"), "widths"),  # factor > 2 apart
        (dict(widths=[48, 54, 60], method="heterodyne", extent_px=5000), "widths.*extent_px"),
        (dict(widths=[96, 128, 192], method="number_theoretic"), "widths.*coprime"),
        (dict(widths=[96.5, 128, 160], method="number_theoretic"), "widths must be integer"),
        (dict(widths=[30, 40, 50], method="number_theoretic"), "widths.*extent_px"),
        (dict(widths=[-50, 400, 3200]), "widths"),
        (dict(method="fourier"), "method"),
        (dict(extent_px=0), "extent_px"),
        (dict(shifts=5), "shifts"),
        (dict(shifts=2.0), "shifts"),
        (dict(frames=_frames(k=2), shifts=2), "shifts"),
        (dict(shifts=np.array([0.0, 0.5, 1.0, 1.5])), "shifts.*2 pi k / K"),
        (dict(frames=_frames(n=2)), "frames.*widths"),
        (dict(frames=np.ones((4, 2, 3))), r"frames.*\(n_widths, K, H, W\)"),
        (dict(frames=np.ones((3, 4, 2, 3), complex)), "frames.*dtype"),
        (dict(max_order_residual=0.7), "max_order_residual"),
        (dict(min_amplitude=-1.0), "min_amplitude"),
        (dict(min_relative_amplitude=np.nan), "min_relative_amplitude"),
        (dict(dtype=np.int32), "dtype"),
    ],
)
def test_bad_arguments_raise_value_error_naming_the_argument(kwargs, match):
    args = dict(frames=_frames(), widths=[50, 400, 3200], shifts=4, extent_px=EXTENT)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        dec.decode_sequence(**args)


def test_equal_widths_in_heterodyne_tree_raise():
    # 1/2 - 1/3 == 1/3 - 1/6: both first beats are 6 px, their beat is constant
    with pytest.raises(ValueError, match="widths.*equal wavelengths"):
        unambiguous_range_px([2, 3, 6], "heterodyne")


def test_other_functions_validate():
    with pytest.raises(ValueError, match="K >= 3"):
        dec.phase_shift(np.ones((2, 3, 3)))
    with pytest.raises(ValueError, match="wrapped_phase has 2 widths"):
        dec.unwrap_phase(np.zeros((2, 3, 3)), [50, 400, 3200], EXTENT)
    with pytest.raises(ValueError, match="amplitude must have"):
        dec.unwrap_phase(np.zeros((3, 3, 3)), [50, 400, 3200], EXTENT, amplitude=np.ones((3, 3)))
    with pytest.raises(ValueError, match="pixel_pitch_mm"):
        dec.monitor_px_to_mm(np.zeros(3), -0.2)
    with pytest.raises(ValueError, match="width_px"):
        dec.phase_to_monitor_px(np.zeros(3), 0)


def test_unambiguous_range():
    assert unambiguous_range_px([50, 400, 3200]) == 3200
    assert unambiguous_range_px([48, 54, 60], "heterodyne") == pytest.approx(2160)
    assert unambiguous_range_px([60, 48], "heterodyne") == pytest.approx(240)
    assert unambiguous_range_px([96, 128, 160], "number_theoretic") == 1920


def test_monitor_coordinate_conversions():
    phi = np.array([[0.0, np.pi, 2 * np.pi * 10.25]])
    np.testing.assert_allclose(dec.phase_to_monitor_px(phi, 50), [[0, 25, 512.5]])
    np.testing.assert_allclose(dec.monitor_px_to_mm([[0.0, 25.0, -0.5]], 0.2331),
                               [[0.0, 5.8275, -0.11655]])


# --------------------------------------------------------------------------- image files


def test_load_image_stack_tiff_and_png(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    from PIL import Image

    rng = np.random.default_rng(5)
    a = rng.integers(0, 65535, (6, 9), dtype=np.uint16)
    b = rng.integers(0, 65535, (2, 6, 9), dtype=np.uint16)
    c = rng.integers(0, 255, (6, 9), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "a.tif", a)
    tifffile.imwrite(tmp_path / "b.tiff", b)
    Image.fromarray(c).save(tmp_path / "c.png")
    stack = load_image_stack([tmp_path / "a.tif", str(tmp_path / "b.tiff")])
    assert stack.shape == (3, 6, 9) and stack.dtype == np.float64
    np.testing.assert_array_equal(stack, np.concatenate([a[None], b]).astype(float))
    png = load_image_stack([tmp_path / "c.png"])
    assert png.shape == (1, 6, 9)
    np.testing.assert_array_equal(png[0], c.astype(float))
    # frames of one sequence come from one camera setting: 16-bit TIFFs and an 8-bit PNG mixed
    with pytest.raises(ValueError, match="c.png.*uint8.*uint16"):
        load_image_stack([tmp_path / "a.tif", tmp_path / "c.png"])

    with pytest.raises(FileNotFoundError, match="missing.tif"):
        load_image_stack([tmp_path / "a.tif", tmp_path / "missing.tif"])
    tifffile.imwrite(tmp_path / "small.tif", a[:5])
    with pytest.raises(ValueError, match="small.tif"):
        load_image_stack([tmp_path / "a.tif", tmp_path / "small.tif"])
    Image.fromarray(np.zeros((6, 9, 3), np.uint8)).save(tmp_path / "rgb.png")
    with pytest.raises(ValueError, match="rgb.png.*single-channel"):
        load_image_stack([tmp_path / "rgb.png"])
    (tmp_path / "x.bmp").write_bytes(b"BM")
    with pytest.raises(ValueError, match="x.bmp"):
        load_image_stack([tmp_path / "x.bmp"])
    (tmp_path / "broken.tif").write_bytes(b"not a tiff")
    with pytest.raises(ValueError, match="broken.tif"):
        load_image_stack([tmp_path / "broken.tif"])
    with pytest.raises(ValueError, match="paths"):
        load_image_stack([])


# --------------------------------------------------------------------------- kernels vs NumPy


def test_atan2_kernel_matches_numpy():
    t = np.linspace(-np.pi, np.pi, 20001)
    scale = np.geomspace(1e-200, 1e200, t.size)
    y = np.concatenate([np.sin(t), scale * np.sin(t[::-1]), [0.0, 0.0, 0.0, 1.0, -1.0, 1e-300]])
    x = np.concatenate([np.cos(t), scale * np.cos(t), [0.0, -1.0, 1.0, 0.0, 0.0, -1.0]])
    got = np.array([kd.atan2(a, b) for a, b in zip(y, x)])
    expected = np.arctan2(y, x)
    expected[expected <= -np.pi] = np.pi
    assert np.abs(got - expected).max() < 1e-15


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("n_shifts", [3, 4, 7])
def test_phase_shift_kernel_matches_naive(dtype, n_shifts):
    rng = np.random.default_rng(n_shifts)
    frames = rng.uniform(-0.2, 1.0, (n_shifts, 5, 13)).astype(dtype)
    frames[1, 2, 3] = np.nan
    res = dec.phase_shift(frames)
    ref = naive.phase_shift(frames)
    for got, exp in zip((res.wrapped_phase, res.amplitude, res.offset, res.modulation), ref):
        np.testing.assert_allclose(got, exp, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(res.valid, np.all(np.isfinite(frames), axis=0))


def _random_phases(rng, n, shape=(6, 50)):
    phases = rng.uniform(-np.pi, np.pi, (n,) + shape)
    phases[0, 1, 2] = np.nan
    phases[-1, 3, 4] = np.nan
    return phases


UNWRAP_CASES = [
    ("hierarchical", [400, 3200, 50], 1920),
    ("hierarchical", [33.0, 1000.0], 700),
    ("hierarchical", [2000.0], 1920),
    ("heterodyne", [54, 48, 60], 1920),
    ("heterodyne", [70, 64, 59, 66], 1920),
    ("number_theoretic", [128, 96, 160], 1920),
    ("number_theoretic", [35, 14], 60),
]


@pytest.mark.parametrize("method, widths, extent", UNWRAP_CASES)
def test_unwrap_kernels_match_naive(method, widths, extent):
    rng = np.random.default_rng(len(widths) + extent)
    phases = _random_phases(rng, len(widths))
    amplitude = rng.uniform(0, 1, phases.shape)
    res = dec.unwrap_phase(phases, widths, extent, method, amplitude=amplitude,
                           min_amplitude=0.05, min_relative_amplitude=0.3)
    big_phi, coord, residual, flags = naive.UNWRAP[method](phases, widths, extent)
    flags = flags | np.where(naive.low_amplitude(amplitude, 0.05, 0.3), naive.LOW_AMPLITUDE,
                             0).astype(np.uint8)
    np.testing.assert_allclose(res.absolute_phase, big_phi, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(res.monitor_coord_px, coord, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(res.order_residual, residual, atol=1e-9)
    np.testing.assert_array_equal(res.flags, flags)
    assert len(np.unique(flags)) >= 3  # the random case exercises several flags
    np.testing.assert_array_equal(res.valid, flags == 0)
    assert res.finest_width_px == min(widths)


@pytest.mark.parametrize("method, widths, extent", UNWRAP_CASES)
def test_fused_decode_kernels_match_naive(method, widths, extent):
    rng = np.random.default_rng(3 * len(widths) + extent)
    n_shifts = 4 if len(widths) > 1 else 5
    frames = rng.uniform(0.0, 1.0, (len(widths), n_shifts, 5, 40))
    frames[0, 1, 2, 3] = np.nan
    frames[:, :, 4, :5] *= 0.1  # some low-amplitude pixels
    res = dec.decode_sequence(frames, widths, n_shifts, extent, method)
    ref = naive.decode_sequence(frames, widths, extent, method)
    for name in ("absolute_phase", "monitor_coord_px", "wrapped_phase", "amplitude", "offset",
                 "modulation", "order_residual"):
        np.testing.assert_allclose(getattr(res, name), ref[name], rtol=1e-12, atol=1e-9,
                                   err_msg=name)
    np.testing.assert_array_equal(res.flags, ref["flags"])
    np.testing.assert_array_equal(res.valid, ref["valid"])


def test_flag_low_amplitude_kernel_matches_naive():
    rng = np.random.default_rng(11)
    amplitude = rng.uniform(0, 1, (3, 7, 9))
    amplitude[1, 2, 2] = np.nan
    flags = rng.integers(0, 16, (7, 9)).astype(np.uint8)
    thresholds = np.array([0.1, 0.5, 0.3])
    out = flags.copy()
    kd.flag_low_amplitude(amplitude, thresholds, out)
    with np.errstate(invalid="ignore"):
        low = np.any(amplitude < thresholds[:, None, None], axis=0)
    np.testing.assert_array_equal(out, flags | np.where(low, 2, 0).astype(np.uint8))
