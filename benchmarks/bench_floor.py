"""Benchmark: how low issue 22's remaining aims can go with today's numerics, measured.

Usage::

    python benchmarks/bench_floor.py [--rounds 20] [--skip-sweep]

It does not compare trees: it measures this tree's irreducible parts and adds them up into
lower bounds (floors) for the aims of issue 22, each generous to the aim:

- **kernel**: ``render_tile`` on 16 camera rows of the Fig. 3 scene (rows 500-515, all on
  the surface), one thread, the best of ``--rounds`` alternations, with the Fig. 3 rule's
  nodes (``n_rays`` 256) and with the rule of ``n_rays`` = 100: the harmonic fringes of
  the three X and three Y widths (what a run computes per ray), and the same rays without
  fringes (phase 1 alone: monitor hits and Ward weights). Nanoseconds per node. The
  embedded rules have fewer nodes per pixel, so their rays cost more each: the main
  rule's figure is the cheapest a ray of the run gets.
- **rays**: the rays a Fig. 3 run traces (every pass, as the run counts them).
- **start-up**: CPU-seconds of a fresh interpreter importing what a run needs before it
  renders (the CLI, the run, the render, the chain, Dask's threaded scheduler, xarray,
  zarr; not matplotlib) and making its first compiled kernel call (loaded from the cache
  this benchmark fills first); the best of 5.
- **sweep** (unless ``--skip-sweep``): the sweep example twice in one process
  (synchronous scheduler, figures on); of the second sweep (a warm worker), the CPU in
  ``Simulation.render_fringes``, in the three sweep figures and in the points' decoding
  and comparison (``chain.decode_fringes``, ``chain.compare``).

Floors printed against the aims:

- Fig. 3 run, CPU-s >= rays x (kernel ns per ray, 256 rule) + start-up: the kernel and
  the imports alone, nothing for the decoding, reconstruction, writing or figures.
- Fig. 3 run, wall >= start-up + rays x (kernel ns per ray) / cores: the imports run on
  one core before the render can start.
- N = 100, M rays per CPU-s <= 1000 / (kernel ns per ray, 100 rule): no time outside the
  kernel; and 1000 / (phase 1 alone) with fringes for free.
- Sweep overhead >= figures / (renders + figures): no decoding, comparison or writing;
  and with the points' decoding and comparison as they are implemented today (not a
  floor of the physics: those could be made cheaper, the figures too).

**Wall-clock figures mean something only on an otherwise idle machine**; the load average
is printed before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIG3 = ROOT / "examples" / "paper_fig3.toml"
SWEEP = ROOT / "examples" / "sweep_roughness.toml"

#: A fresh interpreter: the imports a run needs before its render and one compiled call.
STARTUP_CODE = r"""
import time
c0 = time.process_time()
import numpy as np
import pmdsim.cli, pmdsim.run, pmdsim.render, pmdsim.measure.chain
import dask.threaded, xarray, zarr
c1 = time.process_time()
from pmdsim.kernels import bundle as kb
geo = np.zeros((1, kb.G_SIZE))  # one pixel off the surface: the kernel loads, traces nothing
brdf = np.zeros(kb.B_SIZE)
brdf[kb.B_MODEL] = kb.MODEL_WARD
kb.render_tile(geo, brdf, np.zeros(1), np.zeros(1), np.zeros((0, 2)), 0, 0.01, True,
               np.array([2, 2]), kb.MODE_HARMONIC, np.zeros((0, 1)), np.zeros((0, 1)),
               np.ones(1), np.ones(1), np.zeros((0, 1, 1), np.float32), np.zeros((0, 4)),
               np.empty((1, 6)), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)))
print(c1 - c0, time.process_time() - c1)
"""

#: The sweep example twice in one process; CPU of the second in its renders, its figures,
#: and the points' decoding and comparison with the reference.
SWEEP_CODE = r"""
import json, shutil, sys, time
from pmdsim.render import Simulation
import pmdsim.report.sweep as rs
import pmdsim.measure.chain as chain
spent = {"render": 0.0, "figures": 0.0, "decode": 0.0, "compare": 0.0}
def timed(fn, key):
    def wrapper(*args, **kwargs):
        c = time.thread_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[key] += time.thread_time() - c
    return wrapper
Simulation.render_fringes = timed(Simulation.render_fringes, "render")
rs.sweep_figures = timed(rs.sweep_figures, "figures")
chain.decode_fringes = timed(chain.decode_fringes, "decode")
chain.compare = timed(chain.compare, "compare")
from pmdsim.run.sweep import run_sweep
for k in range(2):
    shutil.rmtree(sys.argv[2], ignore_errors=True)
    for key in spent:
        spent[key] = 0.0
    c0 = time.process_time()
    run_sweep(sys.argv[1], sys.argv[2], scheduler="synchronous", figures=True)
    cpu = time.process_time() - c0
