"""The top level of a run with variants: statistics, dots and comparison figures of all
variants, read back from their folders."""

from __future__ import annotations

from pathlib import Path

from dataclasses import replace

import numpy as np

from ..config import RunConfig
from ..render import Simulation
from ..report.text import summary_text_of
from ..store.schema import CONFIG_NAME
from ..store.manifest import write_run_manifest
from .steps import run_member
from .result import RunResult, draw_safely
from ..store.schema import load_run
from ..store.tables import write_dot_csv, write_json


def run_variants(plan, geometry, reference, tmp: Path, shared_timings: dict) -> RunResult:
    """Every variant of ``plan`` as a complete run folder ``tmp/<variant>`` (sharing the
    geometry and the specular reference), then the top level: configuration, comparison
    figures, statistics of all variants and the manifest."""
    import time

    cfg = plan.cfg
    compare = plan.figures and cfg.patterns.fringes is not None
    subs, datasets = [], {}
    for name, c, sim in plan.members:
        res, ds = run_member(plan, c, sim, geometry, tmp / name, reference=reference,
                             standalone=False)
        res = replace(res, notes=tuple(plan.notes))
        write_run_manifest(tmp / name, c, res, dict(res.timings, **shared_timings))
        subs.append(res)
        if compare:  # keep only what the comparison figure needs (finest width, k = 0)
            keep = [n for n in ("fringes", "fringe_sums_real", "fringe_sums_imag", "f_hit")
                    if n in ds]
            iw = int(np.argmin(ds["width"].values))
            datasets[name] = ds[keep].isel(width=[iw], shift=[0]).copy(deep=True)
        del ds
    (tmp / CONFIG_NAME).write_text(cfg.model_dump_json(indent=2) + "\n")
    figure_paths: list[Path] = []
    t = time.perf_counter()
    descriptions = {v.name: v.description for v in cfg.variants}
    if compare:
        from ..report import scene as plot

        figure_paths += draw_safely(plan.notes, "fringes_variants.png", plot.plot_variant_fringes,
                                    datasets, tmp / "figures" / "fringes_variants.png",
                                    descriptions=descriptions)
    names = [name for name, _, _ in plan.members]
    figure_paths += write_variant_outputs(cfg, tmp, names, subs, plan.figures, descriptions,
                                          plan.sim, plan.notes)
    plan.notes += [f"{r.config.name}: {n}" for r in subs for n in r.notes]
    if plan.figures and (cfg.patterns.fringes is not None or cfg.patterns.dots is not None):
        plan.steps.advance()
    timings = {k: sum(r.timings.get(k, 0.0) for r in subs)
               for k in ("render", "write", "decode", "diagnostics", "figures")}
    timings["figures"] += time.perf_counter() - t
    timings.update(shared_timings)
    top = RunResult(
        outdir=tmp, dataset_path=None,
        image_paths=tuple(p for r in subs for p in r.image_paths),
        figure_paths=tuple(figure_paths) + tuple(p for r in subs for p in r.figure_paths),
        exposure=float("nan"), shape=subs[0].shape, surface_pixels=subs[0].surface_pixels,
        rays_per_pixel=subs[0].rays_per_pixel, rays_traced=sum(r.rays_traced for r in subs),
        timings=timings, config=cfg, variants=tuple(subs), notes=tuple(plan.notes),
        statistics={r.config.name: r.statistics for r in subs if r.statistics})
    return top


def write_variant_outputs(cfg: RunConfig, tmp: Path, names: list[str], subs, figures: bool,
                           descriptions: dict, sim: Simulation,
                           notes: list | None = None) -> list[Path]:
    """Top-level outputs of a run with variants: statistics.json and summary.txt of all
    variants (deviation statistics and diagnostics), dots.csv, and the comparison figures (deviation, dots). Reads the variants'
    datasets back lazily from their folders."""
    stats = {r.config.name: r.statistics for r in subs if r.statistics}
    if stats:
        write_json(tmp / "statistics.json", {"variants": stats})
        (tmp / "summary.txt").write_text("\n".join(summary_text_of(s) for s in stats.values()))
    decoded = any("directions" in s for s in stats.values())
    has_dots = cfg.patterns.dots is not None
    tables = {}
    if has_dots:
        import csv

        rows = []
        for n in names:
            with open(tmp / n / "dots.csv", newline="") as fh:
                part = list(csv.DictReader(fh))
            tables[n] = [{k: (v if k == "variant" else (int(v) if k == "dot" else float(v)))
                          for k, v in r.items()} for r in part]
            rows += tables[n]
        write_dot_csv(tmp / "dots.csv", rows)
    paths: list[Path] = []
    if not figures or not (decoded or has_dots):
        return paths
    from ..report.dots import dot_figures
    from ..report.overview import plot_variant_deviation

    datasets = {n: load_run(tmp / n) for n in names}
    if decoded:
        paths += draw_safely(notes if notes is not None else [], "deviation_variants.png",
                             plot_variant_deviation, datasets,
                             tmp / "figures" / "deviation_variants.png", descriptions)
    if has_dots:
        images = {n: datasets[n]["dots"] for n in names}  # lazy: one dot image at a time
        paths += draw_safely(notes if notes is not None else [], "of the dots",
                             dot_figures, tmp / "figures", images, tables, sim,
                             descriptions)
    return paths
