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
rows keep q > 0 and p >= 0 at given points (a BRDF's valid configurations),
entering by an active set only where violated. The caller verifies the result
like any other candidate and keeps the starting fit if it is not better.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.solvers import solve_qp

__all__ = ["polish_fit"]

Array = NDArray[np.float64]


def _design(rf: RationalFunction, x: Array) -> tuple[Array, Array]:
    P = (rf.p_basis or rf.space).design(x, rf.n)
    Q = (rf.q_basis or rf.space).design(x, rf.m)
    return P, Q


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
) -> RationalFunction | None:
    """The least-squares fit of the same size as ``rf`` whose values stay in the
    inner part (a fraction ``tau`` of each width off both ends) of every segment.

    When that inner part is empty (at the minimal size the feasible set can be
    thinner than 4 % of a width) the cut-off drops to ``tau / 4``, then
    ``tau / 20``.

    ``weights`` (N,) weight each point's error (default 1: plain RMSE).
    ``positive_at`` (G, d) are points (original coordinates) where q > 0 and
    p >= 0 are also required. Returns None when the QP fails; the result is
    a candidate, to be verified by the caller. ``deadline`` (a
    ``time.perf_counter()`` value) is checked between active-set rounds: past
    it the polish gives up (None) rather than hold a time-limited run.
    """
    x = seg.x
    lo = seg.lo[:, channel]
    hi = seg.hi[:, channel]
    y = seg.center[:, channel]
    N = x.shape[0]
    n, m = rf.n, rf.m
    P, Q = _design(rf, x)
    q0 = Q @ rf.q
    if not np.all(np.isfinite(q0)) or np.all(q0 == 0):
        return None
    if np.median(q0) < 0:
        q0 = -q0
    if np.any(q0 <= 0):
        return None
    w = np.ones(N) if weights is None else np.asarray(weights, dtype=float).ravel()
    # Objective: || diag(w / q0) (P a - y Q b) ||^2, plus a tiny ridge for uniqueness.
    M = np.hstack([P, -y[:, None] * Q]) * (w / q0)[:, None]
    k = n + m
    ridge = 1e-10 * max(float(np.sum(M * M)) / k, 1e-300)
    # H = M^T M + ridge I = R^T R, z = R c; R from a QR of the stacked rows, not a
    # Cholesky of H: with q over six decades (a mirror's peak) H's condition is the
    # square of M's and the whitened QP met its rows only to ~1e-4.
    R = _tall_r(M, np.sqrt(ridge) * np.eye(k))
    if not np.all(np.isfinite(R)) or np.any(np.abs(np.diag(R)) == 0):
        return None
    Rinv = np.linalg.solve(R, np.eye(k))
    grid, h_grid = _positivity_rows(rf, q0, positive_at)
    # The band's inner part may be empty at the minimal size (the search's own
    # margin can be 1e-3 of a width): a narrower cut-off before giving up.
    for cut in (tau, tau / 4, tau / 20):
        c = _solve_band(P, Q, lo, hi, Rinv, cut, grid, h_grid, rf, solver,
                        max_rounds, start_rows, deadline)
        if c is not None or (deadline is not None and time.perf_counter() > deadline):
            break
    if c is None:
        return None
    return RationalFunction(rf.space, c[:n], c[n:], p_basis=rf.p_basis, q_basis=rf.q_basis)


def _positivity_rows(rf: RationalFunction, q0: Array,
                     positive_at: ArrayLike | None) -> tuple[Array, Array]:
    """Rows G c >= h keeping q > 0 and p >= 0 at ``positive_at`` (none without points);
    the same for every cut-off, so built once."""
    k = rf.n + rf.m
    if positive_at is None or not len(positive_at):
        return np.zeros((0, k)), np.zeros(0)
    # q on the extra points at least 1 % of its smallest value on the data (q is
    # scaled to mean 1 there): a margin that a sign change between points cannot hide in.
    q_floor = 0.01 * float(q0.min() / q0.mean())
    Pg, Qg = _design(rf, np.asarray(positive_at, dtype=float))
    pn = np.linalg.norm(Pg, axis=1)
    pn[pn == 0] = 1.0
    grid = np.vstack([np.hstack([np.zeros_like(Pg), Qg]),
                      np.hstack([Pg / pn[:, None], np.zeros_like(Qg)])])
    return grid, np.concatenate([np.full(len(Qg), q_floor), np.zeros(len(Pg))])


# Points per block of the polish's passes over every sample: a block's rows stay in
# cache (one LAPACK QR of 262 144 x 45 took 0.7 s, the same R from 8192-row blocks 0.16 s).
_BLOCK = 8192


def _tall_r(M: Array, tail: Array) -> Array:
    """R of the QR of [M; tail], from the R factors of row blocks (TSQR): the same
    R up to signs, as accurate as one Householder QR, several times faster on
    hundreds of thousands of rows."""
    if M.shape[0] <= 4 * _BLOCK:
        return np.linalg.qr(np.vstack([M, tail]), mode="r")
    parts = [np.linalg.qr(M[s:s + _BLOCK], mode="r") for s in range(0, M.shape[0], _BLOCK)]
    return np.linalg.qr(np.vstack([*parts, tail]), mode="r")


