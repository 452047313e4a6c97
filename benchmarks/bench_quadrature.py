"""Time to a phase error of 0.1 mrad (P95 over pixels, every fringe) on Fig. 3: the Gauss
rule (``sampling.mode = "rule"``) against the stratified lattice (the earlier default), both
measured in this run (issue 18: the aim is >= 100x).

Scene: ``examples/paper_fig3.toml`` (paper estimator, 1 deg cone, continuous monitor) with
the camera reduced to 160 x 128 pixels over the same field of view. Reference: the rule at
16 x 64 = 1024 nodes (within 1e-6 mrad of SciPy's cubature on this scene,
tests/test_quadrature.py). For each mode N grows (rule: 64, 100, 144, 196, 256, ...;
stratified: x 4 from 100) until the P95 phase difference from the reference is <= 0.1 mrad
or ``--max-stratified`` is reached; the time is the render's wall time at that N (the rule
without its embedded error pass, as the stratified mode has none). When the stratified
mode does not get there, its time is extrapolated from its last two points (error ~ N^-a,
time ~ N) and the ratio is printed as that estimate.

    python benchmarks/bench_quadrature.py [--max-stratified 102400]

Timings mean something only on an otherwise idle machine (the load average is printed).
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


def config(mode: str, n: int):
    d = tomllib.loads((ROOT / "examples" / "paper_fig3.toml").read_text())
    d["camera"]["resolution"] = [160, 128]
    d["camera"]["pixel_pitch_mm"] = 0.0048 * 8
    d["sampling"].update(mode=mode, n_rays=n, error_estimate=False)
    d["output"] = {"figures": False}
    return parse_config(d)


def render(mode: str, n: int):
    sim = Simulation.from_config(config(mode, n))
    t = time.perf_counter()
    fr = sim.render_fringes(WIDTHS, ["x", "y"])
    return fr.sums, time.perf_counter() - t


def p95_mrad(sums, ref) -> float:
    err = np.abs(np.angle(sums / ref)) * 1e3
    return float(max(np.nanpercentile(err[d, w], 95) for d in range(err.shape[0])
                     for w in range(err.shape[1])))


def walk(mode, ns, ref):
    rows = []
    for n in ns:
        sums, dt = render(mode, n)
        e = p95_mrad(sums, ref)
        rows.append((n, e, dt))
        print(f"  {mode:<10} N = {n:>6}: P95 phase error {e:9.3g} mrad, render {dt:7.3f} s")
        if e <= TARGET_MRAD:
            break
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--max-stratified", type=int, default=102400)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()}; target {TARGET_MRAD} mrad P95")
    render("rule", 64)  # compile the kernels once (not timed)
    ref, _ = render("rule", 1024)
    rule = walk("rule", [k * k * 4 for k in range(4, 17)], ref)
    ns, n = [], 100
    while n <= args.max_stratified:
        ns.append(n)
        n *= 4
    strat = walk("stratified", ns, ref)
    t_rule = rule[-1][2] if rule[-1][1] <= TARGET_MRAD else float("nan")
    if strat[-1][1] <= TARGET_MRAD:
        t_strat, how = strat[-1][2], "measured"
    else:  # extrapolate: error ~ N^-a from the last two points, time ~ N
        (n1, e1, _), (n2, e2, t2) = strat[-2], strat[-1]
        a = math.log(e1 / e2) / math.log(n2 / n1)
        n_need = n2 * (e2 / TARGET_MRAD) ** (1 / a) if a > 0 else float("inf")
        t_strat, how = t2 * n_need / n2, f"extrapolated (error ~ N^-{a:.2f}, N ~ {n_need:.3g})"
    print(f"time to {TARGET_MRAD} mrad: rule {t_rule:.3g} s (N = {rule[-1][0]}), stratified "
          f"{t_strat:.3g} s ({how}); ratio {t_strat / t_rule:.3g}x")


if __name__ == "__main__":
    main()
