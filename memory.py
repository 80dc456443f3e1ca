"""Transparent huge pages for numpy's large arrays: off unless asked for.

numpy advises the kernel to back every large array with transparent huge pages (madvise).
Where the kernel zeroes (and may compact memory for) a 2 MB page on an array's first write, as
on the 2-core VM these benchmarks run on, a fresh array costs several times more to fill than
with ordinary pages (160 MB: 0.38 s against 0.068 s), and a calibration of 10^5 pings fills
gigabytes of fresh arrays (8.97 s against 7.95 s: ``NUMPY_MADVISE_HUGEPAGE=1 python -m
adcpdyn.benchmarks.scale_worker 100000 1`` against the same without it). So adcpdyn turns numpy's advice off when it
is imported, unless ``NUMPY_MADVISE_HUGEPAGE`` (numpy's own switch) is set: then numpy's
choice stands (``NUMPY_MADVISE_HUGEPAGE=1`` restores huge pages).
"""

from __future__ import annotations

import os

ENV = "NUMPY_MADVISE_HUGEPAGE"


def configure_huge_pages() -> bool | None:
    """Turn numpy's huge-page advice off unless ``NUMPY_MADVISE_HUGEPAGE`` is set; the setting
    now in force (None where this numpy has no such switch)."""
    try:
        from numpy._core.multiarray import _get_madvise_hugepage, _set_madvise_hugepage
    except ImportError:  # numpy < 2
        try:
            from numpy.core.multiarray import _get_madvise_hugepage, _set_madvise_hugepage
        except ImportError:
            return None
    if ENV not in os.environ:
        _set_madvise_hugepage(False)
    return bool(_get_madvise_hugepage())
