"""Least-squares polish of a verified fit, inside its segments.

The search answers "what is the smallest (n, m) that fits"; its QP picks, among
the fits of that size, the one of smallest coefficient norm, which may run
along the edge of every segment. Users who compare fits (RMSE against the
measurements, against an analytic BRDF model) want the best fit of that size
inside the bounds. With q fixed in scale (mean of q over the data = 1), the
linearised error sum_i w_i^2 (p(x_i) - y_i q(x_i))^2 / q0(x_i)^2 (Sanathanan-
Koerner weights from the starting fit q0) is a convex quadratic in the
coefficients, and "r(x_i) inside the inner part of segment i" is linear:

    p(x_i) - (lo_i + tau w_i) q(x_i) >= 0,   (hi_i - tau w_i) q(x_i) - p(x_i) >= 0,

so the polish is one more QP in the same bases, with the same (n, m). Extra
rows keep q > 0 at the data and q > 0, p >= 0 at given points (a BRDF's valid
configurations), entering by an active set only where violated. The caller
verifies the result like any other candidate and keeps the starting fit if it is
not better.

The QP is solved in whitened coordinates z = R c (R from a QR of the weighted
rows) by the named solver, the equality mean q = 1 eliminated and every row
scaled to unit norm: in z the rows' norms are tiny and span decades, and
unscaled, DAQP and Clarabel disagreed on the same QP (Clarabel's "optimal"
missed rows by 0.25 % of a unit row). Where the QP still fails at every cut-off
the same problem is tried as the second-order cone program min t s.t.
||R c|| <= t in c itself with Clarabel (slower; the search's repairs, many per
fit, use the QP only).
"""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.qp import _ChunkStore
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.solvers import solve_qp
from ratfit.core.systems import smallest
from ratfit.core.work import WorkBudget

__all__ = ["bound_row_count", "bound_rows", "polish_fit"]

Array = NDArray[np.float64]


def _design(rf: RationalFunction, x: Array) -> tuple[Array, Array]:
    P = (rf.p_basis or rf.space).design(x, rf.n)
    Q = (rf.q_basis or rf.space).design(x, rf.m)
    return P, Q


# Points per block of the polish's passes over every sample: a block's rows stay in
# cache (one LAPACK QR of 262 144 x 45 took 0.7 s, the same R from 8192-row blocks 0.16 s).
_BLOCK = 8192


class _Design:
    """P and Q (the numerator's and denominator's basis values) at every sample, by
    blocks of :data:`_BLOCK` points: kept as far as the process's design budget
    (:data:`ratfit.core.qp.DESIGN_BUDGET`, shared with the searches' systems) goes,
    computed again at each pass otherwise. Held whole, a full MERL table's P and Q at
    n + m = 44 were 373 MiB beside a search's 512 MiB (the default fit's 1.85 GiB
    peak). A block is the same numbers kept or computed again (the same points
    through the same code, both Fortran-ordered), and rows for the active set are
    always evaluated at their own points, so the polish's answer does not depend on
    what the budget let it keep."""

    def __init__(self, rf: RationalFunction, x: Array) -> None:
        self.rf, self.x = rf, x
        self.N = x.shape[0]
        self.n, self.m = rf.n, rf.m
        self.starts = range(0, self.N, _BLOCK)
        self.store = _ChunkStore()
        # the last values asked for (a pass asks for the same coefficients' values
        # several times), each sample's squared row norms, q's column means
        self._recent: list[tuple[bytes, tuple[Array, Array]]] = []
        self._norms: tuple[Array, Array] | None = None
        self._q_mean: Array | None = None
        self.store.reserve(self.N * (self.n + self.m), len(self.starts))

    def block(self, i: int) -> tuple[Array, Array]:
        """(P, Q) at the points of block ``i``."""
        kept = self.store.chunks.get(i)
        if kept is not None:
            return kept
        s = self.starts[i]
        P, Q = _design(self.rf, self.x[s:s + _BLOCK])
        pair = (np.asfortranarray(P), np.asfortranarray(Q))
        self.store.keep(i, pair)
        return pair

    def blocks(self) -> Iterator[tuple[slice, Array, Array]]:
        for i, s in enumerate(self.starts):
            P, Q = self.block(i)
            yield slice(s, s + P.shape[0]), P, Q

    def values(self, c: Array) -> tuple[Array, Array]:
        """p = P a and q = Q b at every sample, for coefficients c = (a, b) (read-only)."""
        key = np.asarray(c, dtype=np.float64).tobytes()
        for k, out in self._recent:
            if k == key:
                return out
        pa, qb = np.empty(self.N), np.empty(self.N)
        a, b = c[:self.n], c[self.n:]
        for sl, P, Q in self.blocks():
            pa[sl] = P @ a
            qb[sl] = Q @ b
        pa.flags.writeable = qb.flags.writeable = False
        self._recent = [(key, (pa, qb)), *self._recent[:1]]
        return pa, qb

    def norms2(self) -> tuple[Array, Array]:
        """|P_i|^2 and |Q_i|^2 at every sample."""
        if self._norms is None:
            pp, qq = np.empty(self.N), np.empty(self.N)
            for sl, P, Q in self.blocks():
                pp[sl] = np.einsum("ij,ij->i", P, P)
                qq[sl] = np.einsum("ij,ij->i", Q, Q)
            self._norms = pp, qq
        return self._norms

    def q_mean(self) -> Array:
        """Mean of each q basis function over the samples."""
        if self._q_mean is None:
            total = np.zeros(self.m)
            for _, _, Q in self.blocks():
                total += Q.sum(axis=0)
            self._q_mean = total / max(self.N, 1)
        return self._q_mean

    def rows(self, idx: NDArray[np.int64]) -> tuple[Array, Array]:
        """(P, Q) at the samples ``idx``, evaluated there (whatever is kept)."""
        return _design(self.rf, self.x[idx])

    def close(self) -> None:
        self.store.clear()
        self._recent, self._norms, self._q_mean = [], None, None


