"""What every command shares: the Typer app, the exit codes, the console, bad input as
one red line (exit 2) and interrupts (exit 130/143)."""

from __future__ import annotations

import contextlib
import functools
import os
import sys

import typer
import typer.rich_utils
from rich.console import Console

#: Width of ``--help`` when it does not go to a terminal (a pipe, a file, a test): Rich's
#: default of 80 columns cut option help into narrow columns and ellipsised long names.
#: A terminal keeps its own width; ``TERMINAL_WIDTH`` or ``COLUMNS`` override both.
HELP_WIDTH = 120
if not (os.environ.get("TERMINAL_WIDTH") or os.environ.get("COLUMNS")) and not sys.stdout.isatty():
    typer.rich_utils.MAX_WIDTH = HELP_WIDTH

app = typer.Typer(
    name="pmdsim",
    help="Simulate Phase Measuring Deflectometry (PMD) of scattering surfaces by reverse "
    "ray tracing with a BRDF-weighted ray bundle per camera pixel.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",  # docstring lines join into paragraphs
)

#: Exit code for bad input (configuration, files, output folder).
EXIT_BAD_INPUT = 2
#: Exit codes of a run stopped by SIGINT (Ctrl-C) / SIGTERM (128 + signal number).
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


def _bad_input() -> tuple[type[BaseException], ...]:
    """The exceptions that mean bad input (exit code 2): everything else is a bug."""
    from ..config import ConfigError, InputError

    return (ConfigError, InputError, FileExistsError, PermissionError, NotADirectoryError,
            IsADirectoryError)


@contextlib.contextmanager
def _guard():
    """Bad input -> one red line, exit 2; SIGINT/SIGTERM -> a note, exit 130/143 (the run's
    temporary folder is already removed); anything else propagates (traceback, exit 1)."""
    from ..store.folder_lock import Terminated

    from . import interrupt

    bad_input = _bad_input()  # imported here, never in an except clause (a Ctrl-C inside an
    # import leaves the module half loaded, and importing it again would be a new error)
    # the start-up is over (options parsed, the command's first imports done, nothing
    # written): from here SIGINT unwinds the command (KeyboardInterrupt), which removes its
    # temporary folder
    interrupt.release()
    previous_hook = sys.unraisablehook
    sys.unraisablehook = functools.partial(_interrupt_where_it_stops, previous_hook)
    try:
        yield
    except bad_input as err:
        _fail(str(err))
    except KeyboardInterrupt as err:
        term = isinstance(err, Terminated)
        _console(stderr=True).print(
            f"{'terminated' if term else 'interrupted'}: stopped; nothing was written "
            "(the temporary folder was removed)", style="bold red", markup=False)
        raise typer.Exit(EXIT_TERMINATED if term else EXIT_INTERRUPTED) from None
    finally:
        sys.unraisablehook = previous_hook


def _interrupt_where_it_stops(previous, unraisable) -> None:
    """``sys.unraisablehook`` inside a command: a Ctrl-C that arrived in a callback from
    compiled code (Numba's JIT calls Python through ctypes while it compiles or loads a
    kernel) is swallowed there, with an "Exception ignored" traceback on stderr, and the
    command would run on. It is delivered again to the main thread, where it stops the
    command (exit 130, its temporary folder removed); other unraisable errors go to the
    ``previous`` hook."""
    if issubclass(unraisable.exc_type, KeyboardInterrupt):
        import _thread
        import threading

        # from another thread, a moment later: raised here, in the main thread, it would
        # land inside this hook (and be swallowed again); should it land in another
        # callback, this hook sends it once more
        later = threading.Timer(0.01, _thread.interrupt_main)
        later.daemon = True
        later.start()
        return
    previous(unraisable)


def _warnings_as_messages() -> None:
    """pmdsim's own warnings (a stale temporary folder removed, a target not met) as one
    line each, "note: ..." / "warning: ...", instead of Python's format with the source
    file and line; other libraries' warnings keep Python's format."""
    import os
    import warnings

    if getattr(warnings.showwarning, "_pmdsim", False):
        return
    original = warnings.showwarning
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the package

    def show(message, category, filename, lineno, file=None, line=None):
        ours = (category.__module__.startswith("pmdsim")
                or os.path.abspath(str(filename)).startswith(here + os.sep))
        if not ours:
            return original(message, category, filename, lineno, file, line)
        note = category.__name__ == "StaleTemporaryWarning"
        _console(stderr=True).print(f"{'note' if note else 'warning'}: {message}",
                                    style="yellow", markup=False)

    show._pmdsim = True
    warnings.showwarning = show


def _version_callback(value: bool) -> None:
    if value:
        from .._version import __version__

        _console().print(f"pmdsim {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version_callback,
                                 is_eager=True, help="Print the pmdsim version and exit."),
) -> None:
    """Simulate Phase Measuring Deflectometry (PMD) of scattering surfaces by reverse ray
    tracing with a BRDF-weighted ray bundle per camera pixel."""
    # SIGINT stays with the start-up handler (pmdsim.cli.interrupt) until the command's
    # guard (_guard) takes it: Ctrl-C before is one line and exit 130
    _warnings_as_messages()


def _console(stderr: bool = False) -> Console:
    return Console(stderr=stderr, soft_wrap=True, highlight=False)


def _fail(message: str) -> None:
    _console(stderr=True).print(f"error: {message}", style="bold red", markup=False)
    raise typer.Exit(EXIT_BAD_INPUT)


def _si(x: float) -> str:
    for unit, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(x) >= scale:
            return f"{x / scale:.2f} {unit}"
    return f"{x:.0f}"


def _numbers(text: str | None, name: str, kind=float) -> list | None:
    if text is None:
        return None
    import math

    from ..config import InputError

    try:
        values = [kind(x) for x in text.replace(" ", "").split(",") if x]
    except ValueError:
        raise InputError(f"{name} must be comma-separated numbers, got {text!r}") from None
    bad = [v for v in values if not math.isfinite(v) or v <= 0]
    if bad:
        raise InputError(f"{name} must be positive finite numbers, got {bad[0]!r} in {text!r}")
    return values


def _output_folder(path, option: str = "-o") -> None:
    """Refuse, before any computation, an output folder that cannot be one: an existing
    file (or a path below one), or a folder that cannot be created or written."""
    import os
    from pathlib import Path

    if path is None:
        return
    path = Path(path)
    if path.exists() and not path.is_dir():
        _fail(f"{option} {path}: exists and is a file, not a folder; choose another {option}")
    parent = path if path.exists() else next((p for p in path.absolute().parents if p.exists()),
                                             None)
    if parent is not None and not parent.is_dir():
        _fail(f"{option} {path}: {parent} is a file, so no folder can be made below it; "
              f"choose another {option}")
    if parent is not None and not os.access(parent, os.W_OK | os.X_OK):
        _fail(f"{option} {path}: {parent} is not writable; choose another {option}")
