"""pmdsim: simulate Phase Measuring Deflectometry of scattering (technical) surfaces.

Public API::

    from pmdsim import load_config, Simulation
    cfg = load_config("examples/paper_fig3.toml")
    sim = Simulation.from_config(cfg)
    result = sim.render_fringes(widths=[50], directions=["x", "y"], shifts=4)

``run_simulation`` and ``load_run`` (:mod:`pmdsim.pipeline`) are available here too; they
and their dependencies (xarray, zarr) are imported on first use. matplotlib is imported
only when figures are drawn (:mod:`pmdsim.plot`).
"""

from __future__ import annotations

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("pmdsim")
except _metadata.PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0+unknown"

from . import patterns
from .config import ConfigError, RunConfig, load_config, parse_config
from .render import Simulation
from .scene import Scene

_LAZY = {"run_simulation", "load_run", "RunResult"}


def __getattr__(name: str):
    if name in _LAZY:
        from . import pipeline

        return getattr(pipeline, name)
    raise AttributeError(f"module 'pmdsim' has no attribute {name!r}")


__all__ = [
    "__version__", "load_config", "parse_config", "ConfigError", "RunConfig", "Scene",
    "Simulation", "patterns", "run_simulation", "load_run", "RunResult",
]