def polish_fit(
    rf: RationalFunction,
    seg: Segments,
    channel: int = 0,
    *,
    weights: ArrayLike | None = None,
    positive_at: ArrayLike | None = None,
    tau: float = 0.02,
    solver: str = "daqp",
    max_rounds: int = 30,
    start_rows: int = 4000,
    deadline: float | None = None,
    method: str = "auto",
    iterations: int = 3,
    repair: bool = False,
    work: WorkBudget | None = None,
    numerator: bool = True,
    ceiling: float | Array | None = None,
    floor: Array | None = None,
) -> RationalFunction | None:
    """The least-squares fit of the same size as ``rf`` whose values stay in the
    inner part (a fraction ``tau`` of each width off both ends) of every segment.

    When that inner part is empty (at the minimal size the feasible set can be
    thinner than 4 % of a width) the cut-off drops to ``tau / 4``, then
    ``tau / 20``.

    ``weights`` (N,) weight each point's error (default 1: plain RMSE).
    ``positive_at`` (G, d) are points (original coordinates) where q > 0 and
    (``numerator``) p >= 0, or (``ceiling`` C, a fit of log values; one per point or one
    for all) p / q <= C and (``floor`` F, one per point; -inf: none there) p / q >= F,
    are also
    required. Returns None when the QP fails; the result is
    a candidate, to be verified by the caller. ``work`` counts each QP solve
    (each active-set round of each cut-off); once it is exhausted the polish gives
    up (None) before the next solve: a count, so where it stops does not depend on
    the machine's load. ``deadline`` (a ``time.perf_counter()`` value, only under a
    user's time limit) is checked between active-set rounds the same way.
    ``method``: "auto" (the whitened QP with ``solver``, the cone program where
    that fails), "qp" or "socp" (the cone program only; needs Clarabel).
    ``iterations``: linearised passes at most (each one searched on the true
    error); None when none makes the fit better.

    ``repair``: the fit of an invalid candidate (negative or through a pole between
    the samples) wants the point that meets every positivity row, not the best
    one: one pass, its QP's answer as it is, with the band cut at half the start's
    own margin where that is below ``tau`` (at the minimal size the inner 96 %
    is often empty: MERL size, a 128 612-row active set before DAQP said so).
    """
    x = seg.x
    lo = seg.lo[:, channel]
    hi = seg.hi[:, channel]
    y = seg.center[:, channel]
    design = _Design(rf, x)
    try:
        return _polish(rf, design, lo, hi, y, weights, positive_at, tau, solver,
                       max_rounds, start_rows, deadline, method, iterations, repair, work,
                       numerator, ceiling, floor)
    finally:
        design.close()


