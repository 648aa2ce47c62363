"""Verification of a fit: every segment met, no pole in the domain.

This is the only place that decides whether a fit is a success. A non-finite
value of r (q = 0 gives inf or NaN, and NaN compares False) counts as a
violation of infinite size, never as satisfied.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from numpy.typing import NDArray

from ratfit.core.rational import RationalFunction, ratio_values
from ratfit.core.segments import Segments
from ratfit.core.systems import domain_grid

__all__ = ["Verification", "verify", "pole_check"]



@dataclass(frozen=True)
class Verification:
    """Outcome of evaluating r at every input point and checking q for poles.

    ``verified`` (also ``success``) is True only when every segment is met
    and q has no zero in the domain; ``message`` says why not in one line.

    Attributes
    ----------
    verified : bool
    max_violation : float
        Largest distance outside a segment (inf where r is not finite).
    max_violation_rel : float
        The same divided by the segment width.
    n_violations, poles_in_domain : int
    linf, max_rel_error : float
        max |r - y| and max |r - y| / |y| (y != 0).
    rejected_by : str
        What a caller's own check found against the fit ("" if nothing): a BRDF
        fit can meet every segment and still have q <= 0 between the samples.

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit import PolynomialSpace, RationalFunction, Segments, verify
    >>> x = np.linspace(-1, 1, 11)
    >>> r = RationalFunction(PolynomialSpace("monomial", [[-1.0, 1.0]]), [1.0], [2.0, 1.0])
    >>> v = verify(r, Segments.from_relative(x, 1 / (2 + x), 0.01))
    >>> v.success, v.max_violation, v.message
    (True, 0.0, 'every segment met, no pole in the domain')
    """

    verified: bool
    max_violation: float  # >= 0; largest distance outside a segment (inf if r non-finite)
    max_violation_rel: float  # the same divided by the segment width
    worst_index: int  # point where r is closest to (or farthest outside) its segment
    n_violations: int
    min_margin: float  # min over points of min(r - lo, hi - r); < 0 means violated
    poles_in_domain: int
    pole_locations: tuple[float, ...]
    denominator_sign_changes: bool
    linf: float  # max |r - y|
    l2: float  # RMSE of r - y
    max_rel_error: float  # max |r - y| / |y| over points with y != 0
    n_points: int
    #: What else rejected the fit, in words, where a caller's own check did (a BRDF
    #: fit's q <= 0 or negative value between the samples); "" where none did.
    rejected_by: str = field(default="", kw_only=True)

    @property
    def success(self) -> bool:
        """The result vocabulary's name for ``verified``."""
        return bool(self.verified)

    @property
    def message(self) -> str:
        """One line: verified, or the first reason it is not."""
        if self.verified:
            return "every segment met, no pole in the domain"
        why = []
        if self.n_violations:
            why.append(f"{self.n_violations} segment(s) missed by up to "
                       f"{self.max_violation:.3g}")
        if self.poles_in_domain:
            why.append(f"{self.poles_in_domain} pole(s) in the domain")
        if self.denominator_sign_changes and not self.poles_in_domain:
            why.append("the denominator changes sign in the domain")
        if self.rejected_by:
            why.append(self.rejected_by)
        return "; ".join(why) or "not verified"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["pole_locations"] = list(self.pole_locations)
        return d


