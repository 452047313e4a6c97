"""Atomic output folders: a folder named ``outdir`` is always complete.

:func:`atomic_run_dir` writes a run into a temporary sibling folder ``<outdir>.tmp-<pid>``
and renames it to ``<outdir>`` only when everything is written. A run folder carries a
manifest ``pmdsim-run.json`` (:data:`MANIFEST`, written last); an existing folder is
replaced only when asked (``overwrite=True``) and only if it is a pmdsim run folder or
empty, so a mistyped ``-o`` can never delete unrelated data. The folder's sizes for the
run's summary (:func:`folder_sizes`, :func:`size_text`).
"""

from __future__ import annotations
import contextlib
import os
import shutil
import warnings
from pathlib import Path
from typing import Iterator
from . import folder_lock as claim


#: File name of the manifest that marks a complete pmdsim run folder.
MANIFEST = "pmdsim-run.json"


# ----------------------------------------------------------------------------- run folders
def is_run_dir(path: str | Path, marker: str = MANIFEST) -> bool:
    """True if ``path`` is a folder with a pmdsim manifest (a complete run); ``marker`` names
    the manifest file of other kinds of output folders (e.g. a convergence study)."""
    return (Path(path) / marker).is_file()


def check_output_dir(final: str | Path, overwrite: bool = False, marker: str = MANIFEST) -> None:
    """Raise :class:`FileExistsError` unless ``final`` may be (re)created as a run folder:
    it does not exist, or ``overwrite`` is true and it is an empty folder or a folder with
    the manifest ``marker``."""
    final = Path(final)
    if not final.exists() and not final.is_symlink():
        return
    if final.is_symlink() or not final.is_dir():
        what = "a link" if final.is_symlink() else "a file, not a folder"
        raise FileExistsError(f"output folder {final} exists and is {what}: choose another "
                              "output folder (-o); --overwrite replaces only a run folder")
    if not overwrite:
        raise FileExistsError(
            f"output folder {final} exists: choose another folder or pass --overwrite "
            "(overwrite=True) to replace it"
        )
    if not is_run_dir(final, marker) and any(final.iterdir()):
        kind = "pmdsim run folder" if marker == MANIFEST else "pmdsim output folder"
        raise FileExistsError(
            f"{final} is not empty and not a {kind} (no {marker}): refusing to "
            "replace it even with overwrite; choose another output folder"
        )


@contextlib.contextmanager
def atomic_run_dir(outdir: str | Path, overwrite: bool = False, marker: str = MANIFEST) -> Iterator[Path]:
    """Context manager yielding a fresh temporary folder that becomes ``outdir`` on success.

    The output folder is first *claimed* (:func:`pmdsim.store.folder_lock.claim_output`, a lock on
    ``<outdir>.lock``): a second run on the same target fails at once with
    :class:`~pmdsim.store.folder_lock.OutputBusy`, before any computation. Under the claim,
    temporary folders that dead processes left (``<outdir>.tmp-<pid>``, ``.old-<pid>``) are
    removed (a :class:`StaleTemporaryWarning` says which).

    The temporary folder is the sibling ``<outdir>.tmp-<pid>``. On normal exit it is
    renamed to ``outdir`` (an existing run folder is first moved aside to
    ``<outdir>.old-<pid>`` and deleted only after the rename succeeded, so a failure never
    loses the old run). On an exception, SIGINT (KeyboardInterrupt) or SIGTERM (turned into
    :class:`~pmdsim.store.folder_lock.Terminated` inside the block) the temporary folder is removed
    after the writers have stopped, and the exception propagates; ``outdir`` is untouched.

    Raises
    ------
    FileExistsError
        ``outdir`` exists and ``overwrite`` is false, or it is not a pmdsim run folder;
        :class:`~pmdsim.store.folder_lock.OutputBusy` when another live run writes it.
    """
    final = Path(outdir).absolute()
    check_output_dir(final, overwrite, marker)  # fail before doing any work
    final.parent.mkdir(parents=True, exist_ok=True)
    with claim.signals_as_interrupt(), claim.claim_output(final):
        removed, kept = claim.remove_stale(final)
        for p in removed:
            warnings.warn(f"removed {p}: the temporary folder of an interrupted run whose "
                          "process no longer exists", StaleTemporaryWarning, stacklevel=3)
        for p in kept:
            warnings.warn(f"{p} belongs to a running process that does not hold the "
                          "output's lock (an older pmdsim?): left alone", StaleTemporaryWarning,
                          stacklevel=3)
        tmp = final.with_name(f"{final.name}.tmp-{os.getpid()}")
        if tmp.exists():
            shutil.rmtree(tmp)  # leftover of a crashed run of this very process id
        try:
            # inside the try: a SIGINT that Python raises as mkdir returns (the folder made,
            # the next statement not reached) removes it too
            tmp.mkdir()
            yield tmp
            check_output_dir(final, overwrite, marker)  # it may have appeared meanwhile
            old = None
            if final.exists():
                old = final.with_name(f"{final.name}.old-{os.getpid()}")
                if old.exists():
                    shutil.rmtree(old)
                os.replace(final, old)
            try:
                os.replace(tmp, final)
            except BaseException:
                if old is not None:
                    os.replace(old, final)
                raise
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        except BaseException:
            claim.remove_tree(tmp)
            raise


