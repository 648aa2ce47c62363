"""ratfit: verified rational fits of vertical segments (interval data)."""

from __future__ import annotations

from .bases import FAMILIES, PolynomialSpace
from .errors import FileFormatError, InputError, RatfitError
from .rational import RationalFunction
from .results import FitResult
from .search import RationalFitter, fit
from .segments import Segments
from .verify import Verification, verify

__version__ = "0.1.0"

__all__ = [
    "FAMILIES",
    "FileFormatError",
    "FitResult",
    "InputError",
    "PolynomialSpace",
    "RatfitError",
    "RationalFitter",
    "RationalFunction",
    "Segments",
    "Verification",
    "__version__",
    "fit",
    "verify",
]
