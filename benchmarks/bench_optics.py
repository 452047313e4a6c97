"""Benchmark: scattered rays per CPU-second of the fringe path with camera optics
(4 sub-pixels x 16 aperture samples per pixel, N = 100 scattered rays each) against the
single-ray path (one pinhole ray per pixel, N = 100), both measured in this run.

Usage::

    python benchmarks/bench_optics.py [--config examples/paper_fig3.toml] [--repeat 3]

Rays are counted the same way for both: scattered rays traced to the monitor and summed
(pixels x vision rays per pixel x N). The optics path renders fewer pixels (a crop of the
camera) so that both runs take comparable time. Prints rays per wall- and CPU-second and the
ratio optics / single-ray (the issue's aim: >= 0.8).

Not a test: timings depend on the machine. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from pmdsim.config import load_config
from pmdsim.render import Simulation

ROOT = Path(__file__).resolve().parents[1]


def _time(fn, repeat: int):
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    return best


def _config(cfg, width: int, height: int, optics: bool):
    cam = dict(cfg.camera.model_dump(), resolution=(width, height))
    cam.pop("principal_point_px", None)
    if optics:
        cam.update(subpixels=2, f_number=8.0, aperture_samples=16,
                   focal_length_mm=cam.get("focal_length_mm") or 50.0)
    samp = dict(cfg.sampling.model_dump(), n_rays=100)
    return cfg.model_validate(dict(cfg.model_dump(), camera=cam, sampling=samp, variants=()))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "examples" / "paper_fig3.toml"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pixels", type=int, default=256 * 200, help="camera pixels of the single-ray run")
    args = ap.parse_args()
    cfg = load_config(args.config)
    fr = cfg.patterns.fringes
    results = {}
    for optics in (False, True):
        w = 256
        h = max(1, args.pixels // w // (64 if optics else 1))
        sim = Simulation.from_config(_config(cfg, w, h, optics))
        run = lambda: sim.render_fringes(fr.widths_px, fr.directions, fr.shifts)  # noqa: E731
        run()  # compile
        wall, cpu = _time(run, args.repeat)
        rays = w * h * sim.scene.camera.rays_per_pixel * sim.scene.rays_per_pixel
        results[optics] = rays / cpu
        name = "4 sub-pixels x 16 aperture x N=100" if optics else "single ray x N=100"
        print(f"{name:38s} {w}x{h} px  {rays / 1e6:8.1f} M rays  wall {wall:6.2f} s  "
              f"{rays / wall / 1e6:7.1f} M rays/s  CPU {cpu:6.2f} s  {rays / cpu / 1e6:7.1f} M rays/CPU-s")
    print(f"ratio optics / single-ray (rays per CPU-second): {results[True] / results[False]:.2f} (aim >= 0.8)")


if __name__ == "__main__":
    main()
