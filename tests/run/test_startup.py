"""Start-up: what ``import pmdsim``, ``pmdsim --help`` and a run without figures import
(fresh interpreters). Numba, Dask, xarray, zarr and matplotlib are imported only where
they are used: the command line answers ``--help`` without any of them, and a run that
draws no figure never imports matplotlib."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).parents[2] / "src")
HEAVY = ("numba", "matplotlib", "dask", "xarray", "zarr", "scipy", "pandas")


def _imported(code: str, cwd: Path | None = None) -> list[str]:
    """Run ``code`` in a fresh interpreter; the heavy packages it imported."""
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")
    env = dict(os.environ, PYTHONPATH=SRC, MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-c", probe], env=env, cwd=cwd,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_import_pmdsim_imports_no_heavy_package():
    assert _imported("import pmdsim; pmdsim.__version__") == []


def test_cli_help_imports_no_heavy_package():
    code = ("from pmdsim.cli import app\n"
            "try:\n    app(['--help'])\nexcept SystemExit as e:\n    assert e.code == 0, e.code\n"
            "try:\n    app(['simulate', '--help'])\nexcept SystemExit as e:\n"
            "    assert e.code == 0, e.code\n")
    assert _imported(code) == []


def _small_run(tmp_path) -> str:
    """Python source that runs the tests' small configuration into ``tmp_path/run``
    without figures (its result: ``res``)."""
    from conftest import base_dict

    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps(base_dict()))
    return ("import json\n"
            "from pmdsim.config import parse_config\n"
            "from pmdsim.run import run_simulation\n"
            f"cfg = parse_config(json.loads(open({str(cfg)!r}).read()))\n"
            f"res = run_simulation(cfg, {str(tmp_path / 'run')!r}, figures=False)\n")


def test_a_run_without_figures_never_imports_matplotlib(tmp_path):
    imported = _imported(_small_run(tmp_path) + "assert res.figure_paths == ()\n")
    assert "numba" in imported and "xarray" in imported  # it did run
    assert "matplotlib" not in imported


def test_a_run_imports_xarray_in_its_background_thread(tmp_path):
    """The dataset's modules are imported by the run's import thread while the render runs,
    never by the run's own thread on its critical path (the dataset step waits for them)."""
    probe = ("import sys, threading\n"
             "first = {}\n"
             "class Probe:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name in ('xarray', 'zarr') and name not in first:\n"
             "            first[name] = threading.current_thread().name\n"
             "        return None\n"
             "sys.meta_path.insert(0, Probe())\n")
    check = "assert first == {'xarray': 'pmdsim-imports', 'zarr': 'pmdsim-imports'}, first\n"
    imported = _imported(probe + _small_run(tmp_path) + check)
    assert "xarray" in imported and "matplotlib" not in imported