def verify(rf: RationalFunction, seg: Segments, *, channel: int = 0,
           box_check: bool = True, values: str = "linear") -> Verification:
    """Evaluate ``rf`` at every point of ``seg`` (one channel) and check poles.

    Non-finite values count as violations (q = 0 at a data point is a miss).
    ``box_check=False`` (n-D only) leaves out q's sign on a grid of the domain
    box, for callers that check a region of their own instead (BRDFs: the
    direction pairs above the horizon); q's sign at the data is still checked.
    ``values="log"``: the fit's value is exp(p / q) (a fit of log values,
    :func:`~ratfit.core.rational.ratio_values`), checked against segments of the values.

    Parameters
    ----------
    rf : RationalFunction
    seg : Segments
    channel : int, default 0
        Which channel's segments.

    Returns
    -------
    Verification

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit import PolynomialSpace, RationalFunction, Segments, verify
    >>> r = RationalFunction(PolynomialSpace("monomial", [[-1.0, 1.0]]), [1.0], [0.0, 1.0])
    >>> v = verify(r, Segments.from_absolute(np.linspace(-1, 1, 5), np.ones(5), 0.1))
    >>> v.verified, v.poles_in_domain     # 1 / t: a pole at 0
    (False, 1)
    """
    lo, hi = seg.lo[:, channel], seg.hi[:, channel]
    y = seg.center[:, channel]
    q = rf.denominator(seg.x)
    p = rf.numerator(seg.x)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = ratio_values(p / q, values)
    finite = np.isfinite(r)
    below = np.where(finite, lo - r, np.inf)
    above = np.where(finite, r - hi, np.inf)
    signed = np.maximum(below, above)  # > 0 outside, <= 0 inside
    worst = int(np.argmax(signed))
    max_violation = float(max(signed[worst], 0.0))
    width = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(signed > 0, signed / width, 0.0)
    rel = np.where((signed > 0) & (width == 0), np.inf, rel)
    n_viol = int(np.count_nonzero(signed > 0))
    err = np.where(finite, np.abs(r - y), np.inf)
    nz = y != 0
    with np.errstate(divide="ignore", invalid="ignore"):
        relerr = err[nz] / np.abs(y[nz])
    poles, sign_change = pole_check(rf, seg.x, q, box=box_check or rf.space.dim == 1)
    ok = n_viol == 0 and not poles and not sign_change and bool(finite.all())
    return Verification(
        verified=ok,
        max_violation=max_violation,
        max_violation_rel=float(rel.max()),
        worst_index=worst,
        n_violations=n_viol,
        min_margin=float(-signed.max()),
        poles_in_domain=len(poles),
        pole_locations=tuple(float(v) for v in poles),
        denominator_sign_changes=sign_change,
        linf=float(err.max()),
        l2=_rms(err),
        max_rel_error=float(relerr.max()) if relerr.size else 0.0,
        n_points=seg.n_points,
    )


def _rms(err: NDArray[np.float64]) -> float:
    """Root mean square without overflowing squares (values of 1e170 are data too)."""
    top = float(np.max(err)) if err.size else 0.0
    if not np.isfinite(top) or top == 0.0:
        return top
    return top * float(np.sqrt(np.mean((err / top) ** 2)))


def pole_check(
    rf: RationalFunction, x: NDArray[np.float64], q_at_x: NDArray[np.float64] | None = None,
    *, box: bool = True,
) -> tuple[list[float], bool]:
    """Poles of r in the domain: (real pole locations in 1-D, whether q changes sign).

    1-D: real roots of q from its basis coefficients (companion matrix), plus a
    sign check of q on a dense grid and the data points, which catches roots the
    eigenvalue solver misplaces. n-D: q's sign on a dense grid of the domain box
    and at the data points; a sign change (or a zero) means q vanishes inside.
    """
    space = rf.space
    q_at_x = rf.denominator(x) if q_at_x is None else q_at_x
    poles: list[float] = []
    if space.dim == 1:
        poles = [float(v) for v in rf.real_poles_in_domain()]
    vals = np.ravel(q_at_x)
    if box:
        grid = domain_grid(space.dim, len(x))  # the grid the q > 0 rows are generated on
        vals = np.concatenate([vals, np.ravel(rf.denominator(grid, window=True))])
    if not np.all(np.isfinite(vals)):
        return poles, True
    sign_change = bool(np.any(vals > 0) and np.any(vals < 0)) or bool(np.any(vals == 0))
    return poles, sign_change
