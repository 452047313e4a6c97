"""The ``pmdsim`` command line (Typer + Rich).

    pmdsim simulate CONFIG -o OUTDIR [--overwrite] [--no-figures] [--decode/--no-decode]
                                     [--no-diagnostics] [--scheduler tcp://..]
    pmdsim decode IMAGES... -o OUT (--widths W1,W2,.. --shifts K --extent-px E | --from-run RUN)
    pmdsim converge CONFIG -o OUTDIR [--n-values 25,50,..] [--theta 0.5,1,..] [--camera 160x128]
    pmdsim sweep CONFIG -o OUTDIR [--scheduler threads|processes|synchronous|tcp://..]
                                  [--workers N] [--overwrite] [--no-figures]
    pmdsim report RUN [--all | --figure NAME ...] [--variant NAME] [-o FOLDER]
    pmdsim export RUN --format x3p|csv|xyz [-o FOLDER] [--overwrite]
    pmdsim texture --feed-um F --nose-radius-mm R [--rq-um Q --correlation-um L] [-o OUT]
    pmdsim fit CONFIG IMAGES... -o OUT
    pmdsim warmup
    pmdsim version
    pmdsim --help

Bad input (an invalid configuration or set-up, a missing or unreadable input file, an
existing or busy output folder) prints one red message and exits with code 2, without a
traceback. Anything else is a bug: Python's traceback and exit code 1. Ctrl-C (SIGINT) and
SIGTERM stop a run, remove its temporary folder and exit with 130 / 143.
"""

from __future__ import annotations

from .interrupt import install as _install_interrupt

_install_interrupt()  # Ctrl-C during the start-up: one line, exit 130 (no traceback)

from ..run.pages import hugepages_at_start
from ..run.threads import blas_pool_at_start

blas_pool_at_start()  # before anything imports NumPy
hugepages_at_start()

from .common import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED, app
from .simulate import simulate
from .decode import decode
from .studies import budget, converge, sweep
from .texture import fit, texture
from .report import report
from .export import export
from .install import version, warmup

#: The commands, in the order ``pmdsim --help`` lists them.
COMMANDS = (simulate, decode, converge, budget, texture, fit, version, sweep, report, export, warmup)
for _command in COMMANDS:
    app.command()(_command)
del _command


def main() -> None:  # pragma: no cover - console entry for `python -m pmdsim.cli`
    app()


__all__ = ["app", "main", "EXIT_BAD_INPUT", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "COMMANDS",
           "simulate", "decode", "converge", "budget", "texture", "fit", "version", "sweep", "report", "export", "warmup"]
