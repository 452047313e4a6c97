"""pmdsim.run.threads: a run limits BLAS to one thread and gives the caller's setting back."""

from __future__ import annotations

import numpy as np
import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")

from pmdsim.run import threads  # noqa: E402


def _blas_threads() -> set[int]:
    np.ones((64, 3)) @ np.eye(3)  # NumPy's BLAS is loaded
    return {d["num_threads"] for d in threadpoolctl.threadpool_info() if d["user_api"] == "blas"}


def test_single_blas_limits_inside_and_restores_after():
    seen = []

    @threads.single_blas
    def work(x):
        seen.append(_blas_threads())
        return x + 1

    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        assert work(1) == 2
        assert seen == [{1}]
        assert _blas_threads() == before  # the caller's setting, not 1


def test_single_blas_restores_after_an_error():
    @threads.single_blas
    def fails():
        raise RuntimeError("boom")

    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        with pytest.raises(RuntimeError, match="boom"):
            fails()
        assert _blas_threads() == before


def test_the_environment_sets_or_lifts_the_limit(monkeypatch):
    seen = []
    work = threads.single_blas(lambda: seen.append(_blas_threads()))
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        monkeypatch.setenv("PMDSIM_BLAS_THREADS", "0")  # no limit: left as it is
        work()
        monkeypatch.setenv("PMDSIM_BLAS_THREADS", "3")
        work()
    assert seen[0] == before
    assert seen[1] == {3}
    for bad in ("two", "-1"):
        monkeypatch.setenv("PMDSIM_BLAS_THREADS", bad)
        with pytest.raises(ValueError, match="PMDSIM_BLAS_THREADS"):
            work()


def test_a_run_works_with_one_blas_thread(monkeypatch, tmp_path):
    """run_simulation is limited from its first step (here stopped right there)."""
    from pmdsim.run import simulate

    seen = []

    def stop(*args, **kwargs):
        seen.append(_blas_threads())
        raise KeyboardInterrupt

    monkeypatch.setattr(simulate, "resolve_roi", stop)  # the first step of a run
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        with pytest.raises(KeyboardInterrupt):
            simulate.run_simulation(None, tmp_path / "run")
        after = _blas_threads()
    assert seen == [{1}]
    assert after == {2}


@pytest.mark.parametrize("env, want", [
    ({}, "1"),                                                   # the run's limit
    ({"PMDSIM_BLAS_THREADS": "3"}, "3"),                         # another limit
    ({"PMDSIM_BLAS_THREADS": "0"}, None),                        # no limit: not set
    ({"OPENBLAS_NUM_THREADS": "2"}, "2"),                        # the user's own
    ({"PMDSIM_BLAS_THREADS": "two"}, None),                      # left to the run to report
])
def test_the_command_line_starts_openblas_with_the_limit(env, want):
    """``import pmdsim.cli`` (a fresh interpreter, NumPy not yet imported) sets
    ``OPENBLAS_NUM_THREADS`` to the run's BLAS limit unless the user set it, and NumPy's
    OpenBLAS then starts with that many threads."""
    import json
    import os
    import subprocess
    import sys

    code = ("import json, os, pmdsim.cli, numpy, threadpoolctl\n"
            "numpy.ones((64, 3)) @ numpy.eye(3)\n"
            "n = [d['num_threads'] for d in threadpoolctl.threadpool_info()"
            " if d['user_api'] == 'blas' and 'numpy' in d['filepath']]\n"
            "print(json.dumps([os.environ.get('OPENBLAS_NUM_THREADS'), n]))")
    base = {k: v for k, v in os.environ.items()
            if k not in ("OPENBLAS_NUM_THREADS", "PMDSIM_BLAS_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, check=True,
                         capture_output=True, text=True).stdout
    value, numbers = json.loads(out.strip().splitlines()[-1])
    assert value == want
    if want is not None:  # OpenBLAS starts at most one thread per core
        assert numbers == [min(int(want), os.cpu_count())]
