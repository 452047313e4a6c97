"""Claiming an output folder (a lock another process sees at once), stale temporary folders
of dead processes, SIGTERM turned into a clean-up (:mod:`pmdsim.store.folder_lock`)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pmdsim.store.folder_lock import (OutputBusy, Terminated, claim_output, lock_path,
                                      remove_stale, signals_as_interrupt)

SRC = str(Path(__file__).parents[2] / "src")


def _holder(target: Path) -> subprocess.Popen:
    """A process that claims ``target`` and waits until killed; returns once it holds it."""
    code = textwrap.dedent(f"""
        import sys, time
        from pmdsim.store.folder_lock import claim_output
        with claim_output({str(target)!r}):
            print("held", flush=True)
            time.sleep(60)
    """)
    env = dict(os.environ, PYTHONPATH=SRC)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, env=env, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_second_claim_on_the_same_target_fails_at_once_naming_the_holder(tmp_path):
    target = tmp_path / "out"
    proc = _holder(target)
    try:
        with pytest.raises(OutputBusy) as info:
            with claim_output(target):
                pass
        assert str(proc.pid) in str(info.value) and "out" in str(info.value)
    finally:
        proc.kill()
        proc.wait()
    # the lock dies with its process (SIGKILL included): the target can be claimed again
    with claim_output(target) as lock:
        assert lock == lock_path(target) and lock.read_text().strip() == str(os.getpid())
    assert not lock_path(target).exists()


def test_other_targets_are_independent(tmp_path):
    with claim_output(tmp_path / "a"):
        with claim_output(tmp_path / "b"):
            pass


def test_stale_temporaries_of_dead_processes_are_removed_live_ones_kept(tmp_path):
    target = tmp_path / "run"
    dead = _dead_pid()
    stale = [tmp_path / f"run.tmp-{dead}", tmp_path / f"run.old-{dead}"]
    for p in stale:
        (p / "run.zarr").mkdir(parents=True)
        (p / "run.zarr" / "chunk").write_bytes(b"x" * 100)
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        live = tmp_path / f"run.tmp-{proc.pid}"
        live.mkdir()
        unrelated = tmp_path / f"runner.tmp-{dead}"
        unrelated.mkdir()
        with claim_output(target):
            removed, kept = remove_stale(target)
        assert sorted(removed) == sorted(stale) and not any(p.exists() for p in stale)
        assert kept == [live] and live.exists() and unrelated.exists()
    finally:
        proc.kill()
        proc.wait()


def test_sigterm_raises_terminated_inside_the_block_only():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated):
        with signals_as_interrupt():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
    assert isinstance(Terminated(), KeyboardInterrupt)
    assert signal.getsignal(signal.SIGTERM) is before  # the previous handler is back
