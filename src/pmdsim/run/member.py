"""One member of a run (the run itself, or one variant): render, write images and
dataset, measure, diagnose, draw."""

from __future__ import annotations

import contextlib
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from dataclasses import replace

from ..config import RunConfig
from ..scene.sensor import Sensor, capture_dn
from ..measure import chain
from ..render import Geometry, Simulation
from ..studies import coverage
from . import files as pio
from .dataset import CONFIG_NAME, DATASET_NAME, build_dataset, write_dataset
from ..report.text import description, summary_text_of
from .dataset import assign_to_dataset, dot_dataset_variables
from .diagnostics import diagnose_run
from .figures import (FIGURES, early_names, figure_names, figure_plan, import_in_background,
                      start_drawings)
from .result import RunResult, _Steps, draw_safely


def run_member(cfg: RunConfig, sim: Simulation, geometry: Geometry, folder: Path,
                steps: _Steps, figures: bool, inputs, reference=None,
                standalone: bool = True, diagnostics: bool = True) -> tuple[RunResult, object]:
    """Render one configuration (no variants) and write its images, dataset, config and
    figures into ``folder`` (no manifest). Returns its result and its in-memory dataset.

    With a ``reference`` the fringes are decoded and compared with it (statistics.json,
    summary.txt, chain variables and figures). Dots get their moments (dots.csv); their
    figures are drawn here only for a ``standalone`` run (a run with variants draws them
    for all variants together). With ``diagnostics`` (and a lobe) the run diagnostics go
    into the dataset, statistics.json and summary.txt, and their warnings into the result."""
    dots, image_files, levels, n_tiles = inputs
    folder.mkdir(parents=True, exist_ok=True)
    if figures:
        import_in_background()  # matplotlib, while the render runs without the GIL
    timings: dict[str, float] = {}
    fr_cfg = cfg.patterns.fringes
    n_calls = (fr_cfg is not None) + bool(dots) + (levels is not None)

    t = time.perf_counter()
    fringes = dot_images = images = None
    if fr_cfg is not None:
        base = steps.done
        fringes = sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts,
                                     progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    if dots:
        base = steps.done
        dot_images = sim.render_dots(dots, progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    if levels is not None:
        base = steps.done
        images = sim.render_images(levels, progress=steps.tiles())
        steps.finish_render(base, n_tiles)
    timings["render"] = time.perf_counter() - t
    # nothing empty is written as if it were a result; bundles off the monitor are flagged
    coverage.check_rendered(None if fringes is None else fringes.images, dot_images)
    off_monitor = None if fringes is None else coverage.off_monitor_mask(
        fringes.f_total, fringes.f_hit, geometry.surface_mask,
        cfg.diagnostics.max_off_monitor_fraction)
    sensor = Sensor.from_config(cfg.sensor)
    if sensor.enabled:  # what the camera writes: digital numbers (docs/system.md)
        if fringes is not None:
            fringes = replace(fringes, images=capture_dn(sensor, fringes.images, 0))
        if dot_images is not None:
            dot_images = capture_dn(sensor, dot_images, 2)
        if images is not None:
            images = capture_dn(sensor, images, 3)

    t = time.perf_counter()
    out = cfg.output
    stacks = [a for a in (None if fringes is None else fringes.images, dot_images, images)
              if a is not None]
    exposure = (pio.exposure_factor(stacks, out.bit_depth) if not sensor.enabled
                else 2.0 ** min(0, out.bit_depth - sensor.bit_depth))
    with contextlib.ExitStack() as stack:
        # the image files are written by a thread while the chain runs (zlib and NumPy
        # release the GIL); on an error the with-block waits for it before unwinding
        writer = stack.enter_context(ThreadPoolExecutor(1, thread_name_prefix="pmdsim-images"))
        ds = build_dataset(cfg, geometry, fringes, dots, dot_images, image_files, images,
                           exposure, sim.scene.rays_per_pixel)
        if off_monitor is not None:
            ds["lobe_off_monitor"] = (("row", "col"), off_monitor, {
                "units": "bool", "description": "surface pixels whose bundle puts more than "
                f"diagnostics.max_off_monitor_fraction = {cfg.diagnostics.max_off_monitor_fraction:g}"
                " of its weight off the monitor (never valid; counted)"})
        if fringes is not None and fringes.sums is not None:
            # the dataset holds the sums' real and imaginary parts: free the complex copy
            # (2 directions x 3 widths x 16 bytes per pixel, 480 MB at 5 MP)
            fringes = replace(fringes, sums=None)
        images_written = writer.submit(pio.write_images, folder, cfg, fringes, dots,
                                       dot_images, image_files, images, exposure,
                                       workers=1) if out.write_images else None
        steps.advance()
        timings["write"] = time.perf_counter() - t

        drawings = []
        stack.callback(lambda: [d.close() for d in drawings])  # an error ends them
        started: list[str] = []

        def draw(names, ds):
            """Fork the drawing processes of the figures ``names`` not started yet."""
            names = [n for n in names if n not in started]
            started.extend(names)
            drawings.extend(start_drawings(names, folder / "figures", cfg.name,
                                           description(cfg), ds, sim, out.figure_workers))

        decoding = reference is not None and fringes is not None
        if figures:
            if reference is not None:
                reference.settle()  # no fork while its reconstruction's thread runs
            # the set-up and fringe figures need nothing of the chain: drawn meanwhile
            draw(early_names(figure_plan(ds, out.figure_set, decoding)), ds)

        t = time.perf_counter()
        stats: dict = {}
        if decoding:
            measured = chain.compare(
                chain.decode_fringes(fringes, cfg.monitor.resolution, cfg.decode,
                                     sensor.saturation_dn if sensor.enabled else None),
                reference.decoded, geometry, reference.distance_mm, cfg.monitor.pixel_pitch_mm,
                cfg.decode, len(fringes.shifts),
                slope_geometry=chain.SlopeGeometry(
                    geometry.points, sim.scene.camera.position, sim.scene.monitor),
                off_monitor=off_monitor)
            stats = chain.statistics(measured, cfg.name)
            ds = assign_to_dataset(ds, measured, stats)
            if figures:
                # the chain's figures (overview, deviation maps, ...) need neither the
                # reconstruction nor the diagnostics: drawn while those run
                draw([n for n in figure_names(ds, out.figure_set)
                      if FIGURES[n][1] == "chain"], ds)
            from . import reconstruction as recon

            if recon.wanted(cfg, measured.directions):
                rvars, rstats = recon.from_chain(cfg, sim.scene, measured,
                                                 reference.reconstruction)
                stats.update(rstats)
                for name in ("surface_x_mm", "surface_y_mm"):
                    if name in rvars:
                        dims, data, attrs = rvars.pop(name)
                        ds = ds.assign_coords({dims[0]: (dims, data, attrs)})
                for name, var in rvars.items():
                    ds[name] = var
                ds.attrs["statistics_json"] = json.dumps(stats)
            del measured
        dot_table = []
        if dot_images is not None:
            dot_table = chain.dot_table(dot_images, dots, cfg.name)
            for name, var in dot_dataset_variables(dot_table).items():
                ds[name] = var
            pio.write_dot_csv(folder / "dots.csv", dot_table)
        timings["decode"] = time.perf_counter() - t

        t = time.perf_counter()
        statistics = dict(stats)  # statistics.json: the chain's (when decoded) + diagnostics
        diagnosed = diagnose_run(cfg, sim, geometry, exclude=off_monitor) if diagnostics else None
        if diagnosed is not None:
            ds = ds.assign_coords(diagnosed.coords)
            for name, var in diagnosed.variables.items():
                ds[name] = var
            statistics.setdefault("name", cfg.name)
            statistics["diagnostics"] = diagnosed.summary
            ds.attrs["statistics_json"] = json.dumps(statistics)
            steps.advance()
        timings["diagnostics"] = time.perf_counter() - t

        if figures:  # the reconstruction's figures are drawn while the dataset is written
            draw(figure_names(ds, out.figure_set), ds)
        t = time.perf_counter()
        write_dataset(ds, folder / DATASET_NAME)
        (folder / CONFIG_NAME).write_text(cfg.model_dump_json(indent=2) + "\n")
        if statistics:
            (folder / "statistics.json").write_text(json.dumps(statistics, indent=2) + "\n")
            (folder / "summary.txt").write_text(summary_text_of(statistics))
        image_paths = images_written.result() if images_written is not None else []
        steps.advance()
        timings["write"] += time.perf_counter() - t

        figure_paths: list[Path] = []
        notes: list[str] = []
        t = time.perf_counter()
        if figures:
            # the run waits only for what the drawing processes have left to do
            for d in drawings:
                figure_paths += d.paths(notes)
            order = {n: i for i, n in enumerate(FIGURES)}
            figure_paths.sort(key=lambda p: order.get(p.stem, len(order)))
            if dot_table and standalone:
                from ..report import chain as plot_chain

                figure_paths += draw_safely(notes, "of the dots", plot_chain.dot_figures,
                                            folder / "figures", {cfg.name: dot_images},
                                            {cfg.name: dot_table}, sim, {})
            steps.advance()
        timings["figures"] = time.perf_counter() - t

    surface_pixels = int(geometry.surface_mask.sum())
    result = RunResult(
        outdir=folder, dataset_path=folder / DATASET_NAME, image_paths=tuple(image_paths),
        figure_paths=tuple(figure_paths), exposure=exposure, shape=sim.shape,
        surface_pixels=surface_pixels,
        rays_per_pixel=sim.scene.rays_per_pixel * sim.scene.camera.rays_per_pixel,
        rays_traced=surface_pixels * sim.scene.rays_per_pixel * sim.scene.camera.rays_per_pixel
        * n_calls, timings=timings,
        config=cfg, statistics=statistics, notes=tuple(notes),
        warnings=() if diagnosed is None else diagnosed.warnings)
    return result, ds
