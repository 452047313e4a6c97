"""Benchmark: monocular reconstruction + slope integration of a 1280 x 1024 map.

Plain script: ``PYTHONPATH=src python benchmarks/bench_reconstruct.py [--repeat N] [--scale S]``.

A 1280 x 1024 camera looks at a concave sphere (R 2000 mm, 100 mm x 80 mm rectangular
aperture) 25 deg off its axis; the exact specular monitor coordinates (a noise-free decode)
are reconstructed on a grid of about 1250 x 1000 nodes (0.08 mm) -- the whole height-normal
iteration (projection, spline interpolation of the decoded coordinates, bisector normals,
Southwell integration) -- and, separately, the slopes of a circular aperture of the same
grid are integrated. Each is timed, in the same run and on the same data, with the fast
solvers (DCT on the full rectangle, PyAMG multigrid on the circle) against SciPy's sparse
direct solver (SuperLU), the plain baseline. Target: reconstruction + integration of the
map under 2 s on 2 cores. Timings are only meaningful on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from pmdsim.config import parse_config
from pmdsim.measure.poisson import clear_operator_cache
from pmdsim.measure.integrate import grid_coordinates, southwell
from pmdsim.measure.reconstruct import reconstruct
from pmdsim.scene import Scene
from pmdsim.trace import specular_monitor_coords, trace_primary


def scene(scale: float):
    return Scene.from_config(parse_config(_dict(scale)))


def _dict(scale: float) -> dict:
    t = math.radians(25.0)
    w, h = int(1280 * scale), int(1024 * scale)
    return {
        "camera": {"resolution": [w, h], "pixel_pitch_mm": 0.0048 / scale, "focal_length_mm": 40.0,
                   "position_mm": [-1000 * math.sin(t), 0.0, 1000 * math.cos(t)],
                   "look_at_mm": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]},
        "monitor": {"resolution": [1920, 1080], "pixel_pitch_mm": 0.25,
                    "centre_mm": [500 * math.sin(t), 0.0, 500 * math.cos(t)],
                    "look_at_mm": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "pixel_model": "continuous"},
        "surface": {"type": "sphere", "radius_mm": 2000.0,
                    "aperture": {"shape": "rectangular", "size_mm": [100.0, 80.0]}},
        "brdf": {"model": "mirror"},
    }


def timed(fn, repeat):
    """(median wall s, median CPU s) of ``repeat`` calls after a warm-up call (JIT); each call
    starts without kept Southwell operators."""
    clear_operator_cache()
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        clear_operator_cache()
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    clear_operator_cache()
    return statistics.median(wall), statistics.median(cpu)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scale", type=float, default=1.0, help="camera and grid size factor")
    args = ap.parse_args()
    sc = scene(args.scale)
    hits = trace_primary(sc)
    u, v, _ = specular_monitor_coords(sc, hits)
    spacing = 0.08 / args.scale
    print(f"camera {sc.camera.width} x {sc.camera.height} px, {np.isfinite(u).mean():.0%} decoded; "
          f"grid spacing {spacing:g} mm")

    # the grid 1 mm inside the aperture (every node measured: the DCT path), the nominal
    # shape 0.5 % off the truth (so the height-normal iteration has work to do)
    xs = np.arange(-49.0, 49.0 + 1e-9, spacing)
    ys = np.arange(-39.0, 39.0 + 1e-9, spacing)
    nominal = Scene.from_config(parse_config({**_dict(args.scale), "surface": {
        "type": "sphere", "radius_mm": 1990.0,
        "aperture": {"shape": "rectangular", "size_mm": [100.0, 80.0]}}})).surface

    def rec(solver):
        return reconstruct(u, v, sc.camera, sc.monitor, nominal, grid=(xs, ys), solver=solver)

    r = rec("auto")
    x, y = np.meshgrid(r.x_mm, r.y_mm)
    z = sc.surface.sag(x, y)[0]
    e = (r.height_mm - z)[r.mask]
    print(f"grid {r.height_mm.shape[1]} x {r.height_mm.shape[0]} nodes ({r.mask.mean():.1%} measured), "
          f"{r.iterations} iterations, height error RMS {np.std(e) * 1e6:.2g} nm")
    (t_fast, c_fast) = timed(lambda: rec("auto"), args.repeat)
    (t_base, c_base) = timed(lambda: rec("direct"), max(1, args.repeat // 2))
    print(f"reconstruction + integration (DCT):     {t_fast:7.3f} s wall, {c_fast:7.3f} s CPU  (target < 2 s)")
    print(f"reconstruction + integration (SuperLU): {t_base:7.3f} s wall, {c_base:7.3f} s CPU  "
          f"ratio {t_base / t_fast:5.1f}x")

    # integration alone on a circular mask of the same grid
    gx, gy = grid_coordinates(r.height_mm.shape, spacing)
    circle = np.hypot(gx, gy) < 0.5 * min(gx.max(), gy.max()) * 2 * 0.49
    sx = np.where(circle, gx / 2000.0, np.nan)
    sy = np.where(circle, gy / 2000.0, np.nan)
    (t_pcg, _) = timed(lambda: southwell(sx, sy, spacing, circle, solver="pcg"), args.repeat)
    (t_amg, _) = timed(lambda: southwell(sx, sy, spacing, circle, solver="amg"), args.repeat)
    (t_lu, _) = timed(lambda: southwell(sx, sy, spacing, circle, solver="direct"), max(1, args.repeat // 2))
    print(f"Southwell on a circle of {circle.sum()} nodes (wall, with set-up): DCT-PCG {t_pcg:6.3f} s, "
          f"PyAMG {t_amg:6.3f} s, SuperLU {t_lu:6.3f} s; SuperLU / DCT-PCG {t_lu / t_pcg:5.1f}x")


if __name__ == "__main__":
    main()
