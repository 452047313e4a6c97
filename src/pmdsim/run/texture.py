"""Write the machining -> parameters report (``pmdsim texture``) to a folder: JSON with
every number, a text table, a figure. (The BRDF fit's folder, ``pmdsim fit``: :mod:`.fit`.)"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ..brdf.turning import TextureParameters, format_texture, texture_parameters
from ..report.texture import plot_texture


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


