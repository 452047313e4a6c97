"""Claiming an output folder, and leaving nothing behind when a run is interrupted.

A run writes ``<out>.tmp-<pid>`` and renames it to ``<out>`` when complete
(:func:`pmdsim.store.folder.atomic_run_dir`). This module makes that safe between processes
and against signals:

* :func:`claim_output` takes an exclusive lock on ``<out>.lock`` (``fcntl.flock``; the
  operating system releases it when the process ends in any way, SIGKILL included) before
  any computation, so a second run on the same target fails at once with
  :class:`OutputBusy`, naming the process that holds it;
* :func:`remove_stale` (under the claim) removes the ``<out>.tmp-<pid>`` and
  ``<out>.old-<pid>`` folders that processes which no longer exist left behind (a SIGKILL,
  a power cut), and reports those of processes that still run;
* :func:`signals_as_interrupt` turns SIGTERM into :class:`Terminated` (a
  :class:`KeyboardInterrupt`), so that SIGINT and SIGTERM both unwind the ``with`` blocks
  (writer threads are joined) and the temporary folder is removed;
* :func:`remove_tree` removes a temporary folder after the writers have stopped (Zarr's
  I/O loop is drained first; a folder that reappears is removed again).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shutil
import signal
import threading
import time
from pathlib import Path
from typing import Iterator

LOCK_SUFFIX = ".lock"


class OutputBusy(FileExistsError):
    """Another live process is writing the same output folder."""


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM (raised in the main thread, like SIGINT's
    :class:`KeyboardInterrupt`, so that clean-up code runs)."""


def lock_path(final: str | Path) -> Path:
    final = Path(final).absolute()
    return final.with_name(final.name + LOCK_SUFFIX)


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, belongs to someone else
    except OSError:
        return False
    return True


@contextlib.contextmanager
def claim_output(final: str | Path) -> Iterator[Path]:
    """Hold an exclusive claim on the output folder ``final`` for the ``with`` block.

    The claim is a lock on the file ``<final>.lock`` (it holds the owner's pid, for the
    message); the lock file is removed when the block ends. Raises :class:`OutputBusy` at
    once when another live process holds the claim.
    """
    path = lock_path(final)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        _refuse_if_held(fd, final, path)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        try:
            yield path
        finally:
            with contextlib.suppress(OSError):
                path.unlink()
    finally:
        os.close(fd)  # releases the lock


def check_free(final: str | Path) -> None:
    """Raise :class:`OutputBusy` now if another live process holds the claim on ``final``
    (a cheap early check for the command line; :func:`claim_output` is what guarantees)."""
    path = lock_path(final)
    try:
        fd = os.open(path, os.O_RDWR)
    except OSError:
        return  # no lock file: nobody holds it
    try:
        _refuse_if_held(fd, final, path)
    finally:
        os.close(fd)


def _refuse_if_held(fd: int, final, path: Path) -> None:
    """Raise :class:`OutputBusy`, naming the owner's pid, if another process holds ``fd``'s lock."""
    if not _try_lock(fd):
        owner = _read_pid(fd)
        who = f"process {owner}" if owner else "another process"
        raise OutputBusy(
            f"output folder {Path(final)} is being written by {who} (lock {path}): wait "
            "for that run to finish or choose another output folder (-o)")


def _try_lock(fd: int) -> bool:
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: fall back to the pid in the file
        owner = _read_pid(fd)
        return not (owner and owner != os.getpid() and _pid_alive(owner))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def _read_pid(fd: int) -> int | None:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 64).decode(errors="replace").strip()
        return int(text) if text.isdigit() else None
    except OSError:
        return None


def temporaries(final: str | Path) -> list[tuple[Path, int]]:
    """The ``<final>.tmp-<pid>`` and ``<final>.old-<pid>`` siblings of ``final`` with their
    pids."""
    final = Path(final).absolute()
    if not final.parent.is_dir():
        return []
    pattern = re.compile(re.escape(final.name) + r"\.(tmp|old)-(\d+)$")
    out = []
    for p in final.parent.iterdir():
        m = pattern.match(p.name)
        if m:
            out.append((p, int(m.group(2))))
    return sorted(out)


def remove_stale(final: str | Path) -> tuple[list[Path], list[Path]]:
    """Remove the temporary folders of ``final`` left by processes that no longer exist.

    Call it while holding :func:`claim_output`. Returns ``(removed, kept)``: ``kept`` are
    those of live processes other than this one (reported, never touched)."""
    removed, kept = [], []
    for p, pid in temporaries(final):
        if pid != os.getpid() and _pid_alive(pid):
            kept.append(p)
            continue
        if pid == os.getpid():
            continue  # atomic_run_dir handles its own
        remove_tree(p, drain=False)
        removed.append(p)
    return removed, kept


def _drain_zarr(timeout: float = 10.0) -> None:
    """Wait until Zarr's I/O event loop has no pending task (writes of a store that the
    main thread stopped waiting for when it was interrupted)."""
    try:
        from zarr.core.sync import sync
    except Exception:  # pragma: no cover - zarr layout changed: nothing to drain
        return

    async def _wait() -> None:
        me = asyncio.current_task()
        others = [t for t in asyncio.all_tasks() if t is not me and not t.done()]
        if others:
            await asyncio.wait(others, timeout=timeout)

    with contextlib.suppress(Exception):
        sync(_wait(), timeout=timeout + 1)


def remove_tree(path: str | Path, drain: bool = True, settle_s: float = 0.3) -> None:
    """Remove the folder ``path`` for good: after Zarr's pending writes (``drain``), and
    again if a late writer recreated it within ``settle_s``."""
    path = Path(path)
    if drain:
        _drain_zarr()
    shutil.rmtree(path, ignore_errors=True)
    deadline = time.monotonic() + settle_s
    while time.monotonic() < deadline:
        time.sleep(0.05)
        if path.exists():
            shutil.rmtree(path, ignore_errors=True)
    shutil.rmtree(path, ignore_errors=True)


@contextlib.contextmanager
def signals_as_interrupt() -> Iterator[None]:
    """Within the block SIGTERM raises :class:`Terminated` in the main thread (SIGINT
    raises :class:`KeyboardInterrupt` as always), so ``finally``/``except`` clean-up runs.
    Outside the main thread (where signal handlers cannot be set) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _handler(signum, frame):
        raise Terminated(f"received signal {signum} (SIGTERM)")

    previous = signal.signal(signal.SIGTERM, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
