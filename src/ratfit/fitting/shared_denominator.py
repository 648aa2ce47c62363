"""One denominator for every channel: r_c = p_c / q, fitted in one QP.

Colour channels (R, G, B) of a measurement share their poles more often than
not; a shared q costs m coefficients once instead of once per channel, and the
fits evaluate with one division per point. The QP stacks every channel's two
rows per point: for channel c, ``p_c - lo_c q >= 0`` and ``hi_c q - p_c >= 0``,
over c = (a_1, ..., a_K, b).

Following :class:`ratfit.core.qp.ArnoldiSystem`, each p_c lives in a basis
orthonormal for the weights ``v / s_c`` and q in one orthonormal for ``v``,
where ``s_c`` is channel c's segment scale and ``v = 1 / |q0|`` for a joint
Sanathanan-Koerner guess q0 (:func:`shared_sk_denominator`). Rows are divided
by ``s_c / v`` (a positive scaling: the feasible set is the seed's).

Search (minimise sum n_c + m). Feasibility is monotone in each n_c and in m.
For m = 1, 2, ...: find a "large" N with (N, ..., N, m) feasible; for each
channel the smallest n_c* with the other channels at N (bisection); then test
(n_1*, ..., n_K*, m). Any feasible vector with entries <= N has n_c >= n_c*,
so sum n_c* + m is a lower bound at this m; when the joint test passes it is
attained. Otherwise channels are raised one at a time (greedy) until feasible,
then lowered while feasible. The walk over m stops when m + K reaches the best
total (no larger m can win).

Guarantee (stated in ``SharedFit.proven``): the returned total is the minimum
over every vector with n_c <= N and the m values tried when the joint test
hit the lower bound at the winning m and every smaller-total m had a lower
bound at least as large; "infeasible" here means the QP (with its cross
check) reported infeasible, the same standard as the single-channel search.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.arnoldi import ArnoldiBasis
from ratfit.core.bases import PolynomialSpace
from ratfit.core.estimator import Regressor
from ratfit.core.options import (
    DEFAULT_TIME_LIMIT,
    DEFAULT_WORK_LIMIT,
    FIT_OPTIONS,
    SEGMENT_OPTIONS,
    FitOptions,
    Option,
    check_options_class,
    extend_spec,
)
from ratfit.core.qp import (
    Attempt,
    denominator_weights,
    segment_scales,
    sk_denominator,
    solve_pole_free,
)
from ratfit.core.rational import RationalFunction
from ratfit.core.results import STATUS_MESSAGES, FitResult
from ratfit.core.segments import Segments
from ratfit.core.systems import denominator_cuts, domain_grid, spread_indices
from ratfit.core.verify import Verification, verify
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter

__all__ = ["SHARED_OPTIONS", "SharedDenominatorFitter", "SharedFit", "SharedOptions",
           "SharedSystem", "shared_sk_denominator"]

Array = NDArray[np.float64]
Sizes = tuple[int, ...]

#: The options of a shared-denominator fit: the fitter's and the largest sizes searched
#: (``jobs`` None: one thread).
SHARED_OPTIONS = extend_spec(
    FIT_OPTIONS,
    Option("max_n", "int", 60, "Largest numerator tried per channel.", minimum=1),
    Option("max_m", "int", 30, "Largest shared denominator tried.", minimum=1),
)
# Options of the single-channel search that mean nothing here, with why: refused
# when they differ from their defaults (never silently ignored).
_NOT_HERE = {
    "n": "the numerator sizes are searched (m alone fixes the shared denominator)",
    "total": "the numerator sizes are searched (m alone fixes the shared denominator)",
    "min_total": "the search minimises sum(n) + m from the smallest sizes up",
    "max_total": "the sizes are bounded by max_n and max_m",
    "strategy": "the shared search has its own walk over m",
    "split_rule": "the shared search keeps the smallest sum(n) + m",
}


@dataclass(frozen=True)
class SharedOptions(FitOptions):
    """The checked options of :class:`SharedDenominatorFitter` (:data:`SHARED_OPTIONS`).

    ``m`` alone fixes the shared denominator; ``n``, ``total``, ``min_total``,
    ``max_total``, ``strategy``, ``split_rule``, ``variable="log"`` and
    ``formulation="basis"`` are refused (one line saying why): the search has
    its own walk in x with data-orthonormal bases.
    """

    SPEC: ClassVar = SHARED_OPTIONS

    max_n: int = 60
    max_m: int = 30

    def _check_together(self, where: str | None) -> None:
        def at(msg: str) -> str:
            return f"{where}: {msg}" if where else msg

        for key, why in _NOT_HERE.items():
            if getattr(self, key) != self.SPEC[key].default:
                raise InputError(at(f"a shared denominator does not take {key}: {why}"))
        if self.variable == "log":
            raise InputError(at("a shared denominator is fitted in x, not log x: "
                                "give variable 'x' or 'auto'"))
        if self.formulation == "basis":
            raise InputError(at("a shared denominator uses data-orthonormal bases: give "
                                "formulation 'arnoldi' or 'auto'"))


check_options_class(SharedOptions)


def shared_sk_denominator(space: PolynomialSpace, seg: Segments, n: Sizes, m: int,
                          steps: int = 4, max_points: int = 4000) -> Array | None:
    """Values at the data of a denominator guess shared by every channel:
    min over q (||q|| = 1, weighted) of sum_c min_{p_c} sum_i v_i^2
    |p_c(x_i) - mid_ic q(x_i)|^2 / s_ic^2, re-weighted a few times."""
    return sk_denominator(space, seg, range(seg.n_channels), n, m, steps, max_points)


class SharedSystem:
    """P(n_1..n_K, m) with one q, in the row protocol of :func:`ratfit.core.qp.solve_fixed`.

    Row r: channel ``r // (2N)``; within it, rows ``< N`` are lo-rows of the
    points and the rest hi-rows. ``solve_fixed`` is called with
    n = sum(n_c); the split of c into blocks is this system's business.
    """

    def __init__(self, space: PolynomialSpace, seg: Segments, n: Sizes, m: int,
                 q0: Array | None = None) -> None:
        if len(n) != seg.n_channels:
            raise InputError(f"{len(n)} numerator sizes for {seg.n_channels} channels")
        self.space, self.sizes, self.m = space, tuple(int(v) for v in n), int(m)
        self.n_points = seg.n_points
        self.K = seg.n_channels
        self.t = space.to_window(seg.x)
        self.scale = segment_scales(seg.lo, seg.hi)
        self.v = denominator_weights(q0, self.n_points)
        self.lo_s = seg.lo / self.scale
        self.hi_s = seg.hi / self.scale
        self.p_bases: list[ArnoldiBasis] = []
        self.U: list[Array] = []
        for c, nc in enumerate(self.sizes):
            basis, U = ArnoldiBasis.build(space, self.t, self.v / self.scale[:, c], nc)
            self.p_bases.append(basis)
            self.U.append(U)
        self.q_basis, self.V = ArnoldiBasis.build(space, self.t, self.v, self.m)
        self.offsets = np.r_[0, np.cumsum(self.sizes)]
        self.k = int(self.offsets[-1]) + self.m
        vq = np.sum(self.V**2, axis=1)
        self._norms = np.concatenate([
            np.sqrt(np.concatenate([np.sum(U**2, 1) + self.lo_s[:, c] ** 2 * vq,
                                    np.sum(U**2, 1) + self.hi_s[:, c] ** 2 * vq]))
            for c, U in enumerate(self.U)
        ])
        self._cond = self._conditioning()
        self._order = np.lexsort(self.t.T[::-1])

    @property
    def n_rows(self) -> int:
        return 2 * self.n_points * self.K

    def prepare(self, n_max: int, m_max: int) -> None:  # built up front
        pass

    def conditioning(self, n: int, m: int) -> tuple[float, float, float]:
        return self._cond

    def _conditioning(self) -> tuple[float, float, float]:
        """From the Gram matrix (blocks 2 I, cross terms, sum over channels)."""
        V, k, off = self.V, self.k, self.offsets
        G = np.zeros((k, k))
        qq = np.zeros((self.m, self.m))
        for c, U in enumerate(self.U):
            sl = slice(off[c], off[c + 1])
            G[sl, sl] = 2.0 * np.eye(U.shape[1])
            cross = -U.T @ ((self.lo_s[:, c] + self.hi_s[:, c])[:, None] * V)
            G[sl, off[-1]:] = cross
            G[off[-1]:, sl] = cross.T
            qq += V.T @ ((self.lo_s[:, c] ** 2 + self.hi_s[:, c] ** 2)[:, None] * V)
        G[off[-1]:, off[-1]:] = qq
        ev = np.linalg.eigvalsh(G)
        smax = float(np.sqrt(max(ev[-1], 0.0)))
        smin = float(np.sqrt(max(ev[0], 0.0)))
        return (smin / smax if smax > 0 else 0.0), smin, smax

    def rows(self, n: int, m: int, ridx: NDArray[np.int64] | None = None) -> Array:
        if ridx is None:
            ridx = np.arange(self.n_rows)
        N = self.n_points
        ch = ridx // (2 * N)
        rr = ridx % (2 * N)
        pts = rr % N
        first = rr < N
        out = np.zeros((ridx.size, self.k))
        for c in np.unique(ch):
            sel = np.flatnonzero(ch == c)
            p = pts[sel]
            sign = np.where(first[sel], 1.0, -1.0)[:, None]
            w = np.where(first[sel], -self.lo_s[p, c], self.hi_s[p, c])[:, None]
            out[sel, self.offsets[c]:self.offsets[c + 1]] = sign * self.U[c][p]
            out[sel, self.offsets[-1]:] = w * self.V[p]
        return out

    def row_norms(self, n: int, m: int) -> Array:
        return self._norms

    def residuals(self, n: int, m: int, c: Array) -> Array:
        q = self.V @ c[self.offsets[-1]:]
        parts = []
        for j, U in enumerate(self.U):
            p = U @ c[self.offsets[j]:self.offsets[j + 1]]
            parts += [p - self.lo_s[:, j] * q, self.hi_s[:, j] * q - p]
        return np.concatenate(parts)

    def initial_rows(self, size: int) -> NDArray[np.int64]:
        N = self.n_points
        if size >= N:
            pts = np.arange(N)
        else:
            pts = self._order[spread_indices(N, size)]
            extra = [np.argmin(self.hi_s - self.lo_s) % N]
            pts = np.unique(np.concatenate([pts, np.asarray(extra, dtype=np.int64)]))
        return np.concatenate([c * 2 * N + np.r_[pts, N + pts] for c in range(self.K)])

    def rationals(self, c: Array) -> list[RationalFunction]:
        b = c[self.offsets[-1]:]
        return [
            RationalFunction(self.space, c[self.offsets[j]:self.offsets[j + 1]], b,
                             p_basis=self.p_bases[j], q_basis=self.q_basis)
            for j in range(self.K)
        ]

    def to_rational(self, n: int, m: int, c: Array) -> RationalFunction:
        """The first channel (``rationals`` gives them all)."""
        return self.rationals(c)[0]

    def q_design(self, t: Array, m: int) -> Array:
        return self.q_basis.design(t, m, window=True)


@dataclass
class _Trial:
    n: Sizes
    m: int
    att: Attempt
    rationals: list[RationalFunction] | None
    verifications: list[Verification] | None

    @property
    def ok(self) -> bool:
        return self.verifications is not None and all(v.verified for v in self.verifications)


@dataclass
class SharedFit:
    """The shared-denominator result: one FitResult per channel (same q)."""

    results: list[FitResult]
    n: Sizes
    m: int
    total: int
    proven: bool  # see the module docstring
    lower_bounds: dict[int, int]  # m -> sum n_c* + m (the bound at that m)
    n_large: int  # N of the guarantee
    qp_solves: int
    seconds: float
    history: list[dict[str, Any]] = field(default_factory=list)

    @property
    def success(self) -> bool:
        """Every channel has a verified fit with the shared denominator."""
        return bool(self.results) and all(r.success for r in self.results)

    @property
    def message(self) -> str:
        """One line: the sizes found, or why a channel has no fit."""
        if self.success:
            proof = "proven minimal" if self.proven else "not proven minimal"
            return (f"shared denominator: n = {list(self.n)}, m = {self.m}, total {self.total} "
                    f"({proof})")
        bad = [r for r in self.results if not r.success]
        if not bad:
            return "no channel fitted"
        return "; ".join(f"{r.channel}: {r.message}" for r in bad)


class SharedDenominatorFitter(Regressor):
    """Fit every channel with one denominator and the fewest coefficients sum(n_c) + m.

    A scikit-learn regressor in shape, like
    :class:`~ratfit.fitting.search.RationalFitter`: ``fit(X, y)`` builds the segments
    from ``dt`` and/or ``abs_width`` (``y`` of shape (N, k): one channel per column),
    ``predict(X)`` evaluates every channel and ``score`` is R^2; ``fit(segments)``
    takes prepared :class:`~ratfit.core.segments.Segments` instead.

    Parameters
    ----------
    dt : float, optional
        Relative half-width of the segments ``fit(X, y)`` builds:
        [(1 - dt) y, (1 + dt) y].
    abs_width : float, optional
        Absolute half-width [y - w, y + w] (with ``dt`` each segment is the union of
        both). ``fit(X, y)`` needs one of the two; ``fit(segments)`` needs neither.
    basis, index_set, domain, solver, cross_check, callback, active_set, formulation, \
