"""pmdsim warmup: every warm-up case is a valid configuration that runs end to end (a case
that main's checks start to reject would leave kernels uncompiled after an install)."""

from __future__ import annotations

from pmdsim.run.warmup import CASES, warmup


def test_every_warmup_case_runs():
    done = []
    seconds = warmup(lambda k, n: done.append((k, n)))
    assert list(seconds) == list(CASES)
    assert done[-1] == (len(CASES), len(CASES))


def test_byte_compile_leaves_a_current_pyc_for_every_module(tmp_path):
    import importlib.util
    import shutil
    from pathlib import Path

    import pmdsim
    from pmdsim.run.warmup import byte_compile

    # on a copy of the package (the checkout's own __pycache__ stays as it is)
    pkg = tmp_path / "pmdsim"
    shutil.copytree(Path(pmdsim.__file__).parent, pkg,
                    ignore=shutil.ignore_patterns("__pycache__"))
    sources = sorted(pkg.rglob("*.py"))
    assert len(sources) > 50
    assert not any(Path(importlib.util.cache_from_source(str(s))).exists() for s in sources)
    assert byte_compile(pkg)
    for src in sources:
        assert Path(importlib.util.cache_from_source(str(src))).is_file(), src


def test_a_run_on_the_threaded_scheduler_does_not_import_distributed(tmp_path):
    """Dask imports ``distributed`` (0.25 s) to look for a client when given a scheduler
    name; the run passes its schedulers as functions (pmdsim.render.local_scheduler)."""
    import subprocess
    import sys

    pytest = __import__("pytest")
    pytest.importorskip("distributed")
    code = (
        "import sys\n"
        "from pmdsim.run.warmup import warmup_configs\n"
        "from pmdsim.run import run_simulation\n"
        "cfg = warmup_configs()['ward-continuous-random']\n"
        "cfg = cfg.model_copy(update={'output': cfg.output.model_copy(update={'write_images': True})})\n"
        f"run_simulation(cfg, {str(tmp_path / 'run')!r}, figures=False)\n"
        "print('distributed' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out[-1] == "False"
