"""Every code block of README.md and docs/*.md runs (Sybil parses the Markdown).

One test per document runs its blocks in order in a fresh folder (where ``examples/`` and
``benchmarks/`` point at the repository's), so a block may use what an earlier block of the
same document wrote (``out/fig3``) or defined (Python names):

- ``python``: executed (one namespace per document);
- ``bash``: each line is a command; ``pmdsim ...`` runs in-process through the command line
  (:data:`pmdsim.cli.app`), ``cat FILE`` checks the file exists; every other line must match
  a rule of :data:`SKIPPED` that states why it does not run here (the set-up lines are CI's
  own steps, benchmarks are timed runs, placeholders name the reader's files);
- ``toml``: parsed, and its sections validated in the Fig. 3 configuration (a renamed field
  fails);
- ``json`` and unlabelled blocks: shown output or schema sketches with ``...``; not run.

Examples run on a **reduced configuration** with the same code path: every configuration
the blocks load (``pmdsim.config.load_config``, the command line's too) gets a camera of
at most :data:`CAMERA_PX` pixels along its width with the same field of view, at most
:data:`MAX_RAYS` rays per bundle and :data:`MAX_APERTURE_SAMPLES` aperture samples. The
numbers the docs state about full-size runs are checked by ``tools/docs_numbers.py``.
A block that cannot run anywhere but on the reader's machine is skipped in the document
itself with a stated reason (``<!-- skip: next "reason" -->``, Sybil's skip).
"""

from __future__ import annotations

import contextlib
import glob
import io
import os
import re
import shlex
import tomllib
import unittest
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))

#: Reduced configurations (same code path, a small camera and few rays).
CAMERA_PX = 64
MAX_RAYS = 24
MAX_APERTURE_SAMPLES = 4

#: Lines of ``bash`` blocks that do not run here, each with the reason (regex, reason).
SKIPPED = [
    (r"^python -m venv ", "CI's own set-up step (.ci/run creates the environment)"),
    (r"^\. \.venv/bin/activate", "CI's own set-up step (.ci/run activates its environment)"),
    (r"^python -m pip install ", "CI's own set-up step (.ci/run installs the package)"),
    (r"^python -m pytest", "the tests themselves"),
    (r"^ruff check", "the linter and the tests themselves (.ci/run runs both)"),
    (r"^pmdsim warmup", "CI's own set-up step (.ci/run warms the kernel cache before the tests; "
                        "tests/run/test_warmup.py runs it)"),
    (r"^python benchmarks/", "a timed benchmark (run on an idle machine, not in the tests)"),
    (r"^pmdsim decode cam/", "a placeholder for the reader's camera images"),
    (r"^pmdsim converge ", "about 100 renders even on a reduced camera (its N x theta x "
                           "estimator grid); tests/run/test_converge.py runs the command"),
    (r"^pmdsim fit CONFIG IMAGES", "a synopsis with placeholders (tests/studies/test_fit.py runs it)"),
]


