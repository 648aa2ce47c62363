"""Foundations: bases, segments, the constraint systems and the QP, solvers, rational
functions, verification, results, monomial conversion. Imports nothing above it.
"""

from ratfit.core.bases import FAMILIES, PolynomialSpace
from ratfit.core.monomial import MonomialForm, to_monomial
from ratfit.core.rational import RationalFunction
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.verify import Verification, verify

__all__ = [
    "FAMILIES",
    "FitResult",
    "MonomialForm",
    "PolynomialSpace",
    "RationalFunction",
    "Segments",
    "Verification",
    "to_monomial",
    "verify",
]
