"""pmdsim warmup: every warm-up case is a valid configuration that runs end to end (a case
that main's checks start to reject would leave kernels uncompiled after an install)."""

from __future__ import annotations

from pmdsim.run.warmup import CASES, warmup


def test_every_warmup_case_runs():
    done = []
    seconds = warmup(lambda k, n: done.append((k, n)))
    assert list(seconds) == list(CASES)
    assert done[-1] == (len(CASES), len(CASES))
