"""Best tolerance at a fixed size: the smallest segment width that (n, m) still fits.

Pole-free feasibility of P(n, m) (the search engine generates q > 0 rows
where a solution's denominator changes sign) is monotone in the width w
(``lo = (1 - w) y, hi = (1 + w) y``, or ``y -+ w`` with ``absolute``): the
segments of a larger w contain those of a smaller one. So the smallest
feasible width is found by bisection with one feasibility QP per step. At the
end the result holds

* ``width``: the smallest width tried that has a *verified* fit (returned), and
* ``lower``: the largest width tried without one (the solver found none), and
* ``proved_lower``: the largest width with a checked Farkas certificate
  (:mod:`ratfit.fitting.certificate`, exact rational arithmetic) that no rational
  of size (n, m) fits there at all.

The certificate is tried at ``lower`` first. Just below the optimum the
infeasibility is so slight that HiGHS's Farkas vector misses a row of its
support (Kirby2 at (10, 10): residual 3e-7 at 0.99 of the optimum, no exact
check possible), so the certificate is then tried at smaller widths, down to a
quarter of ``lower``, and the bracket between a failed and a checked width is
narrowed by a few bisection steps. So the true optimum lies in
(proved_lower, width]; ``lower_certified`` says whether ``proved_lower`` is
``lower`` itself.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ratfit.core.results import FitResult
from ratfit.core.scaling import scale_segments, unscale_result, value_scales
from ratfit.core.segments import Segments, check_points, check_values
from ratfit.errors import InputError
from ratfit.fitting.certificate import Certificate, certify
from ratfit.fitting.search import RationalFitter, SearchEngine

__all__ = ["ToleranceResult", "aaa_error", "best_width"]


@dataclass(frozen=True)
class ToleranceResult:
    """Outcome of :func:`best_width` for one channel."""

    width: float  # smallest width with a verified fit (nan when none was found)
    lower: float  # largest width without one (0 when never bracketed)
    absolute: bool
    fit: FitResult | None  # the verified fit at ``width``
    segments: Segments | None  # the segments at ``width``
    certificate: Certificate | None  # checked at ``proved_lower``, else the one at ``lower``
    steps: tuple[dict[str, Any], ...] = field(default=())
    seconds: float = 0.0
    # The largest width with a checked (exact) infeasibility certificate; nan when none.
    proved_lower: float = math.nan

    @property
    def success(self) -> bool:
        return self.fit is not None and self.fit.success

    @property
    def message(self) -> str:
        """One line: the width found and how the width below it is known to fail."""
        if not self.success:
            return "no verified fit of this size at any width tried"
        return f"verified fit at width {self.width:.6g}; {self.lower_statement}"

    @property
    def lower_statement(self) -> str:
        """What is known below ``width``: which width is proved infeasible."""
        if self.lower_certified:
            return f"{self.lower:.6g} is certified infeasible (exact Farkas certificate)"
        if self.proved:
            return (f"no fit found at {self.lower:.6g} (not proved); {self.proved_lower:.6g} "
                    "is certified infeasible (exact Farkas certificate)")
        return f"no fit found at {self.lower:.6g}; no width below is proved infeasible"

    @property
    def proved(self) -> bool:
        """Some width below ``width`` carries a checked infeasibility certificate."""
        return (self.certificate is not None and self.certificate.checked
                and math.isfinite(self.proved_lower))

    @property
    def lower_certified(self) -> bool:
        """``lower`` itself (the bisection's end) is certified infeasible."""
        return self.proved and self.proved_lower == self.lower

    @property
    def gap(self) -> float:
        """width / lower - 1: how far the bracket is from closing."""
        return self.width / self.lower - 1.0 if self.lower > 0 else math.inf

    def summary(self) -> dict[str, Any]:
        return {
            "width": _num(self.width),
            "width_kind": "absolute" if self.absolute else "relative",
            "lower": _num(self.lower),
            "gap": _num(self.gap),
            "lower_certified": self.lower_certified,
            "proved_lower": _num(self.proved_lower),
            "proved_gap": _num(self.width / self.proved_lower - 1.0
                               if self.proved and self.proved_lower > 0 else math.inf),
            "lower_statement": self.lower_statement,
            "lower_proof": self.certificate.summary() if self.certificate else None,
            "width_steps": list(self.steps),
        }


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def best_width(
    x: ArrayLike,
    y: ArrayLike,
    n: int,
    m: int,
    *,
    absolute: bool = False,
    rtol: float = 1e-3,
    start: float | None = None,
    max_steps: int = 80,
    certify_lower: bool = True,
    name: str = "y0",
    **fitter: Any,
) -> ToleranceResult:
    """Smallest width w at which (n, m) has a verified fit, by bisection on w.

    ``x`` (N,) or (N, d) and ``y`` (N,) one channel. The bracket is closed to
    ``width / lower <= 1 + rtol``. Extra keywords go to
    :class:`~ratfit.fitting.search.RationalFitter` (basis, domain, solver, ...); the
    default cross check is the HiGHS margin LP, so an "infeasible" near the
    optimum is checked by an LP before the width moves up.
    """
    t0 = time.perf_counter()
    xa = check_points(x)
    ya = check_values(y, xa.shape[0], "y")
    if ya.shape[1] != 1:
        raise InputError(f"best_width fits one channel; y has {ya.shape[1]}")
    for k, v in (("n", n), ("m", m)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
            raise InputError(f"{k} must be an integer >= 1, got {v!r}")
    if not (isinstance(rtol, (int, float)) and 0 < rtol < 1):
        raise InputError(f"rtol must be in (0, 1), got {rtol!r}")
    if not absolute and np.any(ya == 0):
        i = int(np.flatnonzero(ya[:, 0] == 0)[0])
        raise InputError(
            f"y is 0 at point {i}: a relative width gives it a zero-width segment; "
            "use an absolute width"
        )
    scale = float(np.max(np.abs(ya))) if absolute else 1.0
    if absolute and scale == 0:
        raise InputError("y is 0 everywhere: every width fits the zero function")
    fitter.setdefault("cross_check", "lp")
    kw = dict(fitter, n=int(n), m=int(m))
    est = RationalFitter(**kw)  # unknown keywords fail here, before any QP

    def segments(w: float) -> Segments:
        if absolute:
            return Segments.from_absolute(xa, ya, w, names=(name,))
        return Segments.from_relative(xa, ya, w, names=(name,))

    steps: list[dict[str, Any]] = []
    fits: dict[float, tuple[FitResult, Segments]] = {}

    def feasible(w: float) -> bool:
        # One split on the search engine (pole-free by constraint generation); no
        # search certificate per step: the bracket's lower end is certified once.
        t1 = time.perf_counter()
        seg = segments(w)
        factor = value_scales(seg)
        work = scale_segments(seg, factor)
        space = est.prepare(seg)
        run = SearchEngine(est.options_, est.search_parts(space, work), space, work, 0)
        chosen = run.fixed(int(n), int(m))
        att, _, ver = run.cache[chosen[0]]
        ok = ver is not None and ver.verified
        if ok:
            res = run.result(chosen, n + m, n + m, time.perf_counter() - t1, certify=False)
            res = unscale_result(res, seg, 0, float(factor[0]), run.parts.verifier)
            ok = res.success
            if ok:
                fits[w] = (res, seg)
        steps.append({"width": w, "verified": ok, "status": att.status,
                      "decided_by": att.decided_by})
        return ok

    hi = lo = math.nan
    w = float(start) if start is not None else 0.1 * scale
    if not (w > 0 and math.isfinite(w)):
        raise InputError(f"start must be a finite width > 0, got {start!r}")
    if feasible(w):
        hi = w
        while len(steps) < max_steps and hi > 1e-15 * scale:
            w = hi / 4.0
            if feasible(w):
                hi = w
            else:
                lo = w
                break
        else:
            lo = 0.0
    else:
        lo = w
        while len(steps) < max_steps and lo < 1e12 * scale:
            w = lo * 4.0
            if feasible(w):
                hi = w
                break
            lo = w
    if math.isnan(hi):
        return ToleranceResult(math.nan, lo, absolute, None, None, None, tuple(steps),
                               time.perf_counter() - t0)
    while lo > 0 and hi / lo > 1.0 + rtol and len(steps) < max_steps:
        w = math.sqrt(lo * hi)
        if feasible(w):
            hi = w
        else:
            lo = w
    cert = None
    proved = math.nan
    fit, seg = fits[hi]
    if certify_lower and lo > 0:
        assert fit.rational is not None  # a verified fit
        space = fit.rational.space
        form = "arnoldi" if _arnoldi_ok(fit) else "basis"

        def proof(w: float) -> Certificate:
            return certify(space, segments(w), 0, int(n), int(m), formulation=form)

        cert, proved = _proved_below(lo, proof)
    return ToleranceResult(hi, lo, absolute, fit, seg, cert, tuple(steps),
                           time.perf_counter() - t0, proved_lower=proved)


# Fractions of the bisection's lower end where a certificate is tried in turn, and the
# bisection steps between the last failed and the first checked one.
_PROOF_FRACTIONS = (1.0, 0.99, 0.95, 0.9, 0.8, 0.65, 0.5, 0.25)
_PROOF_REFINE = 3


def _proved_below(lower: float, proof: Any) -> tuple[Certificate, float]:
    """The largest width <= ``lower`` (from :data:`_PROOF_FRACTIONS`, then refined)
    whose certificate checks, with it; (the certificate at ``lower``, nan) when none."""
    first = proof(lower)
    if first.checked:
        return first, lower
    failed = lower
    for f in _PROOF_FRACTIONS[1:]:
        w = lower * f
        cert = proof(w)
        if cert.checked:
            break
        failed = w
    else:
        return first, math.nan
    good, good_cert = w, cert
    for _ in range(_PROOF_REFINE):
        mid = 0.5 * (good + failed)
        c = proof(mid)
        if c.checked:
            good, good_cert = mid, c
        else:
            failed = mid
    return good_cert, good


def _arnoldi_ok(fit: FitResult) -> bool:
    r = fit.rational
    return r is not None and (r.space.dim == 1 or r.space.index_set == "total")


# -- the comparison -------------------------------------------------------------------------
def aaa_error(x: ArrayLike, y: ArrayLike, degree: int) -> dict[str, Any]:
    """SciPy's AAA of type (degree, degree) on (x, y): its max relative error at
    the data and its real poles inside [min x, max x].

    A type (d, d) rational has 2d + 1 free real parameters, like a ratfit fit
    with n = m = d + 1 coefficients (one is the common scale of p and q).
    """
    try:
        from scipy.interpolate import AAA
    except ImportError as exc:  # pragma: no cover - SciPy < 1.15
        raise InputError(f"scipy.interpolate.AAA needs SciPy >= 1.15: {exc}") from None
    xa = np.asarray(x, dtype=float).ravel()
    ya = np.asarray(y, dtype=float).ravel()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "failed to converge": by design
        r = AAA(xa, ya, rtol=0.0, max_terms=degree + 1, clean_up=False)
    secs = time.perf_counter() - t0
    vals = r(xa)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(vals - ya) / np.abs(ya)
    poles = np.asarray(r.poles())
    width = xa.max() - xa.min()
    real = poles[np.abs(poles.imag) <= 1e-9 * width].real
    inside = int(np.sum((real >= xa.min()) & (real <= xa.max())))
    d = int(len(r.support_points)) - 1
    return {"degree": d, "real_params": 2 * d + 1, "max_rel_error": float(np.max(rel)),
            "real_poles_in_domain": inside, "seconds": secs}
