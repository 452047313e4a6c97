"""The commands' pipelines: ``pmdsim simulate`` (:func:`run_simulation` and its steps), and
the folders of ``decode``, ``converge``, ``budget``, ``sweep``, ``fit``, ``texture`` and
``warmup``. What they write, and how it is read back, is :mod:`pmdsim.store`.

The names below are imported on first use, so that ``pmdsim.run.threads`` can be imported
without the rest."""

_LAZY = {"RunResult": ".result", "run_simulation": ".simulate"}


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    try:  # a submodule (pmdsim.run.simulate, ...)
        return importlib.import_module(f".{name}", __name__)
    except ModuleNotFoundError:
        raise AttributeError(f"module 'pmdsim.run' has no attribute {name!r}") from None


__all__ = ["run_simulation", "RunResult"]
