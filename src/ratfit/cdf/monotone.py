"""Monotone rational fits of cumulative distribution functions (seed section 3).

A CDF fit r = p / q must meet its vertical segments, stay in [0, 1] and be
non-decreasing. With q > 0 (the seed's case (a), which the value rows already
force: ``hi q - p > 0`` and ``p - lo q > 0`` give ``(hi - lo) q > 0``),

    r' >= 0  <=>  p' q - p q' >= 0  <=>  p' >= r q'

and since ``lo <= r <= hi`` at a constraint point, it is enough that

    p' >= max(lo q', hi q')                         (seed eq. 5, "max" form)
    p' - lo q' >= 0  and  p' - hi q' >= 0           (seed eq. 3, "two-row" form)

Both are linear in the coefficients c = (p, q) and they describe the same set
(max(a, b) <= v iff a <= v and b <= v). The two-row form adds both rows per
point; the max form adds one row per point, the one that binds for the sign of
q' at the current solution (hi when q' >= 0, lo otherwise), and adds the other
row only at points where the active set finds it violated. Its final active set
is a subset of the two-row rows whose solution satisfies all of them, so both
forms give the same QP solution.

Constraint points are the data points, the two domain ends, and optionally a
uniform grid of K extra points. At a point z without a segment the bounds are
the monotone envelope of the data, L(z) = max(lo_i : x_i <= z) and
U(z) = min(hi_i : x_i >= z), clipped to [0, 1]: every non-decreasing function
that meets the segments and stays in [0, 1] satisfies L(z) <= r(z) <= U(z), so
these rows remove no valid CDF, and they make the derivative rows at z valid.

Monotonicity between constraint points is not implied; :func:`verify_cdf`
checks it on a dense grid, and a fit that fails the check is not a success.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.bases import PolynomialSpace
from ratfit.core.options import FIT_OPTIONS, FitOptions, Option, check_options_class, extend_spec
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.solvers import first_available
from ratfit.core.systems import spread_indices
from ratfit.core.verify import Verification, verify
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter, SearchParts, SeedSystems

__all__ = [
    "CDF_SOLVER",
    "DEFAULT_ABS_WIDTH",
    "MONOTONE_FORMS",
    "MONOTONE_OPTIONS",
    "MonotoneOptions",
    "CDFVerification",
    "MonotoneFitter",
    "MonotoneSystem",
    "cdf_from_bounds",
    "cdf_from_pdf",
    "cdf_from_samples",
    "cdf_from_table",
    "cdf_segments",
    "dkw_epsilon",
    "fit_cdf",
    "monotone_envelope",
    "rational_derivative",
    "verify_cdf",
]

Array = NDArray[np.float64]
MONOTONE_FORMS = ("two-row", "max")
DEFAULT_ABS_WIDTH = 1e-3
# Points of the dense verification grid (at least; more for large data).
CHECK_POINTS = 10_000
# Tolerance of the monotone and [0, 1] checks: r is a probability, so absolute.
MONOTONE_ATOL = 1e-12
_CHUNK = 32_768


# ----------------------------------------------------------------------------- derivatives
def derivative_matrix(space: PolynomialSpace, count: int) -> Array:
    """M (count, count) with column k = coefficients of d/dt of basis function k."""
    if count <= 1:
        return np.zeros((count, count))
    d = space.family.der(np.eye(count), 1, 1, 0)  # (count - 1, count)
    return np.vstack([d, np.zeros((1, count))])


def rational_derivative(rf: RationalFunction, x: ArrayLike) -> tuple[Array, Array]:
    """(r(x), r'(x)) of a 1-D rational by the quotient rule, vectorised."""
    space = rf.space
    t = space.to_window(np.ravel(np.asarray(x, dtype=float)))[:, 0]
    fam = space.family
    p, q = fam.val(t, rf.p), fam.val(t, rf.q)
    dp, dq = fam.val(t, fam.der(rf.p)), fam.val(t, fam.der(rf.q))
    scale = space._scale[0][0]  # dt/dx
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return p / q, scale * (dp * q - p * dq) / (q * q)


# ----------------------------------------------------------------------------- envelope
def monotone_envelope(
    x: ArrayLike, lo: ArrayLike, hi: ArrayLike, z: ArrayLike
) -> tuple[Array, Array]:
    """Bounds [L(z), U(z)] every non-decreasing r in [0, 1] meeting the segments obeys."""
    xa = np.ravel(np.asarray(x, dtype=float))
    order = np.argsort(xa, kind="stable")
    xs = xa[order]
    cmax = np.maximum.accumulate(np.clip(np.ravel(lo)[order], 0.0, 1.0))
    cmin = np.minimum.accumulate(np.clip(np.ravel(hi)[order], 0.0, 1.0)[::-1])[::-1]
    za = np.ravel(np.asarray(z, dtype=float))
    i = np.searchsorted(xs, za, side="right") - 1  # last x_j <= z
    j = np.searchsorted(xs, za, side="left")  # first x_j >= z
    L = np.where(i >= 0, cmax[np.clip(i, 0, None)], 0.0)
    U = np.where(j < xs.size, cmin[np.clip(j, None, xs.size - 1)], 1.0)
    return L, U


def _check_monotone_feasible(x: Array, lo: Array, hi: Array, where: str = "segments") -> None:
    """Raise unless some non-decreasing function in [0, 1] meets every segment."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    lo_c, hi_c = np.clip(lo[order], 0.0, 1.0), np.clip(hi[order], 0.0, 1.0)
    L, U = monotone_envelope(xs, lo_c, hi_c, xs)
    bad = L > U
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        k = int(np.flatnonzero(lo_c[: i + 1] == L[i])[0])  # where the lower bound comes from
        j = i + int(np.flatnonzero(hi_c[i:] == U[i])[0])  # ... and the upper bound
        raise InputError(
            f"{where}: no non-decreasing function meets them: lower bound {float(lo_c[k]):.6g} "
            f"at x = {float(xs[k]):.6g} exceeds upper bound {float(hi_c[j]):.6g} at "
            f"x = {float(xs[j]):.6g} ({int(bad.sum())} such point(s))"
        )
    flat = L == U
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        raise InputError(
            f"{where}: the segments leave no width at x = {float(xs[i]):.6g} (r must equal "
            f"{float(L[i]):.6g} exactly once clipped to [0, 1] and made monotone); "
            "widen them (an absolute width)"
        )


# ----------------------------------------------------------------------------- the QP rows
class MonotoneSystem:
    """P(n, m) for a CDF: value rows plus derivative rows at every constraint point.

    Rows, for P constraint points with bounds [L, U] and value/derivative
    designs B, D (derivatives in the window variable t; dt/dx > 0 is a constant
    that changes no sign):

    | block | row          | meaning         |
    |-------|--------------|-----------------|
    | 0     | `[ B, -L B ]` | p - L q >= .    |
    | 1     | `[-B,  U B ]` | U q - p >= .    |
    | 2     | `[ D, -L D ]` | p' - L q' >= .  |
    | 3     | `[ D, -U D ]` | p' - U q' >= .  |

    Row r is block r // P, point r % P. ``form="max"`` differs only in the
    starting active set (one derivative row per point, see the module notes).
    """

    def __init__(
        self,
        space: PolynomialSpace,
        seg: Segments,
        channel: int = 0,
        *,
        form: str = "two-row",
        grid: int = 0,
    ) -> None:
        if space.dim != 1 or seg.dim != 1:
            raise InputError("monotone CDF fitting is 1-D; use fit_cdf_2d for two variables")
        if form not in MONOTONE_FORMS:
            raise InputError(f"unknown monotone form {form!r}; choose one of "
                             f"{', '.join(MONOTONE_FORMS)}")
        self.space = space
        xd = seg.x[:, 0]
        lo_d, hi_d = seg.lo[:, channel], seg.hi[:, channel]
        _check_monotone_feasible(xd, lo_d, hi_d)
        a, b = (float(v) for v in space.domain[0])
        extra = np.linspace(a, b, int(grid)) if grid >= 2 else np.empty(0)
        extra = np.unique(np.concatenate([extra, [a, b]]))
        extra = extra[~np.isin(extra, xd)]
        z = np.concatenate([xd, extra])
        self.form = form
        self.n_data = seg.n_points
        self.z = z
        self.L, self.U = monotone_envelope(xd, lo_d, hi_d, z)
        self.lo, self.hi = self.L, self.U
        self.t = space.to_window(z)
        self.x = z[:, None]
        self.n_points = int(z.size)
        self._order = np.argsort(z, kind="stable")
        self.D = np.zeros((self.n_points, 0))
        self._cum_d = self.D
        self._mono_lock = threading.Lock()
        self._k = 0
        self._R: Array | None = None
        self.B = np.zeros((self.n_points, 0))
        self._cum_sq = self.B

    # -- sizes -------------------------------------------------------------------
    def prepare(self, n_max: int, m_max: int) -> None:
        with self._mono_lock:
            k = max(n_max, m_max)
            if k > self._k:
                k = max(k, min(2 * self._k, k + 16))
                self.B = self.space.design(self.t, k, window=True)
                self.D = self.B_deriv(k)
                self._cum_sq = np.cumsum(self.B**2, axis=1)
                self._cum_d = np.cumsum(self.D**2, axis=1)
                self._k = k
                self._R = None
            if self._R is None:
                self._R = self._qr_r()

    def B_deriv(self, k: int) -> Array:
        """Derivative design (P, k) in the window variable: vander @ derivative matrix."""
        return self.space.design(self.t, k, window=True) @ derivative_matrix(self.space, k)

    def _full_block(self, sl: slice) -> Array:
        b, d = self.B[sl], self.D[sl]
        L, U = self.L[sl, None], self.U[sl, None]
        return np.vstack([
            np.hstack([b, -L * b]), np.hstack([-b, U * b]),
            np.hstack([d, -L * d]), np.hstack([d, -U * d]),
        ])

    def _qr_r(self) -> Array:
        """R of the full A (all four blocks, k_max columns each side), chunked."""
        acc: Array | None = None
        for start in range(0, self.n_points, _CHUNK // 4):
            block = self._full_block(slice(start, start + _CHUNK // 4))
            if acc is not None:
                block = np.vstack([acc, block])
            acc = np.asarray(np.linalg.qr(block, mode="r"), dtype=np.float64)
        assert acc is not None
        return acc[: 2 * self._k] if acc.shape[0] > 2 * self._k else acc

    def conditioning(self, n: int, m: int) -> tuple[float, float, float]:
        """(delta, sigma_min, sigma_max) of the full A(n, m), derivative rows included."""
        assert self._R is not None, "call prepare() first"
        cols = np.r_[np.arange(n), self._k + np.arange(m)]
        s = np.linalg.svd(self._R[:, cols], compute_uv=False)
        smax, smin = float(s[0]), float(s[-1])
        return (smin / smax if smax > 0 else 0.0), smin, smax

    # -- the matrix, by rows ---------------------------------------------------------
    @property
    def n_rows(self) -> int:
        return 4 * self.n_points

    def rows(self, n: int, m: int, ridx: NDArray[np.int64] | None = None) -> Array:
        if ridx is None:
            ridx = np.arange(self.n_rows)
        ridx = self._substitute(n, m, ridx)
        P = self.n_points
        blk, pts = ridx // P, ridx % P
        deriv = (blk >= 2)[:, None]
        base = np.where(deriv, self.D[pts], self.B[pts])
        sign = np.where(blk == 1, -1.0, 1.0)[:, None]
        w = np.select([blk == 0, blk == 1, blk == 2], [-self.L[pts], self.U[pts], -self.L[pts]],
                      -self.U[pts])[:, None]
        return np.hstack([sign * base[:, :n], w * base[:, :m]])

    def _raw_norms(self, n: int, m: int) -> Array:
        sp, sq = self._cum_sq[:, n - 1], self._cum_sq[:, m - 1]
        dp, dq = self._cum_d[:, n - 1], self._cum_d[:, m - 1]
        L2, U2 = self.L**2, self.U**2
        return np.sqrt(np.concatenate([sp + L2 * sq, sp + U2 * sq, dp + L2 * dq, dp + U2 * dq]))

    def _substitute(self, n: int, m: int, ridx: NDArray[np.int64]) -> NDArray[np.int64]:
        """A derivative row that is identically zero (n = 1: p' = 0, at L = 0 or with
        m = 1) says 0 >= 0: vacuous. It stands in as a copy of the point's value row,
        so no zero row reaches the solver, whose strict margin would make it infeasible."""
        if n > 1:
            return ridx
        zero = self._raw_norms(n, m)[ridx] == 0
        return np.where(zero, ridx % self.n_points, ridx)

    def row_norms(self, n: int, m: int) -> Array:
        norms = self._raw_norms(n, m)
        return norms[self._substitute(n, m, np.arange(self.n_rows))]

    def residuals(self, n: int, m: int, c: Array) -> Array:
        p, q = self.B[:, :n] @ c[:n], self.B[:, :m] @ c[n:]
        dp, dq = self.D[:, :n] @ c[:n], self.D[:, :m] @ c[n:]
        res = np.concatenate([p - self.L * q, self.U * q - p, dp - self.L * dq, dp - self.U * dq])
        return res[self._substitute(n, m, np.arange(self.n_rows))]

    def derivative_margins(self, n: int, m: int, c: Array, form: str | None = None) -> Array:
        """Derivative constraints at every point: (2, P) two-row residuals, or (P,) for
        the max form p' - max(L q', U q')."""
        dp, dq = self.D[:, :n] @ c[:n], self.D[:, :m] @ c[n:]
        if (form or self.form) == "max":
            return dp - np.maximum(self.L * dq, self.U * dq)
        return np.stack([dp - self.L * dq, dp - self.U * dq])

    def initial_rows(self, size: int) -> NDArray[np.int64]:
        pts = self.spread_subset(size)
        P = self.n_points
        if self.form == "max":
            # One derivative row per point: the one binding when q' >= 0 (U). Points
            # where the solution has q' < 0 get their L row from the active set.
            return np.concatenate([pts, P + pts, 3 * P + pts])
        return np.concatenate([pts + k * P for k in range(4)])

    def spread_subset(self, size: int) -> NDArray[np.int64]:
        if size >= self.n_points:
            return np.arange(self.n_points)
        pick = self._order[spread_indices(self.n_points, size)]
        extra = [np.argmin(self.U - self.L)]
        return np.unique(np.concatenate([pick, np.asarray(extra, dtype=np.int64)]))

    def to_rational(self, n: int, m: int, c: Array) -> RationalFunction:
        return RationalFunction(self.space, c[:n], c[n:])

    def q_design(self, t: Array, m: int) -> Array:
        return self.space.design(t, m, window=True)


class MonotoneSystems(SeedSystems):
    """The engine's system factory for CDFs: one MonotoneSystem per channel
    (the per-split Arnoldi form has no derivative rows)."""

    def __init__(self, form: str, grid: int) -> None:
        self.form, self.grid = form, int(grid)

    def channel(self, space: PolynomialSpace, seg: Segments, j: int) -> MonotoneSystem:
        return MonotoneSystem(space, seg, j, form=self.form, grid=self.grid)


# ----------------------------------------------------------------------------- verification
@dataclass(frozen=True)
class CDFVerification(Verification):
    """:class:`~ratfit.core.verify.Verification` plus the CDF checks on a dense grid."""

    monotone: bool
    in_unit_interval: bool
    segments_ok: bool
    check_points: int
    min_step: float  # min r(z_{k+1}) - r(z_k) on the grid
    min_pdf: float  # min r'(z) on the grid
    r_min: float
    r_max: float

    def monotone_summary(self) -> dict:
        """The ``monotone`` object of ``ratfit cdf --json``."""
        return {
            "verified": bool(self.monotone and self.in_unit_interval),
            "non_decreasing": self.monotone,
            "in_unit_interval": self.in_unit_interval,
            "check_points": self.check_points,
            "min_step": _finite(self.min_step),
            "min_pdf": _finite(self.min_pdf),
            "r_min": _finite(self.r_min),
            "r_max": _finite(self.r_max),
        }


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def verify_cdf(
    rf: RationalFunction,
    seg: Segments,
    *,
    channel: int = 0,
    check_points: int | None = None,
    atol: float = MONOTONE_ATOL,
) -> CDFVerification:
    """Segments met, no pole, and on a dense grid of the domain: r non-decreasing, in [0, 1].

    The grid has ``check_points`` points (default max(10 000, 20 N)) plus the
    data points. Non-decreasing means r(z_{k+1}) - r(z_k) >= -atol and
    r'(z) >= -atol * max|r'| at every grid point.
    """
    with np.errstate(over="ignore"):  # relative errors where F ~ 1e-300 overflow: harmless
        base = verify(rf, seg, channel=channel)
    a, b = (float(v) for v in rf.space.domain[0])
    k = int(check_points or max(CHECK_POINTS, 20 * seg.n_points))
    z = np.union1d(np.linspace(a, b, k), seg.x[:, 0].clip(a, b))
    r, dr = rational_derivative(rf, z)
    finite = bool(np.all(np.isfinite(r)) and np.all(np.isfinite(dr)))
    steps = np.diff(r)
    min_step = float(steps.min()) if finite and steps.size else -math.inf
    min_pdf = float(dr.min()) if finite else -math.inf
    scale = float(np.abs(dr).max()) if finite else math.inf
    monotone = finite and min_step >= -atol and min_pdf >= -atol * max(scale, 1.0)
    r_min = float(r.min()) if finite else -math.inf
    r_max = float(r.max()) if finite else math.inf
    unit = finite and r_min >= -atol and r_max <= 1.0 + atol
    fields = base.__dict__ | {"verified": bool(base.verified and monotone and unit)}
    return CDFVerification(
        **fields, monotone=bool(monotone), in_unit_interval=bool(unit),
        segments_ok=bool(base.verified), check_points=int(z.size), min_step=min_step,
        min_pdf=min_pdf, r_min=r_min, r_max=r_max,
    )


# ----------------------------------------------------------------------------- the fitter
#: The QP solver of CDF fits: DAQP first. quadprog looped forever inside one call on a
#: CDF QP of 516 x 13 (the data sampler of acryl_blue's render; DAQP: 1.3 ms, Clarabel
#: 0.14 s, both optimal), as it did on a BRDF QP
#: (:data:`~ratfit.brdf.options.BRDF_SOLVER`). A renderer's sampler fits ~117 such CDFs
#: per material.
CDF_SOLVER = first_available(("daqp", "quadprog"))
#: :class:`MonotoneFitter`'s options: the fitter's, a "basis" formulation and
#: :data:`CDF_SOLVER` by default, and the derivative rows' own.
MONOTONE_OPTIONS = extend_spec(
    FIT_OPTIONS,
    Option("form", "choice", "two-row", "Derivative rows: two per point, or one (max form).",
           MONOTONE_FORMS, label="monotone form"),
    Option("grid", "int", 0, "Extra constraint points, uniform on the domain.", minimum=0),
    Option("check_points", "int", None, "Points of the dense verification grid.", minimum=2),
    defaults={"formulation": "basis", "solver": CDF_SOLVER},
)


@dataclass(frozen=True)
class MonotoneOptions(FitOptions):
    """The checked options of a monotone CDF fit (:data:`MONOTONE_OPTIONS`)."""

    SPEC: ClassVar = MONOTONE_OPTIONS

    solver: str = CDF_SOLVER
    formulation: str = "basis"
    form: str = "two-row"
    grid: int = 0
    check_points: int | None = None

    def _check_together(self, where: str | None) -> None:
        super()._check_together(where)
        if self.formulation not in ("basis", "auto"):
            msg = (f"formulation {self.formulation!r} has no derivative rows: a monotone CDF "
                   "fit uses the seed's basis formulation")
            raise InputError(f"{where}: {msg}" if where else msg)


check_options_class(MonotoneOptions)


class MonotoneFitter(RationalFitter):
    """:class:`~ratfit.fitting.search.RationalFitter` for CDFs: monotone rows, CDF verification.

    A result is a success only if :func:`verify_cdf` passes (segments met, no
    pole, non-decreasing and within [0, 1] on a dense grid). 1-D only.

    Parameters
    ----------
    form : {"two-row", "max"}, default "two-row"
        Derivative rows: seed eq. 3 (two rows per point) or eq. 5 (one row per
        point, the other added only where the active set needs it; implies the
        active set).
    grid : int, default 0
        Extra constraint points, uniform on the domain (0: the data points and
        the domain ends only).
    check_points : int, optional
        Size of the dense verification grid (default max(10 000, 20 N)).
    formulation : {"basis", "auto"}, default "basis"
        The derivative rows exist in the seed's basis formulation only.
    **params
        Every other :class:`~ratfit.fitting.search.RationalFitter` parameter.

    Attributes
    ----------
    results_, result_, rational_, success_, segments_, space_, options_
        As for :class:`~ratfit.fitting.search.RationalFitter` (``options_`` is a
        :class:`MonotoneOptions`).

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit.cdf import MonotoneFitter, cdf_from_table
    >>> x = np.linspace(0, 1, 40)
    >>> f = MonotoneFitter(grid=50).fit(cdf_from_table(x, x**2, abs_width=1e-3))
    >>> f.result_.success
    True
    """

    def __init__(
        self, *, form: str = "two-row", grid: int = 0, check_points: int | None = None,
        formulation: str = "basis", solver: str = CDF_SOLVER, **params: Any,
    ) -> None:
        super().__init__(formulation=formulation, solver=solver, **params)
        self.form = form
        self.grid = grid
        self.check_points = check_points

    options_type = MonotoneOptions

    def fit(self, X: ArrayLike | Segments, y: ArrayLike | None = None) -> Self:
        """Fit a monotone CDF to every channel (``fit(segments)`` or ``fit(x, y)``
        with ``dt``/``abs_width``); returns self."""
        self.options()  # the options' messages come before the data's
        return super().fit(X, y)

    def _fit_segments(self, segments: Segments) -> Self:
        if segments.dim != 1:
            raise InputError(
                f"monotone CDF fitting is 1-D, the data has {segments.dim} input dimensions"
            )
        return super()._fit_segments(segments)

    def search_parts(self, space: PolynomialSpace, seg: Segments) -> SearchParts:
        o = self.options_
        assert isinstance(o, MonotoneOptions)
        return SearchParts(
            systems=MonotoneSystems(o.form, o.grid),
            verifier=lambda rf, seg, j: verify_cdf(rf, seg, channel=j,
                                                   check_points=o.check_points),
            # the max form *is* its starting active set
            active_set=True if o.form == "max" and o.active_set is None else None,
        )


def fit_cdf(segments: Segments, **params):
    """Fit one monotone CDF: ``MonotoneFitter(**params).fit(segments).result_``.

    Parameters
    ----------
    segments : Segments
        One channel of CDF intervals (:func:`cdf_from_pdf`, :func:`cdf_from_table`,
        :func:`cdf_from_samples`, :func:`cdf_from_bounds`).
    **params
        :class:`MonotoneFitter` parameters.

    Returns
    -------
    FitResult
        A success only when :func:`verify_cdf` passed (monotone, in [0, 1]).

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit.cdf import cdf_from_table, fit_cdf
    >>> x = np.linspace(0, 1, 40)
    >>> res = fit_cdf(cdf_from_table(x, x**2, abs_width=1e-3), grid=50)
    >>> res.success, res.verification.monotone
    (True, True)
    """
    return MonotoneFitter(**params).fit(segments).result_


# ----------------------------------------------------------------------------- inputs
def _sorted_x(x: ArrayLike, name: str) -> tuple[Array, NDArray[np.intp]]:
    try:
        xa = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric: {exc}") from None
    xa = np.ravel(xa) if xa.ndim == 2 and 1 in xa.shape else xa
    if xa.ndim != 1:
        raise InputError(f"{name} must be 1-D (a CDF has one variable), got shape {xa.shape}")
    if xa.size < 2:
        raise InputError(f"{name} needs at least 2 points, got {xa.size}")
    _finite_or_raise(xa, name)
    order = np.argsort(xa, kind="stable")
    xs = xa[order]
    dup = np.flatnonzero(np.diff(xs) == 0)
    if xs[-1] == xs[0]:
        raise InputError(f"{name}: zero-length domain (every point is x = {float(xs[0])!r})")
    if dup.size:
        raise InputError(
            f"{name}: repeated point x = {float(xs[dup[0]])!r} (row {int(order[dup[0] + 1])}); "
            "a table needs distinct points"
        )
    return xs, order


def _finite_or_raise(v: Array, name: str) -> None:
    bad = ~np.isfinite(v)
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        raise InputError(
            f"{name} contains {int(bad.sum())} non-finite value(s) "
            f"({'NaN' if np.isnan(v.ravel()[i]) else 'inf'}); first at row {i}"
        )


def _values(v: ArrayLike, n: int, name: str, order: NDArray[np.intp]) -> Array:
    try:
        va = np.ravel(np.asarray(v, dtype=float))
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric: {exc}") from None
    if va.size != n:
        raise InputError(f"mismatched lengths: x has {n} points but {name} has {va.size}")
    _finite_or_raise(va, name)
    return va[order]


def cdf_segments(
    x: Array, F: Array, *, dt: float | None = None, abs_width: float | None = None,
    name: str = "cdf",
) -> Segments:
    """Segments around CDF values F: half-width max(dt * min(F, 1 - F), abs_width).

    The relative part is relative to the tail probability, so both tails are
    fitted with the same relative accuracy. Without either width the absolute
    width is :data:`DEFAULT_ABS_WIDTH`. Bounds are clipped to [0, 1].
    """
    for val, nm in ((dt, "dt"), (abs_width, "abs_width")):
        if val is not None and (not np.isfinite(val) or val < 0):
            raise InputError(f"{nm} must be a finite number >= 0, got {val!r}")
    if dt is None and abs_width is None:
        abs_width = DEFAULT_ABS_WIDTH
    half = np.zeros_like(F)
    if dt is not None:
        half = np.maximum(half, dt * np.minimum(F, 1.0 - F))
    if abs_width is not None:
        half = np.maximum(half, abs_width)
    lo, hi = np.clip(F - half, 0.0, 1.0), np.clip(F + half, 0.0, 1.0)
    zero = hi <= lo
    if zero.any():
        i = int(np.flatnonzero(zero)[0])
        raise InputError(
            f"{name}: zero-width segment at x = {float(x[i])!r} (F = {float(F[i])!r}); the "
            "relative width vanishes where F is 0 or 1: add an absolute width (--abs-width)"
        )
    return Segments(x[:, None], lo[:, None], hi[:, None], F[:, None], names=("cdf",))


def cdf_from_pdf(
    x: ArrayLike, pdf: ArrayLike, *, dt: float | None = None, abs_width: float | None = None,
) -> Segments:
    """Segments of the CDF of a tabulated PDF (normalised, trapezoid rule)."""
    xs, order = _sorted_x(x, "pdf table x")
    f = _values(pdf, xs.size, "pdf", order)
    neg = f < 0
    if neg.any():
        i = int(np.flatnonzero(neg)[0])
        raise InputError(
            f"pdf has {int(neg.sum())} negative value(s); first {float(f[i])!r} at "
            f"x = {float(xs[i])!r}: a density cannot be negative"
        )
    from scipy.integrate import cumulative_trapezoid

    F = cumulative_trapezoid(f, xs, initial=0.0)
    if not F[-1] > 0:
        raise InputError("pdf integrates to zero over the table: nothing to normalise")
    F = np.clip(F / F[-1], 0.0, 1.0)
    return cdf_segments(xs, F, dt=dt, abs_width=abs_width)


def cdf_from_table(
    x: ArrayLike, cdf: ArrayLike, *, dt: float | None = None, abs_width: float | None = None,
) -> Segments:
    """Segments around tabulated CDF values (must be non-decreasing, within [0, 1])."""
    xs, order = _sorted_x(x, "cdf table x")
    F = _values(cdf, xs.size, "cdf", order)
    dec = np.flatnonzero(np.diff(F) < 0)
    if dec.size:
        i = int(dec[0])
        raise InputError(
            f"cdf table is not non-decreasing: F = {float(F[i])!r} at x = {float(xs[i])!r} "
            f"but F = {float(F[i + 1])!r} at x = {float(xs[i + 1])!r} "
            f"({dec.size} decrease(s))"
        )
    out = (F < 0) | (F > 1)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise InputError(
            f"cdf value {float(F[i])!r} at x = {float(xs[i])!r} lies outside [0, 1]"
        )
    return cdf_segments(xs, F, dt=dt, abs_width=abs_width)


def cdf_from_bounds(x: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> Segments:
    """Explicit CDF intervals, clipped to [0, 1]; checked to admit a monotone function."""
    xs, order = _sorted_x(x, "cdf bounds x")
    lo_s = np.clip(_values(lo, xs.size, "lo", order), 0.0, 1.0)
    hi_s = np.clip(_values(hi, xs.size, "hi", order), 0.0, 1.0)
    bad = lo_s > hi_s
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"lo > hi at x = {float(xs[i])!r} (after clipping to [0, 1]: "
            f"lo = {float(lo_s[i])!r}, hi = {float(hi_s[i])!r})"
        )
    _check_monotone_feasible(xs, lo_s, hi_s, "cdf intervals")
    return Segments(xs[:, None], lo_s[:, None], hi_s[:, None], names=("cdf",))


def dkw_epsilon(n: int, alpha: float) -> float:
    """Half-width of the Dvoretzky-Kiefer-Wolfowitz band: P(sup|F_n - F| > eps) <= alpha."""
    return math.sqrt(math.log(2.0 / alpha) / (2.0 * n))


def cdf_from_samples(
    samples: ArrayLike, *, confidence: float = 0.99, points: int = 256,
    domain: tuple[float, float] | None = None,
) -> Segments:
    """Segments of the empirical CDF with a DKW band at ``confidence`` (simultaneous).

    The ECDF is evaluated at ``points`` sample quantiles (the band holds for
    every x at once, so any subset is valid) plus the domain ends, which
    default to the sample range.
    """
    try:
        s = np.ravel(np.asarray(samples, dtype=float))
    except (TypeError, ValueError) as exc:
        raise InputError(f"samples must be numeric: {exc}") from None
    if s.size < 2:
        raise InputError(f"need at least 2 samples, got {s.size}")
    _finite_or_raise(s, "samples")
    if not 0.0 < confidence < 1.0:
        raise InputError(f"confidence must lie strictly between 0 and 1, got {confidence!r}")
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 2:
        raise InputError(f"points must be an integer >= 2, got {points!r}")
    s = np.sort(s)
    a, b = (float(s[0]), float(s[-1])) if domain is None else (float(domain[0]),
                                                                 float(domain[1]))
    if not (np.isfinite(a) and np.isfinite(b)) or b <= a:
        raise InputError(f"zero-length or reversed domain [{a!r}, {b!r}] for the samples")
    if s[0] < a or s[-1] > b:
        raise InputError(f"samples lie outside the domain [{a!r}, {b!r}]")
    eps = dkw_epsilon(s.size, 1.0 - confidence)
    q = np.quantile(s, np.linspace(0.0, 1.0, points))
    z = np.unique(np.concatenate([q, [a, b]]))
    F = np.searchsorted(s, z, side="right") / s.size
    lo, hi = np.clip(F - eps, 0.0, 1.0), np.clip(F + eps, 0.0, 1.0)
    return Segments(z[:, None], lo[:, None], hi[:, None], F[:, None], names=("cdf",))
