#!/usr/bin/env python
"""Mutation testing of pmdsim's analysis code: plant one small bug at a time, run the tests
that should catch it, count how many are caught (issue 9).

Standard library only (``ast``, ``subprocess``); no mutmut/cosmic-ray needed. For each
target module the script enumerates *mutation sites* in its source and makes one mutant per
site and operator:

- arithmetic: ``+`` <-> ``-``, ``*`` <-> ``/``, ``**`` -> ``*``, ``//`` -> ``/``;
- comparisons (boundaries and negations): ``<`` <-> ``<=``, ``>`` <-> ``>=``,
  ``==`` <-> ``!=``;
- masks and logic: ``&`` <-> ``|``, ``and`` <-> ``or``, ``~x`` -> ``x``, ``not x`` -> ``x``;
- constants: integers ``n`` -> ``n + 1`` (and ``1`` -> ``0``: ddof, off-by-one), floats
  ``c`` -> ``2 c`` (``0.0`` -> ``1.0``), ``True`` <-> ``False``;
- sign: unary ``-x`` -> ``x``;
- reductions: ``mean`` <-> ``median``, ``min`` <-> ``max``, ``nanmin`` <-> ``nanmax``,
  ``abs(x)`` -> ``x``.

Docstrings, f-strings (messages), ``raise`` statements, annotations and decorators are not
mutated. Each mutant is
written into a private copy of ``src/`` (the mutated file's folders are real, everything
else is a symbolic link, so the compiled Numba kernels' cache is reused), the module's test
files run with ``pytest -x`` under a timeout, and the mutant is *killed* when they fail
(or time out), *survives* when they pass. Known equivalent mutants (the code does the same
thing) are listed in :data:`EQUIVALENT` with the reason and left out of the kill rate.

Usage (from the repository root)::

    python tools/mutation.py --list measure/deviation.py
    python tools/mutation.py --sample 30 --seed 1 measure/deviation.py studies/diagnostics.py
    python tools/mutation.py --all            # every site of every target: hours on 2 cores

It prints per module the kill rate (killed / non-equivalent mutants) and every survivor
(``file:line``, the original and the mutated code), and writes ``out/mutation/report.json``.
See docs/testing.md for the last results.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"

#: Target modules (relative to src/pmdsim) and the fast test files that guard them, in the
#: order they run (pytest -x stops at the first failure, so the most targeted file first).
TARGETS = {
    "measure/deviation.py": ["tests/measure/test_deviation_independent.py", "tests/measure/test_analysis.py"],
    "measure/chain.py": ["tests/measure/test_deviation_independent.py",
                         "tests/trace/test_geometry_independent.py",
                         "tests/measure/test_chain.py::test_decode_problem_names_the_widths_and_the_fix",
                         "tests/measure/test_chain.py::test_scattering_that_breaks_the_finest_fringes_is_flagged_not_hidden"],
    "studies/diagnostics.py": [
        "tests/studies/test_diagnostics_independent.py", "tests/test_warnings_true.py",
        *(f"tests/run/test_converge.py::{t}" for t in (
            "test_energy_fraction_matches_dense_quadrature",
            "test_fig3_lobe_holds_about_a_third_inside_one_degree",
            "test_energy_fraction_limits_and_monotone", "test_effective_sample_size_formula",
            "test_delta_method_matches_iid_replications", "test_phase_error_seeds",
            "test_full_map_is_bilinear_and_fills_missing_nodes",
            "test_diagnose_and_check_name_the_fixing_setting",
            "test_check_reports_washed_out_fringes", "test_mirror_has_nothing_to_diagnose"))],
    "studies/diagnostic_warnings.py": [
        "tests/studies/test_diagnostics_independent.py", "tests/test_warnings_true.py",
        "tests/run/test_converge.py::test_diagnose_and_check_name_the_fixing_setting",
        "tests/run/test_converge.py::test_check_reports_washed_out_fringes"],
    "studies/convergence.py": ["tests/studies/test_convergence_independent.py",
                               "tests/run/test_converge.py::test_reduced_config_keeps_the_field_of_view",
                               "tests/run/test_converge.py::test_run_convergence_rejects_bad_input"],
    "measure/decode.py": ["tests/measure/test_decode_independent.py", "tests/measure/test_decode.py"],
}

_AXIS = "axis -1 -> 1 on the 2-D (pixels, rays) arrays this function works on (its documented shapes)"

#: Mutants that cannot change behaviour, by key (see :func:`Mutant.key`), with the reason.
#: (``python tools/mutation.py --list --keys MODULE`` prints the keys.)
EQUIVALENT: dict[str, str] = {
    "studies/diagnostics.py:ess_from_weights:Gt->GtE:s2 > 0#0":
        "weights are >= 0: sum w^2 = 0 only if sum w = 0, and 0/0 is the NaN the where gives",
    "studies/diagnostics.py:phase_error_from_rays:Gt->GtE:wsum > 0#0":
        "wsum = 0 means every weight is 0, so |zbar| n / wsum is 0/0 = NaN as well",
    "studies/diagnostics.py:lobe_energy:LtE->Lt:ang <= th#0":
        "an angle exactly equal to the cone half angle has probability zero",
    "studies/diagnostics.py:lobe_energy:Sub->Add:n_samples - 1#0":
        "the cumulative fraction ends at 1, so (cum < target).sum() <= n - 1 for target <= 1: "
        "the min() never binds",
    "studies/diagnostics.py:incidence:Gt->GtE:dot(i, normal) > 0#0":
        "exactly grazing vision rays (i.n = 0 to the last bit) do not occur",
    "studies/diagnostic_warnings.py:check:float 1.0->2.0:1.0#1":
        "worst starts at -1 or -2: below every standard error (>= 0) either way",
    "studies/diagnostic_warnings.py:check:float 1.0->2.0:1.0#2":
        "'else 1.0' runs only with rays None and phase_se set, which diagnose never makes "
        "(rays is None only for the mirror, whose phase_se is None)",
    "studies/diagnostic_warnings.py:check:float 0.0->1.0:0.0#0":
        "the floor's 'else 0.0' runs when no judged pixel has an ESS, and then no fringe has a "
        "modulation either (each is skipped as NaN), so the floor is never compared",
    "studies/diagnostic_warnings.py:check:float 0.25->0.5:0.25#0":
        "a finite median ESS is >= 1 (any bundle with weight), so max(ESS, 0.25 or 0.5) = ESS",
    "studies/diagnostic_warnings.py:check:Gt->GtE:p95 > worst#0":
        "only ties change: the same worst error and suggested N, the message names the other "
        "of two equally bad fringes",
    "studies/diagnostics.py:full_map:drop-USub:-1#3":
        'np.stack of 1-D coordinate arrays: axis -1 is axis 1',
    "studies/diagnostics.py:incidence:drop-USub:-1#0":
        'np.stack of (K,) arrays (rows, cols are 1-D): axis -1 is axis 1',
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#0":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#1":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#2":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#3":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#4":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#6":
        _AXIS,
    "studies/diagnostics.py:lobe_energy:drop-USub:-1#7":
        _AXIS,
    "studies/diagnostics.py:phase_error_from_rays:drop-USub:-1#0":
        _AXIS,
    "studies/diagnostics.py:phase_error_from_rays:drop-USub:-1#1":
        _AXIS,
    "studies/diagnostics.py:phase_error_from_rays:drop-USub:-1#2":
        _AXIS,
    "studies/diagnostics.py:phase_error_from_rays:drop-USub:-1#3":
        _AXIS,
    "studies/diagnostics.py:ray_phases:drop-USub:-1#0":
        _AXIS,
    "studies/convergence.py:reduced_config:float 1.0->2.0:1.0#0":
        "any scale >= 1 returns the configuration unchanged, so a cap above 1 is never used",
    "measure/deviation.py:image_moments:LtE->Lt:angle <= -np.pi / 2#0":
        "an angle of exactly -pi/2 needs the eigenvector (0, -1), which LAPACK does not return "
        "for the diagonal covariance of an axis-aligned spot (it returns (0, 1))",
    "measure/deviation.py:image_moments:Gt->GtE:img > threshold#0":
        "a pixel exactly at the threshold weighs img - threshold = 0 either way",
    "measure/deviation.py:image_moments:int 2->3:2#0":
        "-pi/3 instead of -pi/2 differs only for raw eigenvector angles in (-90, -60] deg; "
        "LAPACK's 2 x 2 eigenvectors never point into (-90, 0) deg (0 of 20 000 random "
        "covariances), so the branch sees the same angles",
    "studies/diagnostics.py:lobe_energy:float 1.0->2.0:1.0#0":
        "np.clip's upper bound only catches the rounding overshoot of a unit dot product "
        "(1 + 1e-16) for a sample within ~1e-8 rad of P; the lattice has none there",
    "studies/diagnostics.py:lobe_energy:Lt->LtE:cum < target#0":
        "differs only when a cumulative weight fraction equals the target to the last bit",
    "measure/deviation.py:image_moments:Gt->GtE:minor > 0#0":
        "major / 0.0 on float64 is inf, the value of the else branch",
    "measure/chain.py:surface_to_monitor_mm:int 128->129:128#0":
        "the chunk size of the trace does not change the distances",
    "measure/chain.py:dot_table:Gt->GtE:peak > 0#0":
        "peak = 0 gives threshold 0 x 0 = 0, the else value",
}

#: Call names swapped by the reduction operator (attribute or plain name).
SWAPS = {"mean": "median", "median": "mean", "min": "max", "max": "min",
         "nanmin": "nanmax", "nanmax": "nanmin", "nanmean": "nanmedian", "nanmedian": "nanmean"}
BINOPS = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult,
          ast.Pow: ast.Mult, ast.FloorDiv: ast.Div, ast.BitAnd: ast.BitOr, ast.BitOr: ast.BitAnd}
CMPOPS = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt,
          ast.Eq: ast.NotEq, ast.NotEq: ast.Eq}


@dataclass
class Mutant:
    module: str
    index: int          # site number in the module (document order)
    function: str       # enclosing qualified name ("" at module level)
    operator: str
    line: int
    original: str
    mutated: str
    occurrence: int = 0  # how many earlier mutants share (function, operator, original)

    @property
    def key(self) -> str:
        return f"{self.module}:{self.function}:{self.operator}:{self.original}#{self.occurrence}"


# ----------------------------------------------------------------------------- finding sites
def _skipped_nodes(tree: ast.AST) -> set[int]:
    """ids of nodes never mutated: docstrings, f-strings, raise statements, annotations,
    decorators."""
    skip: set[int] = set()

    def mark(node):
        for sub in ast.walk(node):
            skip.add(id(sub))

    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                mark(body[0])
        if isinstance(node, (ast.JoinedStr, ast.Raise)):
            mark(node)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for dec in node.decorator_list:     # @dataclass(frozen=True): not behaviour
                mark(dec)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if node.returns is not None:
                mark(node.returns)
            for a in node.args.args + node.args.kwonlyargs + node.args.posonlyargs:
                if a.annotation is not None:
                    mark(a.annotation)
        if isinstance(node, ast.AnnAssign):
            mark(node.annotation)
    return skip


def _parents(tree):
    """Map node id -> enclosing function/class qualified name."""
    names: dict[int, str] = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                q = f"{prefix}.{child.name}" if prefix else child.name
                for sub in ast.walk(child):
                    names[id(sub)] = q
                visit(child, q)
            else:
                visit(child, prefix)

    visit(tree, "")
    return names


def _variants(node):
    """(operator name, function that mutates a *copy* of the node in place) for a node."""
    out = []
    if isinstance(node, ast.BinOp) and type(node.op) in BINOPS:
        new = BINOPS[type(node.op)]
        out.append((f"{type(node.op).__name__}->{new.__name__}",
                    lambda n, new=new: setattr(n, "op", new())))
    elif isinstance(node, ast.Compare):
        for k, op in enumerate(node.ops):
            if type(op) in CMPOPS:
                new = CMPOPS[type(op)]

                def f(n, k=k, new=new):
                    n.ops[k] = new()
                out.append((f"{type(op).__name__}->{new.__name__}", f))
    elif isinstance(node, ast.BoolOp):
        new = ast.Or if isinstance(node.op, ast.And) else ast.And
        out.append((f"{type(node.op).__name__}->{new.__name__}",
                    lambda n, new=new: setattr(n, "op", new())))
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.Invert, ast.Not)):
        out.append((f"drop-{type(node.op).__name__}", "unwrap"))
    elif isinstance(node, ast.Constant) and not isinstance(node.value, str):
        v = node.value
        if isinstance(v, bool):
            out.append(("bool-flip", lambda n: setattr(n, "value", not n.value)))
        elif isinstance(v, int):
            new = 0 if v == 1 else v + 1
            out.append((f"int {v}->{new}", lambda n, new=new: setattr(n, "value", new)))
        elif isinstance(v, float):
            new = 1.0 if v == 0.0 else 2.0 * v
            out.append((f"float {v!r}->{new!r}", lambda n, new=new: setattr(n, "value", new)))
    elif isinstance(node, ast.Call):
        fn = node.func
        name = fn.attr if isinstance(fn, ast.Attribute) else fn.id if isinstance(fn, ast.Name) else None
        if name in SWAPS:
            new = SWAPS[name]

            def f(n, new=new):
                if isinstance(n.func, ast.Attribute):
                    n.func.attr = new
                else:
                    n.func.id = new
            out.append((f"{name}->{new}", f))
        if name == "abs" and len(node.args) == 1:
            out.append(("drop-abs", "unwrap-call"))
    return out


def find_mutants(module: str) -> list[Mutant]:
    path = SRC / "pmdsim" / module
    source = path.read_text()
    tree = ast.parse(source)
    skip = _skipped_nodes(tree)
    owner = _parents(tree)
    mutants: list[Mutant] = []
    seen: dict[tuple, int] = {}
    for node in ast.walk(tree):
        if id(node) in skip or not hasattr(node, "lineno"):
            continue
        for op, fn in _variants(node):
            original = ast.unparse(node)
            mutated = _apply(source, tree, node, fn, render_only=True)
            if mutated is None or mutated == original:
                continue
            func = owner.get(id(node), "")
            k = (func, op, original)
            occ = seen.get(k, 0)
            seen[k] = occ + 1
            mutants.append(Mutant(module, len(mutants), func, op, node.lineno, original, mutated,
                                  occ))
    mutants.sort(key=lambda m: (m.line, m.index))
    for i, m in enumerate(mutants):
        m.index = i
    return mutants


def _apply(source, tree, node, fn, render_only=False):
    """The mutated node's code (render_only) or the whole mutated module source."""
    import copy

    target = copy.deepcopy(node)
    if fn == "unwrap":
        replacement = target.operand
    elif fn == "unwrap-call":
        replacement = target.args[0]
    else:
        fn(target)
        replacement = target
    if render_only:
        return ast.unparse(replacement)
    # replace the node in a copy of the tree, located by position
    new_tree = copy.deepcopy(tree)
    for parent in ast.walk(new_tree):
        for field, value in ast.iter_fields(parent):
            if isinstance(value, list):
                for i, item in enumerate(value):
                    if _same(item, node):
                        value[i] = replacement
                        return ast.unparse(ast.fix_missing_locations(new_tree))
            elif _same(value, node):
                setattr(parent, field, replacement)
                return ast.unparse(ast.fix_missing_locations(new_tree))
    raise RuntimeError("mutation site not found")


