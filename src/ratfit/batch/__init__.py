"""Batch fitting of many inputs x channels x settings on Dask distributed."""

from ratfit.batch import runner as _runner
from ratfit.batch.runner import *  # noqa: F403  (the public names, listed once, there)

__all__ = list(_runner.__all__)
