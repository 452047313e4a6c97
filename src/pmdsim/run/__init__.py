"""The run folder: orchestration (:func:`run_simulation`), the dataset (:func:`load_run`),
files and manifest, decoding of image files (:mod:`.decode_run`), convergence folders.

The names below are imported on first use, so that ``pmdsim.run.claim`` (the output lock,
standard library only) can be imported without the rest."""

_LAZY = {
    "CONFIG_NAME": ".dataset", "DATASET_NAME": ".dataset", "build_dataset": ".dataset",
    "load_run": ".dataset", "run_config": ".dataset", "RunResult": ".result",
    "run_simulation": ".simulate",
}


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    try:  # a submodule (pmdsim.run.files, ...)
        return importlib.import_module(f".{name}", __name__)
    except ModuleNotFoundError:
        raise AttributeError(f"module 'pmdsim.run' has no attribute {name!r}") from None


__all__ = ["run_simulation", "RunResult", "load_run", "run_config", "build_dataset",
           "DATASET_NAME", "CONFIG_NAME"]
