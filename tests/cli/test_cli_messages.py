"""What a new user meets on the command line (issue 38, item 15), in a real process: Ctrl-C
during the start-up is one line and exit code 130, never a traceback; a stale temporary
folder removed under the claim is a "note:" line, not a Python warning with a source path;
``-o`` naming an existing file gets the same advice with and without ``--overwrite``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pmdsim.cli import app

ROOT = Path(__file__).resolve().parents[2]


def _env():
    return dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _images(tmp_path) -> list[str]:
    import tifffile

    paths = []
    for k in range(8):
        img = (np.random.default_rng(k).random((12, 10)) * 200).astype(np.uint8)
        paths.append(str(tmp_path / f"f{k}.tif"))
        tifffile.imwrite(paths[-1], img)
    return paths


def _decode(tmp_path, out):
    return [sys.executable, "-m", "pmdsim.cli", "decode", *_images(tmp_path), "-o", str(out),
            "--widths", "50,400", "--shifts", "4", "--extent-px", "300"]


def _started(p, timeout=60.0) -> None:
    """Wait until the interpreter of ``p`` is past its own site start-up (which no program
    can guard) and inside pmdsim's: NumPy's library is mapped (pmdsim.cli imports it after
    taking SIGINT over)."""
    deadline = time.monotonic() + timeout
    maps = Path(f"/proc/{p.pid}/maps")
    while time.monotonic() < deadline and p.poll() is None:
        try:
            if "numpy" in maps.read_text():
                return
        except OSError:
            pass
        time.sleep(0.005)


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc (Linux)")
def test_ctrl_c_during_start_up_is_one_line_and_130(tmp_path):
    """SIGINT at several moments of the start-up (imports, option parsing, the command's
    first imports): never a traceback; exit 130 with "interrupted" (or 0 if it finished
    first); no output folder, no temporary."""
    said = 0
    for k, delay_s in enumerate((0.0, 0.2, 0.5, 0.9, 1.4)):
        out = tmp_path / f"dec{k}"
        # SIGINT's default action even where the test process ignores it (a background shell)
        p = subprocess.Popen(_decode(tmp_path, out), env=_env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
        _started(p)
        time.sleep(delay_s)
        p.send_signal(signal.SIGINT)
        _, stderr = p.communicate(timeout=300)
        assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, (delay_s, stderr)
        # 130, or killed by SIGINT (-2; the shell shows 130 too): CPython ends a process that
        # way when a KeyboardInterrupt passed through an exec() of a string, as the standard
        # library's dataclasses do while a module is imported, even when it was handled
        assert p.returncode in (0, 130, -signal.SIGINT), (delay_s, p.returncode, stderr)
        if "interrupted" in stderr:
            said += 1
            assert p.returncode != 0, stderr
            assert not out.exists() and not list(tmp_path.glob(f"dec{k}.tmp-*"))
        else:  # finished before the signal (or during the interpreter's exit): complete
            assert (out / "statistics.json").exists(), (delay_s, p.returncode, stderr)
    assert said >= 3


def test_a_stale_temporary_is_a_note_not_a_python_warning(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"dec.tmp-{dead.pid}"
    stale.mkdir()
    res = subprocess.run(_decode(tmp_path, tmp_path / "dec"), env=_env(), capture_output=True, check=False,
                         text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert f"note: removed {stale}" in res.stderr, res.stderr
    assert "StaleTemporaryWarning" not in res.stderr and ".py:" not in res.stderr
    assert not stale.exists()


@pytest.mark.parametrize("command", ["simulate", "budget", "converge", "sweep", "decode"])
def test_output_naming_an_existing_file_same_advice_with_and_without_overwrite(tmp_path, command):
    readme = tmp_path / "README.md"
    readme.write_text("keep")
    from conftest import base_dict
    from test_cli_bad_input import _toml

    cfg = tmp_path / "run.toml"
    cfg.write_text(_toml(base_dict()))
    args = ([command, str(cfg)] if command != "decode" else
            [command, str(tmp_path / "x.tif"), "--widths", "50,400", "--shifts", "4",
             "--extent-px", "300"])
    for extra in ([], ["--overwrite"]):
        if command in ("converge", "decode") and extra:
            continue  # no --overwrite option
        res = CliRunner().invoke(app, [*args, "-o", str(readme), *extra])
        assert res.exit_code == 2, res.output
        assert "is a file, not a folder" in res.output and "-o" in res.output, res.output
        assert "pass --overwrite" not in res.output
    assert readme.read_text() == "keep"


def test_a_ctrl_c_swallowed_by_a_compiled_callback_still_stops_the_command(capsys):
    """Numba's JIT calls Python through ctypes while it compiles; a KeyboardInterrupt raised
    in such a callback is swallowed by ctypes ("Exception ignored ..." with a traceback) and
    the command would run on. Inside a command's guard it is delivered again and stops the
    command: exit 130, the one line, no traceback."""
    import ctypes

    import typer

    from pmdsim.cli.common import _guard

    def callback():
        raise KeyboardInterrupt

    thunk = ctypes.CFUNCTYPE(None)(callback)
    # a command's process has Python's SIGINT handler inside its guard (cli.interrupt gives it
    # back there); a test worker may hold another one, left by an earlier test or by the
    # worker itself (under SIG_IGN an interrupt_main does nothing): the command's state here
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(typer.Exit) as stop:
            with _guard():
                thunk()  # the interrupt ends inside ctypes
                for _ in range(500):  # the command's work goes on, until it is delivered again
                    time.sleep(0.01)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert stop.value.exit_code == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err and "ignored" not in err, err
