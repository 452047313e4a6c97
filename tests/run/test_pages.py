"""NumPy's huge-page advice off on a machine that reports free pages (run/pages.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from pmdsim.run.pages import free_page_reporting


def _sysfs(tmp_path: Path, *features: str) -> Path:
    for k, bits in enumerate(features):
        dev = tmp_path / "bus" / "virtio" / "drivers" / "virtio_balloon" / f"virtio{k}"
        dev.mkdir(parents=True)
        (dev / "features").write_text(bits + "\n")
    return tmp_path


def test_free_page_reporting_reads_feature_bit_5(tmp_path):
    """Bit 5 (VIRTIO_BALLOON_F_REPORTING) of any balloon device, counted from the left of
    its features string; other bits (stats queue 1, deflate on OOM 2, free page hints 3)
    do not count; no balloon driver, no reporting."""
    assert free_page_reporting(_sysfs(tmp_path / "a", "0110010100000000" + "0" * 112))
    assert not free_page_reporting(_sysfs(tmp_path / "b", "0111100000000000" + "0" * 112))
    assert free_page_reporting(_sysfs(tmp_path / "c", "0000", "0000010"))  # second device
    assert not free_page_reporting(tmp_path / "none")


def _advice_in_cli(env: dict, sysfs: Path) -> str | None:
    code = ("import os, pmdsim.run.pages as p\n"
            f"p.hugepages_at_start({str(sysfs)!r})\n"
            "print(os.environ.get('NUMPY_MADVISE_HUGEPAGE'))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    return None if out == "None" else out


def test_the_command_line_turns_the_advice_off_only_where_pages_are_reported(tmp_path):
    """A fresh interpreter (NumPy not imported): NUMPY_MADVISE_HUGEPAGE=0 where the balloon
    reports free pages, nothing elsewhere; a user's own setting wins. The command line does
    it before NumPy is imported."""
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    yes = _sysfs(tmp_path / "yes", "0000010")
    no = _sysfs(tmp_path / "no", "0000000")
    assert _advice_in_cli(env, yes) == "0"
    assert _advice_in_cli(env, no) is None
    assert _advice_in_cli(dict(env, NUMPY_MADVISE_HUGEPAGE="1"), yes) == "1"
    src = (Path(__file__).parents[2] / "src" / "pmdsim" / "cli" / "__init__.py").read_text()
    assert src.index("hugepages_at_start()") < src.index("from .common import")