def _same(a, b) -> bool:
    return (isinstance(a, ast.AST) and type(a) is type(b)
            and getattr(a, "lineno", None) == b.lineno
            and getattr(a, "col_offset", None) == b.col_offset
            and getattr(a, "end_lineno", None) == getattr(b, "end_lineno", None)
            and getattr(a, "end_col_offset", None) == getattr(b, "end_col_offset", None))


def mutated_source(m: Mutant) -> str:
    path = SRC / "pmdsim" / m.module
    source = path.read_text()
    tree = ast.parse(source)
    skip = _skipped_nodes(tree)
    owner = _parents(tree)
    for node in ast.walk(tree):
        if id(node) in skip or getattr(node, "lineno", None) != m.line:
            continue
        for op, fn in _variants(node):
            if op == m.operator and ast.unparse(node) == m.original \
                    and owner.get(id(node), "") == m.function:
                if _apply(source, tree, node, fn, render_only=True) == m.mutated:
                    return _apply(source, tree, node, fn)
    raise RuntimeError(f"mutant {m.key} not found")


# ----------------------------------------------------------------------------- running
def _mirror_tree(dest: Path, module: str) -> Path:
    """dest/src: links to every entry of src/ except the folders leading to ``module``,
    which are real folders of links; returns the path the mutated file goes to."""
    parts = Path("pmdsim", module).parts
    here_src, here_dst = SRC, dest / "src"
    here_dst.mkdir(parents=True)
    for depth, part in enumerate(parts):
        for entry in here_src.iterdir():
            if entry.name == part or entry.name == "__pycache__":
                continue
            os.symlink(entry, here_dst / entry.name)
        here_src, here_dst = here_src / part, here_dst / part
        if depth < len(parts) - 1:
            here_dst.mkdir()
    return here_dst


