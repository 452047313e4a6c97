"""``--help`` of every command is whole: written to a pipe it is 120 columns wide (not
Rich's default of 80), and even in an 80-column terminal no option's help is cut short
with an ellipsis."""

from __future__ import annotations

import subprocess
import sys

import pytest
import typer.rich_utils
from typer.testing import CliRunner

from pmdsim.cli import app
from pmdsim.cli.common import HELP_WIDTH

COMMANDS = [None] + [c.name or c.callback.__name__ for c in app.registered_commands]


def test_there_are_commands():
    assert {"simulate", "converge", "fit", "budget", "sweep"} <= set(COMMANDS)


@pytest.mark.parametrize("width", [80, HELP_WIDTH])
@pytest.mark.parametrize("command", COMMANDS, ids=[c or "pmdsim" for c in COMMANDS])
def test_help_is_not_cut(command, width, monkeypatch):
    monkeypatch.setattr(typer.rich_utils, "MAX_WIDTH", width)
    res = CliRunner().invoke(app, [command, "--help"] if command else ["--help"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert max(len(s) for s in lines) <= width
    cut = [s for s in lines if "\u2026" in s]
    assert not cut, f"{command} --help at {width} columns cuts: {cut}"


def test_piped_help_is_wide():
    out = subprocess.run([sys.executable, "-m", "pmdsim.cli", "budget", "--help"],
                         capture_output=True, text=True, check=True,
                         env={k: v for k, v in __import__("os").environ.items()
                              if k not in ("COLUMNS", "TERMINAL_WIDTH")}).stdout
    widths = [len(s) for s in out.splitlines()]
    assert max(widths) == HELP_WIDTH, max(widths)