variable, warm_start
        As for :class:`~ratfit.fitting.search.RationalFitter` (``variable`` "x" or
        "auto": a shared denominator is fitted in x; ``formulation`` "arnoldi" or
        "auto": data-orthonormal bases).
    n, total, min_total, max_total, strategy, split_rule
        The single-channel search's; refused unless at their defaults (the sizes
        are searched here, bounded by ``max_n`` and ``max_m``).
    m : int, optional
        Fix the denominator size (then only the numerators are searched).
    max_n : int, default 60
        Largest numerator tried per channel.
    max_m : int, default 30
        Largest denominator tried.
    jobs : int, default 1
        Threads for the per-channel bisections.
    time_limit : float, optional
        Wall-clock seconds for the whole search (default None: no clock); when they
        run out it stops between QPs with the smallest verified fit so far (not
        proven minimal) or none.
    work_limit : int, optional, default 4000
        QP solves for the whole search, the deterministic budget; the same stop.

    Attributes
    ----------
    result_ : SharedFit
        The whole shared fit (sizes, minimality proof, history).
    results_ : list of FitResult
        One result per channel (every channel has the same q).
    success_ : bool
        Every channel has a verified fit.

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit import Segments
    >>> from ratfit.fitting import SharedDenominatorFitter
    >>> x = np.linspace(-1, 1, 40)
    >>> y = np.stack([1 / (2 + x), x / (2 + x)], axis=1)
    >>> f = SharedDenominatorFitter(max_n=8, max_m=4).fit(Segments.from_relative(x, y, 0.01))
    >>> f.success_, f.result_.m
    (True, 2)
    >>> g = SharedDenominatorFitter(dt=0.01, max_n=8, max_m=4).fit(x, y)
    >>> g.result_.m, g.predict([0.5]).round(2).tolist()
    (2, [[0.4, 0.2]])
    """

    options_type: ClassVar[type[SharedOptions]] = SharedOptions

    def __init__(self, *, dt: float | None = None, abs_width: float | None = None,
                 basis: str = "legendre", index_set: str = "total",
                 domain: ArrayLike | None = None, m: int | None = None, max_n: int = 60,
                 max_m: int = 30, solver: str = "quadprog", cross_check: str = "orth",
                 jobs: int | None = 1,
                 callback: Callable[[Attempt], None] | None = None,
                 time_limit: float | None = DEFAULT_TIME_LIMIT,
                 work_limit: int | None = DEFAULT_WORK_LIMIT, n: int | None = None,
                 total: int | None = None, min_total: int = 2, max_total: int | None = None,
                 strategy: str = "staircase", split_rule: str = "min-m",
                 active_set: bool | None = None, formulation: str = "auto",
                 variable: str = "auto", warm_start: bool = True) -> None:
        self.dt, self.abs_width = dt, abs_width
        self.basis, self.index_set, self.domain = basis, index_set, domain
        self.m, self.max_n, self.max_m = m, max_n, max_m
        self.solver, self.cross_check = solver, cross_check
        self.jobs, self.callback = jobs, callback
        self.time_limit = time_limit
        self.work_limit = work_limit
        self.n, self.total, self.min_total, self.max_total = n, total, min_total, max_total
        self.strategy, self.split_rule, self.active_set = strategy, split_rule, active_set
        self.formulation, self.variable, self.warm_start = formulation, variable, warm_start

    @classmethod
    def from_options(cls, options: SharedOptions) -> SharedDenominatorFitter:
        """The fitter of checked ``options`` (the options it cannot honour were refused
        when they were made)."""
        return cls(**options.params())

    def options(self) -> SharedOptions:
        """The constructor parameters as checked options (InputError when one is bad);
        the segment widths (``dt``, ``abs_width``) are not among them."""
        params = self.get_params(deep=False)
        for name in SEGMENT_OPTIONS:
            SEGMENT_OPTIONS[name].check(params.pop(name))
        return self.options_type.from_params(params)

    def fit(self, X: ArrayLike | Segments, y: ArrayLike | None = None) -> SharedDenominatorFitter:
        """Search the shared-denominator sizes; returns self.

        Parameters
        ----------
        X : array-like of shape (N,) or (N, d), or Segments
            Points (with ``y``), or prepared segments (without).
        y : array-like of shape (N, k), optional
            Values, one channel per column; the segments are built around them from
            ``dt`` / ``abs_width``.
        """
        self.options_ = opts = self.options()
        seg = self.segments_of(X, y)
        plain = FitOptions(**{k: getattr(opts, k) for k in ("basis", "index_set", "domain",
                                                             "solver", "cross_check")})
        # the same checks and messages as a normal fit
        space = RationalFitter.from_options(plain).prepare(seg)
        if seg.dim > 1 and space.index_set != "total":
            raise InputError("a shared denominator needs index_set='total' in n-D")
        self.result_ = _SharedSearch(opts, space, seg).run()
        self.results_ = self.result_.results
        self.segments_ = seg
        return self

    @property
    def success_(self) -> bool:
        if not hasattr(self, "result_"):
            raise AttributeError(
                "this SharedDenominatorFitter is not fitted yet: call fit() first"
            )
        return self.result_.success

    def predict(self, X: ArrayLike) -> NDArray[np.float64]:
        """Values of every channel at points ``X`` (N, d) or (N,) in 1-D: shape (N, k),
        (N,) for one channel. Needs a verified shared fit (``success_``)."""
        if not self.success_:
            raise InputError(f"no verified shared fit ({self.result_.message}): nothing to "
                             "predict with; widen the segments (dt, abs_width) or raise "
                             "max_n / max_m")
        cols = [np.asarray(r.rational(X), dtype=float).reshape(-1) for r in self.results_
                if r.rational is not None]
        return cols[0] if len(cols) == 1 else np.stack(cols, axis=1)


class _OutOfTime(Exception):
    """The search's time budget ran out (raised before a new QP)."""