def run_mutant(m: Mutant, tests: list[str], timeout: float, python: str) -> dict:
    code = mutated_source(m)
    with tempfile.TemporaryDirectory(prefix="pmdsim-mut-") as tmp:
        target = _mirror_tree(Path(tmp), m.module)
        target.write_text(code)
        env = dict(os.environ, PYTHONPATH=str(Path(tmp) / "src"), PYTHONDONTWRITEBYTECODE="1")
        cmd = [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--no-header",
               "-W", "ignore", *tests]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True,
                                  timeout=timeout)
            rc, out = proc.returncode, proc.stdout[-2000:]
        except subprocess.TimeoutExpired:
            rc, out = None, "timeout"
        seconds = time.perf_counter() - t0
    status = "timeout" if rc is None else "survived" if rc == 0 else "killed"
    failed = next((ln for ln in out.splitlines() if ln.startswith(("FAILED", "ERROR"))), "")
    return {"status": status, "rc": rc, "seconds": round(seconds, 1), "failed": failed}


def run_baseline(module: str, tests: list[str], timeout: float, python: str) -> dict:
    """The tests on the unmutated copy: they must pass, or every mutant would look killed."""
    source = (SRC / "pmdsim" / module).read_text()
    with tempfile.TemporaryDirectory(prefix="pmdsim-mut-") as tmp:
        _mirror_tree(Path(tmp), module).write_text(source)
        env = dict(os.environ, PYTHONPATH=str(Path(tmp) / "src"), PYTHONDONTWRITEBYTECODE="1")
        cmd = [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--no-header",
               "-W", "ignore", *tests]
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True,
                                  timeout=timeout)
            rc, out = proc.returncode, proc.stdout[-2000:]
        except subprocess.TimeoutExpired:
            rc, out = None, "timeout"
    status = "timeout" if rc is None else "survived" if rc == 0 else "killed"
    failed = next((ln for ln in out.splitlines() if ln.startswith(("FAILED", "ERROR"))), "")
    return {"status": status, "rc": rc, "failed": failed}


