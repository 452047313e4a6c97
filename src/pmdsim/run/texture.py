"""Write the machining -> parameters report (``pmdsim texture``) to a folder: JSON with
every number, a text table, a figure. (The BRDF fit's folder, ``pmdsim fit``: :mod:`.fit`.)"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..brdf.turning import TextureParameters, format_texture, texture_parameters
from ..report.texture import plot_texture
from ..store.folder import staged_files
from ..store.tables import write_json


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
        with staged_files(out, ("texture.txt", "texture.png", "texture.json")) as tmp:
            write_json(tmp["texture.json"], p.as_dict())
            tmp["texture.txt"].write_text(text + "\n")
            if figure:
                plot_texture(p, tmp["texture.png"], wavelengths_nm, weights)
        js = out / "texture.json"
        fig = out / "texture.png" if figure else None
    return TextureRun(p, text, js, fig)


@dataclass(frozen=True)
class TopographyRun:
    analysis: object
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
    from ..config import InputError
    from ..report.texture import plot_topography
    from ..topofile import read_topography

    t = read_topography(path, "--from", spacing_mm=spacing_mm, height_unit=height_unit,
                        level=level, fill=fill, outlier_sigma=outlier_sigma)
    h, dx, dy = tp.to_local(t.heights, t.dx, t.dy, radial_axis)
    try:
        a = tp.analyse(h, dx, dy, wavelength_nm, incidence_deg, source=str(path))
    except tp.FlatTopography as err:
        raise InputError(f"--from {path}: {err}") from None
    n = t.heights.size
    outliers = t.invalid - t.not_measured
    text = tp.format_analysis(a) + (
        f"\nfilled {t.invalid} of {n} points ({fill}): {t.not_measured} not measured (NaN/inf "
        f"or the file's marker), {outliers} outliers" if t.invalid else
        f"\nfilled 0 of {n} points: every point measured and finite")
    js = fig = None
    if outdir is not None:
        out = Path(outdir)
        with staged_files(out, ("topography.txt", "topography.png", "topography.json")) as tmp:
            write_json(tmp["topography.json"], a.as_dict() | {
                "reader": t.reader, "invalid_points": t.invalid,
                "not_measured_points": t.not_measured, "radial_axis": radial_axis})
            tmp["topography.txt"].write_text(text + "\n")
            if figure:
                plot_topography(a, h, dx, dy, tmp["topography.png"])
        js = out / "topography.json"
        fig = out / "topography.png" if figure else None
    return TopographyRun(a, text, js, fig)