class _SharedSearch:
    def __init__(self, options: SharedOptions, space: PolynomialSpace, seg: Segments):
        self.f, self.space, self.seg = options, space, seg
        self.K = seg.n_channels
        self.cache: dict[tuple[Sizes, int], _Trial] = {}
        self.lock = threading.Lock()
        self.deadline = None if options.time_limit is None else (
            time.perf_counter() + options.time_limit)
        # More coefficients than points cannot be independent on the data.
        self.cap = min(options.max_n, seg.n_points)
        grid = domain_grid(space.dim, seg.n_points)
        self.cuts = lambda rf: denominator_cuts(rf, grid)

    def test(self, n: Sizes, m: int) -> _Trial:
        key = (n, m)
        with self.lock:
            if key in self.cache:
                return self.cache[key]
        t0 = time.perf_counter()
        if self.cache and self.deadline is not None and t0 > self.deadline:
            raise _OutOfTime
        if self.cache and self.f.work_limit is not None and self._solves() >= self.f.work_limit:
            raise _OutOfTime
        trial = self.solve(n, m)
        att = trial.att
        att.seconds = time.perf_counter() - t0
        with self.lock:
            self.cache[key] = trial
        if self.f.callback is not None:
            self.f.callback(att)
        return trial

    def solve(self, n: Sizes, m: int) -> _Trial:
        """One QP P(n, m) and its verification, uncached (:meth:`test` caches it)."""
        try:
            att, rats = self.solve_system(n, m)
        except InputError as exc:
            att = Attempt(sum(n), m, "failed", messages=[str(exc)])
            return _Trial(n, m, att, None, None)
        vers = None if rats is None else self.verify_channels(rats)
        return _Trial(n, m, att, rats, vers)

    def solve_system(self, n: Sizes, m: int) -> tuple[Attempt, list[RationalFunction] | None]:
        """The attempt at P(n, m) and its rationals (None without a solution); an
        InputError when its bases cannot be built."""
        q0 = shared_sk_denominator(self.space, self.seg, n, m)
        system = self.system(n, m, q0)
        # pole-free like a single channel: q > 0 rows where the shared q is not
        att, _ = solve_pole_free(system, sum(n), m, cuts=self.cuts,
                                 solver=self.f.solver, cross_check=self.f.cross_check)
        att.formulation = "arnoldi-shared"
        c = att.c if att.c is not None else att.raw_c
        return att, None if c is None else self.shared_system(system).rationals(c)

    def system(self, n: Sizes, m: int, q0: Array | None) -> Any:
        """The row system of P(n, m) (a :class:`SharedSystem`; a subclass may add rows)."""
        return SharedSystem(self.space, self.seg, n, m, q0)

    @staticmethod
    def shared_system(system: Any) -> SharedSystem:
        """The :class:`SharedSystem` under rows a subclass appended."""
        while not isinstance(system, SharedSystem):
            system = system.base
        return system

    def verify_channels(self, rats: list[RationalFunction]) -> list[Verification]:
        """Each channel's verification (a subclass may check more)."""
        return [verify(r, self.seg, channel=j) for j, r in enumerate(rats)]

    def ok(self, n: Sizes, m: int) -> bool:
        return self.test(n, m).ok

    def _smallest(self, c: int, big: int, hi: int, m: int) -> int:
        """Smallest n_c with the other channels at ``big`` (hi known feasible)."""
        lo = 0  # known infeasible (0 coefficients)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            n = tuple(mid if j == c else big for j in range(self.K))
            if self.ok(n, m):
                hi = mid
            else:
                lo = mid
        return hi

    def _map(self, fn, items):
        jobs = self.f.jobs or 1
        if jobs > 1 and len(items) > 1:
            with ThreadPoolExecutor(min(jobs, len(items))) as ex:
                return list(ex.map(fn, items))
        return [fn(i) for i in items]

    def run(self) -> SharedFit:
        t0 = time.perf_counter()
        self.best: tuple[Sizes, int] | None = None
        self.bounds: dict[int, int] = {}
        self.big = min(8, self.cap)
        try:
            self._walk()
        except _OutOfTime:
            # the smallest verified trial so far (each one is a verified fit)
            good = [k for k, t in self.cache.items() if t.ok]
            best = min(good, key=lambda k: (sum(k[0]) + k[1], k[1])) if good else None
            out = self._result(best, self.bounds, self.big, time.perf_counter() - t0)
            return self._timed_out(out)
        return self._result(self.best, self.bounds, self.big, time.perf_counter() - t0)

    def _solves(self) -> int:
        with self.lock:
            return sum(t.att.qp_solves for t in self.cache.values())

    def _timed_out(self, out: SharedFit) -> SharedFit:
        """The result when the time budget ran out: the smallest verified fit so far,
        not proven minimal, else no fit without any claim of impossibility."""
        if self.f.work_limit is not None and self._solves() >= self.f.work_limit:
            note = (f"work limit of {self.f.work_limit} QP solves reached after "
                    f"{len(self.cache)} QP test(s)")
        else:
            limit = float(self.f.time_limit or 0.0)
            note = f"time limit of {limit:g} s reached after {len(self.cache)} QP test(s)"
        if out.success:
            results = [dataclasses.replace(r, time_limited=True,
                                           message=f"{r.message}; {note}: the total may not "
                                                   "be minimal") for r in out.results]
        else:
            results = [dataclasses.replace(
                r, time_limited=True, status=1, success=False,
                message=f"{STATUS_MESSAGES[1]}: {note}; no shared-denominator fit verified "
                        "(not a proof that none exists; raise the limit)")
                for r in out.results]
        return dataclasses.replace(out, results=results, proven=False)

    def _walk(self) -> None:
        K = self.K
        best_total = 10**9
        bounds = self.bounds
        big = self.big
        prev: list[int] | None = None
        ms = [self.f.m] if self.f.m is not None else range(1, self.f.max_m + 1)
        for m in ms:
            if m + K >= best_total or m > self.seg.n_points:
                break
            # A large N that fits at this m (kept across m: monotone in m).
            while not self.ok((big,) * K, m) and big < self.cap:
                big = self.big = min(2 * big, self.cap)
                prev = None
            if not self.ok((big,) * K, m):
                continue
            tops = prev or [big] * K
            stars = self._map(
                lambda c, m=m, tops=tops, big=big: self._smallest(c, big, tops[c], m),
                list(range(K)),
            )
            prev = list(stars)
            bound = sum(stars) + m
            bounds[m] = bound
            if bound >= best_total:
                continue
            n = tuple(stars)
            if not self.ok(n, m):
                n = self._repair(n, m, big)
            n = self._shrink(n, m)
            if sum(n) + m < best_total:
                self.best, best_total = (n, m), sum(n) + m

    def _repair(self, n: Sizes, m: int, big: int) -> Sizes:
        """The lower-bound vector ``n`` is infeasible: raise one channel, the one
        needing the smallest raise (bisection each, others kept); if no single
        channel suffices, raise channels one step at a time until feasible."""
        cands = []
        for c in range(self.K):
            top = tuple(big if j == c else v for j, v in enumerate(n))
            if n[c] >= big or not self.ok(top, m):
                continue
            lo, hi = n[c], big
            while hi - lo > 1:
                mid = (lo + hi) // 2
                trial = tuple(mid if j == c else v for j, v in enumerate(n))
                if self.ok(trial, m):
                    hi = mid
                else:
                    lo = mid
            cands.append(tuple(hi if j == c else v for j, v in enumerate(n)))
        if cands:
            return min(cands, key=sum)
        cur = list(n)
        while True:
            cands = [tuple(v + (j == c) for j, v in enumerate(cur))
                     for c in range(self.K) if cur[c] < big]
            if not cands:
                return (big,) * self.K
            trials = self._map(lambda s: (s, self.ok(s, m)), cands)
            hit = next((s for s, good in trials if good), None)
            if hit is not None:
                return hit
            # None suffices alone: raise the channel whose QP came closest.
            cur = list(cands[0]) if len(cands) == 1 else [min(v + 1, big) for v in cur]
            if self.ok(tuple(cur), m):
                return tuple(cur)

    def _shrink(self, n: Sizes, m: int) -> Sizes:
        cur = list(n)
        changed = True
        while changed:
            changed = False
            for c in range(self.K):
                if cur[c] > 1:
                    trial = tuple(v - (j == c) for j, v in enumerate(cur))
                    if self.ok(trial, m):
                        cur = list(trial)
                        changed = True
        return tuple(cur)

    def _result(self, best: tuple[Sizes, int] | None, bounds: dict[int, int], big: int,
                secs: float) -> SharedFit:
        qp = sum(t.att.qp_solves for t in self.cache.values())
        history = [{"n": list(t.n), "m": t.m, "status": t.att.status, "verified": t.ok,
                    "decided_by": t.att.decided_by, "pole_cuts": t.att.pole_cuts,
                    "seconds": round(t.att.seconds, 6)}
                   for t in self.cache.values()]
        disagreements = tuple(
            f"({list(t.n)},{t.m}): {t.att.disagreement}" for t in self.cache.values()
            if t.att.disagreement
        )
        if best is None:
            # Nothing verified: report the largest attempt, per channel.
            trial = max(self.cache.values(), key=lambda t: (sum(t.n) + t.m, t.m))
            results = [self._fit_result(trial, j, qp, secs, disagreements, 1) for j in
                       range(self.K)]
            return SharedFit(results, trial.n, trial.m, sum(trial.n) + trial.m, False, bounds,
                             big, qp, secs, history)
        n, m = best
        trial = self.cache[(n, m)]
        total = sum(n) + m
        proven = bounds.get(m) == total and all(
            b >= total for mm, b in bounds.items() if mm < m
        )
        results = [self._fit_result(trial, j, qp, secs, disagreements, 0) for j in range(self.K)]
        return SharedFit(results, n, m, total, proven, bounds, big, qp, secs, history)

    def _fit_result(self, trial: _Trial, j: int, qp: int, secs: float,
                    disagreements: tuple[str, ...], status: int) -> FitResult:
        att = trial.att
        rf = trial.rationals[j] if trial.rationals else None
        ver = trial.verifications[j] if trial.verifications else None
        if status == 0:
            msg = STATUS_MESSAGES[0] + " (shared denominator)"
        else:
            msg = (f"{STATUS_MESSAGES[1]}: no shared-denominator fit with n_c <= "
                   f"{self.cap}, m <= {self.f.max_m} was verified")
        return FitResult(
            success=status == 0 and ver is not None and ver.verified, status=status,
            message=msg, n=trial.n[j], m=trial.m, basis=self.space.family.name,
            index_set=self.space.index_set, rational=rf, verification=ver, delta=att.delta,
            sigma_min=att.sigma_min, sigma_max=att.sigma_max,
            active_set_size=att.active_set_size, qp_solves=qp, seconds=secs,
            solver=self.f.solver, decided_by=att.decided_by, solver_status=att.solver_status,
            channel=self.seg.names[j], history=(), disagreements=disagreements,
        )

