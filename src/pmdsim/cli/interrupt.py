"""Ctrl-C before a command's work begins: one line and exit code 130, no traceback.

The command line's start-up (importing NumPy, pydantic, Typer; parsing the options) takes
about a second; Python's default SIGINT handler would print a ``KeyboardInterrupt``
traceback from whatever module was being imported. :func:`install` (the first thing
``pmdsim.cli`` does when it runs as the ``pmdsim`` program) replaces it until the options
are parsed and the command enters its guard, before it writes anything
(``pmdsim.cli.common._guard`` calls :func:`release`):
from there SIGINT is Python's ``KeyboardInterrupt`` again, which the commands turn into
"interrupted" and exit code 130 after removing their temporary folder. Only the standard
library is imported here.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

EXIT_INTERRUPTED = 130


def _interrupted(signum, frame) -> None:
    """Exit at once: nothing has been written yet, and an exception raised here would unwind
    through whatever was being imported (a half-loaded NumPy, a pydantic schema being built
    in compiled code, which wraps it into an error of its own and a traceback)."""
    try:  # straight to the file descriptor: sys.stderr may be inside a write of its own
        # (a reentrant call of its buffer is an error, and the line would be lost)
        os.write(2, b"interrupted: stopped before the command began its work; nothing was "
                    b"written\n")
    finally:
        os._exit(EXIT_INTERRUPTED)


def _is_program() -> bool:
    """True when this process is the ``pmdsim`` program (the console script or
    ``python -m pmdsim.cli``), not a Python session that imports the command line."""
    arg0 = sys.argv[0] if sys.argv else ""
    name = os.path.basename(arg0)
    return (name in ("pmdsim", "pmdsim.exe") or arg0 == "-m"
            or arg0.replace(os.sep, "/").endswith("pmdsim/cli/__main__.py"))


def install() -> None:
    """Take SIGINT over for the start-up (only in the program's main thread, and only
    where SIGINT has Python's default handler: an ignored SIGINT stays ignored)."""
    if (_is_program() and threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        signal.signal(signal.SIGINT, _interrupted)


def active() -> bool:
    return signal.getsignal(signal.SIGINT) is _interrupted


def release() -> bool:
    """Give SIGINT back to Python's default handler; True if this module held it."""
    if active():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        return True
    return False