def check_isolation(python: str) -> None:
    """The mutated copy must shadow the package (an editable install could win)."""
    with tempfile.TemporaryDirectory(prefix="pmdsim-mut-") as tmp:
        _mirror_tree(Path(tmp), "measure/deviation.py").write_text(
            (SRC / "pmdsim/measure/deviation.py").read_text())
        env = dict(os.environ, PYTHONPATH=str(Path(tmp) / "src"))
        got = subprocess.run([python, "-c", "import pmdsim.measure.deviation as m; print(m.__file__)"],
                             env=env, capture_output=True, text=True, cwd=ROOT).stdout.strip()
        if not got.startswith(str(Path(tmp))):
            sys.exit(f"mutants would not be imported (got {got}); is PYTHONPATH ignored?")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("modules", nargs="*", help=f"modules under src/pmdsim (default: all of "
                                               f"{', '.join(TARGETS)})")
    ap.add_argument("--all", action="store_true", help="every mutant (default: a sample)")
    ap.add_argument("--sample", type=int, default=20, help="mutants per module (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the sample")
    ap.add_argument("--only", type=int, nargs="*", help="mutant indices (with one module)")
    ap.add_argument("--tests", nargs="*", help="test files to run instead of the defaults")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per mutant")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--keys", action="store_true", help="with --list: print each mutant's key "
                                                         "(for EQUIVALENT)")
    ap.add_argument("--out", default=str(ROOT / "out" / "mutation" / "report.json"))
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--summary", metavar="REPORT", help="print the summary of a (partial) "
                                                        "report.json and exit")
    args = ap.parse_args(argv)
    modules = args.modules or list(TARGETS)
    for mod in modules:
        if not (SRC / "pmdsim" / mod).is_file():
            ap.error(f"no module src/pmdsim/{mod}")

    if args.summary:
        summarize(json.loads(Path(args.summary).read_text()))
        return 0
    out = Path(args.out)
    if not args.list:
        check_isolation(args.python)
        out.parent.mkdir(parents=True, exist_ok=True)
    report = {"modules": {}, "settings": {k: v for k, v in vars(args).items()
                                          if k not in ("list",)}}
    for mod in modules:
        mutants = find_mutants(mod)
        if args.only is not None:
            chosen = [m for m in mutants if m.index in set(args.only)]
        elif args.all or args.sample >= len(mutants):
            chosen = mutants
        else:
            chosen = sorted(random.Random(f"{args.seed}:{mod}").sample(mutants, args.sample),
                            key=lambda m: m.index)
        if args.list:
            print(f"== {mod}: {len(mutants)} mutants")
            for m in chosen:
                eq = "  [equivalent]" if m.key in EQUIVALENT else ""
                print(f"  #{m.index:4d} {mod}:{m.line:<5d} {m.operator:<22s} "
                      f"{m.original[:60]!s} -> {m.mutated[:60]!s}{eq}")
                if args.keys:
                    print(f"        key: {m.key}")
            continue
        tests = args.tests or TARGETS.get(mod)
        if not tests:
            ap.error(f"no default tests for {mod}: give --tests")
        print(f"== {mod}: {len(chosen)} of {len(mutants)} mutants, tests: {' '.join(tests)}",
              flush=True)
        base = run_baseline(mod, tests, args.timeout, args.python)
        if base["status"] != "survived":
            print(f"  the tests fail WITHOUT a mutation ({base['failed'] or base['status']}): "
                  f"fix them first; {mod} skipped", flush=True)
            report["modules"][mod] = {"n_mutants": len(mutants), "results": [],
                                      "baseline": base}
            continue
        results = []
        for m in chosen:
            res = run_mutant(m, tests, args.timeout, args.python)
            res.update(asdict(m), key=m.key, equivalent=EQUIVALENT.get(m.key))
            results.append(res)
            flag = {"killed": "killed  ", "survived": "SURVIVED", "timeout": "timeout "}[res["status"]]
            print(f"  {flag} #{m.index:4d} line {m.line:<5d} {m.operator:<22s} "
                  f"{m.original[:50]} -> {m.mutated[:50]}  ({res['seconds']:.0f} s)", flush=True)
            report["modules"][mod] = {"n_mutants": len(mutants), "results": results}
            out.write_text(json.dumps(report, indent=1, default=str))   # partial results

    if args.list:
        return 0
    summarize(report)
    return 0