def _polish(rf: RationalFunction, D: _Design, lo: Array, hi: Array, y: Array,
            weights: ArrayLike | None, positive_at: ArrayLike | None, tau: float,
            solver: str, max_rounds: int, start_rows: int, deadline: float | None,
            method: str, iterations: int, repair: bool, work: WorkBudget | None,
            numerator: bool, ceiling: float | Array | None = None,
            floor: Array | None = None) -> RationalFunction | None:
    """:func:`polish_fit` on the samples' basis values ``D``."""
    n = rf.n
    c = np.concatenate([rf.p, rf.q])
    q0 = D.values(c)[1]
    if not np.all(np.isfinite(q0)) or np.all(q0 == 0):
        return None
    scale = float(np.mean(q0))
    c = c / scale  # q > 0 on the data, of mean 1
    if np.any(q0 / scale <= 0):
        return None
    w = np.ones(D.N) if weights is None else np.asarray(weights, dtype=float).ravel()
    grid, p_rows = _positivity_rows(rf, positive_at, numerator, ceiling, floor)
    methods = {"auto": ("qp", "socp"), "qp": ("qp",), "socp": ("socp",)}[method]
    if importlib.util.find_spec("clarabel") is None:
        methods = tuple(x for x in methods if x != "socp") or ("qp",)
    err = _error(D, y, w)

    def stop() -> bool:
        return _past(deadline) or (work is not None and work.exhausted)

    best = err(c)
    improved = False
    # Sanathanan-Koerner: each pass linearises the error around the current q; the
    # step to its QP's answer is searched on the true error, so a pass never makes
    # the fit worse (its QP's optimum can be: cayman R (1, 8), RMSE 0.068 -> 0.25).
    for _ in range(1 if repair else iterations):
        step = _polish_pass(D, lo, hi, y, w, c, grid, p_rows, tau, solver, methods,
                            max_rounds, start_rows, stop, work, repair)
        if step is None:
            break
        if repair:
            c, improved = step, True
            break
        c_new, e_new = _line_search(D, y, w, c, step)
        if not e_new < best:
            break
        gain = 1.0 - e_new / best
        c, best, improved = c_new, e_new, True
        # another pass only after a real gain (acryl_blue: the second pass gains
        # 0.2 % of the squared error where the first gained 90 %)
        if gain < 0.02 or stop():
            break
    if not improved:
        return None
    return RationalFunction(rf.space, c[:n], c[n:], p_basis=rf.p_basis, q_basis=rf.q_basis)


def _error(D: _Design, y: Array, w: Array) -> Callable[[Array], float]:
    """The weighted squared error of coefficients (a, b) at the data (inf when q <= 0)."""

    def err(c: Array) -> float:
        p, q = D.values(c)
        if not np.all(q > 0):
            return float("inf")
        return float(np.sum((w * (p / q - y)) ** 2))

    return err


def _line_search(D: _Design, y: Array, w: Array, c0: Array,
                 c1: Array) -> tuple[Array, float]:
    """The best point of the segment c0 -> c1 for the true error. Both ends meet
    every linear row of the polish (band, q > 0, p >= 0), so every point between
    them does: a coarse scan, then a golden-section refinement around its best.
    p and q are linear along the segment: two products each, then O(N) a point."""
    p0, q0 = D.values(c0)
    p1, q1 = D.values(c1)
    dp, dq = p1 - p0, q1 - q0
    del p1, q1

    def err(a: float) -> float:
        q = q0 + a * dq
        if not np.all(q > 0):
            return float("inf")
        return float(np.sum((w * ((p0 + a * dp) / q - y)) ** 2))

    alphas = np.linspace(0.0, 1.0, 21)
    vals = np.array([err(a) for a in alphas])
    i = int(np.argmin(vals))
    a, b = alphas[max(i - 1, 0)], alphas[min(i + 1, len(alphas) - 1)]
    g = (np.sqrt(5.0) - 1.0) / 2.0
    best_a, best_v = float(alphas[i]), float(vals[i])
    for _ in range(20):
        u, v = b - g * (b - a), a + g * (b - a)
        fu, fv = err(u), err(v)
        for t, ft in ((u, fu), (v, fv)):
            if ft < best_v:
                best_a, best_v = float(t), float(ft)
        if fu < fv:
            b = v
        else:
            a = u
    return c0 + best_a * (c1 - c0), best_v


