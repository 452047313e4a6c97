"""The package's imports point one way, along the data flow (docs/architecture.md).

Every module of ``src/pmdsim`` is parsed (``ast``; nothing is imported), every import in it
(also those inside functions) is resolved to the package's top-level part it names, and
the part's layer must not be above the importing module's. ``kernels`` import nothing of
the package but ``kernels``. A module in a top-level part that is not in :data:`LAYERS`
fails the test until it is given a layer.

Between modules (also inside one part) there is no import cycle, imports inside functions
included; no module re-exports a name at its top level (``noqa: F401`` outside
``__init__.py``); and no function below ``studies`` takes the whole ``RunConfig``: each
takes its own section or plain values (its signature says so).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "pmdsim"

#: Layer of each top-level part of the package, in the order the data flows. A module may
#: import parts of its own layer or below; ``__init__`` (the public facade) and ``cli`` sit
#: on top.
LAYERS = {
    "kernels": 0,
    "_version": 1, "config": 1, "geometry": 1, "patterns": 1, "imagefile": 1, "topofile": 1,
    "quantiles": 1,
    "brdf": 2,
    "scene": 3,
    "trace": 4,
    "render": 5,
    "measure": 6,
    "studies": 7,
    "store": 8,
    "report": 9,
    "run": 10,
    "cli": 11, "__init__": 11, "__main__": 11,
}


def part_of(module: str) -> str:
    """``pmdsim.run.steps`` -> ``run``; ``pmdsim`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported_modules(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module) of every ``pmdsim`` import in ``source``."""
    package = module if is_package else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "pmdsim"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "pmdsim":
                continue
            if target == "pmdsim":  # from pmdsim import x: x is a part
                found += [(node.lineno, f"pmdsim.{a.name}") for a in node.names]
            elif node.module is None:  # from . import x, inside a part
                found += [(node.lineno, f"{target}.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, target))
    return found


def violations(source: str, module: str, is_package: bool = False) -> list[str]:
    """What is wrong with the imports of one module (empty: nothing)."""
    own = part_of(module)
    if own not in LAYERS:
        return [f"{module}: top-level part {own!r} has no layer in tests/test_architecture.py"]
    out = []
    for line, target in imported_modules(source, module, is_package):
        other = part_of(target)
        if other not in LAYERS:
            out.append(f"{module}:{line} imports {target}: unknown part {other!r}")
        elif own == "kernels" and other != "kernels":
            out.append(f"{module}:{line} imports {target}: kernels import only kernels")
        elif own == "report" and other == "store":
            out.append(f"{module}:{line} imports {target}: report draws from a dataset alone, "
                       "never from the store")
        elif LAYERS[other] > LAYERS[own]:
            out.append(f"{module}:{line} imports {target} ({other}, layer {LAYERS[other]}) "
                       f"from {own} (layer {LAYERS[own]}): imports must point down the data flow")
    return out


def all_modules():
    return sorted(PACKAGE.rglob("*.py"))


def test_every_import_points_down_the_data_flow():
    problems = []
    for path in all_modules():
        problems += violations(path.read_text(), module_name(path), path.name == "__init__.py")
    assert problems == [], "\n".join(problems)


@pytest.mark.parametrize("module, source", [
    ("pmdsim.kernels.bundle", "from ..render import Simulation\n"),
    ("pmdsim.kernels.bundle", "def f():\n    from pmdsim.config import RunConfig\n"),
    ("pmdsim.measure.chain", "from ..report import chain as plot_chain\n"),
    ("pmdsim.measure.chain", "def f():\n    from .. import run\n"),
    ("pmdsim.studies.diagnostics", "import pmdsim.cli\n"),
    ("pmdsim.report.text", "from pmdsim.run.simulate import run_simulation\n"),
    ("pmdsim.store.schema", "from ..report import chain\n"),
    ("pmdsim.report.text", "from ..store.schema import load_run\n"),
    ("pmdsim.scene.camera", "from ..trace import trace_primary\n"),
    ("pmdsim.newthing", "import numpy\n"),
])
def test_a_wrong_import_is_found(module, source):
    """The checker itself: each of these imports points up (or comes from an unknown part)."""
    assert violations(source, module) != []


@pytest.mark.parametrize("module, source", [
    ("pmdsim.kernels.primary", "from .bundle import G_A\nfrom ._jit import fastjit\n"),
    ("pmdsim.run.steps", "from ..report import chain\nfrom ..measure import chain as c\n"),
    ("pmdsim.cli", "from .run import run_simulation\n"),
    ("pmdsim.measure.decode", "from ..kernels import decode as _k\n"),
])
def test_a_right_import_passes(module, source):
    assert violations(source, module) == []


#: Longest module, outside ``kernels/``, that needs no stated reason (docs/architecture.md).
MAX_LINES = 600


def long_modules_stated() -> set[str]:
    """The modules docs/architecture.md's "Module size" table says may stay longer."""
    import re

    text = (PACKAGE.parents[1] / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Module size", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `([\w/]+\.py)` \|", section, flags=re.M))


def test_no_module_is_longer_than_its_job_without_a_stated_reason():
    stated = long_modules_stated()
    assert all((PACKAGE / m).is_file() for m in stated), f"stated modules that are gone: {stated}"
    long = {str(p.relative_to(PACKAGE)): len(p.read_text(encoding="utf-8").splitlines())
            for p in all_modules() if p.relative_to(PACKAGE).parts[0] != "kernels"}
    over = {m: n for m, n in long.items() if n > MAX_LINES and m not in stated}
    assert not over, (f"modules over {MAX_LINES} lines without a reason in docs/architecture.md "
                      f"(split them, or state why in its Module size table): {over}")


# ----------------------------------------------------------------------------- cycles
def import_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """module -> the modules of ``sources`` it imports (imports inside functions included).
    ``sources``: module -> (source, is_package). An import names the longest module it
    reaches (``from pmdsim.scene import Scene`` -> ``pmdsim.scene``)."""
    graph = {}
    for module, (source, is_package) in sources.items():
        targets = set()
        for _, target in imported_modules(source, module, is_package):
            while target and target not in sources:
                target = target.rpartition(".")[0]
            if target and target != module:
                targets.add(target)
        graph[module] = targets
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def package_sources() -> dict[str, tuple[str, bool]]:
    return {module_name(p): (p.read_text(), p.name == "__init__.py") for p in all_modules()}


def test_no_import_cycle_between_modules():
    cycles = import_cycles(import_graph(package_sources()))
    assert cycles == [], "import cycles (cut each by giving the shared concept its own module): " + \
        "; ".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("planted", [
    {"pmdsim.brdf.a": ("from .b import f\n", False),
     "pmdsim.brdf.b": ("def g():\n    from .a import h\n", False)},       # inside a function
    {"pmdsim.studies.a": ("from . import b\n", False),
     "pmdsim.studies.b": ("import pmdsim.studies.c\n", False),
     "pmdsim.studies.c": ("from pmdsim.studies.a import x\n", False)},  # a ring of three
    {"pmdsim.store": ("from .schema import load_run\n", True),
     "pmdsim.store.schema": ("from ..store import writer\n", False),
     "pmdsim.store.writer": ("", False)},                                  # a package and its module
])
def test_a_planted_cycle_is_found(planted):
    """The checker itself: each of these holds a cycle, also next to the real package."""
    assert import_cycles(import_graph(planted)) != []
    assert import_cycles(import_graph({**package_sources(), **planted})) != []


def test_imports_without_a_cycle_pass():
    chain_ = {"pmdsim.brdf.a": ("from .b import f\n", False),
              "pmdsim.brdf.b": ("def g():\n    from .c import h\n", False),
              "pmdsim.brdf.c": ("import numpy\n", False)}
    assert import_cycles(import_graph(chain_)) == []


# ----------------------------------------------------------------------------- re-exports
def top_level_reexports(source: str) -> list[int]:
    """Lines of top-level imports marked ``noqa: F401`` (kept although unused: a re-export)."""
    lines = source.splitlines()
    return [n.lineno for n in ast.parse(source).body
            if isinstance(n, (ast.Import, ast.ImportFrom))
            and any("noqa" in line and "F401" in line for line in lines[n.lineno - 1:n.end_lineno])]


def test_no_module_reexports_what_lives_elsewhere():
    found = [f"{module_name(p)}:{line}" for p in all_modules() if p.name != "__init__.py"
             for line in top_level_reexports(p.read_text())]
    assert found == [], "import a name from the module it lives in: " + ", ".join(found)


def test_a_reexport_is_found():
    assert top_level_reexports("from .results import Geometry  # noqa: F401\n") == [1]
    assert top_level_reexports("def f():\n    import x  # noqa: F401\n") == []


# ----------------------------------------------------------------------------- narrow inputs
#: The parts below ``studies``: each takes its own configuration section or plain values.
NARROW = [part for part, layer in LAYERS.items() if 0 < layer < LAYERS["studies"] and part != "config"]
#: Parameter names that hold a configuration (they must say which section).
CONFIG_NAMES = {"cfg", "config", "run_config"}


def whole_config_parameters(source: str) -> list[str]:
    """``function(parameter)`` of every function whose parameter is annotated ``RunConfig``,
    or holds a configuration (:data:`CONFIG_NAMES`) without saying which section."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            for arg in a.posonlyargs + a.args + a.kwonlyargs + [a.vararg, a.kwarg]:
                if arg is None:
                    continue
                note = ast.unparse(arg.annotation) if arg.annotation is not None else None
                if (note is not None and "RunConfig" in note) or (note is None and arg.arg in CONFIG_NAMES):
                    found.append(f"{node.name}({arg.arg}: {note})")
    return found


def test_no_module_below_studies_takes_the_whole_configuration():
    found = [f"{module_name(p)}: {f}" for p in all_modules()
             if part_of(module_name(p)) in NARROW
             for f in whole_config_parameters(p.read_text())]
    assert found == [], ("pass the section (or the plain values) the function reads, annotated: "
                         + ", ".join(found))


@pytest.mark.parametrize("source, bad", [
    ("def f(cfg: RunConfig):\n    pass\n", True),
    ("def f(cfg: 'RunConfig | None' = None):\n    pass\n", True),
    ("class S:\n    def from_config(cls, cfg):\n        pass\n", True),
    ("def f(cfg: MonitorConfig, n: int):\n    pass\n", False),
    ("def f(camera: CameraConfig, surface: SurfaceConfig):\n    pass\n", False),
])
def test_a_whole_configuration_parameter_is_found(source, bad):
    assert (whole_config_parameters(source) != []) is bad
