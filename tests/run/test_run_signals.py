"""Interruption and concurrency of ``pmdsim simulate`` (subprocesses): SIGINT at several
points and SIGTERM leave nothing behind (no output, no temporary folder, no lock), a
SIGKILLed run's temporary folder is removed by the next run, a second run on the same
target fails at once (before the first has finished computing), and the silent-empty
set-ups exit with code 2 and the field to fix."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import base_dict, merge

SRC = str(Path(__file__).parents[2] / "src")


def _toml(data: dict) -> str:
    lines, tables = [], []
    for k, v in data.items():
        (tables if isinstance(v, dict) else lines).append((k, v))
    out = [f"{k} = {json.dumps(v)}" for k, v in lines]
    for k, v in tables:
        out.append(f"[{k}]")
        out += [f"{kk} = {json.dumps(vv)}" for kk, vv in v.items()]
    return "\n".join(out) + "\n"


def _write_config(folder: Path, changes: dict | None = None, slow: bool = True) -> Path:
    """The base scene; ``slow``: a 320 x 256 camera (same view) and 400 rays, a run of a
    few seconds with every stage (render, dataset, figures)."""
    data = base_dict()
    if slow:
        data = merge(data, {"camera": {"resolution": [320, 256], "focal_length_px": 640.0},
                            "sampling": {"n_rays": 400}})
    data = merge(data, changes or {})
    path = folder / "run.toml"
    path.write_text(_toml(data))
    return path


def _start(cfg: Path, out: Path, *extra: str) -> subprocess.Popen:
    """``pmdsim simulate`` in a subprocess, with SIGINT's default action even where this
    process ignores SIGINT: a test run started in the background of a non-interactive
    shell (POSIX gives such jobs SIGINT ignored, and an ignored signal stays ignored across
    ``exec``, so the run would rightly ignore the test's SIGINT). A handled signal is reset
    to its default by ``exec``, so a handler is set for the moment of the start."""
    env = dict(os.environ, PYTHONPATH=SRC, PYTHONFAULTHANDLER="1")
    ignored = (signal.getsignal(signal.SIGINT) == signal.SIG_IGN
               and threading.current_thread() is threading.main_thread())
    if ignored:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return subprocess.Popen([sys.executable, "-m", "pmdsim.cli", "simulate", str(cfg),
                                 "-o", str(out), *extra], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    finally:
        if ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _wait_for(proc: subprocess.Popen, path_fn, timeout: float = 300.0) -> Path | None:
    """Poll until ``path_fn()`` returns an existing path (or the process ends)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        p = path_fn()
        if p is not None and p.exists():
            return p
        if proc.poll() is not None:
            return None
        time.sleep(0.005)
    return None


def _tmp_of(out: Path):
    def find():
        hits = sorted(out.parent.glob(out.name + ".tmp-*"))
        return hits[0] if hits else None
    return find


def _left(folder: Path, cfg: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p != cfg)


@pytest.mark.parametrize("point", ["render", "dataset", "figures"])
def test_sigint_at_any_point_leaves_nothing(tmp_path, point):
    cfg = _write_config(tmp_path)
    out = tmp_path / "out"
    proc = _start(cfg, out)
    tmp = _wait_for(proc, _tmp_of(out))
    assert tmp is not None, proc.communicate()
    marker = {"render": tmp, "dataset": tmp / "run.zarr", "figures": tmp / "figures"}[point]
    seen = _wait_for(proc, lambda: marker)
    assert seen is not None, f"the run ended before {point}: {proc.communicate()}"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    assert _left(tmp_path, cfg) == []  # no out, no out.tmp-<pid>, no out.lock


def test_sigterm_leaves_nothing(tmp_path):
    cfg = _write_config(tmp_path)
    out = tmp_path / "out"
    proc = _start(cfg, out)
    assert _wait_for(proc, _tmp_of(out)) is not None, proc.communicate()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert _left(tmp_path, cfg) == []


def test_a_killed_runs_temporary_folder_is_removed_by_the_next_run(tmp_path):
    cfg = _write_config(tmp_path)
    out = tmp_path / "out"
    proc = _start(cfg, out)
    tmp = _wait_for(proc, _tmp_of(out))
    assert tmp is not None, proc.communicate()
    proc.kill()
    proc.communicate()
    assert tmp.exists()  # SIGKILL cannot clean up
    quick = _write_config(tmp_path, slow=False)
    again = _start(quick, out, "--no-figures")
    _, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    assert not tmp.exists() and str(tmp) in err and "no longer exists" in err
    assert _left(tmp_path, quick) == ["out"]


def test_a_second_run_on_the_same_target_fails_at_once(tmp_path):
    cfg = _write_config(tmp_path)
    out = tmp_path / "out"
    first = _start(cfg, out)
    try:
        tmp = _wait_for(first, _tmp_of(out))
        assert tmp is not None, first.communicate()
        t0 = time.monotonic()
        second = _start(cfg, out)
        _, err = second.communicate(timeout=120)
        seconds = time.monotonic() - t0
        assert second.returncode == 2, err
        assert f"being written by process {first.pid}" in err
        # it failed while the first was still computing (no dataset written yet), and it
        # left nothing of its own
        assert first.poll() is None and not (tmp / "run.zarr").exists(), (
            f"second run took {seconds:.2f} s")
        assert sorted(p.name for p in tmp_path.glob("out.tmp-*")) == [tmp.name]
    finally:
        first.send_signal(signal.SIGINT)
        _end(first)
    assert _left(tmp_path, cfg) == []


def _end(proc: subprocess.Popen, timeout: float = 120.0) -> None:
    """Wait for ``proc`` after its SIGINT; one that does not end in ``timeout`` is a hang:
    SIGABRT makes its faulthandler (PYTHONFAULTHANDLER, set by :func:`_start`) print every
    thread's stack, which the failure shows."""
    try:
        proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        _, err = proc.communicate(timeout=60)
        raise AssertionError(f"the run did not end {timeout:.0f} s after SIGINT; its "
                             f"threads:\n{err[-6000:]}") from None


EMPTY = {
    "camera looks away": ({"camera": {"look_at_mm": [0.0, -2000.0, 0.0]}},
                          "camera.look_at_mm: the camera sees no surface"),
    "monitor never seen": ({"monitor": {"centre_mm": [0.0, -200.0, 300.0],
                                        "look_at_mm": [0.0, 0.0, 0.0]}},
                           "monitor.centre_mm: the surface reflects the camera into no part"),
    "BRDF effectively zero": ({"brdf": {"rho_s": 1e-300}},
                              "brdf: every fringe image is black"),
}


@pytest.mark.parametrize("case", list(EMPTY))
def test_silent_empty_runs_exit_2_naming_the_field(tmp_path, case):
    changes, message = EMPTY[case]
    cfg = _write_config(tmp_path, changes, slow=False)
    proc = _start(cfg, tmp_path / "out", "--no-figures")
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 2, err
    assert message in " ".join(err.split()), err
    assert "Traceback" not in err
    assert _left(tmp_path, cfg) == []
