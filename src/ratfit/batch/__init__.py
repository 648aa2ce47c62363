"""Batch fitting of many inputs x channels x settings on Dask distributed.
"""

from ratfit.batch.runner import (
    COLUMNS,
    FIT_PARAMS,
    BatchInterrupted,
    BatchSummary,
    MissingDependency,
    Task,
    execute,
    load_manifest,
    plan,
    run,
    settings_id,
    write_summary,
)

__all__ = [
    "BatchInterrupted",
    "BatchSummary",
    "COLUMNS",
    "FIT_PARAMS",
    "MissingDependency",
    "Task",
    "execute",
    "load_manifest",
    "plan",
    "run",
    "settings_id",
    "write_summary",
]