def _polish_pass(D: _Design, lo: Array, hi: Array, y: Array, w: Array, c: Array,
                 grid: Array, p_rows: Array, tau: float, solver: str,
                 methods: tuple[str, ...], max_rounds: int, start_rows: int,
                 stop: Callable[[], bool], work: WorkBudget | None,
                 repair: bool = False) -> Array | None:
    """One linearised polish around coefficients ``c`` (q > 0 of mean 1 on the data):
    the QP's coefficients, or None when every cut-off fails."""
    p_start, q0 = D.values(c)
    # Objective: || diag(w / q0) (P a - y Q b) ||^2, plus a tiny ridge for uniqueness.
    # H = M^T M + ridge I = R^T R, z = R c; R from a QR of the stacked rows, not a
    # Cholesky of H: with q over six decades (a mirror's peak) H's condition is the
    # square of M's and the whitened QP met its rows only to ~1e-4.
    R = _objective_r(D, y, w / q0)
    k = R.shape[0]
    if not np.all(np.isfinite(R)) or np.any(np.abs(np.diag(R)) == 0):
        return None
    Rinv = np.asarray(np.linalg.solve(R, np.eye(k)), dtype=np.float64)
    # q at least 1 % of its smallest value on the data, which the start meets: a
    # margin that a sign change between points cannot hide in. p at least 1e-6 of
    # the largest value: a p met to the solver's tolerance (-1e-12) where it touches
    # 0 (a dark region) is a negative BRDF to the validity check, again and again
    # at the next point found beside it (garnet_red G: 4 rounds, no polish).
    # (half the start's own p where that is smaller: the start stays feasible).
    # q at the positivity points at least half the start's own q there: held at 1 % of
    # the data's smallest, a polish sat on that floor where no sample is and dipped below
    # 0 between the points; the proof found a new corner every round (cayman B, every
    # size: no polish, its diffuse part at 0.62 of the data).
    q_floor = 0.01 * float(q0.min())
    grid_start = np.maximum(grid @ c, 0.0)
    h_grid = np.where(p_rows > 0,
                      np.minimum(1e-6 * float(np.max(np.abs(y))) * p_rows, 0.5 * grid_start),
                      np.maximum(q_floor, 0.5 * grid_start))
    # The band's inner part may be empty at the minimal size (the search's own
    # margin can be 1e-3 of a width): narrower cut-offs before giving up, the last
    # one half the starting fit's own margin, where the start itself is feasible.
    cuts = [tau, tau / 4, tau / 20]
    with np.errstate(all="ignore"):
        start = p_start / q0
        margin = float(np.min(np.minimum(start - lo, hi - start) / (hi - lo)))
    if 0 < margin / 2 < cuts[-1]:
        cuts.append(margin / 2)
    if repair and 0 < margin / 2 < tau:
        cuts = [margin / 2]
    # every cut-off with the QP first: the cone program is slower, and where the QP
    # (unit rows) says "infeasible" at 96 % the inner band is usually empty
    for how in methods:
        for cut in cuts:
            qp = _whitened(Rinv, solver) if how == "qp" else _cone(R)
            out = _solve_band(D, lo, hi, qp, cut, grid, h_grid, q_floor, c,
                              max_rounds, start_rows, stop, work)
            if out is not None or stop():
                return out
    return None


def bound_rows(P: Array, Q: Array, ceiling: float | ArrayLike | None = None,
               floor: ArrayLike | None = None, out: Array | None = None) -> Array:
    """Rows in (p, q)'s coefficients, from p's and q's basis values ``P`` and ``Q`` at
    some points, for C q - p >= 0 (``ceiling`` C: one number, or one per point) and for
    p - F q >= 0 (``floor`` F, one per point, at the points where it is finite): where
    q > 0, F <= p / q <= C. Not normalised; the search's rows
    (:func:`ratfit.brdf.fitter._valid_rows`) and the polish's
    (:func:`_positivity_rows`) are these, each scaled its own way. ``out``: an array of
    :func:`bound_row_count` rows to write them into (the polish's rows at 60 000 points
    are 100+ MB, and stacking copies took a tenth of a MERL-table fit)."""
    n, total = P.shape[1], P.shape[1] + Q.shape[1]
    count = bound_row_count(len(P), ceiling, floor)
    if out is None:
        out = np.empty((count, total))
    elif out.shape != (count, total):
        raise ValueError(f"out has shape {out.shape}; the rows need {(count, total)}")
    i = 0
    if ceiling is not None:
        np.negative(P, out=out[:len(P), :n])
        np.multiply(np.reshape(np.asarray(ceiling, dtype=float), (-1, 1)), Q,
                    out=out[:len(P), n:])
        i = len(P)
    if floor is not None:
        f = np.asarray(floor, dtype=float).ravel()
        at = np.isfinite(f)
        out[i:, :n] = P[at]
        np.multiply(-f[at, None], Q[at], out=out[i:, n:])
    return out


