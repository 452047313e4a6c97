"""What a run did (:class:`RunResult`) and the run-wide progress counter."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..config import RunConfig

ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True)
class RunResult:
    """What :func:`run_simulation` did.

    Attributes
    ----------
    outdir : Path
        The complete run folder.
    dataset_path : Path or None
        ``outdir / "run.zarr"``; None for a run with variants (see ``variants``).
    image_paths, figure_paths : tuple of Path
        Written image files (empty when ``output.write_images`` is false) and figures.
    exposure : float
        Run-wide factor from camera values to image integers (``pixel = value * exposure``);
        NaN for a run with variants (each variant has its own).
    shape : (int, int)
        Camera (height, width), px.
    surface_pixels : int
        Pixels whose vision ray hits the surface.
    rays_per_pixel : int
        Scattered rays per pixel: N (P included; 1 for the mirror) times the camera's vision
        rays per pixel (sub-pixels x aperture samples).
    rays_traced : int
        Scattered rays traced in all render passes (surface pixels x rays per pixel x passes).
    timings : dict
        Wall times in s: ``geometry``, ``render``, ``write``, ``figures``, ``total``.
    config : RunConfig
    variants : tuple of RunResult
        One result per variant (folder ``outdir/<name>``); empty without variants.
    notes : tuple of str
        What was skipped and why (e.g. decoding, when the fringe widths do not allow it).
    statistics : dict
        The content of ``statistics.json``: the measurement chain's statistics (when
        decoded) and the run diagnostics under ``"diagnostics"`` (when computed);
        ``{variant: ...}`` for a run with variants; empty when there is neither.
    warnings : tuple of pmdsim.studies.diagnostic_warnings.DiagnosticWarning
        The diagnostics' warnings for this run (each names the setting that fixes it);
        empty for a run with variants (see each variant's).
    """

    outdir: Path
    dataset_path: Path | None
    image_paths: tuple[Path, ...]
    figure_paths: tuple[Path, ...]
    exposure: float
    shape: tuple[int, int]
    surface_pixels: int
    rays_per_pixel: int
    rays_traced: int
    timings: dict = field(default_factory=dict)
    config: RunConfig | None = None
    variants: tuple["RunResult", ...] = ()
    notes: tuple[str, ...] = ()
    statistics: dict = field(default_factory=dict)
    warnings: tuple = ()
    #: bytes of the run folder by part (``total``, ``run.zarr``, ``images``, ``figures``,
    #: ``other``), measured when it was complete
    sizes: dict = field(default_factory=dict)

    @property
    def rays_per_second(self) -> float:
        """Scattered rays per second of render time."""
        t = self.timings.get("render", 0.0)
        return self.rays_traced / t if t > 0 else float("nan")



class _Steps:
    """Turns the per-render-call tile callbacks into one run-wide ``progress(done, total)``."""

    def __init__(self, progress: ProgressFn | None, total: int):
        self.progress = progress
        self.total = total
        self.done = 0

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)

    def tiles(self, n_tiles: int | None = None) -> ProgressFn | None:
        """A callback for one render call: reports its tiles on top of the steps so far.
        With ``n_tiles`` (the steps the plan gave the call) the call's own count is scaled
        to it: a render of several passes (an embedded rule, rqmc replicates) reports more
        tasks than tiles, and the count must never run past the call's share and back."""
        if self.progress is None:
            return None
        base = self.done
        seen = [0]

        def cb(done: int, total: int) -> None:
            if n_tiles is not None and total > 0:
                done = (done * n_tiles) // total
            if done > seen[0]:
                self.done = base + done
                seen[0] = done
                self.progress(min(self.done, self.total), self.total)

        return cb

    def finish_render(self, base_tiles: int, n_tiles: int) -> None:
        """Make sure a render call counts exactly ``n_tiles`` steps."""
        self.done = base_tiles + n_tiles
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)


def draw_safely(notes: list, what: str, draw, *args, **kwargs) -> list:
    """Call a figure function; a figure that cannot be drawn is a note (the run's data are
    complete without it), never a failed run. Returns the paths it drew ([] on failure).
    Interrupts (KeyboardInterrupt) and other BaseExceptions propagate."""
    try:
        out = draw(*args, **kwargs)
    except Exception as err:  # noqa: BLE001 - a figure is never worth the run's data
        notes.append(f"figure(s) {what} could not be drawn ({type(err).__name__}: {err}); "
                     "the data are complete (run.zarr, statistics.json)")
        return []
    return list(out) if isinstance(out, (list, tuple)) else [out]
