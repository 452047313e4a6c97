"""Benchmark: the whole warm run and the sweep example, this tree against a previous one,
in alternating rounds (issue 22: "an answer in seconds"; issue 36: the Fig. 3 answer in
5 s and 9 CPU-s).

Usage::

    python benchmarks/bench_run.py --skip-sweep           # this tree vs 6250089, 3 rounds
    python benchmarks/bench_run.py --baseline main --rounds 4
    python benchmarks/bench_run.py --skip-baseline --rounds 2 --skip-sweep
    python benchmarks/bench_run.py --skip-sweep --work /tmp/bench36   # keep the trees' caches
    python benchmarks/bench_run.py --skip-sweep --fig3-config my_fig3.toml

For this working tree and a baseline commit (checked out with ``git worktree`` into a
temporary folder; default ``6250089``, the tree before issue 36) it first fills
each tree's own Numba cache (one untimed ``pmdsim simulate``), then measures, in fresh
subprocesses and in alternating rounds (baseline, this tree, baseline, ...; the machine's
speed drifts by 10-20 % over minutes, so only one run's ratios mean something):

- **warm Fig. 3**: ``pmdsim simulate examples/paper_fig3.toml -o DIR``, wall of the
  subprocess and its CPU-seconds (process, threads and the forked figure processes it
  waited for: ``RUSAGE_CHILDREN``), and the run's own stage table (``pmdsim-run.json``);
  the aims are <= 5 s wall and <= 9 CPU-s (issue 36; the load average is printed before
  every round: the aims are for a quiet 2-core machine). ``--fig3-config`` runs another
  configuration instead (e.g. Fig. 3 with ``n_rays = 64``, a render of the cost the
  pilot's rule will have: what the chain after the render weighs);
- **same results**: every array of the first round's ``run.zarr`` and
  ``statistics.json`` (less timings and dates) compared between the trees, byte for byte
  (a float array that differs is named with its largest difference relative to its largest
  value: a change of the kernels' vector width changes rounding only; a number of
  ``statistics.json`` that differs is named with its relative difference and, where the
  statistics state one, the difference over the number's own stated error ``*_err``);
- **sweep example** (``examples/sweep_roughness.toml``, one process, synchronous
  scheduler): CPU-seconds in all and inside ``Simulation.render_fringes`` (the points'
  fringes and the specular references); overhead = the CPU outside the renders / all CPU
  (aim < 25 %), for a fresh process ("cold": start-up, kernel loading, figures included)
  and for a second sweep in the same process ("warm worker": a process that keeps its
  imports, compiled kernels and geometry, as a sweep's worker processes do);
- **2 worker processes** (``--scheduler processes`` with 2 workers, this tree): the store's
  arrays byte for byte against the one-process sweep.

It prints medians per tree, their ratios, the aims, and the load average before and after
(and before each round). ``--work DIR`` keeps the trees' Numba caches (and the baseline's
work tree) in ``DIR`` between invocations, so that a second run skips the compilation.
``PYTHONDONTWRITEBYTECODE`` is removed from the subprocesses' environment (an installed
package has its byte code; without it every run compiles pmdsim's sources, ~0.5 CPU-s).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIG3 = ROOT / "examples" / "paper_fig3.toml"
SWEEP = ROOT / "examples" / "sweep_roughness.toml"

CLI_CODE = "import sys; from pmdsim.cli import app; app(sys.argv[1:])"

#: The sweep example twice in one process (synchronous scheduler): CPU-seconds in all and
#: in the render calls of each. The second sweep is what a worker process that keeps its
#: imports, compiled kernels and geometry pays.
SWEEP_CODE = r"""
import json, resource, sys, time
t_start = time.process_time()
from pmdsim.render import Simulation
render = [0.0]
original = Simulation.render_fringes
def timed(self, *args, **kwargs):
    c = time.thread_time()
    try:
        return original(self, *args, **kwargs)
    finally:
        render[0] += time.thread_time() - c
Simulation.render_fringes = timed
from pmdsim.run.sweep import run_sweep
out = []
for k, folder in enumerate(sys.argv[2:4]):
    c0, r0, w0 = (time.process_time() if k else t_start), render[0], time.perf_counter()
    run_sweep(sys.argv[1], folder, scheduler="synchronous", figures=True)
    out.append({"cpu": time.process_time() - c0, "render_cpu": render[0] - r0,
                "wall": time.perf_counter() - w0})
