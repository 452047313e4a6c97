"""The run folder: orchestration (:func:`run_simulation`), the dataset (:func:`load_run`),
files and manifest, decoding of image files (:mod:`.decode_run`), convergence folders."""

from .dataset import CONFIG_NAME, DATASET_NAME, build_dataset, load_run, run_config
from .result import RunResult
from .simulate import run_simulation

__all__ = ["run_simulation", "RunResult", "load_run", "run_config", "build_dataset",
           "DATASET_NAME", "CONFIG_NAME"]