def bound_row_count(points: int, ceiling: float | ArrayLike | None = None,
                    floor: ArrayLike | None = None) -> int:
    """How many rows :func:`bound_rows` gives at ``points`` points."""
    count = points if ceiling is not None else 0
    if floor is not None:
        count += int(np.sum(np.isfinite(np.asarray(floor, dtype=float))))
    return count


def _positivity_rows(rf: RationalFunction, positive_at: ArrayLike | None,
                     numerator: bool = True, ceiling: float | Array | None = None,
                     floor: Array | None = None) -> tuple[Array, Array]:
    """Rows G c >= h keeping q > 0, (``numerator``) p >= 0, (``ceiling`` C) C q - p >= 0
    and (``floor`` F, at the points where it is finite) p - F q >= 0
    at ``positive_at``, and 1 / (the norm each p or bound row was divided by), 0 on q rows;
    built once for every pass and cut-off, in one array (no stacked copies).
    (q > 0 at the data is part of :class:`_BandRows`.)"""
    k = rf.n + rf.m
    pts = None if positive_at is None else np.asarray(positive_at, dtype=float)
    if pts is None or not len(pts):
        return np.zeros((0, k)), np.zeros(0)
    Pg, Qg = _design(rf, pts)
    g, n = len(Qg), Pg.shape[1]
    first = 2 * g if numerator else g  # where the bound rows start
    rows = np.zeros((first + bound_row_count(g, ceiling, floor), k))
    rows[:g, n:] = Qg
    if numerator:
        rows[g:first, :n] = Pg
    bound_rows(Pg, Qg, ceiling, floor, out=rows[first:])
    scaled = rows[g:]
    norms = np.linalg.norm(scaled, axis=1)
    norms[norms == 0] = 1.0
    scaled /= norms[:, None]
    return rows, np.concatenate([np.zeros(g), 1.0 / norms])


QPStep = Callable[[Array, Array, Array], "Array | None"]


def _whitened(Rinv: Array, solver: str) -> QPStep:
    """min ||R c||^2 s.t. G c >= h, mean-q row e c = 1, as min ||z||^2 in z = R c,
    with the equality eliminated: z = z0 + N w (z0 the shortest z on it, N an
    orthonormal basis of the rest), min ||w||^2 s.t. G Rinv N w >= h - G Rinv z0.
    Written as two opposite inequalities, as before, the equality made DAQP call
    polish QPs "infeasible" that have solutions (acryl_blue R, every cut-off)."""

    def step(G: Array, h: Array, e: Array) -> Array | None:
        ez = e @ Rinv
        nz = float(ez @ ez)
        if not nz > 0:
            return None
        z0 = ez / nz
        basis = np.linalg.qr(ez[:, None], mode="complete")[0][:, 1:]
        GR = G @ Rinv
        A, b = GR @ basis, h - GR @ z0
        # unit rows: in z the rows' norms are tiny and span decades (1e-10..1e-5 on
        # acryl_blue), below the solvers' absolute tolerances
        norms = np.linalg.norm(A, axis=1)
        norms[norms == 0] = 1.0
        sol = solve_qp(A / norms[:, None], b / norms, solver)
        if sol.status != "optimal" or sol.x is None:
            return None
        return Rinv @ (z0 + basis @ sol.x)

    return step


