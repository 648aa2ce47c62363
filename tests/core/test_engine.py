"""Engine tests: bases, conditioning, the QP, the search, verification."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import chebyshev as C
from numpy.polynomial import legendre as L

import ratfit
from ratfit.core import qp as qpmod
from ratfit.core.bases import PolynomialSpace, multi_indices
from ratfit.core.qp import ConstraintSystem, solve_fixed
from ratfit.core.rational import RationalFunction
from ratfit.core.solvers import QPSolution, register_solver
from ratfit.core.verify import verify
from ratfit.demos.addendum import PAPER_TABLE, addendum_function, addendum_segments
from ratfit.errors import InputError
from ratfit.io.data import read_data


# ---------------------------------------------------------------------------- bases
def test_multi_indices_graded_orders():
    tot = multi_indices(2, 6, "total")
    assert tot.tolist() == [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    ten = multi_indices(2, 9, "tensor")
    assert sorted(map(tuple, ten.tolist())) == [(i, j) for i in range(3) for j in range(3)]
    assert ten[:4].tolist() == [[0, 0], [1, 0], [0, 1], [1, 1]]
    assert multi_indices(3, 20, "total").sum(axis=1).max() == 3  # 1 + 3 + 6 + 10 terms
    assert multi_indices(1, 5).ravel().tolist() == [0, 1, 2, 3, 4]


def test_design_matches_numpy_vander_2d():
    rng = np.random.default_rng(1)
    x = rng.uniform([0, -5], [2, 5], size=(50, 2))
    space = PolynomialSpace("chebyshev", [[0, 2], [-5, 5]], "tensor")
    t = space.to_window(x)
    assert np.allclose(t[:, 0], x[:, 0] - 1) and np.allclose(t[:, 1], x[:, 1] / 5)
    V = C.chebvander2d(t[:, 0], t[:, 1], [2, 2])  # column i*3 + j is T_i(t0) T_j(t1)
    D = space.design(x, 9)
    for col, (i, j) in enumerate(space.indices(9)):
        assert np.allclose(D[:, col], V[:, 3 * i + j], rtol=1e-14, atol=1e-14)


def test_evaluate_1d_uses_basis_and_domain():
    space = PolynomialSpace("legendre", [[2.0, 6.0]])
    c = np.array([0.5, -1.0, 2.0, 0.25])
    x = np.linspace(2, 6, 17)
    assert np.allclose(space.evaluate(x, c), L.legval((x - 4) / 2, c), rtol=1e-14)


@pytest.mark.parametrize(
    "bad", [dict(family="hermite"), dict(domain=[[1.0, 1.0]]), dict(index_set="sparse")]
)
def test_space_rejects_bad_parameters(bad):
    kw = dict(family="legendre", domain=[[0.0, 1.0]], index_set="total") | bad
    with pytest.raises(InputError):
        PolynomialSpace(kw["family"], kw["domain"], kw["index_set"])


# ---------------------------------------------------------------------------- segments
@pytest.mark.parametrize(
    "x, lo, hi, match",
    [
        ([0, 1, np.nan], [0, 0, 0], [1, 1, 1], "NaN"),
        ([0, 1, 2], [0, 0, np.inf], [1, 1, 1], "inf"),
        ([0, 1, 2], [0, 2, 0], [1, 1, 1], "lo > hi"),
        ([0, 1, 2], [0, 0], [1, 1], "mismatched lengths"),
        ([], [], [], "empty"),
        ([[0, 1], [1, 1], [2, 1]], [0, 0, 0], [1, 1, 1], "constant in dimension 1"),
    ],
)
def test_segments_reject_bad_input(x, lo, hi, match):
    with pytest.raises(InputError, match=match):
        ratfit.Segments(x, lo, hi)


def test_relative_segments_order_negative_values():
    s = ratfit.Segments.from_relative([0, 1], [-2.0, 3.0], 0.1)
    assert np.allclose(s.lo[:, 0], [-2.2, 2.7]) and np.allclose(s.hi[:, 0], [-1.8, 3.3])


# ---------------------------------------------------------------------------- conditioning
def _full_matrix(space, seg, n, m):
    B = space.design(seg.x, max(n, m))
    lo, hi = seg.lo[:, :1], seg.hi[:, :1]
    return np.vstack(
        [np.hstack([B[:, :n], -lo * B[:, :m]]), np.hstack([-B[:, :n], hi * B[:, :m]])]
    )


@pytest.mark.parametrize("chunk", [10_000, 97])
def test_tsqr_conditioning_matches_dense_svd(monkeypatch, chunk):
    monkeypatch.setattr(qpmod, "_CHUNK", chunk)
    seg = addendum_segments(400)
    space = PolynomialSpace("legendre", seg.bounds())
    system = ConstraintSystem(space, seg)
    system.prepare(12, 12)
    for n, m in [(3, 5), (12, 12), (7, 1), (1, 9)]:
        s = np.linalg.svd(_full_matrix(space, seg, n, m), compute_uv=False)
        delta, smin, smax = system.conditioning(n, m)
        assert smin == pytest.approx(s[-1], rel=1e-9)
        assert smax == pytest.approx(s[0], rel=1e-12)
        assert delta == pytest.approx(s[-1] / s[0], rel=1e-9)
        A = _full_matrix(space, seg, n, m)
        assert np.allclose(system.row_norms(n, m), np.linalg.norm(A, axis=1), rtol=1e-13)


@pytest.mark.parametrize("basis", list(PAPER_TABLE))
def test_demo_table_matches_paper(basis):
    seg = addendum_segments()
    system = ConstraintSystem(PolynomialSpace(basis, seg.bounds()), seg)
    system.prepare(20, 20)
    got = system.conditioning(20, 20)
    for value, paper in zip(got, PAPER_TABLE[basis], strict=True):
        assert f"{value:.2g}" == f"{paper:.2g}" or value == pytest.approx(paper, rel=1e-3)


# ---------------------------------------------------------------------------- QP + search
def test_fixed_split_20_20_all_bases_verified():
    seg = addendum_segments()
    for basis in PAPER_TABLE:
        r = ratfit.fit(seg, basis=basis, n=20, m=20)
        assert r.success, (basis, r.message)
        assert r.verification.max_violation == 0.0
        assert r.verification.poles_in_domain == 0
        assert r.n == 20 and r.m == 20


@pytest.mark.slow
def test_demo_minimal_total_below_paper_and_verified():
    seg = addendum_segments()
    r = ratfit.fit(seg)
    assert r.success and r.total < 40
    # independent re-check of every segment with numpy's legval
    x = seg.x[:, 0]
    t = (x - 5) / 5
    fam = r.rational.to_family()  # data-orthonormal (Arnoldi) coefficients -> Legendre
    vals = L.legval(t, fam.p) / L.legval(t, fam.q)
    assert np.all(vals >= seg.lo[:, 0]) and np.all(vals <= seg.hi[:, 0])
    # minimality as far as the solver can tell: no split of total - 1 is verified
    below = ratfit.fit(seg, total=r.total - 1)
    assert not below.success and below.status in (1, 2)


def test_active_set_agrees_with_full_problem():
    seg = addendum_segments()
    space = PolynomialSpace("legendre", seg.bounds())
    system = ConstraintSystem(space, seg)
    for n, m, ctol in [(20, 20, 1e-6), (14, 14, None)]:
        full = solve_fixed(system, n, m, active_set=False)
        act = solve_fixed(system, n, m, active_set=True)
        assert full.status == act.status == "feasible"
        assert act.active_set_size < seg.n_points
        # same optimum of the QP (the objective is what the solver resolves well)
        nf, na = np.linalg.norm(full.c), np.linalg.norm(act.c)
        assert na == pytest.approx(nf, rel=1e-4)
        if ctol is not None:
            assert np.linalg.norm(act.c - full.c) <= ctol * nf


def test_staircase_total_equals_exhaustive_search():
    x = np.linspace(-1, 3, 150)
    y = np.exp(x) / (1 + x**2) + 0.3 * np.sin(3 * x)
    seg = ratfit.Segments.from_relative(x, y, 0.02)
    stair = ratfit.fit(seg, max_total=30)
    exh = ratfit.fit(seg, strategy="exhaustive", max_total=30)
    assert stair.success and exh.success
    assert stair.total == exh.total
    assert stair.qp_solves < exh.qp_solves


@pytest.mark.parametrize("name, limit", [("Kirby2", 6), ("MGH09", 4)])
def test_nist_certified_segments(shared_data, name, limit):
    data = read_data(shared_data / "nist" / f"{name}.dat")
    w = 3 * data.meta["certified_residual_sd"]
    seg = data.segments(abs_width=w)
    r = ratfit.fit(seg)
    assert r.success and r.total <= limit
    vals = r.rational(seg.x)
    assert np.all(np.abs(vals - data.y[:, 0]) <= w)


def test_infeasible_range_reports_best_reached():
    seg = addendum_segments()
    r = ratfit.fit(seg, max_total=8)
    assert not r.success and r.status in (1, 2)
    assert "no verified fit" in r.message or "failed verification" in r.message
    assert r.total <= 8


def test_multichannel_fits_each_channel():
    x = np.linspace(0, 1, 120)
    Y = np.stack([1 / (1 + 4 * x**2), np.cos(4 * x) + 2], axis=1)
    seg = ratfit.Segments.from_relative(x, Y, 0.01)
    f = ratfit.RationalFitter().fit(seg)
    assert len(f.results_) == 2 and f.success_
    for j, r in enumerate(f.results_):
        v = r.rational(x)
        assert np.all((v >= seg.lo[:, j]) & (v <= seg.hi[:, j]))
    assert f.results_[0].total <= 4  # 1 / (1 + 4x^2) is (1, 3) exactly


def test_nd_rational_recovered():
    rng = np.random.default_rng(3)
    X = rng.uniform([1, 2], [3, 5], size=(300, 2))
    Y = (1 + X[:, 0] ** 2 + X[:, 1]) / (2 + X[:, 0] * X[:, 1])
    seg = ratfit.Segments.from_relative(X, Y, 1e-3)
    r = ratfit.fit(seg, max_total=14)
    assert r.success and r.total <= 11  # exact form needs 4 + 5 graded terms at most
    v = r.rational(X)
    assert np.all((v >= seg.lo[:, 0]) & (v <= seg.hi[:, 0]))


def test_fitter_params_and_errors():
    f = ratfit.RationalFitter(basis="chebyshev")
    assert f.get_params()["basis"] == "chebyshev"
    with pytest.raises(InputError, match="unknown parameter"):
        f.set_params(degree=3)
    with pytest.raises(AttributeError, match="not fitted"):
        _ = f.result_
    seg = addendum_segments(50)
    for bad, match in [
        (dict(n=0, m=3), "n must be an integer >= 1"),
        (dict(n=3), "give both n and m"),
        (dict(min_total=10, max_total=5), "max_total"),
        (dict(solver="nope"), "unknown solver"),
        (dict(basis="nope"), "unknown basis"),
        (dict(domain=[[1.0, 2.0]]), "outside the given domain"),
    ]:
        with pytest.raises(InputError, match=match):
            ratfit.RationalFitter(**bad).fit(seg)


# ---------------------------------------------------------------------------- solver robustness
def test_lying_solver_is_cross_checked():
    def liar(A, b):
        return QPSolution("infeasible", None, "claims infeasible", "liar")

    register_solver("liar", "numpy", liar)
    x = np.linspace(0, 2, 80)
    seg = ratfit.Segments.from_relative(x, 1 / (1 + x), 0.05)
    checked = ratfit.fit(seg, solver="liar", max_total=6)
    assert checked.success
    assert checked.disagreements and "liar reported infeasible" in checked.disagreements[0]
    assert checked.decided_by == "liar+orth"
    lp = ratfit.fit(seg, solver="liar", cross_check="lp", max_total=6)
    assert lp.success and lp.decided_by == "liar+lp"
    trusting = ratfit.fit(seg, solver="liar", cross_check="none", max_total=6)
    assert not trusting.success and trusting.status == 1


def test_a_cross_check_that_breaks_down_proves_nothing(monkeypatch):
    """An "infeasible" is believed only when a cross check answered: one whose own
    solver broke down (or ran out of time) leaves the split failed, ruling out nothing."""
    import ratfit.core.qp as qp

    def liar(A, b):
        return QPSolution("infeasible", None, "claims infeasible", "liar")

    register_solver("liar", "numpy", liar)
    x = np.linspace(0, 2, 80)
    seg = ratfit.Segments.from_relative(x, 1 / (1 + x), 0.05)

    def broken(A, kind, time_limit=None):
        raise qp._Undecided("the check's solver broke down")

    monkeypatch.setattr(qp, "_cross_check", broken)
    monkeypatch.setattr(qp, "gordan_bound",
                        lambda A, thorough=True: float("inf"))  # no certificate either
    res = ratfit.fit(seg, solver="liar", max_total=6)
    assert not res.success and res.infeasible_proof is None
    assert {h["status"] for h in res.history} == {"failed"}
    assert "no rational of this size fits" not in res.message
    # a check that answers "no point" is a verdict: the same splits are infeasible
    monkeypatch.setattr(qp, "_cross_check", lambda A, kind, time_limit=None: None)
    res = ratfit.fit(seg, solver="liar", max_total=6)
    assert {h["status"] for h in res.history} == {"infeasible"}


def test_orth_no_point_is_confirmed_by_the_lp(monkeypatch):
    """The orth check (DAQP) missed points on EXR QPs that quadprog and the LP found:
    its "no point" is confirmed by the LP before an infeasibility is believed."""
    import ratfit.core.qp as qp

    def liar(A, b):
        return QPSolution("infeasible", None, "claims infeasible", "liar")

    register_solver("liar", "numpy", liar)
    x = np.linspace(0, 2, 80)
    seg = ratfit.Segments.from_relative(x, 1 / (1 + x), 0.05)
    real = qp._cross_check

    def orth_misses(A, kind, time_limit=None):
        return None if kind == "orth" else real(A, kind, time_limit)

    monkeypatch.setattr(qp, "_ORTH_SOLVER", "daqp")
    monkeypatch.setattr(qp, "_cross_check", orth_misses)
    res = ratfit.fit(seg, solver="liar", max_total=6)
    assert res.success and res.decided_by == "liar+lp"
    assert (res.n, res.m) == (1, 2)  # 1 / (1 + x)


def test_solver_returning_violating_point_is_not_success():
    def garbage(A, b):
        return QPSolution("optimal", np.ones(A.shape[1]), "optimal", "garbage")

    register_solver("garbage", "numpy", garbage)
    seg = addendum_segments(200)
    r = ratfit.fit(seg, solver="garbage", cross_check="none", n=5, m=5)
    assert not r.success


# ---------------------------------------------------------------------------- verification
def test_nan_at_a_point_counts_as_violation():
    space = PolynomialSpace("monomial", [[-1.0, 1.0]])
    rf = RationalFunction(space, [1.0], [0.0, 1.0])  # 1 / t: pole at 0
    x = np.linspace(-1, 1, 5)  # contains 0
    seg = ratfit.Segments(x, np.full(5, -10.0), np.full(5, 10.0))
    v = verify(rf, seg)
    assert not v.verified
    assert v.max_violation == np.inf and v.worst_index == 2
    assert v.poles_in_domain == 1 and v.pole_locations[0] == pytest.approx(0.0, abs=1e-12)


def test_pole_between_points_is_caught():
    space = PolynomialSpace("legendre", [[0.0, 1.0]])
    # zero at x = 0.51, i.e. t = 0.02 on the window
    q = L.poly2leg(np.polynomial.polynomial.polyfromroots([0.02]))
    rf = RationalFunction(space, [1e-9], q)
    x = np.array([0.0, 0.5, 1.0])  # no data point at the pole
    r = rf(x)
    seg = ratfit.Segments(x, r - 1, r + 1)
    v = verify(rf, seg)
    assert v.n_violations == 0
    assert not v.verified and v.poles_in_domain == 1 and v.denominator_sign_changes
    assert v.pole_locations[0] == pytest.approx(0.51, abs=1e-12)


def test_nd_sign_change_of_denominator_is_a_pole():
    space = PolynomialSpace("legendre", [[0.0, 1.0], [0.0, 1.0]])
    rf = RationalFunction(space, [1.0], [0.05, 0.0, 1.0])  # q = 0.05 + t1: zero inside
    X = np.array([[0.1, 0.9], [0.5, 0.8], [0.9, 0.95]])
    r = rf(X)
    seg = ratfit.Segments(X, r - 1, r + 1)
    v = verify(rf, seg)
    assert v.n_violations == 0 and not v.verified and v.denominator_sign_changes


def test_addendum_function_values():
    assert addendum_function(np.array([0.0]))[0] == pytest.approx(0.1)
    expected = 1000 * np.exp(-1) + 0.1 * np.exp(-6400) + 0.1
    assert addendum_function(np.array([1.0]))[0] == pytest.approx(expected, rel=1e-12)


def test_active_set_takes_the_same_rows_from_a_partial_sort():
    """smallest() (argpartition) picks the rows a full argsort picked; NaN rows last."""
    from ratfit.core.systems import smallest

    rng = np.random.default_rng(7)
    v = rng.normal(size=5000)
    v[[3, 99]] = np.nan
    for count in (1, 64, 4998):
        got = np.sort(smallest(v, count))
        assert np.array_equal(got, np.sort(np.argsort(v)[:count]))
    assert not np.isin([3, 99], smallest(v, 4998)).any()
    assert np.array_equal(np.sort(smallest(v, 10**6)), np.arange(5000))
    assert smallest(v, 0).size == 0


def test_lp_margin_falls_back_to_interior_point_when_the_simplex_cycles(monkeypatch) -> None:
    """HiGHS's dual simplex cycles on a few degenerate margin LPs (MERL size: 92 s and
    118 s inside one split): it is capped at 2 iterations per row and column and the
    LP goes to the interior-point method, whose margin is the verdict."""
    import scipy.optimize

    from ratfit.core import qp

    rng = np.random.default_rng(11)
    x = rng.uniform(-1, 1, (40, 3))
    An = np.hstack([np.ones((40, 1)), x])  # c = (1, 0, 0, 0) has margin 1/|row|
    An /= np.linalg.norm(An, axis=1)[:, None]
    calls = []
    real = scipy.optimize.linprog

    def linprog(*a, method, options, **kw):
        calls.append((method, options.get("maxiter")))
        if method == "highs-ds":  # as if it cycled up to its cap
            return scipy.optimize.OptimizeResult(status=1, message="iteration limit", x=None)
        return real(*a, method=method, options=options, **kw)

    monkeypatch.setattr(scipy.optimize, "linprog", linprog)
    c = qp._lp_margin(An)
    assert calls == [("highs-ds", min(2 * (40 + 4), qp.LP_SIMPLEX_PER_COLUMN * 5)),
                     ("highs-ipm", qp.LP_IPM_ITERATIONS)]
    assert c is not None and np.all(An @ c > 0.1)
    # both give up: no verdict, never "no point"
    monkeypatch.setattr(scipy.optimize, "linprog", lambda *a, **k: scipy.optimize.OptimizeResult(
        status=1, message="iteration limit", x=None))
    with pytest.raises(qp._Undecided):
        qp._lp_margin(An)


def test_tall_margin_lps_are_solved_on_subsets_with_the_same_verdicts(monkeypatch) -> None:
    """Past LP_MAX_ROWS rows the margin LP is solved on a subset, more rows added where
    its direction fails: a direction it returns has a positive margin at every row,
    and "no direction" comes with a tight certificate (here: rows r and -r)."""
    from ratfit.core import qp

    monkeypatch.setattr(qp, "LP_MAX_ROWS", 200)
    sizes = []
    real = qp._lp_margin_rows

    def spy(An, *a, **k):
        sizes.append(An.shape[0])
        return real(An, *a, **k)

    monkeypatch.setattr(qp, "_lp_margin_rows", spy)
    rng = np.random.default_rng(7)
    rows, k = 3000, 6
    x = rng.normal(size=(rows, k))
    x[:, 0] = np.abs(x[:, 0]) * 0.02 + 1e-3  # a thin cone around the first axis
    An = x / np.linalg.norm(x, axis=1)[:, None]
    c = qp._lp_margin(An)
    assert c is not None and np.min(An @ c) > 0
    assert max(sizes) <= 4 * 200 and sizes[0] == 100
    # the LP on all rows at once finds a margin no larger
    whole = real(An)
    assert np.min(An @ whole) >= np.min(An @ c) - 1e-9
    # no direction: one row and its opposite among the 3000
    bad = An.copy()
    bad[2500] = -bad[1700]
    sizes.clear()
    # the certificate is found once rows 1700 and 2500 have both joined the subset
    assert qp._lp_margin(bad) is None and len(sizes) >= 2


def test_a_subset_direction_missing_only_its_own_rows_goes_to_the_sign_test(monkeypatch):
    """A subset's direction that misses only rows already in the subset (met to the
    LP's tolerance) is handed back once, for the caller's sign test: no endless loop."""
    from ratfit.core import qp
    from ratfit.core.systems import spread_indices

    monkeypatch.setattr(qp, "LP_MAX_ROWS", 200)
    rows = 1000
    An = np.tile([1.0, 0.0], (rows, 1))
    first = int(spread_indices(rows, 100)[0])
    An[first] = [-1.0, 0.0]  # the only row a direction along the first axis misses
    calls = []

    def fake(A, *a, **k):
        calls.append(A.shape[0])
        return np.array([1.0, 0.0])

    monkeypatch.setattr(qp, "_lp_margin_rows", fake)
    c = qp._lp_margin(An)
    assert calls == [100] and np.array_equal(c, [1.0, 0.0])