print(json.dumps(out))
"""

#: The sweep example on 2 worker processes (this tree only).
PROCESSES_CODE = r"""
import sys
from pmdsim.run.sweep import run_sweep
run_sweep(sys.argv[1], sys.argv[2], scheduler="processes", num_workers=2, figures=False)
"""

COMPARE_CODE = r"""
import json, sys, numpy as np, zarr
from pathlib import Path
a, b, kind = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
name = "run.zarr" if kind == "run" else "sweep.zarr"
za, zb = zarr.open_group(str(a / name), mode="r"), zarr.open_group(str(b / name), mode="r")
ka, kb = sorted(za.array_keys()), sorted(zb.array_keys())
diff = sorted(set(ka) ^ set(kb))
for k in sorted(set(ka) & set(kb)):
    x, y = za[k][...], zb[k][...]
    if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
        if x.shape == y.shape and x.dtype.kind in "fc" and y.dtype.kind in "fc":
            scale = np.nanmax(np.abs(x)) if np.isfinite(x).any() else 0.0
            if scale:
                d = np.nanmax(np.abs(x.astype(np.complex128) - y))
                k = f"{k} ({d / scale:.1e} of its largest value)"
        diff.append(k)
def strip(d):
    if isinstance(d, dict):
        return {k: strip(v) for k, v in d.items() if k not in ("timings", "seconds", "created_utc")}
    return [strip(v) for v in d] if isinstance(d, list) else d
numbers = []
def walk(x, y, path, parent_x):
    if isinstance(x, dict) and isinstance(y, dict):
        for k in sorted(set(x) | set(y)):
            if k not in x or k not in y:
                numbers.append((path + "/" + k, "only in one", None))
            else:
                walk(x[k], y[k], path + "/" + k, x)
    elif isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
        for i, (p, q) in enumerate(zip(x, y)):
            walk(p, q, f"{path}[{i}]", None)
    elif isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
        if x != y:
            rel = abs(x - y) / max(abs(x), abs(y))
            key = path.rsplit("/", 1)[-1]
            e = parent_x.get(key + "_err") if isinstance(parent_x, dict) else None
            over = abs(x - y) / e if isinstance(e, (int, float)) and e > 0 else None
            numbers.append((path, rel, over))
    elif x != y:
        numbers.append((path, "differs", None))
if kind == "run":
    sa = strip(json.loads((a / "statistics.json").read_text()))
    sb = strip(json.loads((b / "statistics.json").read_text()))
    walk(sa, sb, "", None)
    if numbers:
        rel = [n for n in numbers if isinstance(n[1], float)]
        worst = max(rel, key=lambda n: n[1]) if rel else None
        over = [n for n in rel if n[2] is not None]
        most = max(over, key=lambda n: n[2]) if over else None
        text = f"statistics.json ({len(numbers)} values"
        if worst:
            text += f"; largest relative difference {worst[1]:.1e} at {worst[0]}"
        if most:
            text += f"; largest difference / its stated error {most[2]:.2g} at {most[0]}"
        other = [n[0] for n in numbers if not isinstance(n[1], float)]
        if other:
            text += f"; not numbers: {', '.join(other[:5])}"
        diff.append(text + ")")
print(json.dumps({"arrays": len(set(ka) | set(kb)), "different": diff}))
"""


def _env(src: Path, cache: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src), MPLBACKEND="Agg", NUMBA_CACHE_DIR=str(cache))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _run(code: str, args: list, src: Path, cache: Path, cwd: Path) -> tuple[float, float, str]:
    """(wall, CPU-seconds of the subprocess and everything it waited for, stdout)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code, *map(str, args)], check=False,
                       env=_env(src, cache), cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"{args} failed in {src}:\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return wall, cpu, p.stdout


