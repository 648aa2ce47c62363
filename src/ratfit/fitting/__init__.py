"""The search over sizes (n, m) and what builds on it: certificates of infeasibility,
best tolerance at a fixed size, shared denominators, dense-grid constraint generation.
"""

from ratfit.fitting.certificate import Certificate
from ratfit.fitting.dense import DenseCheck, DenseFit, dense_check, fit_dense
from ratfit.fitting.search import RationalFitter, fit
from ratfit.fitting.shared_denominator import SharedDenominatorFitter, SharedFit
from ratfit.fitting.tolerance import ToleranceResult, best_width

__all__ = [
    "Certificate",
    "DenseCheck",
    "DenseFit",
    "RationalFitter",
    "SharedDenominatorFitter",
    "SharedFit",
    "ToleranceResult",
    "best_width",
    "dense_check",
    "fit",
    "fit_dense",
]
