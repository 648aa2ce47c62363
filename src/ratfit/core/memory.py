"""Handing free heap memory back to the system between the large passes of a fit.

numpy's arrays of a few MB (a vector over a million samples, a chunk of a split's
rows) come from the C allocator's heaps, one per thread on glibc; what a pass frees
there stays resident until the allocator trims it, so a search over a full MERL table
(1.1e6 samples, two channel threads) carried several hundred MB of freed memory from
split to split. :func:`release_free_memory` asks glibc to return it (``malloc_trim``);
elsewhere it does nothing. It changes no number, only the resident size.

:func:`prefer_small_pages` asks numpy not to back its large arrays with transparent
huge pages (what ``NUMPY_MADVISE_HUGEPAGE=0`` does at import). The ``ratfit`` command
calls it: a fit over a million samples allocates and frees vectors of a few MB all the
time, and the kernel zeroed each fresh 2 MB page again (clear_page, 19 % of the CPU
time of a full MERL table's fit; 31 s of system time, 23 s with small pages).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections.abc import Callable

__all__ = ["prefer_small_pages", "release_free_memory"]

_TRIM: Callable[[int], int] | None = None
_LOOKED = False


def _trim() -> Callable[[int], int] | None:
    global _TRIM, _LOOKED
    if not _LOOKED:
        _LOOKED = True
        if sys.platform.startswith("linux"):
            try:
                libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                fn = libc.malloc_trim
                fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
                _TRIM = fn
            except (OSError, AttributeError):  # not glibc (musl has no malloc_trim)
                _TRIM = None
    return _TRIM


def release_free_memory() -> bool:
    """Return the C heap's free memory to the system where the allocator can (glibc);
    True when it was asked."""
    fn = _trim()
    if fn is None:
        return False
    fn(0)
    return True


def prefer_small_pages() -> bool:
    """Stop numpy asking for transparent huge pages for its large arrays in this
    process; True when numpy offers the switch. It changes no number, only the
    time the kernel spends zeroing fresh memory."""
    import numpy as np

    core = getattr(np, "_core", None) or getattr(np, "core", None)  # numpy 2 / 1.x
    switch = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if switch is None:
        return False
    switch(False)
    return True