class Tree:
    def __init__(self, name: str, src: Path, work: Path):
        self.name, self.src, self.work = name, src, work / name
        self.work.mkdir(exist_ok=True)
        self.cache = self.work / "numba-cache"
        self.fig3: list[dict] = []
        self.sweep: list[dict] = []

    def prepare(self, fig3: bool, sweep: bool) -> None:
        """Untimed: compile the kernels the measured commands use into the tree's cache."""
        print(f"[{self.name}] first runs: compile the kernels into its cache ...", flush=True)
        if fig3:
            shutil.rmtree(self.work / "compile", ignore_errors=True)
            _run(CLI_CODE, ["simulate", FIG3, "-o", self.work / "compile", "--no-figures"],
                 self.src, self.cache, self.work)
            shutil.rmtree(self.work / "compile", ignore_errors=True)
        if sweep:
            shutil.rmtree(self.work / "compile-sweep", ignore_errors=True)
            _run(CLI_CODE, ["sweep", SWEEP, "-o", self.work / "compile-sweep", "--scheduler",
                            "synchronous", "--no-figures"], self.src, self.cache, self.work)

    def fig3_round(self, k: int) -> None:
        out = self.work / f"fig3-{k}"
        shutil.rmtree(out, ignore_errors=True)
        load = os.getloadavg()[0]
        wall, cpu, _ = _run(CLI_CODE, ["simulate", FIG3, "-o", out], self.src, self.cache,
                            self.work)
        stages = json.loads((out / "pmdsim-run.json").read_text()).get("timings_s", {})
        self.fig3.append({"wall": wall, "cpu": cpu, "stages": stages, "load": load})
        print(f"[{self.name}] warm Fig. 3 round {k + 1}: {wall:.2f} s wall, {cpu:.2f} CPU-s "
              f"(load average {load:.2f} before)", flush=True)
        if k:
            shutil.rmtree(out, ignore_errors=True)

    def sweep_round(self, k: int) -> None:
        folders = [self.work / f"sweep-{k}-{j}" for j in range(2)]
        _, _, text = _run(SWEEP_CODE, [SWEEP, *folders], self.src, self.cache, self.work)
        cold, warm = json.loads(text.strip().splitlines()[-1])
        self.sweep.append({"cold": cold, "warm": warm})
        print(f"[{self.name}] sweep round {k + 1}: cold {cold['cpu']:.2f} CPU-s "
              f"({_overhead(cold):.0f} % overhead), warm worker {warm['cpu']:.2f} CPU-s "
              f"({_overhead(warm):.0f} %)", flush=True)
        for f in folders[1:] if k == 0 else folders:
            shutil.rmtree(f, ignore_errors=True)


def _overhead(r: dict) -> float:
    return 100.0 * (1.0 - r["render_cpu"] / r["cpu"])


def _median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def rows(t: Tree) -> dict:
    out = {}
    if t.fig3:
        out["fig3_wall"] = _median([r["wall"] for r in t.fig3])
        out["fig3_cpu"] = _median([r["cpu"] for r in t.fig3])
        out["fig3_load"] = _median([r["load"] for r in t.fig3])
        for st in ("geometry", "reference", "render", "decode", "diagnostics", "write",
                   "figures", "total"):
            out["stage_" + st] = _median([r["stages"].get(st) for r in t.fig3])
    if t.sweep:
        for kind in ("cold", "warm"):
            out[f"sweep_{kind}_cpu"] = _median([r[kind]["cpu"] for r in t.sweep])
            out[f"sweep_{kind}_render"] = _median([r[kind]["render_cpu"] for r in t.sweep])
            out[f"sweep_{kind}_overhead"] = _median([_overhead(r[kind]) for r in t.sweep])
    return out


