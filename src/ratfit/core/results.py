"""The result of a fit: a fixed schema in OptimizeResult's vocabulary.

``success`` is True only when :func:`ratfit.core.verify.verify` passed: every
segment met at every input point and no pole in the domain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ratfit.core.rational import RationalFunction
from ratfit.core.verify import Verification

__all__ = ["FitResult", "STATUS_MESSAGES"]

STATUS_MESSAGES = {
    0: "verified fit found",
    1: "no verified fit in the search range",
    2: "a fit was computed but failed verification",
}


@dataclass(frozen=True)
class FitResult:
    """One channel's fit: what was found, how well it is verified, how it was decided.

    Attributes
    ----------
    success : bool
        True only when the fit is verified (every segment met, no pole).
    status : int
        0 verified, 1 no verified fit in the search range, 2 a fit failed verification.
    message : str
        One line saying what happened.
    n, m : int
        Numerator and denominator coefficient counts (``total`` = n + m).
    rational : RationalFunction or None
        The fit (None when no candidate was computed).
    verification : Verification or None
        Its check at every input point.
    delta, sigma_min, sigma_max : float
        Conditioning of the deciding QP (delta = 1 / cond(A)).
    history : tuple of dict
        Every split tested, with its status and deciding method.
    time_limited : bool
        The time limit ended the search: a verified fit whose total may not be minimal.
    work_limit : int or None
        The search's budget of QP solves for this channel (``qp_solves`` were spent).

    Examples
    --------
    >>> import numpy as np
    >>> import ratfit
    >>> x = np.linspace(0, 1, 30)
    >>> res = ratfit.fit(ratfit.Segments.from_relative(x, np.exp(x), 1e-3))
    >>> res.success, res.summary()["verified"], res.message
    (True, True, 'verified fit found')
    """

    success: bool
    status: int
    message: str
    n: int
    m: int
    basis: str
    index_set: str
    rational: RationalFunction | None
    verification: Verification | None
    delta: float
    sigma_min: float
    sigma_max: float
    active_set_size: int
    qp_solves: int
    seconds: float
    solver: str
    decided_by: str
    solver_status: str = ""
    formulation: str = "basis"  # how the deciding QP was written: "basis" or "arnoldi"
    channel: str = "y0"
    history: tuple[dict, ...] = field(default=())
    disagreements: tuple[str, ...] = field(default=())
    # A checked Farkas certificate (ratfit.fitting.certificate.Certificate.summary()) when
    # status 1 comes from a proven infeasibility rather than a numerical failure.
    infeasible_proof: dict | None = None
    # The search's time limit ran out: the fit is verified, its total not shown minimal.
    time_limited: bool = False
    # The search's work budget (QP solves per channel; None: none), next to qp_solves.
    work_limit: int | None = None

    @property
    def total(self) -> int:
        return self.n + self.m

    @property
    def cond(self) -> float:
        return self.sigma_max / self.sigma_min if self.sigma_min > 0 else math.inf

    @property
    def coef_norm(self) -> float:
        if self.rational is None:
            return math.nan
        r = self.rational
        return math.sqrt(float((r.p**2).sum() + (r.q**2).sum()))

    @property
    def max_violation(self) -> float:
        return self.verification.max_violation if self.verification else math.inf

    def summary(self) -> dict:
        """Flat, JSON-ready diagnostics (the keys of ``ratfit fit --json``)."""
        v = self.verification
        return {
            "channel": self.channel,
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "n": self.n,
            "m": self.m,
            "total": self.total,
            "basis": self.basis,
            "index_set": self.index_set,
            "verified": bool(v.verified) if v else False,
            "max_violation": _num(v.max_violation) if v else None,
            "max_violation_rel": _num(v.max_violation_rel) if v else None,
            "worst_index": v.worst_index if v else None,
            "min_margin": _num(v.min_margin) if v else None,
            "poles_in_domain": v.poles_in_domain if v else None,
            "linf": _num(v.linf) if v else None,
            "l2": _num(v.l2) if v else None,
            "max_rel_error": _num(v.max_rel_error) if v else None,
            "delta": _num(self.delta),
            "sigma_min": _num(self.sigma_min),
            "sigma_max": _num(self.sigma_max),
            "cond": _num(self.cond),
            "coef_norm": _num(self.coef_norm),
            "active_set_size": self.active_set_size,
            "qp_solves": self.qp_solves,
            "work_limit": self.work_limit,
            "solver": self.solver,
            "solver_status": self.solver_status,
            "decided_by": self.decided_by,
            "formulation": self.formulation,
            "disagreements": list(self.disagreements),
            "seconds": round(self.seconds, 6),
            "infeasible_proof": self.infeasible_proof,
            "time_limited": self.time_limited,
        }


def _num(v: float) -> float | None:
    """JSON has no inf/NaN: report them as null."""
    return float(v) if v is not None and math.isfinite(v) else None
