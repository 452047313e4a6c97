"""Benchmark: what each part of the default Fig. 3 run costs, by leaving parts out (issue 36:
the 5 s / 9 CPU-s aim against what the run's default outputs weigh).

Usage::

    python benchmarks/bench_parts.py [--rounds 3] [--config examples/paper_fig3.toml]

Runs ``pmdsim simulate`` on the configuration in fresh subprocesses (warm Numba cache:
run ``pmdsim warmup`` or one run first), in alternating rounds, each time with one more
part left out:

1. the shipped defaults;
2. without the figures (``--no-figures``);
3. also without the run diagnostics and the TIFF images (``--no-diagnostics``,
   ``output.write_images = false``);
4. also without the reconstruction (``reconstruct.enabled = false``);
5. also without the measurement chain (``--no-decode``: render and write only).

It prints the median wall and CPU-seconds (the subprocess and the figure processes it
waited for) of each, and what each left-out part cost: the difference to the line above.
The aims of issue 36 (5 s, 9 CPU-s) are for a quiet 2-core machine: the load average is
printed before and after. The changed configurations are written to a temporary folder (a
configuration that names files by a relative path would not find them there).
"""

from __future__ import annotations

import argparse
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
CLI_CODE = "import sys; from pmdsim.cli import app; app(sys.argv[1:])"


def _variant(text: str, *, images: bool, reconstruct: bool) -> str:
    """The configuration text with ``output.write_images`` and ``reconstruct.enabled`` set
    (TOML tables appended or their keys replaced; refuses a text it cannot change)."""
    lines = text.splitlines()
    out, table = [], ""
    seen = {"output": False, "reconstruct": False}
    for line in lines:
        s = line.strip()
        if s.startswith("[") and not s.startswith("[["):
            table = s.strip("[]").strip()
        if table == "output" and s.startswith("write_images"):
            line = f"write_images = {str(images).lower()}"
            seen["output"] = True
        if table == "reconstruct" and s.startswith("enabled"):
            line = f"enabled = {str(reconstruct).lower()}"
            seen["reconstruct"] = True
        out.append(line)
    if not seen["output"]:
        if "[output]" in text:
            raise SystemExit("bench_parts: cannot set output.write_images in this config")
        out += ["", "[output]", f"write_images = {str(images).lower()}"]
    if not seen["reconstruct"]:
        if "[reconstruct]" in text:
            raise SystemExit("bench_parts: cannot set reconstruct.enabled in this config")
        out += ["", "[reconstruct]", f"enabled = {str(reconstruct).lower()}"]
    return "\n".join(out) + "\n"


def _run(args: list[str], out: Path) -> tuple[float, float]:
    """(wall, CPU-seconds of the subprocess and everything it waited for)."""
    shutil.rmtree(out, ignore_errors=True)
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", CLI_CODE, "simulate", *args, "-o", str(out)],
                       capture_output=True, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"bench_parts: pmdsim simulate {' '.join(args)} failed:\n{p.stderr}")
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--config", default=str(ROOT / "examples" / "paper_fig3.toml"))
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="pmdsim-bench-parts-") as tmp:
        tmp = Path(tmp)
        text = Path(a.config).read_text()
        no_images = tmp / "no_images.toml"
        no_images.write_text(_variant(text, images=False, reconstruct=True))
        no_recon = tmp / "no_reconstruction.toml"
        no_recon.write_text(_variant(text, images=False, reconstruct=False))
        quiet = ["--no-figures", "--no-diagnostics"]
        cases = [
            ("the shipped defaults", [a.config]),
            ("without the figures", [a.config, "--no-figures"]),
            ("... the diagnostics and the TIFF images", [str(no_images), *quiet]),
            ("... the reconstruction", [str(no_recon), *quiet]),
            ("... the measurement chain (render, write)", [str(no_recon), *quiet, "--no-decode"]),
        ]
        print(f"load average before: {os.getloadavg()}, cores: {os.cpu_count()}")
        _run([a.config, "--no-figures"], tmp / "first")  # fills caches, untimed
        times: dict[str, list] = {name: [] for name, _ in cases}
        for r in range(a.rounds):
            print(f"round {r + 1}: load average {os.getloadavg()[0]:.2f}")
            for name, args in cases:
                times[name].append(_run(args, tmp / "out"))
        print(f"load average after: {os.getloadavg()}")
    print(f"\nmedians of {a.rounds} alternating rounds (aim of issue 36: <= 5 s, <= 9 CPU-s)")
    print(f"{'':<44}{'wall s':>8}{'CPU-s':>8}{'part: wall s':>15}{'CPU-s':>8}")
    prev = None
    for name, _ in cases:
        w = statistics.median(t[0] for t in times[name])
        c = statistics.median(t[1] for t in times[name])
        part = "" if prev is None else f"{prev[0] - w:>15.2f}{prev[1] - c:>8.2f}"
        print(f"{name:<44}{w:>8.2f}{c:>8.2f}{part}")
        prev = (w, c)
    print("part: what the line's left-out part cost (the line above minus this one)")


if __name__ == "__main__":
    main()