LABELS = [
    ("fig3_wall", "warm Fig. 3 run, wall (s)", "<= 5"),
    ("fig3_cpu", "warm Fig. 3 run, CPU-s (with figure processes)", "<= 9"),
    ("fig3_load", "  load average before its rounds", ""),
    ("stage_geometry", "  stage: geometry (s)", ""),
    ("stage_reference", "  stage: specular reference (s)", ""),
    ("stage_render", "  stage: render (s)", ""),
    ("stage_decode", "  stage: decoding, deviation, reconstruction (s)", ""),
    ("stage_diagnostics", "  stage: diagnostics (s)", ""),
    ("stage_write", "  stage: writing, waited for (s)", ""),
    ("stage_figures", "  stage: figures, waited for (s)", ""),
    ("stage_total", "  the run's own total, after start-up (s)", ""),
    ("sweep_cold_cpu", "sweep example, fresh process, CPU-s", ""),
    ("sweep_cold_render", "  of it in the render calls, CPU-s", ""),
    ("sweep_cold_overhead", "  overhead: CPU outside the renders (%)", "< 25"),
    ("sweep_warm_cpu", "sweep example, warm worker process, CPU-s", ""),
    ("sweep_warm_render", "  of it in the render calls, CPU-s", ""),
    ("sweep_warm_overhead", "  overhead: CPU outside the renders (%)", "< 25"),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default="6250089", help="commit of the previous tree")
    ap.add_argument("--fig3-config", type=Path, default=None,
                    help="the configuration of the 'Fig. 3' rounds (default: the example)")
    ap.add_argument("--work", type=Path, default=None,
                    help="keep the trees' caches and the baseline's work tree in this folder")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--skip-baseline", action="store_true")
    ap.add_argument("--skip-sweep", action="store_true")
    ap.add_argument("--skip-fig3", action="store_true")
    ap.add_argument("--skip-processes", action="store_true",
                    help="skip the 2-worker-process sweep (starts a local cluster)")
    args = ap.parse_args()
    global FIG3
    if args.fig3_config is not None:
        FIG3 = args.fig3_config.resolve()
    print(f"load average before: {os.getloadavg()}, cores: {os.cpu_count()}", flush=True)
    keep = args.work is not None
    with (contextlib.nullcontext(str(args.work)) if keep
          else tempfile.TemporaryDirectory(prefix="pmdsim-bench-run-")) as tmp:
        tmp = Path(tmp)
        tmp.mkdir(parents=True, exist_ok=True)
        trees = []
        base = tmp / f"baseline-tree-{args.baseline}"
        if not args.skip_baseline:
            if not (base / "src").is_dir():
                subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach",
                                str(base), args.baseline], check=True, capture_output=True)
            trees.append(Tree("baseline", base / "src", tmp))
        trees.append(Tree("this", ROOT / "src", tmp))
        try:
            for t in trees:
                t.prepare(not args.skip_fig3, not args.skip_sweep)
            for k in range(args.rounds):
                for t in trees:
                    if not args.skip_fig3:
                        t.fig3_round(k)
                    if not args.skip_sweep:
                        t.sweep_round(k)
            same = {}
            if len(trees) == 2 and args.rounds > 0:
                if not args.skip_fig3:
                    same["Fig. 3 run"] = _compare(trees[0].work / "fig3-0",
                                                  trees[1].work / "fig3-0", "run")
                if not args.skip_sweep:
                    same["sweep example"] = _compare(trees[0].work / "sweep-0-0",
                                                     trees[1].work / "sweep-0-0", "sweep")
            if not args.skip_sweep and not args.skip_processes and args.rounds > 0:
                this = trees[-1]
                print("[this] sweep example on 2 worker processes ...", flush=True)
                _run(PROCESSES_CODE, [SWEEP, this.work / "sweep-processes"], this.src,
                     this.cache, this.work)
                same["sweep: 2 worker processes vs 1 process (this tree)"] = _compare(
                    this.work / "sweep-0-0", this.work / "sweep-processes", "sweep")
        finally:
            if not args.skip_baseline and not keep:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                str(base)], check=False, capture_output=True)
    print(f"load average after: {os.getloadavg()}")
    table = {t.name: rows(t) for t in trees}
    cols = list(table)
    head = f"{'':50}" + "".join(f"{c:>11}" for c in cols) + f"{'ratio':>8}{'aim':>7}"
    print(f"\nmedians of {args.rounds} alternating rounds\n{head}\n" + "-" * len(head))
    for key, label, aim in LABELS:
        vals = [table[c].get(key) for c in cols]
        if all(v is None for v in vals):
            continue
        cells = "".join(f"{v:11.3g}" if v is not None else f"{'-':>11}" for v in vals)
        ratio = (f"{vals[1] / vals[0]:8.2f}" if len(vals) == 2 and None not in vals and vals[0]
                 else f"{'':>8}")
        print(f"{label:50}{cells}{ratio}{aim:>7}")
    for what, r in same.items():
        verdict = ("identical" if not r["different"]
                   else f"DIFFERENT: {', '.join(r['different'])}")
        print(f"same bytes, {what}: {r['arrays']} arrays, {verdict}")
    print("\nratio = this tree / baseline; wall and CPU-s of the subprocess (figure processes "
          "included). Timings mean something only on an otherwise idle machine.")


def _compare(a: Path, b: Path, kind: str) -> dict:
    _, _, text = _run(COMPARE_CODE, [a, b, kind], ROOT / "src", Path(tempfile.gettempdir()),
                      ROOT)
    return json.loads(text.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