class _BandRows:
    """The rows of the polish's band, G c >= h: per point i the lower row
    (P_i, -lo_i Q_i) / |.| and the upper row (-P_i, hi_i Q_i) / |.| (2N rows, never
    stored as one 2N x k matrix), then the positivity rows ``grid``."""

    def __init__(self, P: Array, Q: Array, lo_in: Array, hi_in: Array, grid: Array,
                 h_grid: Array) -> None:
        self.P, self.Q, self.lo_in, self.hi_in = P, Q, lo_in, hi_in
        self.grid, self.h_grid = grid, h_grid
        self.N = P.shape[0]
        s_lo = np.empty(self.N)
        s_hi = np.empty(self.N)
        for s in range(0, self.N, _BLOCK):
            sl = slice(s, s + _BLOCK)
            p, q = P[sl], Q[sl]
            s_lo[sl] = np.linalg.norm(np.hstack([p, -lo_in[sl, None] * q]), axis=1)
            s_hi[sl] = np.linalg.norm(np.hstack([-p, hi_in[sl, None] * q]), axis=1)
        s_lo[s_lo == 0] = 1.0
        s_hi[s_hi == 0] = 1.0
        self.s_lo, self.s_hi = s_lo, s_hi

    @property
    def count(self) -> int:
        return 2 * self.N + self.grid.shape[0]

    def rows(self, idx: NDArray[np.int64]) -> tuple[Array, Array]:
        """(G, h) at rows ``idx``."""
        N = self.N
        out = np.empty((idx.size, self.P.shape[1] + self.Q.shape[1]))
        h = np.zeros(idx.size)
        n = self.P.shape[1]
        lo_r, hi_r, g_r = idx < N, (idx >= N) & (idx < 2 * N), idx >= 2 * N
        i = idx[lo_r]
        out[lo_r, :n] = self.P[i] / self.s_lo[i, None]
        out[lo_r, n:] = -(self.lo_in[i] / self.s_lo[i])[:, None] * self.Q[i]
        i = idx[hi_r] - N
        out[hi_r, :n] = -self.P[i] / self.s_hi[i, None]
        out[hi_r, n:] = (self.hi_in[i] / self.s_hi[i])[:, None] * self.Q[i]
        out[g_r] = self.grid[idx[g_r] - 2 * N]
        h[g_r] = self.h_grid[idx[g_r] - 2 * N]
        return out, h

    def data_residuals(self, pa: Array, qb: Array) -> Array:
        """G c at the 2N data rows, from p = P a and q = Q b at every point."""
        return np.concatenate([(pa - self.lo_in * qb) / self.s_lo,
                               (self.hi_in * qb - pa) / self.s_hi])


def _solve_band(P: Array, Q: Array, lo: Array, hi: Array, Rinv: Array, tau: float,
                grid: Array, h_grid: Array, rf: RationalFunction, solver: str,
                max_rounds: int, start_rows: int, deadline: float | None) -> Array | None:
    """The active-set QP of :func:`polish_fit` for one cut-off ``tau``: its
    coefficients (a, b), or None when infeasible, unsolved or out of time."""
    n, m = P.shape[1], Q.shape[1]
    k = n + m
    width = hi - lo
    band = _BandRows(P, Q, lo + tau * width, hi - tau * width, grid, h_grid)
    mean_q = np.concatenate([np.zeros(n), Q.mean(axis=0)])
    # Start from the rows nearest to binding for the starting fit, spread over the data.
    c0 = np.concatenate([rf.p, rf.q]) / float(Q.mean(axis=0) @ rf.q)
    slack = band.data_residuals(P @ c0[:n], Q @ c0[n:])
    order = np.argsort(slack)
    active = np.zeros(band.count, dtype=bool)
    active[order[: min(start_rows, order.size)]] = True
    batch = max(200, 8 * k)
    e = mean_q @ Rinv  # mean q = 1 as two inequalities (the adapters take A z >= b only)
    # Right-hand sides raised where the solver met an active row only to its own
    # tolerance: in z = R c coordinates an ill-conditioned H (a specular peak, q
    # over four decades) turns that tolerance into real misses of the band.
    lift = np.zeros(band.count)
    for _ in range(max_rounds):
        if deadline is not None and time.perf_counter() > deadline:
            return None
        idx = np.flatnonzero(active)
        G, h = band.rows(idx)
        A = np.vstack([G @ Rinv, e, -e])
        b = np.concatenate([h + lift[idx], [1.0, -1.0]])
        sol = solve_qp(A, b, solver)
        if sol.status != "optimal" or sol.x is None:
            return None
        c = Rinv @ sol.x
        pa, qb = P @ c[:n], Q @ c[n:]
        res = np.concatenate([band.data_residuals(pa, qb), grid @ c - h_grid])
        # missed: the value itself lands in the outer half of the cut (or, at tau = 0,
        # outside the segment by more than 1e-9 of its width); a positivity row by
        # more than 1e-9. A row met to rounding is not missed: with q over six decades
        # lifting those never settles.
        with np.errstate(all="ignore"):
            r = pa / qb
        slack = np.minimum(r - (lo + 0.5 * tau * width), (hi - 0.5 * tau * width) - r)
        off = ~(slack >= -1e-9 * width)
        # (only the side a missed value crossed: lifting the other would loosen it)
        missed = active & (res < 0) & np.concatenate([off, off, res[2 * len(lo):] < -1e-9])
        bad = np.flatnonzero(~(res >= 0) & ~active)
        if bad.size == 0 and not missed.any():
            break
        lift[missed] += 2.0 * -res[missed]
        active[bad[np.argsort(res[bad])[:batch]]] = True
    else:
        return None
    return c
