"""Benchmark: writing a run's dataset and drawing its default figures (issue 13, item 1).

Usage::

    python benchmarks/bench_output.py [--config examples/paper_fig3.toml] [--repeat 3]

Runs the configuration once (no figures) and loads its dataset, then measures in this
process, each the best of ``--repeat``:

- **writing** ``run.zarr``: this tree's :func:`pmdsim.store.writer.write_dataset` (Blosc LZ4,
  rounded and compressed one image at a time on Dask threads) against the previous way,
  kept here as the baseline (Blosc zstd level 5, the whole dataset rounded at once, then
  written): CPU-seconds of the process (all threads), wall, bytes, and the peak of NumPy
  allocations during the write (``tracemalloc``);
- **figures**: CPU-seconds to draw each default figure in this process.

Timings mean something only on an otherwise idle machine (the load average is printed).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _old_write(ds, path):
    """The writer before issue 13: zstd level 5, a rounded copy of every variable first."""
    from zarr.codecs import BloscCodec

    from pmdsim.store import writer as d

    enc = d._encoding(ds)
    for e in enc.values():
        e["compressors"] = (BloscCodec(cname="zstd", clevel=5, shuffle="bitshuffle"),)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Consolidated metadata")
        d.storage_form(ds, lazy=False).to_zarr(path, mode="w-", consolidated=True,
                                              encoding=enc, zarr_format=3)


def _measure(fn, repeat: int) -> dict:
    """Best CPU time of ``repeat`` runs, then one more under ``tracemalloc`` for the peak
    (tracing slows every allocation: it is not timed)."""
    best = None
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        size = fn()
        r = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c,
             "mb": size / 1e6}
        best = r if best is None or r["cpu_s"] < best["cpu_s"] else best
    tracemalloc.start()
    fn()
    best["peak_mb"] = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "examples" / "paper_fig3.toml")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from pmdsim import load_run
    from pmdsim.config import load_config
    from pmdsim.run import run_simulation
    from pmdsim.store.writer import write_dataset
    from pmdsim.run.figures import _simulation, draw_one, figure_names
    from pmdsim.report.text import description

    print(f"load average before: {os.getloadavg()}, cores: {os.cpu_count()}")
    cfg = load_config(args.config)
    with tempfile.TemporaryDirectory(prefix="pmdsim-bench-output-") as tmp:
        tmp = Path(tmp)
        run_simulation(cfg, tmp / "run", figures=False)
        ds = load_run(tmp / "run").load()

        def writer(fn):
            def go():
                path = tmp / "w.zarr"
                shutil.rmtree(path, ignore_errors=True)
                fn(ds, path)
                return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
            return go

        old = _measure(writer(_old_write), args.repeat)
        new = _measure(writer(write_dataset), args.repeat)
        print(f"\n{'writing run.zarr':28}{'previous':>12}{'this tree':>12}{'ratio':>8}")
        for key, label in (("cpu_s", "CPU s (all threads)"), ("wall_s", "wall s"),
                           ("mb", "MB on disk"), ("peak_mb", "peak NumPy MB (tracemalloc)")):
            print(f"{label:28}{old[key]:12.3g}{new[key]:12.3g}{new[key] / old[key]:8.2f}")

        sim = _simulation(ds)
        names = figure_names(ds, "summary")
        for n in names:  # imports, kernel loading
            draw_one(ds, n, tmp / "fig", cfg.name, description(cfg), sim)
        print(f"\n{'figure (default set)':28}{'CPU s':>12}")
        total = 0.0
        for n in names:
            c = time.process_time()
            for _ in range(args.repeat):
                draw_one(ds, n, tmp / "fig", cfg.name, description(cfg), sim)
            t = (time.process_time() - c) / args.repeat
            total += t
            print(f"{n:28}{t:12.3g}")
        print(f"{'all, drawn one after another':28}{total:12.3g}")
    print(f"\nload average after: {os.getloadavg()}. Timings are only meaningful on an idle "
          "machine.")


if __name__ == "__main__":
    main()
