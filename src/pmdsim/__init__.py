"""pmdsim: simulate Phase Measuring Deflectometry of scattering (technical) surfaces.

Public API::

    from pmdsim import load_config, Simulation
    cfg = load_config("examples/paper_fig3.toml")
    sim = Simulation.from_config(cfg)
    result = sim.render_fringes(widths=[50], directions=["x", "y"], shifts=4)

``run_simulation`` (:mod:`pmdsim.run`) and ``load_run`` (:mod:`pmdsim.store.schema`) are
available here too; they
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
#: Names of objects -> the module that defines them.
_LAZY = {
    "ConfigError": ".config", "RunConfig": ".config", "load_config": ".config",
    "parse_config": ".config",
    "run_simulation": ".run", "load_run": ".store.schema", "RunResult": ".run",
    "Simulation": ".render", "Scene": ".scene",
}
#: Names of modules -> the module.
_LAZY_MODULES = {"patterns": ".patterns", "decode": ".measure.decode"}


def __getattr__(name: str):
    import importlib

    if name in _LAZY_MODULES:
        return importlib.import_module(_LAZY_MODULES[name], __name__)
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'pmdsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | set(_LAZY_MODULES))


__all__ = [
    "__version__", "load_config", "parse_config", "ConfigError", "RunConfig", "Scene",
    "Simulation", "patterns", "decode", "run_simulation", "load_run", "RunResult",
]