def summarize(report: dict) -> None:
    """Print the kill rate per module and the survivors of a (possibly partial) report
    (equivalence from the current :data:`EQUIVALENT`, so a later review counts)."""
    for r in report["modules"].values():
        for x in r["results"]:
            x["equivalent"] = EQUIVALENT.get(x["key"]) or x.get("equivalent")
    print("\nmodule                      run  equiv  killed  survived  timeout  kill rate")
    for mod, r in report["modules"].items():
        res = r["results"]
        eq = [x for x in res if x["equivalent"]]
        ne = [x for x in res if not x["equivalent"]]
        killed = sum(x["status"] != "survived" for x in ne)
        timeouts = sum(x["status"] == "timeout" for x in ne)
        rate = killed / len(ne) if ne else float("nan")
        r["kill_rate"] = rate
        print(f"{mod:<27s} {len(res):4d} {len(eq):6d} {killed:7d} {len(ne) - killed:9d} "
              f"{timeouts:8d}  {100 * rate:8.1f} %")
    print("\nsurvivors (non-equivalent):")
    for mod, r in report["modules"].items():
        for x in r["results"]:
            if x["status"] == "survived" and not x["equivalent"]:
                print(f"  {mod}:{x['line']} [{x['function']}] {x['operator']}: "
                      f"{x['original']} -> {x['mutated']}")
    print("\nequivalent (not counted):")
    for mod, r in report["modules"].items():
        for x in r["results"]:
            if x["equivalent"]:
                print(f"  {mod}:{x['line']} {x['original']} -> {x['mutated']} "
                      f"({x['status']}): {x['equivalent']}")


if __name__ == "__main__":
    sys.exit(main())