print(json.dumps(dict(spent, cpu=cpu)))
"""


def kernel_ns(rounds: int) -> tuple[dict, dict]:
    """Nanoseconds per node of the bundle kernel (the run's own, ``Simulation._kernel``),
    one thread, best of ``rounds``, as ``({(n_rays, "fringes" | "phase 1"): ns},
    {n_rays: nodes of its rule})``."""
    import tomllib

    import numpy as np

    from pmdsim.config import parse_config
    from pmdsim.kernels import bundle as kb
    from pmdsim.render import Simulation
    from pmdsim.render.geometry_rows import scene_geometry_rows

    raw = tomllib.loads(FIG3.read_text())
    cases, nodes = {}, {}
    for n_rays in (256, 100):
        raw.setdefault("sampling", {})["n_rays"] = n_rays
        cfg = parse_config(raw)
        sim = Simulation.from_config(cfg)
        sc = sim.scene
        geo, _ = scene_geometry_rows(sc, 500, 516)
        if not np.all(geo[:, kb.G_VALID] == 1.0):
            raise SystemExit("rows 500-515 of the Fig. 3 camera are no longer all on the surface")
        sc.sampling.orient(geo, sc.brdf.kernel_params())  # once: orient is not idempotent
        nodes[n_rays] = len(sc.sampling.ray_weights(False))
        k = 2 * np.pi / np.asarray(cfg.patterns.fringes.widths_px, np.float64)
        for name, ku in (("fringes", k), ("phase 1", np.zeros(0))):
            ncols = kb.OUT_FIRST + 4 * ku.size  # the same widths in X and in Y
            kernel = sim._kernel(sc, kb.MODE_HARMONIC, ncols, k_u=ku, k_v=ku, orient=False)
            out, rot = np.empty((geo.shape[0], ncols)), np.zeros((0, 2))

            def call(kernel=kernel, geo=geo, rot=rot, out=out):
                kernel(geo, rot, out)

            call()
            cases[n_rays, name] = (call, geo.shape[0] * nodes[n_rays])
    best = dict.fromkeys(cases, float("inf"))
    for _ in range(rounds):
        for key, (call, _) in cases.items():
            t = time.perf_counter()
            call()
            best[key] = min(best[key], time.perf_counter() - t)
    return {key: best[key] / rays * 1e9 for key, (_, rays) in cases.items()}, nodes


def fig3_rays() -> int:
    """The rays a Fig. 3 run traces (every pass), as :class:`pmdsim.run.RunResult` counts."""
    from pmdsim.config import load_config
    from pmdsim.render import Simulation
    from pmdsim.run.steps import _passes_share

    sim = Simulation.from_config(load_config(FIG3))
    mask = sim.geometry().surface_mask
    share = _passes_share(sim, sim.fringes_smooth(), mask)
    return int(round(int(mask.sum()) * sim.scene.rays_per_pixel * share))


def _python(code: str, args=(), cache: Path | None = None) -> str:
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    p = subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, cwd=ROOT,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"subprocess failed:\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}")
    return p.stdout.strip().splitlines()[-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=20, help="kernel alternations (best of)")
    ap.add_argument("--skip-sweep", action="store_true")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    print(f"load average before: {os.getloadavg()}  ({cores} cores)", flush=True)

    with tempfile.TemporaryDirectory(prefix="pmdsim-bench-floor-") as tmp:
        cache = Path(tmp) / "numba-cache"
        _python(STARTUP_CODE, cache=cache)  # fill the cache: later calls load from it
        starts = [tuple(map(float, _python(STARTUP_CODE, cache=cache).split()))
                  for _ in range(5)]
        imports, first_call = min(starts, key=sum)
        sweep = (None if args.skip_sweep
                 else json.loads(_python(SWEEP_CODE, (SWEEP, Path(tmp) / "sweep"))))
    ns, nodes = kernel_ns(args.rounds)
    rays = fig3_rays()
    start = imports + first_call

    print(f"\nkernel, one thread, best of {args.rounds} (ns per node; 16 Fig. 3 camera rows):")
    for n_rays in (256, 100):
        print(f"  n_rays {n_rays:3d} ({nodes[n_rays]} nodes): phase 1 alone "
              f"{ns[n_rays, 'phase 1']:.2f}, with the 3 + 3 widths {ns[n_rays, 'fringes']:.2f}")
    print(f"Fig. 3 run: {rays:,} rays; start-up {imports:.2f} CPU-s of imports + "
          f"{first_call:.2f} for the first compiled call")
    cpu = rays * ns[256, "fringes"] * 1e-9
    rows = [
        ("Fig. 3 run, CPU-s >= kernel + start-up", cpu + start, "<= 6"),
        ("Fig. 3 run, wall s >= start-up + kernel / cores", start + cpu / cores, "<= 5"),
        ("N = 100, M rays per CPU-s <= kernel alone", 1e3 / ns[100, "fringes"], ">= 200"),
        ("N = 100, M rays per CPU-s <= phase 1 alone", 1e3 / ns[100, "phase 1"], ">= 200"),
    ]
    if sweep is not None:
        share = sweep["figures"] / (sweep["render"] + sweep["figures"])
        chain = sweep["decode"] + sweep["compare"]
        print(f"sweep example, warm worker: {sweep['cpu']:.2f} CPU-s, of it renders "
              f"{sweep['render']:.2f}, figures {sweep['figures']:.2f}, the points' decoding "
              f"{sweep['decode']:.2f} and comparison {sweep['compare']:.2f}")
        rows.append(("sweep, overhead % >= figures / (renders + figures)", 100 * share, "< 25"))
        rows.append(("  + decoding and comparison as implemented",
                     100 * (sweep["figures"] + chain)
                     / (sweep["render"] + sweep["figures"] + chain), "< 25"))
    print(f"\n{'floor':58s} {'value':>8s}   aim")
    for label, value, aim in rows:
        print(f"{label:58s} {value:8.2f}   {aim}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
