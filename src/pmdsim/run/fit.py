"""``pmdsim fit``: fit a BRDF's alphas to fringe images and write the result to a folder.

Images that a pmdsim run wrote (``RUN/fringes/*.tif``) carry that run's numerical error:
the fit reads the run's sampling (:func:`images_sampling_of`) and carries the images' error
to the parameters; integer images carry their quantisation (one count).

OUT/fit.json (every number, ``success`` and ``reason``), fit.txt (the table), fit.png
(modulation against width) and the marker ``pmdsim-fit.json``. The folder is checked before
anything is read or computed (an existing file or folder is refused unless ``overwrite``
and it is a fit folder) and created atomically (:func:`pmdsim.store.folder.atomic_run_dir`).
A fit that *failed* (:attr:`pmdsim.studies.fit.FitResult.success` false: not converged,
an alpha at its bound, or a reduced chi-square above ``max_chi2``) is written all the same,
marked failed in fit.json, fit.txt and the figure's title; the caller decides the exit code.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import ConfigError, InputError, RunConfig
from ..studies.fit import (MAX_CHI2, MAX_RAYS, FitResult, check_fit_resources,
                           fit_fringe_images, format_fit)
from ..studies.fit_stats import NoiseModel
from ..studies.physics_checks import check_physics
from .threads import single_blas
from ..store.folder import atomic_run_dir, check_output_dir
from ..store.tables import write_json

MARKER = "pmdsim-fit.json"


@dataclass(frozen=True)
class FitRun:
    result: FitResult
    text: str
    json: Path
    figure: Path | None
    outdir: Path
    saturated: int = 0
    notes: tuple = ()


def check_fit_output(outdir, overwrite: bool = False) -> Path:
    """Refuse, before any work, an output that may not become a fit folder."""
    final = Path(outdir).absolute()
    if final.exists() and not final.is_dir():
        raise FileExistsError(f"output {final} is an existing file, not a folder: name a new "
                              "folder for fit.json, fit.txt and fit.png")
    check_output_dir(final, overwrite, MARKER)
    return final


def load_fit_images(cfg: RunConfig, image_paths) -> tuple[np.ndarray, NoiseModel | None, int]:
    """The images as (directions, widths, K, H, W) signal values (the sensor's dark level
    subtracted, saturated values NaN), the sensor's noise model (None without an enabled
    ``[sensor]``) and the count of saturated values."""
    from ..measure.images import load_image_stack

    fr = cfg.patterns.fringes
    if fr is None:
        raise ConfigError("fit: the configuration needs [patterns.fringes] (widths_px, shifts, "
                          "directions) describing the images")
    paths = [Path(p) for p in image_paths]
    nd, nw, k = len(fr.directions), len(fr.widths_px), fr.shifts
    stack = load_image_stack(paths).astype(np.float64)
    if stack.shape[0] != nd * nw * k:
        raise InputError(f"fit: {stack.shape[0]} frames in {len(paths)} files, but "
                         f"patterns.fringes describes {nd} directions x {nw} widths x {k} "
                         f"shifts = {nd * nw * k} (order: direction, width, shift)")
    images = stack.reshape(nd, nw, k, *stack.shape[-2:])
    noise = None
    saturated = 0
    sensor = getattr(cfg, "sensor", None)
    if sensor is not None and sensor.enabled:
        from ..scene.sensor import Sensor

        s = Sensor.from_config(sensor)
        noise = NoiseModel.from_sensor(s)
        sat = images >= s.saturation_dn
        saturated = int(sat.sum())
        images = np.where(sat, np.nan, noise.signal(images))
    return images, noise, saturated


def images_sampling_of(image_paths) -> dict | None:
    """The ``[sampling]`` the images were rendered with when they are a pmdsim run's own
    fringe images (``RUN/fringes/*`` or ``RUN/VARIANT/fringes/*`` next to the run's
    ``config.json``; the order a target error chose, from ``statistics.json``), else None."""
    from ..store.schema import CONFIG_NAME

    parents = {Path(p).absolute().parent for p in image_paths}
    if len(parents) != 1:
        return None
    folder = parents.pop()
    run = folder.parent
    if folder.name != "fringes" or not (run / CONFIG_NAME).is_file():
        return None
    try:
        cfg = RunConfig.model_validate_json((run / CONFIG_NAME).read_text())
    except ValueError:
        return None
    out = cfg.sampling.model_dump()
    try:  # the order a target error chose
        stats = json.loads((run / "statistics.json").read_text())
        n = (stats.get("sampling") or {}).get("n_rays")
        if n:
            out.update(n_rays=int(n), target_error_mrad=None)
    except (OSError, ValueError):
        pass
    return out


@single_blas
def run_fit(cfg: RunConfig, image_paths, outdir, *, figure: bool = True, overwrite: bool = False,
            max_chi2: float = MAX_CHI2, max_rays: int = MAX_RAYS) -> FitRun:
    """Fit the configured model's alphas to fringe images (files in the order direction,
    width, shift of ``patterns.fringes``), write fit.json, fit.txt, fit.png to ``outdir``.
    Returns also when the fit failed (``result.success`` false; the files say so)."""
    final = check_fit_output(outdir, overwrite)
    check_fit_resources(cfg, max_rays)  # memory and time, before the images are read
    notes = check_physics(cfg)  # a sensor/display/BRDF that leaves no signal, named
    fr = cfg.patterns.fringes
    images, noise, saturated = load_fit_images(cfg, image_paths)
    finite = images[np.isfinite(images)]
    # integer files (TIFF/PNG counts) are quantised in steps of one count
    step = 1.0 if noise is None and finite.size and np.all(finite == np.round(finite)) else None
    res = fit_fringe_images(cfg, images, fr.widths_px, fr.directions, noise, max_chi2=max_chi2,
                            max_rays=max_rays, quantisation_step=step,
                            images_sampling=images_sampling_of(image_paths))
    text = format_fit(res, cfg.anisotropy.frame)
    if saturated:
        text += f"\n{saturated} saturated values left out"
    fig = None
    with atomic_run_dir(final, overwrite, marker=MARKER) as tmp:
        write_json(tmp / "fit.json", res.as_dict() | {
            "model_name": cfg.brdf.model, "frame": cfg.anisotropy.frame,
            "saturated_values": saturated})
        (tmp / "fit.txt").write_text(text + "\n")
        if figure:
            from ..report.texture import plot_fit

            plot_fit(res, tmp / "fit.png", cfg.anisotropy.frame)
            fig = final / "fit.png"
        (tmp / MARKER).write_text(json.dumps({"name": cfg.name, "kind": "fit",
                                              "success": res.success}) + "\n")
    return FitRun(res, text, final / "fit.json", fig, final, saturated, tuple(notes))
