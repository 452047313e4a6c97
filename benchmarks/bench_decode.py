"""Benchmark: decode 24 camera images (2 directions x 3 widths x 4 shifts, 1280 x 1024).

Plain script: ``PYTHONPATH=src python benchmarks/bench_decode.py [--repeat N]``.

Times, in the same run and on the same synthetic float32 frames, the fused Numba path
(:func:`pmdsim.decode.decode_sequence`, once per direction: wrapped phase, amplitude, offset,
modulation, hierarchical unwrapping, order residual, flags) against a straightforward
vectorised NumPy implementation of the same outputs, after a warm-up call (JIT compilation).
Target: at most 0.2 s for both directions on 2 cores.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numba
import numpy as np

from pmdsim.measure.decode import decode_sequence

HEIGHT, WIDTH = 1024, 1280  # camera px
N_SHIFTS = 4
WIDTHS = (50.0, 400.0, 3200.0)  # monitor px
EXTENT = {"x": 1920.0, "y": 1080.0}  # monitor px


def synthetic_frames(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """(3, 4, H, W) float32 frames per direction: a smooth camera -> monitor mapping, offset
    and amplitude varying over the image, gamma 1, Gaussian camera noise."""
    row, col = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    monitor = {
        "x": 100.0 + 1.35 * col + 0.05 * row + 4.0 * np.sin(row / 97.0),
        "y": 60.0 + 0.9 * row - 0.03 * col + 3.0 * np.cos(col / 131.0),
    }
    offset = 0.45 + 0.1 * np.cos(col / 400.0) * np.cos(row / 300.0)
    amplitude = 0.35 * (1.0 - 0.3 * ((row - HEIGHT / 2) ** 2 + (col - WIDTH / 2) ** 2)
                        / (HEIGHT**2 + WIDTH**2))
    delta = 2 * np.pi * np.arange(N_SHIFTS) / N_SHIFTS
    frames = {}
    for direction, u in monitor.items():
        stack = np.empty((len(WIDTHS), N_SHIFTS, HEIGHT, WIDTH), np.float32)
        for j, w in enumerate(WIDTHS):
            for k in range(N_SHIFTS):
                image = offset + amplitude * np.cos(2 * np.pi * u / w + delta[k])
                stack[j, k] = image + rng.normal(0.0, 0.003, image.shape)
        frames[direction] = stack
    return frames


def numpy_decode(frames: np.ndarray, widths, extent: float, min_relative_amplitude=0.1,
                 max_order_residual=0.25) -> dict[str, np.ndarray]:
    """Straightforward NumPy version of decode_sequence (hierarchical), same outputs."""
    n, n_shifts = frames.shape[:2]
    delta = 2 * np.pi * np.arange(n_shifts) / n_shifts
    x = frames.astype(np.float64)
    z = np.tensordot(np.exp(-1j * delta), x, axes=([0], [1]))  # (n, H, W)
    wrapped = np.angle(z)
    wrapped[wrapped <= -np.pi] = np.pi
    amplitude = 2.0 * np.abs(z) / n_shifts
    offset = x.mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        modulation = np.where(offset > 0, amplitude / offset, np.nan)
    bad = ~np.all(np.isfinite(x), axis=(0, 1))
    widths = np.asarray(widths, dtype=np.float64)
    order = np.argsort(-widths)
    w0 = widths[order[0]]
    lo = 0.5 * (extent - w0 - 1)
    u = lo + np.mod(wrapped[order[0]] * w0 / (2 * np.pi) - lo, w0)
    residual = np.zeros(u.shape)
    big_phi = 2 * np.pi * u / w0
    for j in order[1:]:
        u_fine = wrapped[j] * widths[j] / (2 * np.pi)
        t = (u - u_fine) / widths[j]
        m = np.floor(t + 0.5)
        residual = np.maximum(residual, np.abs(t - m))
        u = u_fine + m * widths[j]
        big_phi = wrapped[j] + 2 * np.pi * m
    w_fine = widths[order[-1]]
    big_phi = 2 * np.pi * (lo + np.mod(big_phi * w_fine / (2 * np.pi) - lo, w0)) / w_fine
    coord = big_phi * w_fine / (2 * np.pi)
    flags = np.zeros(coord.shape, np.uint8)
    flags[residual > max_order_residual] |= 4
    flags[~((coord >= -0.5) & (coord < extent - 0.5))] |= 8
    for j in range(n):
        threshold = min_relative_amplitude * np.nanmedian(amplitude[j])
        flags[amplitude[j] < threshold] |= 2
    flags[bad] = 1
    return dict(absolute_phase=big_phi, monitor_coord_px=coord, wrapped_phase=wrapped,
                amplitude=amplitude, offset=offset, modulation=modulation,
                order_residual=residual, flags=flags)


def timed(fn, repeat: int) -> list[float]:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="timed repetitions (default 7)")
    args = parser.parse_args()

    frames = synthetic_frames(np.random.default_rng(0))
    print(f"frames: 2 directions x {frames['x'].shape} {frames['x'].dtype} "
          f"= {2 * frames['x'][:, :, 0, 0].size} images of {WIDTH} x {HEIGHT}; "
          f"numba threads: {numba.get_num_threads()}")

    def fast():
        return {d: decode_sequence(f, WIDTHS, N_SHIFTS, EXTENT[d]) for d, f in frames.items()}

    def slow():
        return {d: numpy_decode(f, WIDTHS, EXTENT[d]) for d, f in frames.items()}

    t0 = time.perf_counter()
    fast_result = fast()
    print(f"warm-up (JIT compile or cache load): {time.perf_counter() - t0:.2f} s")
    slow_result = slow()

    for d in frames:
        a, b = fast_result[d], slow_result[d]
        diff = np.nanmax(np.abs(a.monitor_coord_px - b["monitor_coord_px"]))
        same = np.mean(a.flags == b["flags"])
        print(f"direction {d}: valid {a.valid.mean():.4f}, max |coord fast - numpy| "
              f"{diff:.2e} monitor px, identical flags {same:.6f}")

    t_fast = timed(fast, args.repeat)
    t_slow = timed(slow, max(1, args.repeat // 2))
    fast_med, slow_med = statistics.median(t_fast), statistics.median(t_slow)
    print(f"numba fused : median {fast_med * 1e3:7.1f} ms  (min {min(t_fast) * 1e3:.1f} ms, "
          f"{len(t_fast)} runs)  [target <= 200 ms]")
    print(f"numpy       : median {slow_med * 1e3:7.1f} ms  (min {min(t_slow) * 1e3:.1f} ms, "
          f"{len(t_slow)} runs)")
    print(f"speed-up    : {slow_med / fast_med:.1f}x")


if __name__ == "__main__":
    main()