def _cone(R: Array) -> QPStep:
    """The same problem as the cone program min t s.t. ||R c|| <= t in c itself
    (Clarabel): no inverse of R, whose scale the active-set solver's tolerances
    do not survive where q spans decades."""

    def step(G: Array, h: Array, e: Array) -> Array | None:
        import clarabel
        import scipy.sparse as sp

        k = R.shape[0]
        # variables (c, t), Clarabel's form A x + s = b, s in a cone: s = 1 - e c = 0,
        # s = G c - h >= 0, s = (t, R c) in the second-order cone
        A = np.vstack([
            np.append(e, 0.0)[None, :],
            np.hstack([-G, np.zeros((G.shape[0], 1))]),
            np.append(np.zeros(k), -1.0)[None, :],
            np.hstack([-R, np.zeros((k, 1))]),
        ])
        b = np.concatenate([[1.0], -h, np.zeros(k + 1)])
        cost = np.zeros(k + 1)
        cost[-1] = 1.0
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(G.shape[0]),
                 clarabel.SecondOrderConeT(k + 1)]
        try:
            res = clarabel.DefaultSolver(sp.csc_matrix((k + 1, k + 1)), cost,
                                         sp.csc_matrix(A), b, cones, settings).solve()
        except Exception:  # a solver crash is a failed cut-off, not a crash of the fit
            return None
        if str(res.status) not in ("Solved", "AlmostSolved"):
            return None
        c = np.asarray(res.x[:k], dtype=float)
        return c if np.all(np.isfinite(c)) else None

    return step


def _past(deadline: float | None) -> bool:
    return deadline is not None and time.perf_counter() > deadline


def _objective_r(D: _Design, y: Array, scale: Array, ridge: float = 1e-10) -> Array:
    """R of the QR of [M; sqrt(r) I] with M = diag(scale) [P, -y Q] and r = ``ridge``
    x the mean squared column norm of M: M is never stored whole; each block of rows
    is built and reduced to its R factor (TSQR), the same R up to signs, as accurate
    as one Householder QR and several times faster on hundreds of thousands of rows."""
    k = D.n + D.m
    parts = []
    for sl, P, Q in D.blocks():
        M = np.hstack([P, -y[sl, None] * Q])
        M *= scale[sl, None]
        parts.append(_r_factor(M))
    R0 = parts[0] if len(parts) == 1 else _r_factor(np.vstack(parts))
    # ||M||_F^2 = ||R0||_F^2: the ridge without another pass over the rows
    r = ridge * max(float(np.sum(R0 * R0)) / k, 1e-300)
    return _r_factor(np.vstack([R0, np.sqrt(r) * np.eye(k)]))


def _r_factor(M: Array) -> Array:
    """R of M = QR (numpy's stubs type mode="r" as the full result)."""
    return np.asarray(np.linalg.qr(M, mode="r"), dtype=np.float64)


# which samples: every one (slice(None)) or some (sorted indices)
_Samples = slice | NDArray[np.int64]


