"""Benchmark: the compiled render, this tree against a pinned baseline, in one run.

Usage::

    python benchmarks/bench_render.py [--baseline 4c74c4d] [--config examples/paper_fig3.toml]
                                      [--repeat 5] [--workers 2] [--no-compile] [--rounds 1]
                                      [--set sampling.n_rays=100 --set monitor.pixel_model=nearest]

The baseline commit (default ``4c74c4d``, the tree before issue 13's kernel work) is checked
out with ``git worktree`` into a temporary folder. Both trees are measured by the same code
in fresh subprocesses, alternately, with the same settings:

- **compile**: the CPU time of the first ``render_fringes`` of the Fig. 3 sequence with an
  empty ``NUMBA_CACHE_DIR`` minus that of the same call with the kernels cached, i.e. the
  seconds of JIT compilation the render kernels (bundle, synth; not the geometry kernel,
  compiled before) cost a first run (skipped with ``--no-compile``);
- **fringe path**: X and Y, one width, 4 shifts, after compilation: wall and scattered
  rays per CPU-second of the process (``time.process_time``: robust to other processes
  sharing the cores, unlike wall time);
- **Fig. 3 sequence**: X and Y, all configured widths, 4 shifts, at the configured camera
  size: wall (best of ``--repeat``) and rays per CPU-second;
- **agreement**: the largest difference between the two trees' Fig. 3 images, relative to
  their largest value (both compute the same estimator; the kernels differ in rounding).

With ``--rounds R`` the cached-kernel measurements alternate between the trees R times
(baseline, this tree, baseline, ...) and each figure is the median over the rounds, so
that a change of the machine's load during the run hits both trees alike.

``--set SECTION.KEY=VALUE`` overrides a value of the configuration in both trees (the
issue's N = 100 aim: ``--set sampling.n_rays=100``; the nearest-pixel monitor:
``--set monitor.pixel_model=nearest``). Rays per CPU-second count every ray traced,
including the passes of the error estimate (the embedded rules, the replicates), as the
run counts them (``rays_traced``: each pass's own nodes, a pass on a grid of pixels its
grid; the nearest monitor's control variate ``control.rays_share``: the rule, its
embedded rule and the replicates' passes). Until 2026-12-02 every pass of a rule counted
``n_rays`` rays, though the embedded rules have about 0.56 and 0.25 of them: the figures
printed for mode "rule" before then were 1.58-1.66 x the rays actually traced.

It prints both columns, their ratio, the issue's aims (>= 200 M rays per CPU-second at
N = 100; the Fig. 3 sequence in <= 0.3 s wall on 2 cores) and the load average before and
after. **Wall times mean something only on an otherwise idle machine.**
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CODE = r"""
import json, sys, time, tomllib
import numpy as np
from pmdsim.config import parse_config
from pmdsim.render import Simulation
config, repeat, workers, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
raw = tomllib.load(open(config, "rb"))
for item in json.loads(sys.argv[5]):  # --set SECTION.KEY=VALUE overrides
    *path, key = item[0].split(".")
    node = raw
    for part in path:
        node = node.setdefault(part, {})
    node[key] = item[1]
cfg = parse_config(raw)
sim = Simulation.from_config(cfg)
sim.num_workers = workers
fr = cfg.patterns.fringes
widths, dirs, shifts = tuple(fr.widths_px), ("x", "y"), fr.shifts

def timed(fn):
    w0, c0 = time.perf_counter(), time.process_time()
    res = fn()
    return res, time.perf_counter() - w0, time.process_time() - c0

mask = sim.geometry().surface_mask
_, first, first_cpu = timed(lambda: sim.render_fringes(widths, dirs, shifts))
one = [timed(lambda: sim.render_fringes(widths[:1], dirs, shifts))[1:] for _ in range(repeat)]
seq = []
for _ in range(repeat):
    res, w, c = timed(lambda: sim.render_fringes(widths, dirs, shifts))
    seq.append((w, c))
np.save(out, res.images[:, :, :, ::8, ::8])
# every ray traced: the passes of the error estimate (embedded rule, replicates) count too;
# the nearest monitor's control variate counts as the run counts it (control.rays_share)
try:
    from pmdsim.render import control as ctrl
except ImportError:
    ctrl = None
if ctrl is not None and hasattr(ctrl, "rays_share") and ctrl.applies(sim):
    rays = int(round(int(mask.sum()) * sim.scene.rays_per_pixel
                     * ctrl.rays_share(sim, res.sampling["mode"])))
else:
    try:  # the run's own count: each pass's nodes (a rule's embedded rules have fewer than
        # n_rays; rqmc's replicates share n_rays), a pass on a grid of pixels its grid
        import inspect
        from pmdsim.run.steps import _passes_share
        args = (sim, sim.fringes_smooth())
        if len(inspect.signature(_passes_share).parameters) > 2:
            args += (mask,)
        rays = int(round(int(mask.sum()) * sim.scene.rays_per_pixel * _passes_share(*args)))
    except ImportError:  # trees before it: n_rays per pass (overcounts a rule's passes)
        plan = getattr(sim, "plan", None)
        passes = plan(sim.fringes_smooth()) if plan is not None else (sim.scene.sampling,)
        rays = int(mask.sum()) * sum(sim.scene.replace(sampling=p).rays_per_pixel for p in passes)
