"""Handing free heap memory back to the system between the large passes of a fit.

numpy's arrays of a few MB (a vector over a million samples, a chunk of a split's
rows) come from the C allocator's heaps, one per thread on glibc; what a pass frees
there stays resident until the allocator trims it, so a search over a full MERL table
(1.1e6 samples, two channel threads) carried several hundred MB of freed memory from
split to split. :func:`release_free_memory` asks glibc to return it (``malloc_trim``);
elsewhere it does nothing. It changes no number, only the resident size.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections.abc import Callable

__all__ = ["release_free_memory"]

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