class _BandRows:
    """The rows of the polish's band, G c >= h: per point i the lower row
    (P_i, -lo_i Q_i) / |.| and the upper row (-P_i, hi_i Q_i) / |.| (2N rows, never
    stored as one 2N x k matrix), with ``q_floor`` the rows q(x_i) >= q_floor
    (N more), then the positivity rows ``grid``."""

    def __init__(self, D: _Design, lo_in: Array, hi_in: Array, grid: Array,
                 h_grid: Array, q_floor: float | None = None) -> None:
        self.D, self.lo_in, self.hi_in = D, lo_in, hi_in
        self.grid, self.h_grid = grid, h_grid
        self.N = D.N
        # with a q_floor, N more rows (0, Q_i) >= q_floor after the band's 2N
        self.q_floor = q_floor
        self.n_data = (3 if q_floor is not None else 2) * self.N
        # |(P_i, -lo_i Q_i)| = sqrt(|P_i|^2 + lo_i^2 |Q_i|^2): no N x k temporary
        pp, qq = D.norms2()
        s_lo = np.sqrt(pp + lo_in * lo_in * qq)
        s_hi = np.sqrt(pp + hi_in * hi_in * qq)
        s_lo[s_lo == 0] = 1.0
        s_hi[s_hi == 0] = 1.0
        self.s_lo, self.s_hi = s_lo, s_hi

    @property
    def count(self) -> int:
        return self.n_data + self.grid.shape[0]

    def rows(self, idx: NDArray[np.int64]) -> tuple[Array, Array]:
        """(G, h) at rows ``idx``."""
        N = self.N
        n = self.D.n
        out = np.empty((idx.size, n + self.D.m))
        h = np.zeros(idx.size)
        D = self.n_data
        lo_r, hi_r, g_r = idx < N, (idx >= N) & (idx < 2 * N), idx >= D
        q_r = (idx >= 2 * N) & (idx < D)
        # the samples these rows need, evaluated once each
        pts = np.unique(idx[idx < D] % N)
        P, Q = self.D.rows(pts)

        def at(i: NDArray[np.int64]) -> NDArray[np.int64]:
            return np.searchsorted(pts, i)

        i = idx[lo_r]
        out[lo_r, :n] = P[at(i)] / self.s_lo[i, None]
        out[lo_r, n:] = -(self.lo_in[i] / self.s_lo[i])[:, None] * Q[at(i)]
        i = idx[hi_r] - N
        out[hi_r, :n] = -P[at(i)] / self.s_hi[i, None]
        out[hi_r, n:] = (self.hi_in[i] / self.s_hi[i])[:, None] * Q[at(i)]
        if q_r.any():
            out[q_r, :n] = 0.0
            out[q_r, n:] = Q[at(idx[q_r] - 2 * N)]
            h[q_r] = self.q_floor
        out[g_r] = self.grid[idx[g_r] - D]
        h[g_r] = self.h_grid[idx[g_r] - D]
        return out, h

    def data_residuals(self, pa: Array, qb: Array, at: _Samples = slice(None)) -> Array:
        """G c at the band rows (lower, then upper) of the samples ``at`` (every
        sample by default), from p = P a and q = Q b there."""
        return np.concatenate([(pa - self.lo_in[at] * qb) / self.s_lo[at],
                               (self.hi_in[at] * qb - pa) / self.s_hi[at]])

    def residuals(self, c: Array, pa: Array, qb: Array, at: _Samples = slice(None)) -> Array:
        """G c - h at the data rows of the samples ``at`` (band, q floor) and at every
        positivity row, in the order of :meth:`row_indices`."""
        parts = [self.data_residuals(pa, qb, at)]
        if self.q_floor is not None:
            parts.append(qb - self.q_floor)
        parts.append(self.grid @ c - self.h_grid)
        return np.concatenate(parts)

    def row_indices(self, samples: NDArray[np.int64]) -> NDArray[np.int64]:
        """The rows of the samples ``samples`` (lower, upper, q floor), then every
        positivity row."""
        N = self.N
        parts = [samples, samples + N] + ([samples + 2 * N] if self.q_floor is not None else [])
        return np.concatenate(parts + [np.arange(self.n_data, self.count)])


# Large data: the active-set rounds check the samples most likely to bind (the
# starting fit's tightest, and every sample whose row a round added), this many at
# least, and pass over every sample only when all of those are met. On a full MERL
# table 63 of a polish's 86 passes over every sample were rounds' checks.
_SCREEN = 65_536