print(json.dumps({"first": first, "first_cpu": first_cpu, "one_wall": min(w for w, _ in one),
                  "one_cpu": min(c for _, c in one), "seq_wall": min(w for w, _ in seq),
                  "seq_cpu": min(c for _, c in seq), "rays": rays}))
"""


def _run(src: Path, cache: Path, args: list[str]) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache))
    p = subprocess.run([sys.executable, "-c", CODE, *args], env=env, cwd=src,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"render failed in {src}:\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="4c74c4d", help="git commit of the baseline tree")
    ap.add_argument("--config", default=str(ROOT / "examples" / "paper_fig3.toml"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--no-compile", action="store_true", help="skip the empty-cache compile runs")
    ap.add_argument("--rounds", type=int, default=1,
                    help="alternate the cached-kernel runs of the two trees this many times")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="override a configuration value (VALUE as JSON, else a string), e.g. "
                    "--set sampling.n_rays=100 --set monitor.pixel_model=nearest")
    args = ap.parse_args()
    sets = []
    for item in args.set:
        key, _, val = item.partition("=")
        try:
            sets.append((key, json.loads(val)))
        except json.JSONDecodeError:
            sets.append((key, val))

    print(f"load average before: {os.getloadavg()}  ({os.cpu_count()} cores)", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="pmdsim-bench-render-"))
    base_src = tmp / "baseline"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base_src),
                    args.baseline], check=True, capture_output=True)
    trees = {"baseline": base_src / "src", "this tree": ROOT / "src"}
    try:
        res = {}
        cold = {}
        common = [args.config, str(args.repeat), str(args.workers)]
        cache = {name: tmp / f"cache-{name.replace(' ', '-')}" for name in trees}
        for i, (name, src) in enumerate(trees.items()):
            if not args.no_compile:  # empty cache: the first call compiles the kernels
                print(f"[{name}] empty NUMBA_CACHE_DIR ...", flush=True)
                cold[name] = _run(src, cache[name],
                                  common + [str(tmp / f"cold-{i}.npy"), json.dumps(sets)])
        runs = {name: [] for name in trees}
        for r in range(max(args.rounds, 1)):
            for i, (name, src) in enumerate(trees.items()):
                print(f"[{name}] cached kernels, round {r + 1} ...", flush=True)
                runs[name].append(_run(src, cache[name],
                                       common + [str(tmp / f"img-{i}.npy"), json.dumps(sets)]))
        for name in trees:
            warm = {k: float(np.median([run[k] for run in runs[name]])) for k in runs[name][0]}
            warm["compile"] = (None if args.no_compile
                               else cold[name]["first_cpu"] - warm["first_cpu"])
            res[name] = warm
        if args.rounds > 1:
            ratios = [b["seq_cpu"] / a["seq_cpu"]
                      for a, b in zip(runs["baseline"], runs["this tree"])]
            print("Fig. 3 sequence CPU-s, this tree / baseline, per round: "
                  + ", ".join(f"{x:.3f}" for x in ratios))
        a = np.load(tmp / "img-0.npy")
        b = np.load(tmp / "img-1.npy")
        m = np.isfinite(a) & np.isfinite(b)
        diff = np.max(np.abs(a[m] - b[m])) / np.max(np.abs(a[m]))
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_src)],
                       capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)

    rays = res["this tree"]["rays"]
    rows = [
        ("render kernels' JIT compile, CPU-s", "compile", 1.0, None),
        ("fringe path X+Y, 1 width: M rays per CPU-s", "one_cpu", None, 200.0),
        ("fringe path X+Y, 1 width: wall, s", "one_wall", 1.0, None),
        ("Fig. 3 sequence: M rays per CPU-s", "seq_cpu", None, 200.0),
        ("Fig. 3 sequence: wall, s", "seq_wall", 1.0, 0.3),
        ("Fig. 3 sequence: CPU, s", "seq_cpu", 1.0, None),
    ]
    print(f"\n{rays / 1e6:.0f} M scattered rays per Fig. 3 frame set (every pass), "
          f"{args.workers} workers, settings {sets or 'as configured'}")
    print(f"{'':46s} {'baseline':>10s} {'this tree':>10s} {'ratio':>7s} {'aim':>8s}")
    for label, key, scale, aim in rows:
        vals = []
        for name in trees:
            v = res[name][key]
            if v is not None and scale is None:  # a rate
                v = rays / v / 1e6
            vals.append(v)
        if any(v is None for v in vals):
            continue
        ratio = vals[1] / vals[0]
        aim_s = "" if aim is None else (f">= {aim:g}" if scale is None else f"<= {aim:g}")
        print(f"{label:46s} {vals[0]:10.3f} {vals[1]:10.3f} {ratio:7.2f} {aim_s:>8s}")
    print(f"max |this - baseline| / max over the Fig. 3 images: {diff:.2e}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
