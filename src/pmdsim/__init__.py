"""pmdsim: simulate Phase Measuring Deflectometry of scattering (technical) surfaces.

Public API::

    from pmdsim import load_config, Simulation
    cfg = load_config("examples/paper_fig3.toml")
    sim = Simulation.from_config(cfg)
    result = sim.render_fringes(widths=[50], directions=["x", "y"], shifts=4)

``run_simulation`` and ``load_run`` (:mod:`pmdsim.run`) are available here too; they
and their dependencies (xarray, zarr) are imported on first use. matplotlib is imported
only when figures are drawn (:mod:`pmdsim.report`). ``pmdsim.decode`` is
:mod:`pmdsim.measure.decode` (decoding phase-shifted images, plain arrays).

Packages, in the order the data flows (see docs/architecture.md): ``config``, ``scene``
and ``brdf``, ``trace``, ``render`` (compiled ``kernels`` underneath), ``measure``,
``studies``, ``run``, ``report``, ``cli``.
"""

from __future__ import annotations

from ._version import __version__

#: Imported on first use (``pmdsim.Simulation``, ``from pmdsim import run_simulation``):
#: ``import pmdsim`` and the command line's first checks stay fast (no Numba, xarray,
#: zarr), so that e.g. a second run on a busy output folder fails at once.
_LAZY = {
    "ConfigError": ".config", "RunConfig": ".config", "load_config": ".config",
    "parse_config": ".config",
    "run_simulation": ".run", "load_run": ".run", "RunResult": ".run",
    "Simulation": ".render", "Scene": ".scene", "patterns": None, "decode": ".measure",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        where = _LAZY[name]
        if where is None:
            return importlib.import_module(f".{name}", __name__)
        return getattr(importlib.import_module(where, __name__), name)
    raise AttributeError(f"module 'pmdsim' has no attribute {name!r}")


__all__ = [
    "__version__", "load_config", "parse_config", "ConfigError", "RunConfig", "Scene",
    "Simulation", "patterns", "decode", "run_simulation", "load_run", "RunResult",
]
