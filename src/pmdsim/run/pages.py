"""NumPy's huge-page advice off where the machine hands freed memory back to its host.

NumPy advises the kernel to back every array of 4 MB or more with 2 MB huge pages
(``madvise(MADV_HUGEPAGE)``). On a virtual machine whose balloon driver reports free pages
to the host (virtio-balloon's free page reporting, feature bit 5), every freed 2 MB block
goes back to the host, and the next huge page a process touches first costs about 2 s per
GB, against 0.45 s per GB for 4 KB pages (docs/performance.md, "First-touch page faults").
A run allocates and frees its camera-sized temporaries many times: on such a machine the
Fig. 3 run used 19.9 instead of 21.5 CPU-s without the advice (three alternations,
2026-12-03). Elsewhere huge pages make first touches cheaper, so the advice is turned off
only where the reporting is found (:func:`free_page_reporting`), and only for the command
line (:func:`hugepages_at_start`, before NumPy is imported); ``NUMPY_MADVISE_HUGEPAGE``,
when set, wins.
"""

from __future__ import annotations

import os
from pathlib import Path

#: virtio-balloon's VIRTIO_BALLOON_F_REPORTING feature bit.
REPORTING_BIT = 5


def free_page_reporting(sysfs: str | Path = "/sys") -> bool:
    """Whether a virtio balloon device of this machine reports free pages to its host (its
    ``features`` string, one character per feature bit, has bit 5 set)."""
    root = Path(sysfs) / "bus" / "virtio" / "drivers" / "virtio_balloon"
    try:
        devices = list(root.glob("virtio*"))
    except OSError:
        return False
    for dev in devices:
        try:
            bits = (dev / "features").read_text().strip()
        except OSError:
            continue
        if len(bits) > REPORTING_BIT and bits[REPORTING_BIT] == "1":
            return True
    return False


def hugepages_at_start(sysfs: str | Path = "/sys") -> None:
    """For the command line, before NumPy is imported: ``NUMPY_MADVISE_HUGEPAGE=0`` where
    the machine reports free pages (:func:`free_page_reporting`), unless it is set."""
    import sys

    if "numpy" in sys.modules or "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        return
    if free_page_reporting(sysfs):
        os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"


__all__ = ["free_page_reporting", "hugepages_at_start"]
