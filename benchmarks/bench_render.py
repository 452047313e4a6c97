"""Benchmark: scattered rays per second on the fringe path, and the paper's Fig. 3 run.

Usage::

    python benchmarks/bench_render.py [--config examples/paper_fig3.toml] [--repeat 3]

Prints, all measured in this run after JIT compilation:

- the compiled fringe path (X and Y, 4 shifts, one width): wall time and scattered rays
  per second, per wall-second and per CPU-second;
- the whole Fig. 3 sequence (X and Y, 3 widths, 4 shifts) at the configured camera size;
- a plain NumPy implementation of the same estimator (vectorised over rays, no Numba),
  timed on a subset of pixels and scaled, and the speed ratio;
- the largest difference between the two on that subset (they compute the same numbers).

Not a test: timings depend on the machine. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from pmdsim.config import load_config
from pmdsim.geometry import dot, normalize
from pmdsim.patterns import fringe_value, phase_shifts
from pmdsim.render import Simulation
from pmdsim.trace import cone_basis, trace_primary

ROOT = Path(__file__).resolve().parents[1]


def numpy_fringes(sim: Simulation, rows: slice, widths, shifts: int):
    """Plain NumPy: paper estimator (1/N) sum f_p L(u_p) for X and Y fringes, one row block.

    Straight from the formulas: world directions of every ray, monitor-plane intersection,
    Ward weight, nearest monitor pixel, the fringe value there. Returns
    (directions, widths, shifts, rows, cols) camera values.
    """
    scene = sim.scene
    mon = scene.monitor
    brdf = scene.brdf
    hits = trace_primary(scene, rows.start, rows.stop)
    e1, e2, p = cone_basis(hits)
    local = scene.sampling.local_directions()  # (N, 3)
    o = (local[:, 0, None, None, None] * e1 + local[:, 1, None, None, None] * e2
         + local[:, 2, None, None, None] * p)  # (N, r, c, 3)
    t = ((mon.centre - hits.point) @ mon.normal) / (o @ mon.normal)
    x = hits.point + t[..., None] * o
    uv = mon.world_to_pixel(x)
    u, v = uv[..., 0], uv[..., 1]
    on_monitor = ((o @ mon.normal) < 0) & (t > 0) & (u >= -0.5) & (u < mon.width - 0.5) \
        & (v >= -0.5) & (v < mon.height - 0.5)
    i = hits.to_camera
    i_loc = np.stack([dot(i, hits.x_axis), dot(i, hits.y_axis), dot(i, hits.normal)], -1)
    o_loc = np.stack([dot(o, hits.x_axis), dot(o, hits.y_axis), dot(o, hits.normal)], -1)
    f = brdf.evaluate(np.broadcast_to(i_loc, o_loc.shape), o_loc)
    f = np.where(on_monitor, f, 0.0)
    iu = np.floor(np.where(on_monitor, u, 0) + 0.5)
    iv = np.floor(np.where(on_monitor, v, 0) + 0.5)
    n = local.shape[0]
    out = np.empty((2, len(widths), shifts) + u.shape[1:])
    for di, c in enumerate((iu, iv)):
        for wi, w in enumerate(widths):
            for k, delta in enumerate(phase_shifts(shifts)):
                lum = mon.luminance(fringe_value(c, w, delta))
                out[di, wi, k] = (f * lum).sum(axis=0) / n
    return out


def _time(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        c0 = time.process_time()
        res = fn()
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        if wall < best:
            best, best_cpu = wall, cpu
    return res, best, best_cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "examples" / "paper_fig3.toml"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--numpy-rows", type=int, default=8, help="camera rows for the NumPy baseline")
    args = ap.parse_args()

    cfg = load_config(args.config)
    sim = Simulation.from_config(cfg)
    h, w = sim.shape
    n = sim.scene.rays_per_pixel
    widths = tuple(cfg.patterns.fringes.widths_px)
    geo = sim.geometry()
    n_valid = int(geo.surface_mask.sum())
    rays = n_valid * n
    print(f"camera {w} x {h} px, {n_valid} pixels on the surface, N = {n} rays per pixel, "
          f"{os.cpu_count()} cores")

    sim.render_fringes(widths[:1], ("x", "y"), 4)  # compile
    _, t1, c1 = _time(lambda: sim.render_fringes(widths[:1], ("x", "y"), 4), args.repeat)
    print(f"fringe path, X+Y, 1 width, 4 shifts: {t1:.3f} s wall, "
          f"{rays / t1 / 1e6:.0f} M rays/s, {rays / c1 / 1e6:.0f} M rays per CPU-second")
    _, t3, c3 = _time(lambda: sim.render_fringes(widths, ("x", "y"), 4), args.repeat)
    print(f"Fig. 3 sequence, X+Y, {len(widths)} widths {widths}, 4 shifts: {t3:.3f} s wall "
          f"({c3:.3f} CPU-s), {rays / c3 / 1e6:.0f} M rays per CPU-second")

    # NumPy baseline on a row block near the image centre, scaled to the same ray count.
    r0 = h // 2
    rows = slice(r0, r0 + args.numpy_rows)
    ref, tn, _ = _time(lambda: numpy_fringes(sim, rows, widths, 4), 1)
    sub_valid = int(geo.surface_mask[rows].sum())
    numpy_rate = sub_valid * n / tn
    fast_rate = rays / t3
    print(f"plain NumPy, same estimator, {sub_valid} pixels: {tn:.3f} s -> "
          f"{numpy_rate / 1e6:.2f} M rays/s; compiled/NumPy speed ratio {fast_rate / numpy_rate:.0f}x")
    full = sim.render_fringes(widths, ("x", "y"), 4).images[:, :, :, rows]
    m = np.isfinite(full) & np.isfinite(ref)
    scale = np.nanmax(np.abs(ref))
    print(f"max |compiled - NumPy| / max = {np.max(np.abs(full[m] - ref[m])) / scale:.2e}")


if __name__ == "__main__":
    main()
