"""ratfit: verified rational fits of vertical segments (interval data)."""

from __future__ import annotations

from ratfit._version import __version__
from ratfit.core.bases import FAMILIES, PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.verify import Verification, verify
from ratfit.errors import FileFormatError, InputError, RatfitError
from ratfit.fitting.search import RationalFitter, fit

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
