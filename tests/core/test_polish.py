"""The least-squares polish: same (n, m), inside the segments, closer to the data."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ratfit.core.bases import PolynomialSpace
from ratfit.core.polish import _positivity_rows, bound_row_count, bound_rows, polish_fit
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.verify import verify
from ratfit.fitting.search import RationalFitter


def _rmse(rf, seg: Segments) -> float:
    return float(np.sqrt(np.mean((rf(seg.x) - seg.center[:, 0]) ** 2)))


def _fit(x: np.ndarray, y: np.ndarray, dt: float):
    seg = Segments.from_widths(x, y, dt=dt)
    res = RationalFitter(solver="daqp").fit(seg).result_
    assert res.success
    return res.rational, seg


def test_polish_keeps_size_stays_inside_and_halves_the_error() -> None:
    x = np.linspace(0.0, 1.0, 400)
    y = np.exp(2 * x) / (1.3 - x)
    rf, seg = _fit(x, y, 0.05)
    pol = polish_fit(rf, seg, 0, tau=0.02)
    assert pol is not None and (pol.n, pol.m) == (rf.n, rf.m)
    ver = verify(pol, seg, channel=0)
    assert ver.verified and ver.n_violations == 0 and ver.poles_in_domain == 0
    # inside the inner 96 % of every segment (tau = 0.02 off each end)
    w = seg.hi[:, 0] - seg.lo[:, 0]
    r = pol(seg.x)
    assert np.all(r >= seg.lo[:, 0] + 0.02 * w - 1e-9 * np.abs(seg.hi[:, 0]))
    assert np.all(r <= seg.hi[:, 0] - 0.02 * w + 1e-9 * np.abs(seg.hi[:, 0]))
    # the minimum-norm fit runs along the segments' edges; the polish does not
    assert _rmse(pol, seg) < 0.5 * _rmse(rf, seg)


def test_polish_respects_extra_positivity_points() -> None:
    # p / q fitted on [0, 1] only; the polish must also keep q > 0, p >= 0 on [1, 1.5].
    x = np.linspace(0.0, 1.0, 300)
    y = 1.0 + np.sin(3 * x) ** 2
    rf, seg = _fit(x, y, 0.03)
    extra = np.linspace(0.0, 1.5, 301)[:, None]
    pol = polish_fit(rf, seg, 0, positive_at=extra)
    assert pol is not None
    assert np.all(pol.denominator(extra) > 0)
    assert np.all(pol.numerator(extra) >= -1e-12)
    assert verify(pol, seg, channel=0).verified


def test_polish_refuses_a_start_with_q_of_both_signs() -> None:
    x = np.linspace(-1.0, 1.0, 50)
    seg = Segments.from_widths(x, np.ones_like(x), dt=0.1)
    from ratfit.core.bases import PolynomialSpace
    from ratfit.core.rational import RationalFunction

    rf = RationalFunction(PolynomialSpace("legendre", [[-1.0, 1.0]]), [1.0], [0.0, 1.0])
    assert polish_fit(rf, seg, 0) is None


@settings(max_examples=15, deadline=None)
@given(a=st.floats(0.2, 3.0), c=st.floats(1.05, 3.0), dt=st.sampled_from([0.01, 0.05, 0.2]))
def test_polish_is_never_outside_its_band(a: float, c: float, dt: float) -> None:
    x = np.linspace(0.0, 1.0, 120)
    y = np.exp(a * x) / (c - x)
    rf, seg = _fit(x, y, dt)
    pol = polish_fit(rf, seg, 0)
    if pol is None:  # allowed: the caller keeps the fit it has
        return
    assert verify(pol, seg, channel=0).verified
    lo, hi = seg.lo[:, 0], seg.hi[:, 0]
    w = hi - lo
    r, r0 = pol(seg.x), rf(seg.x)
    # Each pass's QP point keeps tau = 0.02 of every width off the ends (or tau / 20,
    # or half the start's smallest margin, where the minimal size leaves no room),
    # and the line search's point is a positive-weight average of it and the start
    # at every sample (weights q0 (1 - a) / q, q1 a / q): no sample gets closer to
    # an end than both of them.
    start = np.minimum(r0 - lo, hi - r0)
    keep = np.minimum(start, np.minimum(0.001, 0.5 * np.min(start / w)) * w)
    assert np.all(r - lo >= keep - 1e-9 * y.max())
    assert np.all(hi - r >= keep - 1e-9 * y.max())


@pytest.mark.parametrize("tau", [0.0, 0.1])
def test_polish_tau_bounds_the_band(tau: float) -> None:
    x = np.linspace(0.0, 1.0, 200)
    y = 2.0 + x**2
    rf, seg = _fit(x, y, 0.1)
    pol = polish_fit(rf, seg, 0, tau=tau)
    assert pol is not None
    w = seg.hi[:, 0] - seg.lo[:, 0]
    r = pol(seg.x)
    assert np.all(r >= seg.lo[:, 0] + tau * w - 1e-9)
    assert np.all(r <= seg.hi[:, 0] - tau * w + 1e-9)


def test_polish_gives_up_past_its_deadline() -> None:
    import time

    x = np.linspace(0.0, 1.0, 400)
    rf, seg = _fit(x, np.exp(2 * x) / (1.3 - x), 0.05)
    assert polish_fit(rf, seg, 0, deadline=time.perf_counter() + 60) is not None
    assert polish_fit(rf, seg, 0, deadline=time.perf_counter() - 1) is None


def test_cone_program_gives_the_same_polish_as_the_qp() -> None:
    """The fallback (Clarabel's cone program in c) solves the problem the whitened QP
    solves: the same fit, to the solvers' accuracy."""
    pytest.importorskip("clarabel")
    x = np.linspace(0.0, 1.0, 300)
    y = np.exp(2 * x) / (1.3 - x)
    rf, seg = _fit(x, y, 0.05)
    qp = polish_fit(rf, seg, 0, method="qp")
    cone = polish_fit(rf, seg, 0, method="socp")
    assert qp is not None and cone is not None
    assert verify(cone, seg, channel=0).verified
    assert _rmse(cone, seg) < 0.7 * _rmse(rf, seg)
    assert abs(_rmse(cone, seg) - _rmse(qp, seg)) < 1e-3 * _rmse(qp, seg)
    t = np.linspace(0.0, 1.0, 1000)
    assert np.max(np.abs(cone(t) - qp(t))) < 1e-3 * np.max(np.abs(qp(t)))


def test_polish_uses_the_cone_program_where_the_qp_fails(monkeypatch) -> None:
    pytest.importorskip("clarabel")
    import ratfit.core.polish as polish

    x = np.linspace(0.0, 1.0, 300)
    y = np.exp(2 * x) / (1.3 - x)
    rf, seg = _fit(x, y, 0.05)
    monkeypatch.setattr(polish, "_whitened", lambda Rinv, solver: lambda G, h, e: None)
    assert polish_fit(rf, seg, 0, method="qp") is None
    pol = polish_fit(rf, seg, 0)
    assert pol is not None and verify(pol, seg, channel=0).verified
    assert _rmse(pol, seg) < 0.7 * _rmse(rf, seg)


def test_polish_asks_p_above_a_margin_at_the_positivity_points(monkeypatch) -> None:
    """A row p >= 0 met to the solver's tolerance leaves p at -1e-13 where it touches
    0: a negative BRDF to the validity check, found again beside every point added
    (garnet_red G: four rounds, no polish). The rows ask p >= 1e-6 of the largest
    value, or half the start's p where that is smaller, so the start stays feasible."""
    import ratfit.core.polish as polish

    x = np.linspace(0.0, 1.0, 300)
    y = 1.0 + np.sin(3 * x) ** 2
    rf, seg = _fit(x, y, 0.03)
    extra = np.linspace(0.0, 1.5, 301)[:, None]
    seen = []
    real = polish._solve_band

    def spy(D, lo, hi, qp, tau, grid, h_grid, q_floor, c, *rest):
        seen.append((grid, h_grid, q_floor, c, D))
        return real(D, lo, hi, qp, tau, grid, h_grid, q_floor, c, *rest)

    monkeypatch.setattr(polish, "_solve_band", spy)
    assert polish_fit(rf, seg, 0, positive_at=extra) is not None
    grid, h, q_floor, c, D = seen[0]
    p_rows = np.arange(len(h)) >= len(h) - len(extra)  # the p rows come last
    start = grid[p_rows] @ c
    assert np.all(start > 0)
    pn = np.linalg.norm(polish._design(rf, extra)[0], axis=1)  # rows: p / ||design row||
    expect = np.minimum(1e-6 * y.max() / pn, 0.5 * start)
    assert np.allclose(h[p_rows], expect, rtol=1e-9) and np.all(h[p_rows] > 0)
    # q rows: at the data 1 % of the start's smallest q there (q scaled to mean 1 there);
    # at the extra points half the start's own q where that is more (a q held at 1 % of
    # the data's smallest dipped below 0 between the points, cayman B: a new corner
    # found by the proof every round, no polish)
    assert np.isclose(q_floor, 0.01 * np.min(D.values(c)[1]), rtol=1e-9)
    q_start = grid[~p_rows] @ c
    assert np.all(q_start > 0)
    np.testing.assert_allclose(h[~p_rows], np.maximum(q_floor, 0.5 * q_start), rtol=1e-12)
    assert np.any(h[~p_rows] > q_floor)


class _Rows:
    """A stand-in basis whose values at point i are row i of a matrix."""

    def __init__(self, M: np.ndarray) -> None:
        self.M = M

    def design(self, x: np.ndarray, count: int) -> np.ndarray:
        return self.M[np.asarray(x, dtype=int).ravel(), :count]


def _matrices(P: np.ndarray, Q: np.ndarray):
    """The polish's sample values with P and Q given as matrices."""
    from types import SimpleNamespace

    from ratfit.core import polish

    rf = SimpleNamespace(n=P.shape[1], m=Q.shape[1], p_basis=_Rows(P), q_basis=_Rows(Q),
                         space=None)
    return polish._Design(rf, np.arange(P.shape[0]))


def test_blocked_r_factor_and_band_rows_match_the_stacked_matrices() -> None:
    """The polish's passes in blocks (TSQR, band rows built per active set) give the
    numbers of the one-matrix form they replaced."""
    from ratfit.core import polish

    rng = np.random.default_rng(3)
    N, n, m = 5 * polish._BLOCK + 17, 4, 3  # beyond 4 blocks: the blocked path
    P, Q = rng.normal(size=(N, n)), rng.normal(size=(N, m))
    y, scale = rng.uniform(0.5, 2.0, N), rng.uniform(0.1, 10.0, N)
    M = np.hstack([P, -y[:, None] * Q]) * scale[:, None]
    ridge = 1e-10 * np.sum(M * M) / (n + m)
    D = _matrices(P, Q)
    R = polish._objective_r(D, y, scale)
    R_ref = np.linalg.qr(np.vstack([M, np.sqrt(ridge) * np.eye(n + m)]), mode="r")
    assert np.allclose(np.abs(R), np.abs(R_ref), rtol=1e-10, atol=1e-10)
    assert np.allclose(R.T @ R, M.T @ M + ridge * np.eye(n + m), rtol=1e-10)
    lo, hi = rng.uniform(0.5, 1.0, N), rng.uniform(1.5, 2.0, N)
    grid, h = rng.normal(size=(5, n + m)), rng.uniform(size=5)
    band = polish._BandRows(D, lo, hi, grid, h)
    G_lo = np.hstack([P, -lo[:, None] * Q])
    G_hi = np.hstack([-P, hi[:, None] * Q])
    ref = np.vstack([G_lo / np.linalg.norm(G_lo, axis=1)[:, None],
                     G_hi / np.linalg.norm(G_hi, axis=1)[:, None], grid])
    idx = np.array([0, 7, N - 1, N, N + 5, 2 * N - 1, 2 * N, 2 * N + 4])
    rows, hh = band.rows(idx)
    assert np.allclose(rows, ref[idx], rtol=1e-12, atol=1e-14)
    assert np.array_equal(hh, np.concatenate([np.zeros(6), h[[0, 4]]]))
    c = rng.normal(size=n + m)
    res = band.data_residuals(P @ c[:n], Q @ c[n:])
    assert np.allclose(res, ref[:2 * N] @ c, rtol=1e-9, atol=1e-12)


def test_band_rows_keep_q_above_its_floor_at_the_data() -> None:
    """With a q floor the band has N more rows, (0, Q_i) >= q_floor, between the 2N
    band rows and the positivity rows: p and q both near 0 at a sample meet the band
    rows for any value of r = p / q."""
    from ratfit.core import polish

    rng = np.random.default_rng(5)
    N, n, m = 50, 3, 2
    P, Q = rng.normal(size=(N, n)), rng.normal(size=(N, m))
    lo, hi = rng.uniform(0.5, 1.0, N), rng.uniform(1.5, 2.0, N)
    grid, h = rng.normal(size=(4, n + m)), rng.uniform(size=4)
    band = polish._BandRows(_matrices(P, Q), lo, hi, grid, h, q_floor=0.25)
    assert band.count == 3 * N + 4
    idx = np.array([2 * N, 2 * N + 7, 3 * N - 1, 3 * N, 3 * N + 3])
    rows, hh = band.rows(idx)
    assert np.allclose(rows[:3, :n], 0.0) and np.allclose(rows[:3, n:], Q[[0, 7, N - 1]])
    assert np.allclose(rows[3:], grid[[0, 3]])
    assert np.allclose(hh, [0.25, 0.25, 0.25, h[0], h[3]])
    c = rng.normal(size=n + m)
    res = band.residuals(c, P @ c[:n], Q @ c[n:])
    assert np.allclose(res[2 * N:3 * N], Q @ c[n:] - 0.25)
    assert np.allclose(res[3 * N:], grid @ c - h)


def test_repair_mode_is_one_pass_inside_half_the_start_margin(monkeypatch) -> None:
    """A repair (an invalid candidate of the search) takes one linearised pass and its
    QP's answer as it is: q > 0, p >= 0 at the positivity points, and the band cut at
    half the start's own margin (the inner 96 % is often empty at the minimal size)."""
    import ratfit.core.polish as polish

    x = np.linspace(0.0, 1.0, 300)
    y = 1.0 + np.sin(3 * x) ** 2
    rf, seg = _fit(x, y, 0.03)
    lo, hi = seg.lo[:, 0], seg.hi[:, 0]
    w = hi - lo
    r0 = rf(seg.x)
    margin = float(np.min(np.minimum(r0 - lo, hi - r0) / w))
    tau = 0.4  # above this start's own margin, as 0.02 is at a minimal BRDF size
    assert 0 < margin / 2 < tau
    passes, cuts = [], []
    real_pass, real_band = polish._polish_pass, polish._solve_band

    def counting_pass(*a, **k):
        passes.append(a[-1] if len(a) > 14 else k.get("repair"))
        return real_pass(*a, **k)

    def recording_band(D, lo_, hi_, qp, tau, *a, **k):
        cuts.append(tau)
        return real_band(D, lo_, hi_, qp, tau, *a, **k)

    monkeypatch.setattr(polish, "_polish_pass", counting_pass)
    monkeypatch.setattr(polish, "_solve_band", recording_band)
    extra = np.linspace(0.0, 1.5, 301)[:, None]
    fixed = polish_fit(rf, seg, 0, positive_at=extra, tau=tau, repair=True)
    assert fixed is not None and passes == [True]
    assert cuts == [pytest.approx(margin / 2, rel=1e-9)]
    assert np.all(fixed.denominator(extra) > 0)
    assert np.all(fixed.numerator(extra) >= -1e-12)
    r = fixed(seg.x)
    assert np.all(r >= lo + 0.25 * margin * w) and np.all(r <= hi - 0.25 * margin * w)
    assert verify(fixed, seg, channel=0).verified
    # the full polish of the same start tries tau first, in passes of its own
    passes.clear()
    cuts.clear()
    polish_fit(rf, seg, 0, positive_at=extra, tau=tau)
    assert cuts[0] == tau and passes and set(passes) == {False}


@pytest.mark.parametrize("screen", [None, 600])
def test_polish_is_the_same_whatever_the_design_budget_keeps(monkeypatch, screen) -> None:
    """The polish keeps its basis values at every sample only as far as the process's
    design budget goes and computes the rest again at each pass: with the budget
    exhausted, half of it or all of it, the same coefficients bit for bit, and the
    budget's bytes all handed back afterwards (with the rounds screening a few
    samples before every sample, as on large data, too)."""
    from ratfit.core import polish, qp

    if screen is not None:
        monkeypatch.setattr(polish, "_SCREEN", screen)
    x = np.linspace(0.0, 1.0, 3 * polish._BLOCK + 123)  # four blocks
    y = np.exp(2 * x) / (1.3 - x)
    rf, seg = _fit(x, y, 0.05)
    k = rf.n + rf.m
    results = []
    for limit in (0, 8 * k * polish._BLOCK * 2, qp.DESIGN_BUDGET):
        monkeypatch.setattr(qp._DESIGN_BUDGET, "limit", limit)
        kept = []
        real_close = polish._Design.close

        def spy_close(self, kept=kept, real_close=real_close):
            kept.append(len(self.store.chunks))
            real_close(self)

        monkeypatch.setattr(polish._Design, "close", spy_close)
        pol = polish_fit(rf, seg, 0, tau=0.02)
        assert pol is not None and qp._DESIGN_BUDGET.used == 0
        results.append((np.concatenate([pol.p, pol.q]), kept[0]))
    (c0, kept0), (c1, kept1), (c2, kept2) = results
    assert (kept0, kept2) == (0, 4) and 0 < kept1 < 4
    assert np.array_equal(c0, c1) and np.array_equal(c0, c2)
    assert verify(polish_fit(rf, seg, 0, tau=0.02), seg, channel=0).verified


def test_screened_rounds_give_the_fit_of_the_full_rounds(monkeypatch) -> None:
    """On large data the active-set rounds check the samples most likely to bind and
    every sample only when those are met: the polished fit stays inside the inner band
    at every sample, is as good as the fit of rounds that check every sample, and its
    QP solves pass over every sample fewer times."""
    from ratfit.core import polish

    x = np.linspace(0.0, 1.0, 20_000)
    y = 1.0 + 0.5 * np.sin(9 * x) + 2.0 / (1.05 - x)
    rf, seg = _fit(x, y, 0.02)
    fits, passes = [], []
    real_values = polish._Design.values

    def counting(self, c):
        passes[-1] += 1
        return real_values(self, c)

    monkeypatch.setattr(polish._Design, "values", counting)
    for screen in (10**9, 500):  # every sample each round; 500 screened
        monkeypatch.setattr(polish, "_SCREEN", screen)
        passes.append(0)
        pol = polish_fit(rf, seg, 0, tau=0.02, start_rows=100)  # a few rounds
        assert pol is not None and verify(pol, seg, channel=0).verified
        w = seg.hi[:, 0] - seg.lo[:, 0]
        r = pol(seg.x)
        assert np.all(r >= seg.lo[:, 0] + 0.01 * w) and np.all(r <= seg.hi[:, 0] - 0.01 * w)
        fits.append(_rmse(pol, seg))
    assert fits[1] <= 1.01 * fits[0] and fits[0] < 0.9 * _rmse(rf, seg)
    assert passes[1] < passes[0]


def test_bound_rows_are_the_ceiling_and_floor_in_coefficients() -> None:
    rng = np.random.default_rng(3)
    P, Q = rng.normal(size=(6, 3)), rng.normal(size=(6, 2))
    p, q = rng.normal(size=3), rng.normal(size=2)
    c = np.concatenate([p, q])
    ceiling = rng.normal(size=6)
    floor = np.array([0.5, -np.inf, 2.0, -np.inf, -np.inf, 1.0])
    rows = bound_rows(P, Q, ceiling, floor)
    assert rows.shape == (6 + 3, 5)  # one ceiling row a point, a floor row where finite
    np.testing.assert_allclose(rows[:6] @ c, ceiling * (Q @ q) - P @ p, rtol=1e-13)
    at = np.isfinite(floor)
    np.testing.assert_allclose(rows[6:] @ c, (P @ p - floor * (Q @ q))[at], rtol=1e-13)
    # one ceiling for every point; nothing asked, no rows
    np.testing.assert_allclose(bound_rows(P, Q, 2.0) @ c, 2.0 * (Q @ q) - P @ p, rtol=1e-13)
    assert bound_rows(P, Q).shape == (0, 5)
    # written into a given array: the same numbers, and the count it needs
    assert bound_row_count(6, ceiling, floor) == 9 and bound_row_count(6) == 0
    out = np.full((10, 5), np.nan)
    assert bound_rows(P, Q, ceiling, floor, out=out[1:]) is not None
    assert np.array_equal(out[1:], rows) and np.isnan(out[0]).all()
    with pytest.raises(ValueError, match="rows need"):
        bound_rows(P, Q, ceiling, floor, out=out)


def test_the_polishs_validity_rows_are_q_p_and_the_bounds_unit_scaled() -> None:
    """_positivity_rows: q rows as they are, then p rows and the bound rows, each divided
    by its norm (the second array: 1 / that norm, 0 on q rows), in one array."""
    space = PolynomialSpace("legendre", [[-1.0, 1.0]], "total")
    rf = RationalFunction(space, np.array([1.0, 0.5, 0.2]), np.array([2.0, 0.3]))
    pts = np.linspace(-1, 1, 7)[:, None]
    P = np.polynomial.legendre.legvander(pts[:, 0], 2)
    Q = np.polynomial.legendre.legvander(pts[:, 0], 1)
    floor = np.where(pts[:, 0] > 0, 0.1, -np.inf)
    G, inv = _positivity_rows(rf, pts, numerator=True, ceiling=3.0, floor=floor)
    assert G.shape == (7 + 7 + 7 + 3, 5) and inv.shape == (24,)
    assert np.array_equal(G[:7], np.hstack([np.zeros((7, 3)), Q])) and not inv[:7].any()
    raw = np.vstack([np.hstack([P, np.zeros((7, 2))]), bound_rows(P, Q, 3.0, floor)])
    np.testing.assert_allclose(G[7:], raw / np.linalg.norm(raw, axis=1)[:, None], rtol=1e-15)
    np.testing.assert_allclose(inv[7:], 1.0 / np.linalg.norm(raw, axis=1), rtol=1e-15)
    q_only, none = _positivity_rows(rf, pts, numerator=False)
    assert np.array_equal(q_only, G[:7]) and not none.any()
