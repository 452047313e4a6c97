"""Time to a phase error of 0.1 mrad (P95 over pixels, every fringe) on Fig. 3: the Gauss
rule (``sampling.mode = "rule"``) against the stratified lattice (the earlier default), both
measured in this run (issue 18: the aim is >= 100x).

Scene: ``examples/paper_fig3.toml`` (paper estimator, 1 deg cone, continuous monitor) with
the camera reduced to 160 x 128 pixels (``--camera``) over the same field of view: the
time per ray does not depend on the camera, the error statistic is over 20 000 pixels.
Reference: the rule at 32 x 128 = 4096 nodes (the rule at 16 x 64 is within 1e-8 mrad of
it, and 8 x 32 within 0.001 mrad of SciPy's cubature, tests/test_quadrature.py).

For each mode N grows (rule: 4 k^2 = 64, 100, 144, ... nodes; ``stratified``, the
Fibonacci lattice with P, the same for every pixel, and ``random``, that lattice shifted
per pixel by a seeded random offset: x 2 from 100) until the P95 phase difference from
the reference is <= 0.1 mrad; a mode that does not get there by ``--max-stratified`` has
its time extrapolated from its last two points (error ~ N^-a, time ~ N). Times are CPU
seconds of the render (``time.process_time``: all threads; robust to a loaded machine,
unlike wall time), the rule's without its error passes (the other modes have none) and,
printed too, with them.

    python benchmarks/bench_quadrature.py [--max-stratified 25600] [--camera 160 128]

Measured figures and their conditions: docs/performance.md ("Quadrature").
"""

from __future__ import annotations

import argparse
import math
import os
import time
import tomllib
from pathlib import Path

import numpy as np

from pmdsim.config import parse_config
from pmdsim.render import Simulation

ROOT = Path(__file__).resolve().parent.parent
WIDTHS = (50.0, 400.0, 3200.0)
TARGET_MRAD = 0.1


def config(mode: str, n: int, camera: tuple[int, int], error: bool = False):
    d = tomllib.loads((ROOT / "examples" / "paper_fig3.toml").read_text())
    w, h = camera
    d["camera"]["resolution"] = [w, h]
    d["camera"]["pixel_pitch_mm"] = 0.0048 * 1280 / w
    d["sampling"].update(mode=mode, n_rays=n, error_estimate=error)
    d["output"] = {"figures": False}
    return parse_config(d)


def render(mode: str, n: int, camera, error: bool = False):
    sim = Simulation.from_config(config(mode, n, camera, error))
    t = time.process_time()
    fr = sim.render_fringes(WIDTHS, ["x", "y"])
    return fr, time.process_time() - t


def p95_mrad(sums, ref) -> float:
    with np.errstate(invalid="ignore", divide="ignore"):
        err = np.abs(np.angle(sums / ref)) * 1e3
    return float(max(np.nanpercentile(err[d, w], 95) for d in range(err.shape[0])
                     for w in range(err.shape[1])))


def walk(mode, ns, ref, camera):
    rows = []
    for n in ns:
        fr, dt = render(mode, n, camera)
        e = p95_mrad(fr.sums, ref)
        rows.append((n, e, dt))
        print(f"  {mode:<10} N = {n:>6}: P95 phase error {e:9.3g} mrad, render {dt:8.3f} CPU s",
              flush=True)
        if e <= TARGET_MRAD:
            break
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--max-stratified", type=int, default=25600)
    ap.add_argument("--camera", type=int, nargs=2, default=(160, 128), metavar=("W", "H"))
    args = ap.parse_args()
    camera = tuple(args.camera)
    print(f"load average {os.getloadavg()}; camera {camera[0]} x {camera[1]} over Fig. 3's view;"
          f" target {TARGET_MRAD} mrad P95, worst fringe")
    render("rule", 64, camera)  # compile the kernels once (not timed)
    render("stratified", 100, camera)
    ref = render("rule", 4096, camera)[0].sums
    rule = walk("rule", [4 * k * k for k in range(4, 17)], ref, camera)
    n_rule, e_rule, t_rule = rule[-1]
    if e_rule > TARGET_MRAD:
        raise SystemExit("the rule did not reach the target: nothing to compare")
    fr, t_rule_err = render("rule", n_rule, camera, error=True)
    stated = np.nanpercentile(fr.phase_error(), 95, axis=(-2, -1)) * 1e3
    print(f"  rule with its error passes (N = {n_rule}): {t_rule_err:.3f} CPU s, stated P95 "
          f"{np.array2string(stated.ravel(), precision=3)} mrad (X 50/400/3200, Y ...)")
    ns, n = [], 100
    while n <= args.max_stratified:
        ns.append(n)
        n *= 2
    for mode in ("stratified", "random"):
        rows = walk(mode, ns, ref, camera)
        (n1, e1, _), (n2, e2, t2) = rows[-2], rows[-1]
        if e2 <= TARGET_MRAD:  # measured: the first N (x 2 steps) that meets the target
            t_mc, how = t2, f"measured at N = {n2}"
        else:  # extrapolated from the last two points: error ~ N^-a, time ~ N
            a = math.log(e1 / e2) / math.log(n2 / n1)
            n_need = n2 * (e2 / TARGET_MRAD) ** (1 / a) if a > 0 else float("inf")
            t_mc, how = t2 * n_need / n2, f"extrapolated: error ~ N^-{a:.2f}, N ~ {n_need:.3g}"
        print(f"time to {TARGET_MRAD} mrad: rule {t_rule:.3g} CPU s (N = {n_rule}; "
              f"{t_rule_err:.3g} with its error passes), {mode} {t_mc:.3g} CPU s ({how}); "
              f"ratio {t_mc / t_rule:.3g}x ({t_mc / t_rule_err:.3g}x with the error passes)",
              flush=True)
    print(f"load average at the end {os.getloadavg()}")

if __name__ == "__main__":
    main()