@contextlib.contextmanager
def staged_files(folder: str | Path, names: tuple[str, ...]) -> Iterator[dict]:
    """Files ``names`` of ``folder`` written together: yields {name: temporary path} (a
    hidden sibling ``.<stem>.tmp-<pid><suffix>``, so a writer that reads the suffix still
    sees it); on success each written one is renamed over its name, the last name last (the
    file that says "done"); on an exception, SIGINT or SIGTERM the temporaries are removed
    and nothing of ``folder`` changes. For commands that write a few files into a folder
    of the user's (``pmdsim texture -o``), where a folder-level rename would replace
    the user's other files."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = {n: folder / f".{Path(n).stem}.tmp-{os.getpid()}{Path(n).suffix}" for n in names}
    try:
        with claim.signals_as_interrupt():
            yield tmp
            for n in names:
                if tmp[n].exists():
                    os.replace(tmp[n], folder / n)
    finally:
        for t in tmp.values():
            with contextlib.suppress(FileNotFoundError):
                t.unlink()


class StaleTemporaryWarning(UserWarning):
    """A temporary folder of an earlier, interrupted run was found next to the output."""


def folder_sizes(folder: str | Path) -> dict:
    """Bytes of a run folder: ``total`` and its parts ``run.zarr`` (every dataset, variants
    included), ``images`` (fringes/, dots/, images/), ``figures`` and ``other``."""
    folder = Path(folder)
    sizes = {"total": 0, "run.zarr": 0, "images": 0, "figures": 0, "other": 0}
    for p in folder.rglob("*"):
        if not p.is_file():
            continue
        n = p.stat().st_size
        parts = p.relative_to(folder).parts
        if any(x.endswith(".zarr") for x in parts):
            key = "run.zarr"
        elif any(x in ("fringes", "dots", "images") for x in parts[:-1]):
            key = "images"
        elif "figures" in parts[:-1]:
            key = "figures"
        else:
            key = "other"
        sizes[key] += n
        sizes["total"] += n
    return sizes


def size_text(sizes: dict) -> str:
    """``run folder: 86.3 MB (run.zarr 73.1 MB, images 11.0 MB, figures 1.9 MB)``"""
    mb = lambda n: f"{n / 1e6:.1f} MB"  # noqa: E731
    parts = ", ".join(f"{k} {mb(sizes[k])}" for k in ("run.zarr", "images", "figures")
                      if sizes.get(k))
    return f"run folder: {mb(sizes.get('total', 0))}" + (f" ({parts})" if parts else "")
