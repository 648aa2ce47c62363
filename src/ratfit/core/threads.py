"""One BLAS thread while a search runs.

The search runs its own threads (independent QPs) and calls BLAS on small
matrices, where OpenBLAS's worker threads only spin: on a shared 2-core
machine an SVD of a 1000 x 50 matrix took 0.72 s with two BLAS threads and
2 ms with one (the EXR fit of issue 12). Fits therefore run with BLAS
limited to one thread, restored afterwards.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

__all__ = ["one_blas_thread"]


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Limit BLAS/OpenMP pools to one thread inside the block (threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a core dependency
        yield
        return
    with threadpool_limits(limits=1):
        yield
