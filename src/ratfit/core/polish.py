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
    R = np.linalg.qr(np.vstack([M, np.sqrt(ridge) * np.eye(k)]), mode="r")
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


def _solve_band(P: Array, Q: Array, lo: Array, hi: Array, Rinv: Array, tau: float,
                grid: Array, h_grid: Array, rf: RationalFunction, solver: str,
                max_rounds: int, start_rows: int, deadline: float | None) -> Array | None:
    """The active-set QP of :func:`polish_fit` for one cut-off ``tau``: its
    coefficients (a, b), or None when infeasible, unsolved or out of time."""
    n, m = P.shape[1], Q.shape[1]
    k = n + m
    width = hi - lo
    lo_in = lo + tau * width
    hi_in = hi - tau * width
    # Inequality rows G c >= h, in the (a, b) coefficients.
    G_lo = np.hstack([P, -lo_in[:, None] * Q])
    G_hi = np.hstack([-P, hi_in[:, None] * Q])
    mean_q = np.concatenate([np.zeros(n), Q.mean(axis=0)])
    rows_data = np.vstack([G_lo, G_hi])
    scale = np.linalg.norm(rows_data, axis=1)
    scale[scale == 0] = 1.0
    rows_data = rows_data / scale[:, None]
    all_rows = np.vstack([rows_data, grid])
    all_h = np.concatenate([np.zeros(rows_data.shape[0]), h_grid])
    # Start from the rows nearest to binding for the starting fit, spread over the data.
    c0 = np.concatenate([rf.p, rf.q]) / float(Q.mean(axis=0) @ rf.q)
    slack = rows_data @ c0
    order = np.argsort(slack)
    active = np.zeros(all_rows.shape[0], dtype=bool)
    active[order[: min(start_rows, order.size)]] = True
    batch = max(200, 8 * k)
    e = mean_q @ Rinv  # mean q = 1 as two inequalities (the adapters take A z >= b only)
    # Right-hand sides raised where the solver met an active row only to its own
    # tolerance: in z = R c coordinates an ill-conditioned H (a specular peak, q
    # over four decades) turns that tolerance into real misses of the band.
    lift = np.zeros_like(all_h)
    for _ in range(max_rounds):
        if deadline is not None and time.perf_counter() > deadline:
            return None
        idx = np.flatnonzero(active)
        A = np.vstack([all_rows[idx] @ Rinv, e, -e])
        b = np.concatenate([all_h[idx] + lift[idx], [1.0, -1.0]])
        sol = solve_qp(A, b, solver)
        if sol.status != "optimal" or sol.x is None:
            return None
        c = Rinv @ sol.x
        res = all_rows @ c - all_h
        # missed: the value itself lands in the outer half of the cut (or, at tau = 0,
        # outside the segment by more than 1e-9 of its width); a positivity row by
        # more than 1e-9. A row met to rounding is not missed: with q over six decades
        # lifting those never settles.
        with np.errstate(all="ignore"):
            r = (P @ c[:n]) / (Q @ c[n:])
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