def reduce_config(cfg):
    """``cfg`` with a camera of at most :data:`CAMERA_PX` px across (same field of view: the
    focal length in pixels, or the pixel pitch, and the principal point scaled together),
    at most :data:`MAX_RAYS` rays and :data:`MAX_APERTURE_SAMPLES` aperture samples."""
    data = cfg.model_dump()
    cam = data["camera"]
    w, h = cam["resolution"]
    s = min(1.0, CAMERA_PX / w)
    if s < 1.0:
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        sx, sy = nw / w, nh / h
        cam["resolution"] = (nw, nh)
        if cam["camera_matrix"] is not None:
            (fx, _, cx), (_, fy, cy), last = cam["camera_matrix"]
            cam["camera_matrix"] = ((fx * sx, 0.0, (cx + 0.5) * sx - 0.5),
                                    (0.0, fy * sy, (cy + 0.5) * sy - 0.5), last)
        elif cam["focal_length_px"] is not None:
            cam["focal_length_px"] *= sx
            if cam["pixel_pitch_mm"] is not None:
                cam["pixel_pitch_mm"] /= sx
        else:
            cam["pixel_pitch_mm"] /= sx
        if cam["principal_point_px"] is not None:
            cx, cy = cam["principal_point_px"]
            cam["principal_point_px"] = ((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5)
    cam["aperture_samples"] = min(cam["aperture_samples"], MAX_APERTURE_SAMPLES)
    for sampling in [data["sampling"]] + [v["sampling"] for v in data["variants"]
                                          if v.get("sampling")]:
        sampling["n_rays"] = min(sampling["n_rays"], MAX_RAYS)
    return type(cfg).model_validate(data)


def _skip_reason(line: str) -> str | None:
    return next((why for pattern, why in SKIPPED if re.search(pattern, line)), None)


def _commands(source: str) -> list[str]:
    """The commands of a bash block: comments dropped, continuation lines joined."""
    text = re.sub(r"\\\n", " ", source)
    lines = [re.sub(r"(^|\s)#.*$", "", ln).strip() for ln in text.splitlines()]
    return [ln for ln in lines if ln]


def run_bash(source: str) -> None:
    from typer.testing import CliRunner

    from pmdsim.cli import app

    for line in _commands(source):
        for cmd in (c.strip() for c in line.split("&&")):
            if _skip_reason(cmd):
                continue
            words = shlex.split(cmd)
            if words[0] == "cat":
                assert all(Path(w).is_file() for w in words[1:]), f"{cmd}: no such file"
                continue
            assert words[0] == "pmdsim", (
                f"{cmd!r}: a command the docs test cannot run; run it as pmdsim, or add a rule "
                "with its reason to SKIPPED in tests/test_docs.py")
            args = []
            for w in words[1:]:
                args += sorted(glob.glob(w)) or [w] if any(c in w for c in "*?[") else [w]
            res = CliRunner().invoke(app, args)
            assert res.exit_code == 0, f"{cmd}\n{res.output}\n{res.exception!r}"


def check_toml(source: str) -> None:
    """A TOML snippet parses, and each of its sections is valid in the Fig. 3 configuration
    (in a rotational BRDF frame, which every BRDF snippet of the docs may use)."""
    from pmdsim.config import load_config, parse_config

    snippet = tomllib.loads(source)
    base = load_config(ROOT / "examples" / "paper_fig3.toml").model_dump(exclude_none=True)
    base.update(variants=[], anisotropy={"frame": "rotational"})
    parse_config({**base, **snippet}, "docs snippet")


def _parsed(path: Path):
    from sybil import Sybil
    from sybil.parsers.markdown import CodeBlockParser, PythonCodeBlockParser, SkipParser

    def bash(example):
        run_bash(example.parsed)

    def toml(example):
        check_toml(example.parsed)

    parsers = [PythonCodeBlockParser(), CodeBlockParser("bash", bash),
               CodeBlockParser("toml", toml), SkipParser()]
    return Sybil(parsers, path=str(path.parent)).parse(path)


def test_code_blocks_are_found():
    # the parser sees the blocks (a broken parser would make every document pass)
    doc = _parsed(ROOT / "README.md")
    kinds = [type(e.region.parsed).__name__ for e in doc.examples()]
    assert len(kinds) >= 10, kinds
    assert _skip_reason("python benchmarks/bench_render.py") and not _skip_reason("pmdsim report x")
    assert _commands("pmdsim a \\\n  --b 1   # c\n# d\n") == ["pmdsim a    --b 1"]


@pytest.mark.parametrize("path", DOCUMENTS, ids=[p.name for p in DOCUMENTS])
def test_document_code_blocks_run(path, tmp_path, monkeypatch):
    import pmdsim.config

    load = pmdsim.config.load_config
    monkeypatch.setattr(pmdsim.config, "load_config", lambda p: reduce_config(load(p)))
    for name in ("examples", "benchmarks"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    doc = _parsed(path)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for example in doc.examples():
            try:
                example.evaluate()
            except unittest.SkipTest:  # skipped in the document, with its reason
                continue
            except Exception as err:
                raise AssertionError(f"{path.name}, line {example.line}: {err}") from err
    if os.environ.get("PMDSIM_DOCS_VERBOSE"):
        print(out.getvalue())
