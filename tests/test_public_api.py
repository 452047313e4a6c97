"""Every public name imports in a fresh interpreter.

``pmdsim`` resolves most of its names lazily (``pmdsim.__getattr__``), and a lazy name that
points at the wrong module only fails in an interpreter that has not imported that module
by another path: so each name of ``pmdsim.__all__`` is imported in its own fresh Python
process (``from pmdsim import NAME``), and every other module that declares ``__all__``
is imported fresh and each of its names looked up. The module list is read from the
source (``ast``), so a new module with ``__all__`` is checked without editing this file.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "pmdsim"


def _declared_all(path: Path) -> list[str] | None:
    """The literal ``__all__`` of a module's source (None: the module declares none)."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name) and node.targets[0].id == "__all__"):
            return list(ast.literal_eval(node.value))
    return None


def _module(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module(p): names for p in sorted(PACKAGE.rglob("*.py"))
           if (names := _declared_all(p)) is not None}
TOP = MODULES.pop("pmdsim")


def _run_all(scripts: dict[str, str]) -> dict[str, subprocess.CompletedProcess]:
    """Run each script in its own fresh interpreter, a few at a time (they mostly wait on
    imports); {key: completed process}."""
    env = dict(os.environ, PYTHONPATH=str(SRC))

    def one(script):
        return subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, timeout=300)

    with ThreadPoolExecutor(max_workers=3) as pool:
        return dict(zip(scripts, pool.map(one, scripts.values())))


def test_the_lists_are_read():
    # the parsing above found the facade and the packages' lists (a broken reader would
    # make the tests below vacuous)
    assert {"load_config", "Simulation", "decode", "run_simulation"} <= set(TOP)
    assert {"pmdsim.config", "pmdsim.cli", "pmdsim.measure.decode"} <= set(MODULES)


def test_every_name_of_pmdsim_imports_in_a_fresh_interpreter():
    scripts = {n: f"import pmdsim\nfrom pmdsim import {n}\nassert getattr(pmdsim, {n!r}) is {n}\n"
               for n in TOP if n != "__version__"}
    failed = {n: r.stderr.strip().splitlines()[-1:] for n, r in _run_all(scripts).items()
              if r.returncode != 0}
    assert not failed, f"names of pmdsim.__all__ that do not import: {failed}"


def test_decode_is_the_decoding_module():
    # the package docstring promises pmdsim.decode == pmdsim.measure.decode
    script = ("import pmdsim, pmdsim.measure.decode as d\n"
              "assert pmdsim.decode is d, pmdsim.decode\n"
              "assert callable(pmdsim.decode.decode_sequence)\n")
    r = _run_all({"decode": script})["decode"]
    assert r.returncode == 0, r.stderr


def test_an_unknown_name_is_an_attribute_error():
    script = ("import pmdsim\ntry:\n    pmdsim.no_such_name\nexcept AttributeError as e:\n"
              "    print(e)\nelse:\n    raise SystemExit('no AttributeError')\n")
    r = _run_all({"x": script})["x"]
    assert r.returncode == 0 and "no_such_name" in r.stdout, r.stderr


@pytest.mark.parametrize("chunk", [0, 1])
def test_every_module_all_resolves_in_a_fresh_interpreter(chunk):
    names = sorted(MODULES)[chunk::2]
    scripts = {m: f"import importlib\nm = importlib.import_module({m!r})\n"
               f"missing = [n for n in m.__all__ if not hasattr(m, n)]\n"
               f"assert not missing, missing\n" for m in names}
    failed = {m: r.stderr.strip().splitlines()[-1:] for m, r in _run_all(scripts).items()
              if r.returncode != 0}
    assert not failed, f"modules whose __all__ names a missing attribute: {failed}"