def _solve_band(D: _Design, lo: Array, hi: Array, qp: QPStep, tau: float,
                grid: Array, h_grid: Array, q_floor: float, c_start: Array,
                max_rounds: int, start_rows: int, stop: Callable[[], bool],
                work: WorkBudget | None) -> Array | None:
    """The active-set QP of :func:`polish_fit` for one cut-off ``tau``: its
    coefficients (a, b), or None when infeasible, unsolved or out of time."""
    n, m = D.n, D.m
    k = n + m
    N = D.N
    width = hi - lo
    band = _BandRows(D, lo + tau * width, hi - tau * width, grid, h_grid, q_floor)
    mean_q = np.concatenate([np.zeros(n), D.q_mean()])
    # Start from the rows nearest to binding for the starting fit, spread over the data.
    slack = band.data_residuals(*D.values(c_start))
    active = np.zeros(band.count, dtype=bool)
    active[smallest(slack, start_rows)] = True
    # rows added a round (k coefficients): the most-missed max(200, 2 k) first, 1.5x more
    # each round, at most 10 max(200, 8 k) (the cap of before, when 8 k came first).
    # DAQP's time grows faster than its rows (satin_rosaline G (113, 112), 140 302 rows
    # of which ~220 bind: 0.03 s at 4 000 rows, 1.3 s at 19 000), so small first batches
    # pay: 8k first gave 1.2-1.8 s of QPs a cut-off, ending at 10 000 rows; 2k, 0.5-0.7 s
    # at 7 000, one round more (the same answer to 1e-12).
    batch = max(200, 2 * k)
    most = 10 * max(200, 8 * k)
    # Right-hand sides raised where the solver met an active row only to its own
    # tolerance: in z = R c coordinates an ill-conditioned H (a specular peak, q
    # over four decades) turns that tolerance into real misses of the band.
    lift = np.zeros(band.count)
    # a value is missed when it lands in the outer half of the cut (below)
    lo_half, hi_half = lo + 0.5 * tau * width, hi - 0.5 * tau * width
    tol = -1e-9 * width
    screen = None
    if N > 4 * _SCREEN:
        tight = np.minimum(slack[:N], slack[N:])
        screen = _Screen(D, band, np.union1d(smallest(tight, _SCREEN),
                                             np.flatnonzero(active[:2 * N]) % N))
    del slack

    def check(c: Array, at: _Screen | None) -> tuple[NDArray[np.int64], Array, Array]:
        """Rows checked, their G c - h, and which of them are missed (below)."""
        sel: _Samples
        if at is None:
            pa, qb = D.values(c)
            rows, sel = np.arange(band.count), slice(None)
        else:
            pa, qb = at.values(c)
            rows, sel = at.rows, at.samples
        res = band.residuals(c, pa, qb, sel)
        # missed: the value itself lands in the outer half of the cut (or, at tau = 0,
        # outside the segment by more than 1e-9 of its width); a positivity row by
        # more than 1e-9. A row met to rounding is not missed: with q over six decades
        # lifting those never settles.
        with np.errstate(all="ignore"):
            r = pa / qb
        off = ~(np.minimum(r - lo_half[sel], hi_half[sel] - r) >= tol[sel])
        # (only the side a missed value crossed: lifting the other would loosen it)
        n_off = 2 * off.size
        missed = active[rows] & (res < 0) & np.concatenate([off, off, res[n_off:] < -1e-9])
        return rows, res, missed

    for _ in range(max_rounds):
        if stop():
            return None
        idx = np.flatnonzero(active)
        G, h = band.rows(idx)
        c = qp(G, h + lift[idx], mean_q)
        if work is not None:
            work.spend()
        if c is None:
            return None
        rows, res, missed = check(c, screen)
        bad = ~(res >= 0) & ~active[rows]
        if screen is not None and not bad.any() and not missed.any():
            rows, res, missed = check(c, None)  # the screened rows met: every row
            bad = ~(res >= 0) & ~active[rows]
        if not bad.any() and not missed.any():
            break
        lift[rows[missed]] += 2.0 * -res[missed]
        new = rows[bad][smallest(res[bad], batch)]
        active[new] = True
        if screen is not None:
            screen.add(new[new < 2 * N] % N)
        # many rounds: take more rows each time, up to ``most`` (DAQP's time grows with
        # the rows: a 128 612-row active set took 1.4 s of QPs in one cut-off)
        batch = min(int(1.5 * batch), most)
    else:
        return None
    return c


class _Screen:
    """The band's rows at some of the samples (``samples``, sorted): the data rows
    (lower, upper, q floor) of those samples and every positivity row, with P and Q
    there kept (a few tens of MB)."""

    def __init__(self, D: _Design, band: _BandRows, samples: NDArray[np.int64]) -> None:
        self.D, self.band = D, band
        self.samples = np.zeros(0, dtype=np.int64)
        self.P, self.Q = np.zeros((0, D.n)), np.zeros((0, D.m))
        self.rows = band.row_indices(self.samples)  # the positivity rows
        self.add(samples)

    def add(self, samples: NDArray[np.int64]) -> None:
        fresh = np.setdiff1d(samples, self.samples)
        if not fresh.size:
            return
        P, Q = self.D.rows(fresh)
        order = np.argsort(np.concatenate([self.samples, fresh]), kind="stable")
        self.samples = np.concatenate([self.samples, fresh])[order]
        self.P = np.vstack([self.P, P])[order]
        self.Q = np.vstack([self.Q, Q])[order]
        self.rows = self.band.row_indices(self.samples)

    def values(self, c: Array) -> tuple[Array, Array]:
        return self.P @ c[:self.D.n], self.Q @ c[self.D.n:]
