"""Files in and out: tabular data (ALTA text, CSV, .npz, NIST StRD), ratfit fit files,
ALTA function files.

The names below are imported from their modules on first use: reading data and
writing fit files (``ratfit fit``) does not load the ALTA function format.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ratfit._lazy import lazy_names

if TYPE_CHECKING:
    from ratfit.io.alta_function import (
        ALTAFunction,
        read_alta_function,
        write_alta_data,
        write_alta_function,
    )
    from ratfit.io.data import Dataset, read_data, write_alta, write_csv
    from ratfit.io.fitfile import SavedFit, fit_document, load_fit, save_fit

_WHERE = {
    "ALTAFunction": "alta_function", "read_alta_function": "alta_function",
    "write_alta_data": "alta_function", "write_alta_function": "alta_function",
    "Dataset": "data", "read_data": "data", "write_alta": "data", "write_csv": "data",
    "SavedFit": "fitfile", "fit_document": "fitfile", "load_fit": "fitfile",
    "save_fit": "fitfile",
}

__all__ = [
    "ALTAFunction",
    "Dataset",
    "SavedFit",
    "fit_document",
    "load_fit",
    "read_alta_function",
    "read_data",
    "save_fit",
    "write_alta",
    "write_alta_data",
    "write_alta_function",
    "write_csv",
]


__getattr__, __dir__ = lazy_names(globals(), _WHERE)
