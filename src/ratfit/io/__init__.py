"""Files in and out: tabular data (ALTA text, CSV, .npz, NIST StRD), ratfit fit files,
ALTA function files.
"""

from ratfit.io.alta_function import (
    ALTAFunction,
    read_alta_function,
    write_alta_data,
    write_alta_function,
)
from ratfit.io.data import Dataset, read_data, write_alta, write_csv
from ratfit.io.fitfile import SavedFit, fit_document, load_fit, save_fit

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
