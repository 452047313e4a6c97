"""Benchmark: the radiometric estimator against the cone estimator on the Fig. 3 scene.

Usage::

    python benchmarks/bench_radiometric.py [--config examples/paper_fig3.toml] [--rays 256]
                                           [--repeat 3] [--mode stratified]

Renders the configured fringe sequence (X and Y, all widths, K shifts) at the configured
camera size (1280 x 1024 for the Fig. 3 example) twice, with the same number of rays per
pixel: once with the paper's cone estimator (``theta_max`` and ``scheme`` from the config)
and once with the ``radiometric`` estimator (directions importance-sampled from the Ward
lobe, weights f cos / pdf). Prints, measured in this run after JIT compilation (best of
``--repeat``), the wall time and scattered rays per second of each and their ratio
(target: radiometric >= 0.5 x cone).

Not a test: timings depend on the machine; run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from pmdsim.config import load_config
from pmdsim.render import Simulation

ROOT = Path(__file__).resolve().parents[1]


def _best(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "examples" / "paper_fig3.toml"))
    ap.add_argument("--rays", type=int, default=256, help="rays per pixel for both estimators")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mode", choices=("stratified", "random"), default=None,
                    help="sampling mode (default: the config's)")
    args = ap.parse_args()

    cfg = load_config(args.config)
    fr = cfg.patterns.fringes
    widths, directions, shifts = fr.widths_px, fr.directions, fr.shifts
    rates = {}
    for est in ("paper", "radiometric"):
        upd = {"n_rays": args.rays, "estimator": est}
        if args.mode:
            upd["mode"] = args.mode
        c = cfg.model_copy(update={"sampling": cfg.sampling.model_copy(update=upd)})
        sim = Simulation.from_config(c)
        if est == "paper":
            h, w = sim.shape
            n_valid = int(sim.geometry().surface_mask.sum())
            print(f"{c.name}: camera {w} x {h} px, {n_valid} pixels on the surface, "
                  f"{args.rays} rays per pixel, fringes {directions} x {widths} px x {shifts} "
                  f"shifts, mode {c.sampling.mode}, {os.cpu_count()} cores")
        sim.render_fringes(widths, directions, shifts)  # compile + warm up
        t = _best(lambda: sim.render_fringes(widths, directions, shifts), args.repeat)
        rays = n_valid * args.rays
        rates[est] = rays / t
        label = (f"cone ({c.sampling.theta_max_deg:g} deg, {c.sampling.scheme})" if est == "paper"
                 else "radiometric (lobe-sampled)")
        print(f"{label:32s}: {t:7.3f} s wall, {rays / t / 1e6:7.1f} M rays/s")
    print(f"radiometric / cone rays per second: {rates['radiometric'] / rates['paper']:.2f} "
          "(target >= 0.5)")


if __name__ == "__main__":
    main()
