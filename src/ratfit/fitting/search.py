"""Search for the rational function with the fewest coefficients n + m.

Feasibility of P(n, m) is upward closed: a solution at (n, m) gives one at
(n + 1, m) and (n, m + 1) (pad with a zero coefficient). So the feasible splits
form a staircase, and the minimal total is found by walking it:

1. Balanced probe: totals T = min_total, min_total + 1, ... with the split
   (ceil(T/2), floor(T/2)) until one is feasible; that bounds the answer. Each
   infeasible probe (k, l) also rules out every (n, m) with n <= k, m <= l.
2. Staircase: with ``best`` the smallest feasible total so far, visit
   m = 1, 2, ... and test (best - 1 - m, m); when feasible, ``best`` drops by
   one and the same m is tried again, otherwise m grows. Every infeasible
   answer rules out the whole column below it, so each test is at total
   best - 1 and the walk costs O(best) QPs instead of ALTA's O(best^2).
   Column m below the best split's m is tested at the best total first
   (best - m, m): the min-m rule needs that split anyway, and when it is
   infeasible it rules out (best - 1 - m, m) as well.

Split rule: among feasible splits of the minimal total, the one with the
fewest denominator coefficients m (the closest to a polynomial: fewest
candidate poles, cheapest to evaluate); that is the default
``split_rule="min-m"``. After the walk every split of the minimal total with
a smaller m that no proved infeasibility rules out is tested, so a split the
walk stepped past (a solve that failed numerically) is not missed.

Pole-freedom is part of feasibility: a QP solution whose q changes sign in
the domain gets q > 0 rows there and is solved again
(:func:`ratfit.core.qp.solve_pole_free`), so "infeasible" means "no pole-free
solution", which is upward closed like plain feasibility.

``split_rule="error"`` tests every split of the minimal total and keeps the
one whose values are most central in their segments (smallest
max |r - y| / half-width).

The engine (:class:`SearchEngine`) takes the checked options
(:class:`~ratfit.core.options.FitOptions`) and its collaborators
(:class:`SearchParts`): a system factory (which row systems to solve), a
verifier (what counts as success) and the pole guard (where q > 0 is
generated). Subclasses of :class:`RationalFitter` supply theirs through the one
public hook :meth:`RationalFitter.search_parts`, and their own options through
``options_type`` (a :class:`~ratfit.core.options.FitOptions` subclass).

Independent QPs (speculative tests of the next columns, all splits of one
total) run in a thread pool: the solvers release the GIL. Large multi-channel
data (from :data:`CHANNEL_THREADS_POINTS` samples) is searched a channel per
thread instead, each channel's splits one at a time: speculative splits there
cost more than they save (MERL size, 3 channels, 2 threads: 85 s split-parallel,
59 s with one thread). So is a search of one fixed (n, m), which has no other
split to test.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import ClassVar, Protocol, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.bases import PolynomialSpace
from ratfit.core.estimator import Regressor
from ratfit.core.options import (  # noqa: F401  (re-exported: where they used to live)
    DEFAULT_MAX_TOTAL,
    DEFAULT_TIME_LIMIT,
    DEFAULT_WORK_LIMIT,
    FIT_OPTIONS,
    FORMULATIONS,
    SEGMENT_OPTIONS,
    SPLIT_RULES,
    STRATEGIES,
    FitOptions,
    check_fit_params,
)
from ratfit.core.qp import (
    ArnoldiSystem,
    Attempt,
    ConstraintSystem,
    certified_infeasible,
    sk_denominator,
    solve_pole_free,
)
from ratfit.core.rational import RationalFunction
from ratfit.core.results import STATUS_MESSAGES, FitResult
from ratfit.core.scaling import scale_segments, unscale_result, value_scales
from ratfit.core.segments import Segments
from ratfit.core.systems import RowSystem, denominator_cuts, domain_grid
from ratfit.core.threads import one_blas_thread
from ratfit.core.verify import Verification, verify
from ratfit.core.work import WorkBudget
from ratfit.errors import InputError

__all__ = [
    "ArnoldiSystems", "RationalFitter", "SearchEngine", "SearchParts", "SeedSystems",
    "SystemFactory", "fit", "verify_channel",
]

Array = NDArray[np.float64]



class RationalFitter(Regressor):
    """Fit r = p / q inside vertical segments with the fewest coefficients.

    A scikit-learn regressor in shape: ``fit(X, y)`` builds the segments from
    ``dt`` and/or ``abs_width``, ``predict(X)`` evaluates the fit and ``score``
    is R^2, so ``cross_val_score``, ``clone``, grid searches and pipelines work
    (scikit-learn itself is not needed). ``fit(segments)`` takes prepared
    :class:`~ratfit.core.segments.Segments` (bounds of one's own) instead.
    Every parameter is stored unchanged and checked in :meth:`fit`.

    Parameters
    ----------
    dt : float, optional
        Relative half-width of the segments ``fit(X, y)`` builds:
        [(1 - dt) y, (1 + dt) y].
    abs_width : float, optional
        Absolute half-width [y - w, y + w] (with ``dt`` each segment is the
        union of both). ``fit(X, y)`` needs one of the two; ``fit(segments)``
        needs neither (its segments carry their bounds).
    basis : {"legendre", "chebyshev", "monomial"}, default "legendre"
        Polynomial family of p and q ("monomial": powers of the scaled
        variable, the seed's "centered monomials").
    index_set : {"total", "tensor"}, default "total"
        n-D graded order of the basis functions (the same thing in 1-D).
    domain : array-like of shape (d, 2), optional
        Bounds mapped to [-1, 1]^d; default: the data bounds.
    n, m : int, optional
        Fix the split (coefficient counts, not degrees): one QP, no search.
        Give both or neither.
    total : int, optional
        Try every split of this one total.
    min_total, max_total : int, default 2 and None (= 100)
        Search range of n + m.
    strategy : {"staircase", "exhaustive"}, default "staircase"
        "exhaustive" tests every split of every total, ascending (ALTA's search).
    split_rule : {"min-m", "error"}, default "min-m"
        Which feasible split of the minimal total to keep (see the module notes).
    solver : str, default "quadprog"
        QP solver name (``ratfit.core.solvers.available_solvers()``).
    cross_check : {"orth", "lp", "none"}, default "orth"
        How a solver's "infeasible" is checked before it is believed.
    active_set : bool, optional
        None: automatic (large data), True or False.
    jobs : int, optional
        Threads for independent QPs; default all cores, used once QPs take
        long enough for threads to pay off (> 20 ms each on average).
    callback : callable, optional
        Called with each :class:`~ratfit.core.qp.Attempt` (progress).
    formulation : {"auto", "arnoldi", "basis"}, default "auto"
        How P(n, m) is written for the solver: "arnoldi" (p and q in bases
        orthonormal on the data, weighted by a denominator guess; finds the
        smallest fits), "basis" (the seed's matrix), "auto" (arnoldi in 1-D
        and for the total index set in n-D).
    variable : {"auto", "x", "log"}, default "auto"
        The variable p and q are polynomials in. "log": log x (1-D, positive
        x; recorded in the fit, so evaluation and files stay correct; no
        monomial form or code export). "auto": a search on positive 1-D data
        spanning more than three decades (a tenth of the points more than three
        decades below the largest x) fits in log x first, then in x below
        that total, and keeps the smaller verified fit (sqrt on 1e-15..1 needs
        10 coefficients in log x at 10 %, and has no fit up to 100 in x);
        otherwise x.
    time_limit : float, optional
        Wall-clock seconds per channel; when they run out the search stops
        between splits and says so (status 1, or the smallest verified fit so
        far flagged as not proven minimal). Default None: no clock, so the answer
        does not depend on the machine's load.
    work_limit : int, optional, default 4000
        QP solves per channel (counted between splits, in the walk's order);
        when they run out the search stops like at the time limit. A count, so
        the same data and options give the same (n, m) and coefficients on any
        load and with any ``jobs``. None: no limit.
    warm_start : bool, default True
        Carry the binding rows of one split into the next split's active set.
        Only the speed depends on it (the benchmarks and tests switch it off to
        compare).

    Attributes
    ----------
    results_ : list of FitResult
        One verified-or-not result per channel of the fitted segments.
    result_ : FitResult
        The result of the only channel (an error when several were fitted).
    rational_ : RationalFunction or None
        ``result_.rational``.
    success_ : bool
        Every channel has a verified fit.
    segments_ : Segments
        The fitted segments.
    space_ : PolynomialSpace
        The basis, index set and domain of the fit.
    options_ : FitOptions
        The checked options the search ran with (an ``options_type``).

    Examples
    --------
    >>> import numpy as np
    >>> from ratfit import RationalFitter, Segments
    >>> x = np.linspace(-1, 1, 50)
    >>> f = RationalFitter(dt=0.01).fit(x[:, None], 1 / (2 + x))
    >>> f.success_, f.result_.verification.max_violation, round(f.score(x, 1 / (2 + x)), 4)
    (True, 0.0, 1.0)
    >>> f.predict([[0.5]]).round(2).tolist(), round(f.rational_(0.5), 2)   # 1 / 2.5 +- 1 %
    ([0.4], 0.4)
    >>> f = RationalFitter().fit(Segments.from_relative(x, 1 / (2 + x), 0.01))
    >>> f.result_.success
    True
    """

    #: The class of this estimator's checked options: every constructor parameter
    #: is one of its fields (subclasses with options of their own extend it).
    options_type: ClassVar[type[FitOptions]] = FitOptions

    def __init__(
        self,
        *,
        dt: float | None = None,
        abs_width: float | None = None,
        basis: str = "legendre",
        index_set: str = "total",
        domain: ArrayLike | None = None,
        n: int | None = None,
        m: int | None = None,
        total: int | None = None,
        min_total: int = 2,
        max_total: int | None = None,
        strategy: str = "staircase",
        split_rule: str = "min-m",
        solver: str = "quadprog",
        cross_check: str = "orth",
        active_set: bool | None = None,
        jobs: int | None = None,
        callback: Callable[[Attempt], None] | None = None,
        formulation: str = "auto",
        time_limit: float | None = DEFAULT_TIME_LIMIT,
        work_limit: int | None = DEFAULT_WORK_LIMIT,
        variable: str = "auto",
        warm_start: bool = True,
    ) -> None:
        self.dt = dt
        self.abs_width = abs_width
        self.basis = basis
        self.index_set = index_set
        self.domain = domain
        self.n = n
        self.m = m
        self.total = total
        self.min_total = min_total
        self.max_total = max_total
        self.strategy = strategy
        self.split_rule = split_rule
        self.solver = solver
        self.cross_check = cross_check
        self.active_set = active_set
        self.jobs = jobs
        self.callback = callback
        self.formulation = formulation
        self.time_limit = time_limit
        self.work_limit = work_limit
        self.variable = variable
        self.warm_start = warm_start

    # -- validation -------------------------------------------------------------------
    @classmethod
    def from_options(cls, options: FitOptions) -> Self:
        """The estimator of checked ``options`` (an ``options_type``)."""
        if type(options) is not cls.options_type:
            raise TypeError(f"{cls.__name__} takes {cls.options_type.__name__}, "
                            f"got {type(options).__name__}")
        return cls(**options.params())

    def options(self) -> FitOptions:
        """The search's constructor parameters as checked options (InputError when one
        is bad); the segment widths (``dt``, ``abs_width``) are not among them."""
        params = self.get_params(deep=False)
        for name in SEGMENT_OPTIONS:
            SEGMENT_OPTIONS[name].check(params.pop(name))
        return self.options_type.from_params(params)

    def prepare(self, seg: Segments) -> PolynomialSpace:
        """Check the options, alone and against ``seg``, and keep them (``options_``);
        returns the polynomial space of a fit of ``seg``. :meth:`fit` starts here;
        callers that drive a :class:`SearchEngine` themselves do too."""
        self.options_ = self.options()
        return self._validate(seg, self.options_)

    def _validate(self, seg: Segments, options: FitOptions | None = None) -> PolynomialSpace:
        """The polynomial space of a fit of ``seg``, after every check of the options
        against the data (one-line InputError)."""
        opts = self.options() if options is None else options
        p = opts.params()
        if p["formulation"] == "arnoldi" and seg.dim > 1 and p["index_set"] != "total":
            raise InputError("formulation 'arnoldi' needs index_set='total' in n-D")
        if p["max_total"] is None and p["min_total"] > DEFAULT_MAX_TOTAL:
            raise InputError(
                f"min_total={p['min_total']} exceeds the default max_total "
                f"{DEFAULT_MAX_TOTAL}: give max_total too"
            )
        for name in ("n", "m"):
            v = p[name]
            if v is not None and v > seg.n_points:
                raise InputError(
                    f"{name}={v} is more coefficients than the {seg.n_points} data point(s) "
                    "can determine"
                )
        if p["jobs"] is not None and p["jobs"] > MAX_JOBS:
            raise InputError(f"jobs={p['jobs']} threads is beyond reason (at most {MAX_JOBS})")
        most = 2 * seg.n_points  # n and m are capped at the number of distinct points
        for name in ("total", "min_total"):
            v = p[name]
            if v is not None and v > max(most, 2):
                raise InputError(
                    f"{name}={v} is more coefficients than {seg.n_points} point(s) can "
                    f"determine (n and m are each at most the number of points)"
                )
        zero = seg.hi == seg.lo
        if zero.any():
            i, j = (int(v) for v in np.argwhere(zero)[0])
            raise InputError(
                f"{int(zero.sum())} segment(s) have zero width (first: row {i}, channel "
                f"{seg.names[j]}, lo = hi = {float(seg.lo[i, j])!r}); a rational cannot be "
                "verified to hit a value exactly in floating point: give the segments an "
                "absolute floor (CLI: add --abs-width W next to --dt; each segment takes "
                "the larger)"
            )
        domain = seg.bounds() if opts.domain is None else np.asarray(opts.domain, float)
        domain = np.asarray(domain, dtype=float).reshape(-1, 2)
        if domain.shape[0] != seg.dim:
            raise InputError(f"domain has {domain.shape[0]} dimension(s), data has {seg.dim}")
        if seg.n_points == 1 and opts.domain is None:
            raise InputError("a single data point has no domain: give domain bounds")
        outside = (seg.x < domain[:, 0]) | (seg.x > domain[:, 1])
        if outside.any():
            i = int(np.argwhere(outside)[0][0])
            raise InputError(f"point {i} ({seg.x[i].tolist()}) lies outside the given domain")
        from ratfit.core.columns import axis_degree_caps

        # n-D: no degree above what an axis's distinct values can carry (grids).
        caps = axis_degree_caps(seg.x) if seg.dim > 1 else None
        return PolynomialSpace(opts.basis, domain, opts.index_set, caps,
                               variable="log" if opts.variable == "log" else "x")

    def _log_space(self, space: PolynomialSpace, seg: Segments) -> PolynomialSpace | None:
        """The log-x space that variable="auto" also tries, or None."""
        dom = space.domain
        o = self.options_
        plain = type(self).search_parts is RationalFitter.search_parts
        if (o.variable != "auto" or not plain or seg.dim != 1 or o.n is not None
                or o.total is not None or dom[0, 0] <= 0):
            return None
        # Many decades means many points there: a tenth of them more than three decades
        # below the largest x (one point near 0 on a linear grid does not count).
        if float(np.quantile(seg.x[:, 0], 0.1)) * 1e3 > float(dom[0, 1]):
            return None
        return PolynomialSpace(space.family.name, dom, space.index_set, space.max_degree,
                               variable="log")

    def _fit_either(self, space: PolynomialSpace, log_space: PolynomialSpace | None,
                    seg: Segments, j: int, alone: bool = False) -> FitResult:
        """The channel's fit in x, or with ``log_space`` the smaller of log x and x.
        ``alone``: the channel runs beside others (see :meth:`_fit_channel`)."""
        if log_space is None:
            return self._fit_channel(space, seg, j, alone=alone)
        lg = self._fit_channel(log_space, seg, j, alone=alone)
        if not lg.success:
            return self._fit_channel(space, seg, j, spent=lg.seconds, solves=lg.qp_solves,
                                     alone=alone)
        if lg.n + lg.m <= self.options_.min_total:
            return lg
        xs = self._fit_channel(space, seg, j, max_total=lg.n + lg.m - 1, spent=lg.seconds,
                               solves=lg.qp_solves, alone=alone)
        return xs if xs.success else lg

    def _channel_threads(self, seg: Segments) -> int:
        """How many channels are searched at once: one per thread (up to ``jobs``)
        for large multi-channel data and for a fixed (n, m), whose search is one split
        with nothing to test beside it; else 1 (channels in turn, splits in threads)."""
        o = self.options_
        jobs = int(o.jobs or os.cpu_count() or 1)
        fixed = o.n is not None and o.m is not None
        if jobs <= 1 or seg.n_channels <= 1 or (seg.n_points < CHANNEL_THREADS_POINTS
                                                and not fixed):
            return 1
        return min(jobs, seg.n_channels)

    def _fit_side_by_side(self, space: PolynomialSpace, log_space: PolynomialSpace | None,
                          seg: Segments, threads: int,
                          finished: Callable[[int, FitResult], FitResult]) -> list[FitResult]:
        """Every channel's fit, ``threads`` tasks at a time: each channel's search, then
        ``finished(j, result)`` (a BRDF channel's polish and proof). A search that ends
        frees its thread for the next channel's search first; the finished searches'
        follow-ups take the threads the searches leave (the last channel's search does
        not wait for the first channels' polish). Each channel starts its search at
        ``min_total`` (no hint from another channel) and keeps what it learns to itself
        (a BRDF fit's validity points are kept per channel): its answer does not
        depend on timing. Ctrl-C stops every channel at its next split."""
        self._cancel = threading.Event()
        alone = threads > 1
        waiting = list(range(seg.n_channels))  # channels whose search has not started
        results: dict[int, FitResult] = {}
        ex = ThreadPoolExecutor(threads)
        tasks: dict[Future[FitResult], tuple[str, int]] = {}

        def start_search() -> None:
            j = waiting.pop(0)
            tasks[ex.submit(self._fit_either, space, log_space, seg, j, alone=alone)] = (
                "search", j)

        try:
            for _ in range(min(threads, len(waiting))):
                start_search()
            while tasks:
                done, _ = wait(tasks, return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=lambda f: tasks[f][1]):  # in channel order
                    kind, j = tasks.pop(fut)
                    res = fut.result()
                    if kind == "finish":
                        results[j] = res
                        continue
                    if waiting:  # queued before the follow-up: it runs first
                        start_search()
                    tasks[ex.submit(finished, j, res)] = ("finish", j)
        except BaseException:
            # the threads still running see it at their next split (and keep their
            # thread-local state until then); the fitter is not reused after this
            self._cancel.set()
            raise
        finally:
            ex.shutdown(wait=False, cancel_futures=True)
        del self._cancel  # not picklable; a later fit starts afresh
        return [results[j] for j in range(seg.n_channels)]

    # -- collaborators of the search engine (subclasses: monotone CDFs, BRDFs) ---------
    def search_parts(self, space: PolynomialSpace, seg: Segments) -> SearchParts:
        """The engine's collaborators for this data: which systems, which verifier.

        The one extension point of a fitter: a subclass (monotone CDFs, BRDFs)
        returns its own systems, verifier, pole guard or repair here; the engine
        gets them and the checked options (``options_``), never the fitter.
        """
        form = self.options_.formulation
        if form == "auto":
            form = "arnoldi" if seg.dim == 1 or space.index_set == "total" else "basis"
        systems: SystemFactory = ArnoldiSystems() if form == "arnoldi" else SeedSystems()
        return SearchParts(systems=systems, verifier=verify_channel)

    # -- fitting -----------------------------------------------------------------------
    def fit(self, X: ArrayLike | Segments, y: ArrayLike | None = None) -> Self:
        """Fit every channel; returns self.

        Parameters
        ----------
        X : array-like of shape (N,) or (N, d), or Segments
            Points (with ``y``), or prepared segments (without).
        y : array-like of shape (N,) or (N, k), optional
            Values; the segments are built around them from ``dt`` / ``abs_width``.
        """
        return self._fit_segments(self.segments_of(X, y))

    def _fit_segments(self, segments: Segments) -> Self:
        """Fit every channel of ``segments`` (subclasses extend this, not :meth:`fit`)."""
        space = self.prepare(segments)
        self.space_ = space
        self.segments_ = segments
        # Values beyond ~1e150 or below ~1e-150 overflow the QP's squares: such
        # channels are fitted scaled by a power of two (exact) and scaled back.
        factors = value_scales(segments)
        work = scale_segments(segments, factors)
        log_space = self._log_space(space, segments)
        self.__dict__.pop("_cancel", None)  # left by an interrupted side-by-side fit
        threads = self._channel_threads(work)
        verifier = self.search_parts(space, segments).verifier

        def finished(j: int, res: FitResult) -> FitResult:
            res = unscale_result(res, segments, j, float(factors[j]), verifier)
            return self._finish_channel(res, segments, j)

        with one_blas_thread():  # the search's own threads; BLAS pools only spin
            if segments.n_channels > 1:
                # Every channel with its own state, in threads or one after another:
                # its answer depends neither on --jobs nor on the other channels.
                results = self._fit_side_by_side(space, log_space, work, threads,
                                                 finished)
            else:
                results = [finished(0, self._fit_either(space, log_space, work, 0))]
        self.results_ = results
        return self

    def _finish_channel(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """What follows channel ``j``'s search (``seg``: the data's own segments), in
        the channel's thread while other channels still search: nothing here;
        subclasses polish and prove."""
        return res

    def predict(self, X: ArrayLike) -> Array:
        """Values of the fit at points ``X`` (N, d) or (N,) in 1-D: shape (N,) for
        one channel, (N, k) for k. Every channel needs a verified fit
        (``success_``); a pole-free verified fit is finite on its domain."""
        res = self._fitted().results_
        fits = [r.rational for r in res if r.success]
        missing = [r.channel for r in res if not r.success]
        if missing or None in fits:
            raise InputError(
                f"no verified fit for channel(s) {', '.join(missing)} "
                f"({res[0].message if len(res) == 1 else 'see results_'}): nothing to predict "
                "with; widen the segments (dt, abs_width) or raise max_total")
        cols = [np.asarray(rf(X), dtype=float).reshape(-1) for rf in fits if rf is not None]
        return cols[0] if len(cols) == 1 else np.stack(cols, axis=1)

    @property
    def result_(self) -> FitResult:
        """The fit of the only channel; with several channels use ``results_[j]``."""
        return self._single().results_[0]

    @property
    def rational_(self) -> RationalFunction | None:
        """The fitted rational of the only channel (None when no fit verified)."""
        return self._single().results_[0].rational

    @property
    def success_(self) -> bool:
        """Whether every channel has a verified fit."""
        return all(r.success for r in self._fitted().results_)

    def _fitted(self) -> RationalFitter:
        if not hasattr(self, "results_"):
            raise AttributeError(
                f"this {type(self).__name__} is not fitted yet: call fit() first"
            )
        return self

    def _single(self) -> RationalFitter:
        res = self._fitted().results_
        if len(res) != 1:
            names = ", ".join(r.channel for r in res)
            raise InputError(
                f"{type(self).__name__} fitted {len(res)} channels ({names}): result_ and "
                "rational_ name one channel; use results_[j] (one FitResult per channel)"
            )
        return self

    def _fit_channel(self, space: PolynomialSpace, seg: Segments, j: int,
                     max_total: int | None = None, spent: float = 0.0, solves: int = 0,
                     alone: bool = False) -> FitResult:
        """``alone``: the channel runs in a thread beside others: its splits one at
        a time. ``spent`` seconds and ``solves`` QP solves were used by a search of
        this channel in another variable."""
        t0 = time.perf_counter()
        o = self.options_
        clash = disjoint_repeats(seg, j)
        if clash is not None:  # no function at all: nothing to search
            return no_function_fits(clash, space, seg, j, self.options_.solver,
                                    time.perf_counter() - t0)
        deadline = None
        if o.time_limit is not None:
            # ``spent``: seconds this channel already used in another variable; the
            # second search still gets a quarter of the budget.
            deadline = t0 + max(o.time_limit - spent, 0.25 * o.time_limit)
        budget = None
        if o.work_limit is not None:  # the second search still gets a quarter
            budget = max(o.work_limit - solves, o.work_limit // 4)
        run = SearchEngine(o, self.search_parts(space, seg), space, seg, j,
                           jobs=1 if alone else None, deadline=deadline,
                           cancel=getattr(self, "_cancel", None), budget=budget)
        if o.n is not None and o.m is not None:
            lo_t = hi_t = o.n + o.m
        elif o.total is not None:
            lo_t = hi_t = o.total
        else:
            lo_t = o.min_total
            hi_t = int(max_total or o.max_total or DEFAULT_MAX_TOTAL)
        try:
            if o.n is not None and o.m is not None:
                best = run.fixed(o.n, o.m)
            elif o.total is not None:
                best = run.all_splits(lo_t)
            else:
                # every channel's walk starts at min_total: a start taken from
                # another channel's answer made the answer depend on channel order
                best = run.exhaustive(lo_t, hi_t) if o.strategy == "exhaustive" else (
                    run.staircase(lo_t, hi_t))
        except _OutOfTime:
            return run.timed_out(lo_t, hi_t, time.perf_counter() - t0)
        return run.result(best, lo_t, hi_t, time.perf_counter() - t0)


class SystemFactory(Protocol):
    """Makes the row systems the engine solves (see :class:`ratfit.core.systems.RowSystem`)."""

    #: True when ``split`` builds a system per split (the channel's system is then
    #: only the fallback and is not prepared before threads).
    per_split: bool

    def channel(self, space: PolynomialSpace, seg: Segments, j: int) -> RowSystem:
        """The system shared by every split of channel j (prepared to the largest size)."""
        ...

    def split(self, space: PolynomialSpace, seg: Segments, j: int, n: int, m: int,
              like: RowSystem | None = None) -> RowSystem | None:
        """A system for split (n, m) only, or None: use the channel's."""
        ...


class SeedSystems:
    """The seed's matrix in the basis family, one system per channel."""

    per_split = False

    def channel(self, space: PolynomialSpace, seg: Segments, j: int) -> RowSystem:
        return ConstraintSystem(space, seg, j)

    def split(self, space: PolynomialSpace, seg: Segments, j: int, n: int, m: int,
              like: RowSystem | None = None) -> RowSystem | None:
        return None


class ArnoldiSystems(SeedSystems):
    """Per split, the weighted Arnoldi form (denominator guess from Sanathanan-Koerner);
    the seed's matrix stays as the fallback when the weighted form fails."""

    per_split = True

    def split(self, space: PolynomialSpace, seg: Segments, j: int, n: int, m: int,
              like: RowSystem | None = None) -> RowSystem | None:
        try:
            q0 = sk_denominator(space, seg, j, n, m, like=like,  # type: ignore[arg-type]
                                as_function=True)
            return ArnoldiSystem(space, seg, j, n, m, q0, like=like)  # type: ignore[arg-type]
        except InputError:
            return None  # too few points for this many coefficients: the seed's form says so


def verify_channel(rf: RationalFunction, seg: Segments, j: int) -> Verification:
    """The default verifier: every segment of channel j met, no pole in the domain."""
    return verify(rf, seg, channel=j)


@dataclass(frozen=True)
class SearchParts:
    """What configures the search engine besides the fitter's options.

    ``systems`` builds the row systems, ``verifier`` decides success, and
    ``pole_free`` turns on q > 0 constraint generation
    (:func:`ratfit.core.qp.solve_pole_free`) on the domain grid, or on
    ``pole_grid`` (window points) when given. ``repair``, when given, gets a
    candidate that meets every segment but fails the verifier otherwise and may
    return another fit of the same (n, m) with its (passing) verification; its
    QP solves count against the :class:`~ratfit.core.work.WorkBudget` it is given
    (what is left of the search's ``work_limit``).
    ``constraint_points``, when given, counts the points the verifier has added
    to a channel's split systems' constraints (constraint generation); a split whose
    candidate was rejected while that count grew is solved again with them, up
    to ``regenerate`` times. ``active_set``, when not None, is the active-set
    mode the systems need in place of the options' (the monotone "max" form
    starts from an active set by construction).
    """

    systems: SystemFactory
    verifier: Callable[[RationalFunction, Segments, int], Verification]
    pole_free: bool = True
    pole_grid: Array | None = None
    repair: Callable[[RationalFunction, Segments, int, WorkBudget],
                     tuple[RationalFunction, Verification] | None] | None = None
    constraint_points: Callable[[int], int] | None = None
    regenerate: int = 2
    active_set: bool | None = None


def disjoint_repeats(seg: Segments, j: int) -> str | None:
    """Why no function meets channel j's segments, or None: two segments at one x
    (a repeated sample) that do not overlap. Sorting the rows is all it costs."""
    if seg.n_points < 2:
        return None
    order = np.lexsort(seg.x.T[::-1])
    xs = seg.x[order]
    new_group = np.r_[True, np.any(xs[1:] != xs[:-1], axis=1)]
    if new_group.all():
        return None
    starts = np.flatnonzero(new_group)
    lo, hi = seg.lo[order, j], seg.hi[order, j]
    top_lo = np.maximum.reduceat(lo, starts)
    low_hi = np.minimum.reduceat(hi, starts)
    gap = top_lo - low_hi
    if not np.any(gap > 0):
        return None
    g = int(np.argmax(gap))
    members = order[starts[g]:(starts[g + 1] if g + 1 < starts.size else order.size)]
    a = int(members[np.argmax(seg.lo[members, j])])
    b = int(members[np.argmin(seg.hi[members, j])])
    where = ", ".join(f"{v:.10g}" for v in seg.x[a])
    return (f"no function fits: at x = {where} the segments of rows {min(a, b)} and "
            f"{max(a, b)} do not overlap ([{seg.lo[a, j]:.10g}, {seg.hi[a, j]:.10g}] and "
            f"[{seg.lo[b, j]:.10g}, {seg.hi[b, j]:.10g}]; {int(np.count_nonzero(gap > 0))} "
            "repeated x value(s) with disjoint segments); widen the segments")


def no_function_fits(reason: str, space: PolynomialSpace, seg: Segments, j: int,
                     solver: str, seconds: float) -> FitResult:
    """Status 1 without a search: ``reason`` says why no function meets the segments."""
    nan = float("nan")
    return FitResult(
        success=False, status=1, message=reason, n=0, m=0,
        basis=space.family.name, index_set=space.index_set, rational=None,
        verification=None, delta=nan, sigma_min=nan, sigma_max=nan, active_set_size=0,
        qp_solves=0, seconds=seconds, solver=solver, decided_by="disjoint segments",
        channel=seg.names[j])


def fit(segments: Segments, **params) -> FitResult:
    """Functional shortcut: ``RationalFitter(**params).fit(segments).result_`` (one channel).

    Parameters
    ----------
    segments : Segments
        One channel (several: use :class:`RationalFitter` and ``results_``).
    **params
        :class:`RationalFitter` parameters.

    Returns
    -------
    FitResult

    Examples
    --------
    >>> import numpy as np
    >>> import ratfit
    >>> x = np.linspace(0, 1, 30)
    >>> r = ratfit.fit(ratfit.Segments.from_relative(x, 1 / (1 + x), 1e-3))
    >>> r.success, r.n, r.m
    (True, 1, 2)
    """
    return RationalFitter(**params).fit(segments).result_


MAX_JOBS = 1024
# From this many samples, several channels are searched side by side, one thread each.
CHANNEL_THREADS_POINTS = 65_536
# Rejected candidates are solved again with the verifier's new constraint points
# up to this many samples (see SearchEngine._run).
REGENERATE_POINTS = 65_536


def _is_int(v: object) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


Candidate = tuple[Attempt, RationalFunction | None, Verification | None]


def _rejected_between(ver: Verification | None) -> bool:
    """A candidate that met every segment (finite values) and was still not verified:
    the verifier's other checks (a BRDF negative or through a pole between the samples)
    rejected it."""
    return (ver is not None and not ver.verified and not ver.n_violations
            and bool(np.isfinite(ver.linf)))


class SearchEngine:
    """One channel's search: cached attempts and their verifications.

    ``options`` (solver, cross check, active set, jobs, callback, split rule, warm
    start, time limit) are the checked options of the fit; ``parts`` its
    collaborators (system factory, verifier, pole guard, repair). ``jobs``
    overrides ``options.jobs`` (1: a channel searched beside others);
    ``deadline`` is a ``time.perf_counter()`` value after which the search stops
    between splits; ``cancel``, once set, stops it at the next split (Ctrl-C in
    another channel's thread).
    """

    def __init__(self, options: FitOptions, parts: SearchParts, space: PolynomialSpace,
                 seg: Segments, j: int, *, jobs: int | None = None,
                 deadline: float | None = None, cancel: threading.Event | None = None,
                 budget: int | None = None):
        self.options = options
        self.space = space
        self.seg = seg
        self.channel = j
        self.parts = parts
        self.system = self.parts.systems.channel(space, seg, j)
        self.cache: dict[tuple[int, int], Candidate] = {}
        self.second_opinion = False
        self.warm: NDArray[np.int64] | None = None
        self.infeasible: list[tuple[int, int]] = []
        self.jobs = int(jobs or options.jobs or os.cpu_count() or 1)
        self.active_set = parts.active_set if parts.active_set is not None \
            else options.active_set
        self.deadline = deadline
        self.budget = budget  # QP solves (None: no limit), checked between batches
        self.cancel = cancel
        # distinct points, from the system's sort order (np.unique on rows is slow)
        order = getattr(self.system, "_order", None)
        srt = self.system.t[np.lexsort(self.system.t.T[::-1]) if order is None else order]
        self.cap = 1 + int(np.count_nonzero(np.any(srt[1:] != srt[:-1], axis=1)))
        grid = self.parts.pole_grid
        if grid is None:
            grid = domain_grid(space.dim, seg.n_points)
        self.cuts = (lambda rf: denominator_cuts(rf, grid)) if self.parts.pole_free else (
            lambda rf: np.zeros((0, space.dim)))
        # the seed's matrix screens splits before their weighted systems are built
        # (plain fits only: see _screen)
        self.screen = (type(self.parts.systems) is ArnoldiSystems
                       and type(self.system) is ConstraintSystem)

    # -- testing one split -----------------------------------------------------------
    def split_system(self, n: int, m: int) -> RowSystem | None:
        """The per-split system of (n, m), or None when the channel's system serves."""
        return self.parts.systems.split(self.space, self.seg, self.channel, n, m,
                                        like=self.system)

    def _solve(self, system: RowSystem, n: int, m: int, form: str,
               warm_rows: NDArray[np.int64] | None = None) -> Candidate:
        # the warm rows of the batch's start (test_many): every split of a batch gets
        # the same ones, whichever thread runs it and in whatever order; a split solved
        # again (``_run``) starts from its own last rows
        warm = None if not self.options.warm_start else (
            self.warm if warm_rows is None else warm_rows)
        att, system = solve_pole_free(
            system, n, m, cuts=self.cuts, solver=self.options.solver,
            cross_check=self.options.cross_check, active_set=self.active_set, warm_rows=warm,
            deadline=self.deadline,
        )
        att.formulation = form
        rf = ver = None
        if att.timed_out:
            return att, None, None
        c = att.c if att.c is not None else att.raw_c
        if c is not None:
            rf = system.to_rational(n, m, c)
            ver = self.parts.verifier(rf, self.seg, self.channel)
        return att, rf, ver

    def _repaired(self, out: Candidate) -> Candidate:
        """``out`` with a candidate that meets every segment but failed the
        verifier's other checks (a BRDF negative or through a pole between the
        samples) replaced by ``parts.repair``'s verified one, when there is one."""
        att, rf, ver = out
        if (self.parts.repair is None or rf is None or not _rejected_between(ver)
                or (self.deadline is not None and time.perf_counter() > self.deadline)):
            return out
        # the repair's QP solves count toward the search's budget, like its own
        work = WorkBudget(None if self.budget is None
                          else max(self.budget - self.solves() - att.qp_solves, 0))
        fixed = self.parts.repair(rf, self.seg, self.channel, work)
        att.qp_solves += work.spent
        return out if fixed is None else (att, *fixed)

    def _seed(self, n: int, m: int, warm_rows: NDArray[np.int64] | None = None) -> Candidate:
        self.system.prepare(n, m)
        return self._solve(self.system, n, m, "basis", warm_rows)

    def _run(self, n: int, m: int) -> Candidate:
        """Test (n, m); a QP-feasible candidate that the verifier rejected after
        adding constraint points (``parts.constraint_points`` grew: a BRDF fit
        negative or through a pole between samples) is solved again with them, up
        to ``parts.regenerate`` times: it then verifies, or the split becomes
        infeasible, which rules out every smaller split (a rejected candidate rules
        out nothing and makes the walk go on below its total)."""
        count = self.parts.constraint_points
        before = count(self.channel) if count is not None else 0
        out = self._run_once(n, m)
        # large data: a second solve is a second pass over every sample (the walk's
        # cost there is in the solves, not in the verifier)
        again_at_most = 0 if count is None or self.seg.n_points > REGENERATE_POINTS else (
            self.parts.regenerate)
        for _ in range(again_at_most):
            att, _, ver = out
            if att.timed_out or att.status != "feasible" or not _rejected_between(ver):
                break
            assert count is not None  # again_at_most is 0 without it
            now = count(self.channel)
            if now <= before or (self.deadline is not None
                                 and time.perf_counter() > self.deadline):
                break
            before = now
            # the data rows binding at the rejected candidate: the points added move
            # the solution little (satin_rosaline G at (113, 112): each solve again
            # climbed from 1 806 rows to 3 900 in 11 rounds)
            again = self._run_once(n, m, self._data_rows(att))
            again[0].qp_solves += att.qp_solves
            again[0].seconds += att.seconds
            again[0].messages = att.messages + [
                "solved again with the validity points its rejected candidate added"
            ] + again[0].messages
            out = again
        # The repair (a least-squares fit under the validity rows) comes after the
        # solves again: its fit is valid but weighted by the rejected candidate's
        # q, so it can be far worse (mystique B: RMSE 0.78) than the minimum-norm
        # solve with the validity points (0.059), which the polish then improves.
        return self._repaired(out)

    def _screen(self, n: int, m: int) -> Attempt | None:
        """The seed's matrix's verdict on (n, m) before the split's weighted system is
        built (:func:`~ratfit.core.qp.certified_infeasible`): most splits of a walk are
        infeasible, and a certificate on the channel's shared matrix costs a fraction
        of a denominator guess and two Arnoldi bases. Only for the default systems
        (subclasses' systems carry rows of their own) and with a cross check."""
        if (not self.screen or self.options.cross_check == "none" or self.second_opinion
                or (self.deadline is not None and time.perf_counter() > self.deadline)):
            return None
        return certified_infeasible(self.system, n, m, solver=self.options.solver,
                                    warm_rows=self.warm if self.options.warm_start else None)

    def _data_rows(self, att: Attempt) -> NDArray[np.int64] | None:
        """The data rows (both bounds of each sample: the same indices in every system
        of the channel) binding at ``att``'s solution, or None."""
        rows = att.active_rows
        return None if rows is None else rows[rows < 2 * self.seg.n_points]

    def _run_once(self, n: int, m: int,
                  warm_rows: NDArray[np.int64] | None = None) -> Candidate:
        pre = self._screen(n, m)
        if pre is not None and pre.status == "infeasible":
            return pre, None, None
        system = self.split_system(n, m)
        if system is None:
            out = self._seed(n, m, warm_rows)
        else:
            out = self._solve(system, n, m, "arnoldi", warm_rows)
        if pre is not None:  # its QP counts toward the work budget
            out[0].qp_solves += pre.qp_solves
            out[0].seconds += pre.seconds
        if system is None:
            return out
        att = out[0]
        if att.timed_out:
            return out
        ver = out[2]
        verified = ver is not None and ver.verified
        # A candidate that meets every segment, rejected by a verifier that adds
        # constraint points (a BRDF negative or through a pole between the samples):
        # the split's system carries the validity rows, the seed's has none, so its
        # candidate fails the same way (ilm_solo_m_68 R (113, 112): three seed solves of
        # 25-46 s, each candidate invalid); the split is solved again or repaired (_run).
        between = self.parts.constraint_points is not None and _rejected_between(ver)
        if att.status == "failed" or (self.second_opinion and not verified and not between):
            # A numerical failure in the weighted form (or, for a single split, any
            # answer but a verified fit): the seed's form decides when it can.
            retry = self._seed(n, m, warm_rows)
            ok = retry[2] is not None and retry[2].verified
            if ok or (att.status == "failed" and retry[0].status != "failed"):
                retry[0].messages = att.messages + retry[0].messages
                retry[0].qp_solves += att.qp_solves
                return retry
        return out

    def _effective(self, s: tuple[int, int]) -> tuple[int, int]:
        """Feasibility only sees values at the data: beyond as many coefficients
        as distinct points, p (or q) takes any values already. (n, m) is then
        answered by (min(n, N), min(m, N)), which the seed's matrix (rank-deficient
        there) would only make harder for the solver."""
        return min(s[0], self.cap), min(s[1], self.cap)

    def test_many(self, splits: Iterable[tuple[int, int]]) -> None:
        splits = list(dict.fromkeys(splits))
        aliases = {s: self._effective(s) for s in splits if self._effective(s) != s}
        if aliases:
            self.test_many([self._effective(s) for s in splits])
            for s, e in aliases.items():
                self.cache.setdefault(s, self.cache[e])
            return
        todo = [s for s in splits if s not in self.cache]
        if not todo:
            return
        if self.cancel is not None and self.cancel.is_set():
            raise KeyboardInterrupt  # another channel's thread was interrupted
        if self.cache and self.deadline is not None and time.perf_counter() > self.deadline:
            raise _OutOfTime
        if self.cache and self.budget is not None and self.solves() >= self.budget:
            raise _OutOfTime
        n_max = max(s[0] for s in todo)
        m_max = max(s[1] for s in todo)
        if not self.parts.systems.per_split or self.screen:
            self.system.prepare(n_max, m_max)
        if self._parallel() and len(todo) > 1:
            ex = ThreadPoolExecutor(min(self.jobs, len(todo)))
            try:
                outs = list(ex.map(lambda s: self._run(*s), todo))
            finally:  # on Ctrl-C, do not wait for QPs still running
                ex.shutdown(wait=False, cancel_futures=True)
        else:
            outs = [self._run(*s) for s in todo]
        cut = False
        for s, out in zip(todo, outs, strict=True):
            cut = cut or out[0].timed_out  # cut short: "failed", which rules out nothing
            self.cache[s] = out
            rows = out[0].active_rows
            if rows is not None:
                # the data rows binding at the batch's last solution (in the batch's
                # order, not the threads') start the next batch's splits
                self.warm = self._data_rows(out[0])
            if out[0].status == "infeasible":
                self.infeasible.append(s)
            if self.options.callback is not None:
                self.options.callback(out[0])
        if cut:
            raise _OutOfTime

    def _parallel(self) -> bool:
        """Threads pay off only when QPs are slow: on small problems the Python
        overhead between solver calls holds the GIL and two threads run slower
        than one (measured in benchmarks/bench_core.py). With ``jobs=None`` the
        pool is used once the QPs so far average more than 20 ms.

        A verifier that learns from each candidate (``parts.constraint_points``:
        the BRDF validity points that later splits carry) makes each split depend
        on the ones verified before it, so its splits run one at a time, in the
        walk's order: splits tested side by side took those points in whatever
        order their threads finished, and the same fit of cayman.brdf gave other
        coefficients (and 3+7 instead of 1+8 for R) from run to run."""
        if self.jobs <= 1 or self.parts.constraint_points is not None:
            return False
        if self.options.jobs is not None:
            return True
        secs = [c[0].seconds for c in self.cache.values()]
        return bool(secs) and sum(secs) / len(secs) > 0.02

    def _batch_width(self) -> int:
        """How many splits the walk tests at once: one. A width from ``jobs`` (or
        from the QPs' measured seconds) changed which splits were tested, their warm
        rows and, near the feasibility boundary, the answer: the walk is the same
        for any ``jobs`` and load; threads serve the batches whose splits are fixed
        (every split of a total: ``total``, ``strategy="exhaustive"``,
        ``split_rule="error"``)."""
        return 1

    def solves(self) -> int:
        """QP solves spent so far (the work budget's unit)."""
        seen: set[int] = set()
        total = 0
        for att, _, _ in self.cache.values():
            if id(att) not in seen:  # aliases share one attempt
                seen.add(id(att))
                total += att.qp_solves
        return total

    def ok(self, s: tuple[int, int]) -> bool:
        self.test_many([s])
        ver = self.cache[s][2]
        return ver is not None and ver.verified

    def ruled_out(self, n: int, m: int) -> bool:
        return any(n <= a and m <= b for a, b in self.infeasible)

    # -- strategies --------------------------------------------------------------------
    def fixed(self, n: int, m: int) -> list[tuple[int, int]]:
        # One split: an answer other than a verified fit in the weighted form is
        # worth the seed form's opinion too (each form finds fits the other misses
        # near the feasibility boundary).
        self.second_opinion = True
        self.test_many([(n, m)])
        return [(n, m)]

    def all_splits(self, total: int) -> list[tuple[int, int]]:
        splits = [(total - m, m) for m in range(1, total)]
        self.test_many(splits)
        return self._choose([s for s in splits if self.ok(s)]) or splits

    def exhaustive(self, lo: int, hi: int) -> list[tuple[int, int]]:
        for total in range(lo, hi + 1):
            splits = [(total - m, m) for m in range(1, total)]
            self.test_many(splits)
            good = [s for s in splits if self.ok(s)]
            if good:
                return self._choose(good)
        return []

    def _bracket(self, lo: int, hi: int, start: int | None) -> tuple[int, int] | None:
        """A feasible split near the minimal total, from balanced splits: galloping
        totals start, start + 1, start + 3, start + 6, start + 10, start + 16, ...
        (steps growing by half each time; start: a hint such as the
        previous channel's total, else lo) up to the first feasible one, then
        bisection between it and the largest infeasible one. Feasibility of the
        balanced split grows with the total, so this takes O(log) tests where a
        walk up from lo took one per total. Where it lands only sets how much the
        staircase walk below it has to do: the walk proves the total minimal.
        """
        t0 = lo if start is None else min(max(int(start), lo), hi)
        below, above = lo - 1, None  # largest balanced total that failed, smallest that fit
        poly: tuple[int, int] | None = None
        step = 1
        total = t0
        while above is None and total <= hi:
            width = self._batch_width()
            probes: list[tuple[int, int]] = []
            t, st = total, step
            while len(probes) < width and t <= hi:
                probes.append(_balanced(t))
                # the last total hi is always tested: no jump past the range
                # steps 1, 2, 3, 4, 6, 9, 13, ...: a feasible probe far above the
                # answer is the most expensive test of a search (on the EXR's B
                # channel a (32, 32) probe cost more than the walk below it)
                t, st = (min(t + st, hi) if t < hi else hi + 1), max(st + 1, (3 * st) // 2)
            extra = []
            if poly is None and sum(probes[-1]) >= self.cap + 1 >= lo:
                # A polynomial through every point (q constant: no pole) always fits;
                # it bounds the answer when balanced splits keep finding poles.
                extra = [(self.cap, 1)]
            self.test_many(probes + extra)
            for p in probes:
                if self.ok(p):
                    above = sum(p)
                    break
                below = max(below, sum(p))
            if extra and self.ok(extra[0]):
                poly = extra[0]
            if above is None and poly is not None:
                return poly
            total, step = t, st
        if above is None:
            # Nothing fitted up to hi. Only a proved infeasibility rules out the totals
            # below it: a numerical failure at a large total says nothing about smaller
            # ones, so every balanced total above the largest proved one is tested.
            proved = max((sum(s) for s in self.infeasible
                          if s == _balanced(sum(s))), default=lo - 1)
            for t in range(max(proved + 1, lo), hi + 1):
                if self.ok(_balanced(t)):
                    return _balanced(t)
            return poly
        while above - below > 1:  # bisection, `width` totals at a time
            width = min(self._batch_width(), above - below - 1)
            mids = sorted({below + (above - below) * (i + 1) // (width + 1)
                           for i in range(width)} - {below, above})
            self.test_many([_balanced(t) for t in mids])
            for t in mids:
                if self.ok(_balanced(t)):
                    above = t
                    break
                below = t
        return _balanced(above)

    def staircase(self, lo: int, hi: int, start: int | None = None) -> list[tuple[int, int]]:
        best = self._bracket(lo, hi, start)
        if best is None:
            return []
        # 2. staircase walk below the best total.
        m = 1
        target = best[0] + best[1] - 1
        while True:
            while target >= lo:
                cols: list[tuple[int, int]] = []
                mm = m
                width = self._batch_width()
                while len(cols) < width and target - mm >= 1:
                    best = self._test_above(best, mm)
                    if not self.ruled_out(target - mm, mm):
                        cols.append((target - mm, mm))
                    mm += 1
                if not cols:
                    # No split of this total verified. When one of them was a QP-feasible
                    # candidate rejected by the verifier (a BRDF fit negative or through a
                    # pole between samples), success is not monotone in the total: a
                    # smaller total may still verify, so the walk goes on below it.
                    rejected = any(k[0] + k[1] == target and v[0].status == "feasible"
                                   for k, v in self.cache.items())
                    if not rejected:
                        break
                    target, m = target - 1, 1
                    continue
                self.test_many(cols)
                hit = next((s for s in cols if self.ok(s)), None)
                if hit is not None:
                    best, m = hit, hit[1]
                    target = best[0] + best[1] - 1
                else:
                    m = mm
            # A failed split (no verdict) rules out nothing below it, so the walk may
            # have stepped past splits of the total below the best one: those neither
            # tested nor ruled out are tested now, and a verified one resumes the walk.
            hit = self._sweep(best, lo)
            if hit is None:
                break
            best, m = hit, hit[1]
            target = best[0] + best[1] - 1
        tot = best[0] + best[1]
        if self.options.split_rule == "error":
            splits = [(tot - k, k) for k in range(1, tot)]
            self.test_many(splits)
            return self._choose([s for s in splits if self.ok(s)])
        # min-m: the walk reached the minimal total at column best[1], but a split
        # with fewer denominator coefficients may still fit there (a candidate with
        # poles, a failed solve or a speculative batch made the walk step past it).
        # Every such split not ruled out by a proved infeasibility is tested, so the
        # answer is the lowest-m feasible split of the total whatever the walk's path
        # (and the number of threads) was.
        lower = [(tot - k, k) for k in range(1, best[1]) if not self.ruled_out(tot - k, k)]
        while lower:  # ascending m, `jobs` at a time, up to the first verified split
            batch, lower = lower[: self._batch_width()], lower[self._batch_width():]
            self.test_many(batch)
            if any(self.ok(s) for s in batch):
                break
        feasible = sorted((s for s in self.cache if s[0] + s[1] == tot and self.ok(s)),
                          key=lambda s: s[1])
        return feasible[:1]

    def _sweep(self, best: tuple[int, int], lo: int) -> tuple[int, int] | None:
        """The first verified split, by ascending m, among the splits of the total
        below ``best``'s that were neither tested nor ruled out by an infeasible one;
        None when there is none (then every split of that total has been answered)."""
        below = best[0] + best[1] - 1
        if below < max(lo, 2):
            return None
        todo = [(below - k, k) for k in range(1, below)
                if (below - k, k) not in self.cache and not self.ruled_out(below - k, k)]
        return next((s for s in todo if self.ok(s)), None)

    def _test_above(self, best: tuple[int, int], m: int) -> tuple[int, int]:
        """Column m of the walk below ``best``'s total T, first at T itself when m <
        best's m: (T - m, m) is a split the min-m rule has to test anyway, and when
        it is infeasible it rules out (T - 1 - m, m) too (one QP for two splits; the
        seed's walk: 34 splits where it took 46). Verified, it is the better split of
        T (fewer denominator coefficients); the walk goes on with column m either way.
        """
        tot = best[0] + best[1]
        if m >= best[1] or tot - m < 1 or self.ruled_out(tot - m, m):
            return best
        return (tot - m, m) if self.ok((tot - m, m)) else best

    def _choose(self, good: list[tuple[int, int]]) -> list[tuple[int, int]]:
        if not good:
            return []
        if self.options.split_rule == "error":
            return [min(good, key=lambda s: (self._centrality(s), s[1]))]
        return [min(good, key=lambda s: s[1])]

    def _centrality(self, s: tuple[int, int]) -> float:
        rf = self.cache[s][1]
        assert rf is not None
        seg = self.seg
        r = rf(seg.x)
        mid = 0.5 * (seg.lo[:, self.channel] + seg.hi[:, self.channel])
        half = 0.5 * (seg.hi[:, self.channel] - seg.lo[:, self.channel])
        with np.errstate(divide="ignore", invalid="ignore"):
            return float(np.max(np.where(half > 0, np.abs(r - mid) / half, 0.0)))

    # -- the result ---------------------------------------------------------------------
    def result(self, chosen: list[tuple[int, int]], lo: int, hi: int, secs: float,
               certify: bool = True) -> FitResult:
        history = tuple(c[0].summary() for c in self.cache.values())
        disagreements = tuple(
            f"({a.n},{a.m}): {a.disagreement}" for a, _, _ in self.cache.values() if a.disagreement
        )
        qp_solves = sum(c[0].qp_solves for c in self.cache.values())
        name = self.seg.names[self.channel]
        proof = None
        if chosen and self.ok(chosen[0]):
            att, rf, ver = self.cache[chosen[0]]
            status, msg = 0, STATUS_MESSAGES[0]
            if self.space.variable == "log":
                msg += " (p and q are polynomials in log x)"
        else:
            att, rf, ver = self._closest()
            if ver is not None:
                status = 2
                # why it failed, in the verifier's words: a candidate that meets every
                # segment can still fail (a BRDF fit's q <= 0 between the samples)
                msg = (f"{STATUS_MESSAGES[2]}: best candidate (n={att.n}, m={att.m}): "
                       f"{ver.message}")
            else:
                status = 1
                span = f"total {lo}" if lo == hi else f"totals {lo}..{hi}"
                # what was searched, not more: the walk tests some splits of a total
                span = f"the {len(self.cache)} (n, m) split(s) tested with {span}"
                from ratfit.fitting.certificate import search_proof

                limit = self.options.time_limit
                proof = search_proof(self, time_limit=60.0 if limit is None else
                                     min(60.0, max(5.0, 0.25 * float(limit)))) if certify else None
                if proof is not None and proof["checked"]:  # exact: a proof
                    msg = (
                        f"{STATUS_MESSAGES[1]}: no rational of this size fits these "
                        f"segments (certificate: "
                        f"{proof['statement']}); none of {span} gave a verified fit; "
                        f"{self.coverage(lo, hi)}"
                    )
                elif proof is not None and proof["numerical"]:
                    msg = (
                        f"{STATUS_MESSAGES[1]}: none of {span} gave a verified fit "
                        f"({proof['statement']}); {self.coverage(lo, hi)}"
                    )
                else:
                    msg = (
                        f"{STATUS_MESSAGES[1]}: none of {span} gave a verified fit "
                        f"(largest tried: n={att.n}, m={att.m}); {self.coverage(lo, hi)} "
                        "(float checks, no exact certificate)"
                    )
        return FitResult(
            success=status == 0,
            status=status,
            message=msg,
            n=att.n,
            m=att.m,
            basis=self.space.family.name,
            index_set=self.space.index_set,
            rational=rf,
            verification=ver,
            delta=att.delta,
            sigma_min=att.sigma_min,
            sigma_max=att.sigma_max,
            active_set_size=att.active_set_size,
            qp_solves=qp_solves,
            seconds=secs,
            solver=self.options.solver,
            decided_by=att.decided_by,
            solver_status=att.solver_status,
            formulation=att.formulation,
            channel=name,
            history=history,
            disagreements=disagreements,
            infeasible_proof=proof if status == 1 else None,
            work_limit=self.budget,
        )

    def coverage(self, lo: int, hi: int) -> str:
        """What the search covered of the splits of totals lo..hi, for a status 1
        without a proof: how many an infeasible split rules out (float checks, no
        exact certificate), how many were tested without a verdict, how many were
        neither (beyond the balanced splits, which the walk stops at)."""
        ns, ms = [], []
        for t in range(max(lo, 2), hi + 1):
            m = np.arange(1, t)
            ns.append(t - m)
            ms.append(m)
        if not ns:
            return "no split in range"
        n_all, m_all = np.concatenate(ns), np.concatenate(ms)
        out = np.zeros(n_all.size, dtype=bool)
        for a, b in self.infeasible:
            out |= (n_all <= a) & (m_all <= b)
        tested = {s for s in self.cache if lo <= sum(s) <= hi}
        undecided = sum(1 for s in tested if self.cache[s][0].status != "infeasible"
                        and not out[_split_index(s, lo)])
        left = int(n_all.size - out.sum()) - undecided
        top = max((s for s in self.infeasible), key=sum, default=None)
        parts = [f"of the {n_all.size} splits of these totals, {int(out.sum())} are ruled out "
                 "by splits found infeasible"]
        if undecided:
            parts.append(f"{undecided} tested gave no verdict (solver failed: a breakdown, "
                         "a margin at its tolerance, or a candidate that failed verification)")
        if left > 0:
            if top is not None and all(a <= top[0] and b <= top[1] for a, b in self.infeasible):
                why = (f"n > {top[0]} or m > {top[1]}: the walk stops where the balanced "
                       "splits give no fit")
            else:
                why = "neither tested nor ruled out"
            parts.append(f"{left} were not tested ({why})")
        return "; ".join(parts)

    def timed_out(self, lo: int, hi: int, secs: float) -> FitResult:
        """The result when the time budget ran out: the smallest verified fit so far
        (not proven minimal), else status 1 without any claim of impossibility."""
        good = sorted((s for s in self.cache if self.ok(s)), key=lambda s: (sum(s), s[1]))
        tried = max((sum(s) for s in self.cache), default=lo)
        if self.budget is not None and self.solves() >= self.budget:
            what, raise_it = (f"work limit of {self.budget} QP solves", "--work-limit")
        else:
            limit = float(self.options.time_limit or 0.0)
            what, raise_it = f"time limit of {limit:g} s", "--time-limit"
        note = (f"{what} reached after {len(self.cache)} split(s), "
                f"totals {lo}..{tried} of {lo}..{hi}")
        if good:
            res = self.result(good[:1], lo, hi, secs)
            return dataclasses.replace(
                res, message=f"{res.message}; {note}: the total may not be minimal",
                time_limited=True)
        res = self.result([], lo, hi, secs, certify=False)
        return dataclasses.replace(
            res, time_limited=True, message=f"{STATUS_MESSAGES[1]}: {note}; no verified fit found "
                         f"(not a proof that none exists; raise {raise_it})")

    def _closest(self) -> Candidate:
        """The best thing reached when nothing verified: smallest violation, else largest."""
        with_c = [c for c in self.cache.values() if c[2] is not None]
        if with_c:
            return min(with_c, key=lambda c: (c[2].max_violation_rel, c[0].total))  # type: ignore[union-attr]
        return max(self.cache.values(), key=lambda c: (c[0].total, c[0].m))


class _OutOfTime(Exception):
    """The search's time budget ran out (raised between splits)."""


def _split_index(s: tuple[int, int], lo: int) -> int:
    """Position of split s in the list of every split of totals max(lo, 2), ... by m."""
    first = max(lo, 2)
    t = s[0] + s[1]
    return sum(u - 1 for u in range(first, t)) + s[1] - 1


def _balanced(total: int) -> tuple[int, int]:
    return (total + 1) // 2, total // 2
