"""The search over sizes (n, m) and what builds on it: certificates of infeasibility,
best tolerance at a fixed size, shared denominators, dense-grid constraint generation.

The names below are imported from their modules on first use: the search
(``import ratfit``, ``ratfit fit``) does not load the others.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ratfit._lazy import lazy_names

if TYPE_CHECKING:
    from ratfit.fitting.certificate import Certificate
    from ratfit.fitting.dense import DenseCheck, DenseFit, dense_check, fit_dense
    from ratfit.fitting.search import RationalFitter, fit
    from ratfit.fitting.shared_denominator import SharedDenominatorFitter, SharedFit
    from ratfit.fitting.tolerance import ToleranceResult, best_width

_WHERE = {
    "Certificate": "certificate",
    "DenseCheck": "dense", "DenseFit": "dense", "dense_check": "dense", "fit_dense": "dense",
    "RationalFitter": "search", "fit": "search",
    "SharedDenominatorFitter": "shared_denominator", "SharedFit": "shared_denominator",
    "ToleranceResult": "tolerance", "best_width": "tolerance",
}

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


__getattr__, __dir__ = lazy_names(globals(), _WHERE)
