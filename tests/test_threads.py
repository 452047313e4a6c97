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
