"""``tools/docs_numbers.py``: the numbers the docs state about the examples agree with what
the examples compute (the fast entries here; ``--all`` adds the full-size runs), and the
checker itself finds a changed number and rewrites it with ``--update``."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("docs_numbers", ROOT / "tools" / "docs_numbers.py")
docs_numbers = importlib.util.module_from_spec(_spec)
sys.modules["docs_numbers"] = docs_numbers  # dataclasses look their module up
_spec.loader.exec_module(docs_numbers)

FAST = [c for c in docs_numbers.CHECKS if c.fast]


@pytest.mark.parametrize("check", FAST, ids=[c.name for c in FAST])
def test_documented_number_agrees(check):
    r = docs_numbers.evaluate(check)
    assert not r.bad, (f"{check.doc}:{r.line} {check.name}: written {r.written}, computed "
                       f"{r.computed}; rerun `python tools/docs_numbers.py --update` and review")


@pytest.mark.parametrize("check", docs_numbers.CHECKS, ids=[c.name for c in docs_numbers.CHECKS])
def test_every_checked_sentence_is_in_its_document(check):
    # also the slow entries: a reworded sentence must be re-pointed, not silently unchecked
    text = (ROOT / check.doc).read_text(encoding="utf-8")
    assert docs_numbers.find(check, text).groups()


def test_a_changed_example_fails_the_check(monkeypatch):
    """Doubling the Fig. 3 lobe's alpha_x (an edit of the example) moves the energy inside
    its cone, and the README's number no longer agrees."""
    cfg = docs_numbers._fig3_config()
    wider = cfg.model_copy(update={"brdf": cfg.brdf.model_copy(
        update={"alpha_x": 2 * cfg.brdf.alpha_x})})
    monkeypatch.setattr(docs_numbers, "_fig3_config", lambda: wider)
    check = next(c for c in docs_numbers.CHECKS if c.name == "fig3-energy")
    assert docs_numbers.evaluate(check).bad == [0]


def test_digits_shown_and_update(tmp_path, monkeypatch):
    assert docs_numbers._half_ulp("0.34") == pytest.approx(0.005)
    assert docs_numbers._half_ulp("142") == pytest.approx(0.5)
    assert docs_numbers._half_ulp("1.5e3") == pytest.approx(50.0)
    assert docs_numbers._format_like(0.37123, "0.375") == "0.371"
    assert docs_numbers._format_like(14.27, "57.5") == "14.3"
    assert docs_numbers._format_like(8.284, "87") == "8.3"  # the digits shown, not the decimals
    assert docs_numbers._format_like(233.4, "142") == "233"
    (tmp_path / "doc.md").write_text("the lobe keeps 0.34 of its energy and 57 / 87 mrad\n")
    monkeypatch.setattr(docs_numbers, "ROOT", tmp_path)
    check = docs_numbers.Check("t", "doc.md", r"keeps " + docs_numbers.NUMBER + r" of[\s\S]*?"
                               + docs_numbers.NUMBER + r" / " + docs_numbers.NUMBER + " mrad",
                               lambda: (0.3449, 14.27, 87.2))
    r = docs_numbers.evaluate(check)
    assert r.bad == [1]  # 0.3449 shows as 0.34; 87.2 is 87 to the digits shown
    assert docs_numbers.update(r)
    assert (tmp_path / "doc.md").read_text() == "the lobe keeps 0.34 of its energy and 14 / 87 mrad\n"
    assert not docs_numbers.evaluate(check).bad
