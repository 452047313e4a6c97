"""Write the machining -> parameters report (``pmdsim texture``) and a BRDF fit
(``pmdsim fit``) to a folder: JSON with every number, a text table, a figure."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..brdf.turning import TextureParameters, format_texture, texture_parameters
from ..config import ConfigError, RunConfig
from ..report.texture import plot_fit, plot_texture
from ..studies.fit import FitResult, NoiseModel, fit_fringe_images, format_fit
from .threads import single_blas


@dataclass(frozen=True)
class TextureRun:
    parameters: TextureParameters
    text: str
    json: Path | None
    figure: Path | None


def run_texture(outdir=None, *, figure: bool = True, wavelengths_nm=(610.0, 545.0, 465.0),
                weights=(1.0, 1.0, 1.0), **kwargs) -> TextureRun:
    """:func:`~pmdsim.brdf.turning.texture_parameters` (``kwargs``), written to ``outdir``
    (texture.json, texture.txt, texture.png) if given."""
    p = texture_parameters(**kwargs)
    text = format_texture(p)
    js = fig = None
    if outdir is not None:
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        js = out / "texture.json"
        js.write_text(json.dumps(p.as_dict(), indent=2))
        (out / "texture.txt").write_text(text + "\n")
        if figure:
            fig = plot_texture(p, out / "texture.png", wavelengths_nm, weights)
    return TextureRun(p, text, js, fig)


@dataclass(frozen=True)
class FitRun:
    result: FitResult
    text: str
    json: Path
    figure: Path | None


@single_blas
def run_fit(cfg: RunConfig, image_paths, outdir, *, figure: bool = True) -> FitRun:
    """Fit the configured model's alphas to fringe images (files in the order direction,
    width, shift of ``patterns.fringes``), write fit.json, fit.txt, fit.png to ``outdir``."""
    from ..measure.images import load_image_stack

    fr = cfg.patterns.fringes
    if fr is None:
        raise ConfigError("fit: the configuration needs [patterns.fringes] (widths_px, shifts, "
                          "directions) describing the images")
    paths = [Path(p) for p in image_paths]
    nd, nw, k = len(fr.directions), len(fr.widths_px), fr.shifts
    stack = load_image_stack(paths).astype(np.float64)
    if stack.shape[0] != nd * nw * k:
        raise ConfigError(f"fit: {stack.shape[0]} frames in {len(paths)} files, but "
                          f"patterns.fringes describes {nd} directions x {nw} widths x {k} "
                          f"shifts = {nd * nw * k} (order: direction, width, shift)")
    images = stack.reshape(nd, nw, k, *stack.shape[-2:])
    noise = None
    sensor = getattr(cfg, "sensor", None)
    if sensor is not None and sensor.enabled:
        from ..scene.sensor import Sensor

        s = Sensor.from_config(sensor)
        noise = NoiseModel(s.gain, s.dark_noise_electrons)
    res = fit_fringe_images(cfg, images, fr.widths_px, fr.directions, noise)
    text = format_fit(res, cfg.anisotropy.frame)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    js = out / "fit.json"
    js.write_text(json.dumps(res.as_dict() | {"model": cfg.brdf.model,
                                              "frame": cfg.anisotropy.frame}, indent=2))
    (out / "fit.txt").write_text(text + "\n")
    fig = plot_fit(res, out / "fit.png", cfg.anisotropy.frame) if figure else None
    return FitRun(res, text, js, fig)


@dataclass(frozen=True)
class TopographyRun:
    analysis: "object"
    text: str
    json: Path | None
    figure: Path | None


def run_topography(path, outdir=None, *, figure: bool = True, spacing_mm=None,
                   height_unit: str = "um", radial_axis: str = "y", level: str = "plane",
                   fill: str = "nearest", outlier_sigma=None, wavelength_nm: float = 545.0,
                   incidence_deg: float = 0.0) -> TopographyRun:
    """``pmdsim texture --from FILE``: read a measured topography
    (:func:`pmdsim.topofile.read_topography`, errors name ``--from``), analyse it in the
    local frame (:func:`pmdsim.brdf.topography.analyse`) and write topography.json,
    topography.txt and topography.png to ``outdir`` if given."""
    from ..brdf import topography as tp
    from ..report.texture import plot_topography
    from ..topofile import read_topography

    t = read_topography(path, "--from", spacing_mm=spacing_mm, height_unit=height_unit,
                        level=level, fill=fill, outlier_sigma=outlier_sigma)
    h, dx, dy = tp.to_local(t.heights, t.dx, t.dy, radial_axis)
    a = tp.analyse(h, dx, dy, wavelength_nm, incidence_deg, source=str(path))
    text = tp.format_analysis(a)
    js = fig = None
    if outdir is not None:
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        js = out / "topography.json"
        js.write_text(json.dumps(a.as_dict() | {"reader": t.reader, "invalid_points": t.invalid,
                                                "radial_axis": radial_axis}, indent=2))
        (out / "topography.txt").write_text(text + "\n")
        if figure:
            fig = plot_topography(a, h, dx, dy, out / "topography.png")
    return TopographyRun(a, text, js, fig)
