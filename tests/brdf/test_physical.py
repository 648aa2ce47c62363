"""A BRDF fit that is negative or has a pole between the samples is never a success."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import lobe_on_sparse_grid

from ratfit.brdf.fitter import BRDFFitter, fit_brdf, nonnegative_segments
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import check_validity, configurations
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.errors import InputError
from ratfit.io.data import Dataset

P = "ISOTROPIC_TV_TL_DPHI"
DEG = np.pi / 180


def _samples() -> np.ndarray:
    """A sparse gonioreflectometer grid: elevations every 20 deg, azimuths every 45."""
    th = np.array([0, 20, 40, 60, 80]) * DEG
    ph = np.array([0, 45, 90, 135, 180]) * DEG
    return np.stack([g.ravel() for g in np.meshgrid(th, th, ph, indexing="ij")], axis=1)


def _candidate(p_poly, q_poly) -> tuple[RationalFunction, Segments]:
    """r = p / q given as monomials in (theta_v, theta_l) (radians), exactly in the
    Legendre space of the samples' box; segments hugging r at the samples."""
    x = _samples()
    space = PolynomialSpace("legendre", np.stack([x.min(0), x.max(0)], 1), "total")
    t = space.to_window(configurations(P, space.domain, 4000))
    X = space.from_window(t)
    B = space.design(X, 10)  # total degree <= 2 in 3 variables
    p = np.linalg.lstsq(B, p_poly(X), rcond=None)[0]
    q = np.linalg.lstsq(B, q_poly(X), rcond=None)[0]
    rf = RationalFunction(space, p, q)
    y = rf(x)
    return rf, Segments.from_bounds(x, y - 0.05 * np.abs(y) - 1e-3, y + 0.05 * np.abs(y) + 1e-3, y)


def _fitter() -> BRDFFitter:
    return BRDFFitter(parametrization=P)


def test_pole_between_samples_at_75_degrees_is_rejected() -> None:
    a = 75 * DEG
    rf, seg = _candidate(lambda X: np.ones(len(X)),
                         lambda X: (X[:, 0] - a) ** 2 + (X[:, 1] - a) ** 2 - 0.01)
    q_s = rf.denominator(seg.x)
    assert np.all(q_s > 0)  # the samples never see it
    ver = _fitter()._verify(rf, seg, 0)
    assert ver.n_violations == 0
    assert not ver.verified and ver.denominator_sign_changes
    chk = check_validity(rf, P)
    assert chk is not None and not chk.valid and chk.min_q < 0
    # the bad configurations found are around theta_v = theta_l = 75 deg
    assert np.all(np.abs(chk.bad_points[:, :2] - a) < 6 * DEG)


def test_negative_between_samples_is_rejected() -> None:
    b = 50 * DEG
    rf, seg = _candidate(lambda X: (X[:, 0] - b) ** 2 - 0.005, lambda X: np.ones(len(X)))
    assert np.all(rf(seg.x) > 0)  # 40 and 60 deg are positive; 50 deg is not
    ver = _fitter()._verify(rf, seg, 0)
    assert ver.n_violations == 0 and not ver.verified
    chk = check_validity(rf, P)
    assert chk is not None and not chk.valid and chk.min_r < 0
    assert np.all(np.abs(chk.bad_points[:, 0] - b) < 5 * DEG)


def test_validity_points_stay_with_their_channel() -> None:
    """Where one channel's candidate had a pole, that channel's later splits get q > 0
    rows; another channel's do not: its answer must not depend on which channels were
    fitted with it (garnet_red's G carried R's points: 10 000+ row systems, and 69
    coefficients where G alone has 68)."""
    a = 75 * DEG
    rf, seg = _candidate(lambda X: np.ones(len(X)),
                         lambda X: (X[:, 0] - a) ** 2 + (X[:, 1] - a) ** 2 - 0.01)
    two = Segments(seg.x, np.hstack([seg.lo, seg.lo]), np.hstack([seg.hi, seg.hi]),
                   np.hstack([seg.y, seg.y]), ("R", "G"))
    fitter, fresh = _fitter(), _fitter()
    space = fitter.prepare(two)
    fresh.prepare(two)
    assert not fitter._verify(rf, two, 0).verified
    added = sum(len(e) for e in fitter._points_of(0))
    assert added > 0 and fitter._points_of(1) == []
    rows = [fitter._split_system(space, two, j, 5, 5).n_rows for j in (0, 1)]
    alone = fresh._split_system(space, two, 1, 5, 5).n_rows
    assert rows[1] == alone and rows[0] == alone + 2 * added  # q > 0 and p >= 0 rows


def test_a_positive_pole_free_candidate_passes() -> None:
    rf, seg = _candidate(lambda X: 1.0 + X[:, 0] ** 2, lambda X: 2.0 + X[:, 1])
    ver = _fitter()._verify(rf, seg, 0)
    assert ver.verified
    chk = check_validity(rf, P)
    assert chk.valid and chk.min_q > 0 and chk.min_r > 0 and chk.checked > 50_000


def test_segments_never_allow_negative_values() -> None:
    x = _samples()[::12][:10]
    seg = Segments.from_absolute(x, np.linspace(0.0, 1.0, 10), 0.5)
    out = nonnegative_segments(seg)
    assert out.lo.min() == 0.0 and np.array_equal(out.hi, seg.hi)
    with pytest.raises(InputError, match="--clamp 0"):
        nonnegative_segments(Segments.from_bounds(x, np.full(10, -2.0), np.full(10, -1.0)))


@pytest.mark.slow
def test_fit_is_physical_where_the_data_is_sparse() -> None:
    """A lobe measured on the sparse grid: the verified fit keeps q > 0 and r >= 0 on
    the dense valid set, not only at the 125 samples."""
    ds = lobe_on_sparse_grid()
    fitter, seg, _ = fit_brdf(ds, dt=0.1, max_total=30)
    assert fitter.success_, fitter.result_.message
    chk = fitter.validity_[0]
    assert chk is not None and chk.valid and chk.min_q > 0 and chk.min_r >= 0
    again = check_validity(fitter.result_.rational, P, points=600_000)
    assert again.valid


def test_constant_coordinate_is_dropped_and_recorded(tmp_path) -> None:
    """Cornell-style Cartesian pairs with L in the x-z plane: ly is constant, the fit
    drops it, says so in the fit file, and evaluation on full coordinates works."""
    from ratfit.brdf.fitter import load_brdf_fit, save_brdf_fit

    rng = np.random.default_rng(3)
    tl, tv = rng.uniform(0, 1.3, 300), rng.uniform(0, 1.3, 300)
    pv = rng.uniform(-np.pi, np.pi, 300)
    L = np.stack([np.sin(tl), np.zeros(300), np.cos(tl)], axis=1)
    V = np.stack([np.sin(tv) * np.cos(pv), np.sin(tv) * np.sin(pv), np.cos(tv)], axis=1)
    cart = get_parametrization("CARTESIAN")
    x = cart.from_dirs(L, V)
    y = (0.3 + 0.1 * V[:, 2])[:, None]
    ds = Dataset(x, y, None, None, cart.coords, ("R",), {"param_in": "CARTESIAN"})
    fitter, seg, meta = fit_brdf(ds, dt=0.05, max_total=8)
    assert fitter.success_, fitter.result_.message
    assert meta["dropped_coords"] == {"4": 0.0} and seg.dim == 5
    path = tmp_path / "fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    fit = load_brdf_fit(path)
    assert fit.dropped == (4,)
    assert np.allclose(fit.eval_coords(x)[:, 0], y[:, 0], rtol=0.06)


@pytest.mark.slow
def test_polish_past_the_time_limit_keeps_the_search_fit(monkeypatch) -> None:
    """A time-limited fit never waits on its polish: the search's verified fit stays,
    and the message says the polish was cut."""
    import time

    ds = lobe_on_sparse_grid()
    polished, seg, _ = fit_brdf(ds, dt=0.1, max_total=30)
    assert "least-squares polish: RMSE" in polished.result_.message  # dt alone: absolute
    monkeypatch.setattr(BRDFFitter, "_polish_deadline", lambda self: time.perf_counter() - 1.0)
    cut, _, _ = fit_brdf(ds, dt=0.1, max_total=30)
    res = cut.result_
    assert res.success and "polish stopped at the time limit" in res.message
    assert (res.n, res.m) == (polished.result_.n, polished.result_.m)
    assert res.verification.n_violations == 0
    # the unpolished (minimum-norm) fit is the worse one on the data
    rm = [float(np.sqrt(np.mean((f.result_.rational(seg.x) - seg.center[:, 0]) ** 2)))
          for f in (polished, cut)]
    assert rm[0] < rm[1]


def test_spread_keeps_points_from_the_whole_list() -> None:
    from ratfit.brdf.fitter import _spread

    pts = np.arange(3000.0)[:, None] * np.ones((1, 3))
    out = _spread(pts, 500)
    assert out.shape == (500, 3)
    assert out[0, 0] == 0.0 and out[-1, 0] == 2999.0  # both ends of the list
    assert np.all(np.diff(out[:, 0]) >= 5)  # evenly spaced, no repeats
    assert _spread(pts[:200], 500) is not None and len(_spread(pts[:200], 500)) == 200


def test_repair_adds_spread_bad_points_round_after_round(monkeypatch) -> None:
    """retro-3M-jaune-dense: a repair's q still dips below 0 between the validity points
    after 3 rounds (by 1e-7..1e-9 of max|q|), and the check's bad points listed first
    all lie in one corner. Each round adds ROUND_POINTS spread over every bad point,
    for up to REPAIR_ROUNDS rounds: here the 7th round's fit is valid."""
    import ratfit.brdf.fitter as F
    import ratfit.core.polish as polish
    from ratfit.brdf.validity import ValidityCheck

    rf, seg = _candidate(lambda X: 1.0 + X[:, 0] ** 2, lambda X: 2.0 + X[:, 1])
    fitter = _fitter()
    fitter._checks, fitter._points = {}, {}
    sizes: list[int] = []
    added: list[np.ndarray] = []
    bad = np.stack([np.linspace(0.1, 1.2, 4000), np.full(4000, 0.5), np.zeros(4000)], 1)

    def fake_polish(rf_, seg_, j, *, positive_at, **kw):
        sizes.append(len(positive_at))
        added.append(np.asarray(positive_at))
        return RationalFunction(rf_.space, rf_.p.copy(), rf_.q.copy())

    def fake_verify(self, cand, seg_, j):
        ver = F.verify(cand, seg_, channel=j, box_check=False)
        if len(sizes) < 7:
            self._checks[id(cand)] = ValidityCheck(False, 1, -1e-8, -np.inf, bad, "test")
            return F.replace(ver, verified=False)
        return ver

    monkeypatch.setattr(polish, "polish_fit", fake_polish)
    monkeypatch.setattr(BRDFFitter, "_verify", fake_verify)
    out = fitter._repair(rf, seg, 0)
    assert out is not None and len(sizes) == 7 <= F.REPAIR_ROUNDS
    # each round: ROUND_POINTS more, spread from the first bad point to the last
    assert np.all(np.diff(sizes) == F.ROUND_POINTS)
    spread = F._spread(bad, F.ROUND_POINTS)
    assert np.array_equal(added[1][sizes[0]:], spread)
    assert spread[0, 0] == 0.1 and spread[-1, 0] == 1.2


def test_blend_is_the_mix_of_both_fits_scaled_to_mean_q_one() -> None:
    """A point of the line from a valid fit to its polish: each end scaled to a mean q
    of 1 at the samples, so a step of 0 and 1 give the two functions themselves and any
    row linear and homogeneous in (p, q) that both meet (inside a segment) holds."""
    from ratfit.brdf.fitter import _blend

    start, seg = _candidate(lambda X: 1.0 + X[:, 0] ** 2, lambda X: 2.0 + X[:, 1])
    end = RationalFunction(start.space, 3.0 * start.p + 0.01 * start.q, 3.0 * start.q)
    x = seg.x
    for step, want in ((0.0, start(x)), (1.0, end(x))):
        mix = _blend(start, end, x, step)
        assert mix is not None
        np.testing.assert_allclose(mix(x), want, rtol=1e-12)
        np.testing.assert_allclose(np.mean(mix.denominator(x)), 1.0, rtol=1e-12)
    half = _blend(start, end, x, 0.5)
    assert half is not None
    p0, q0 = start.numerator(x), start.denominator(x)
    p1, q1 = end.numerator(x), end.denominator(x)
    want = (0.5 * p0 / q0.mean() + 0.5 * p1 / q1.mean()) / (
        0.5 * q0 / q0.mean() + 0.5 * q1 / q1.mean())
    np.testing.assert_allclose(half(x), want, rtol=1e-12)
    # both ends inside [min, max] of their values at each sample: so is the mix
    lo, hi = np.minimum(start(x), end(x)), np.maximum(start(x), end(x))
    assert np.all(half(x) >= lo - 1e-12) and np.all(half(x) <= hi + 1e-12)
    assert not np.allclose(half(x), start(x))  # it moved
    flipped = RationalFunction(start.space, start.p, -start.q)
    assert _blend(start, flipped, x, 0.5) is None  # q negative on average: no line


def test_refuted_polish_of_a_valid_fit_takes_the_half_way_fit(monkeypatch) -> None:
    """satin_rosaline G: the polish of the search's valid fit was refuted four rounds
    running (82 s) and the fit stayed unpolished. The fit half way to the first refuted
    polish is verified and kept where no later round verifies; a later round's full
    polish that verifies wins over it; a repair (whose start is not valid) takes no
    blend."""
    import ratfit.brdf.fitter as F
    import ratfit.core.polish as polish
    from ratfit.brdf.validity import ValidityCheck

    rf, seg = _candidate(lambda X: 1.0 + X[:, 0] ** 2, lambda X: 2.0 + X[:, 1])
    moved = RationalFunction(rf.space, 1.1 * rf.p, rf.q)
    bad = np.array([[0.3, 0.5, 0.0]])
    calls: list[int] = []
    verified: list[RationalFunction] = []

    def fake_polish(rf_, seg_, j, *, positive_at, **kw):
        calls.append(len(positive_at))
        return moved

    def fake_verify(self, cand, seg_, j):
        ver = F.verify(cand, seg_, channel=j, box_check=False)
        verified.append(cand)
        if cand is moved:
            self._checks[id(cand)] = ValidityCheck(False, 1, -1e-8, -np.inf, bad, "test")
            return F.replace(ver, verified=False)
        return F.replace(ver, verified=True)

    monkeypatch.setattr(polish, "polish_fit", fake_polish)
    monkeypatch.setattr(BRDFFitter, "_verify", fake_verify)
    fitter = _fitter()
    fitter._checks, fitter._points = {}, {}
    out = fitter._polish_rounds(rf, seg, 0, None, start_valid=True)
    assert out is not None and len(calls) == 4  # every round refuted: the blend
    half = F._blend(rf, moved, seg.x, F.BLEND_STEPS[0])
    assert half is not None
    np.testing.assert_allclose(out[0](seg.x), half(seg.x), rtol=1e-12)
    assert verified[0] is moved and verified[1] is out[0]
    # the second round's polish verifies: it, not the blend of the first
    better = RationalFunction(rf.space, 1.05 * rf.p, rf.q)
    answers = iter([moved, better])
    monkeypatch.setattr(polish, "polish_fit", lambda *a, **kw: next(answers))
    fitter._checks = {}
    out = fitter._polish_rounds(rf, seg, 0, None, start_valid=True)
    assert out is not None and out[0] is better
    monkeypatch.setattr(polish, "polish_fit", fake_polish)
    # a repair's start is not valid: no blend, the next round polishes again
    calls.clear()
    fitter._checks = {}
    assert fitter._polish_rounds(rf, seg, 0, None, rounds=2, repair=True) is None
    assert len(calls) == 2 and calls[1] == calls[0] + 1  # the refuting point added


def test_the_dense_checks_signs_are_the_exact_evaluations() -> None:
    """The offset grid is screened with BLAS sums (not the fixed order the verdicts and
    the exports use); where q or p is within SCREEN_MARGIN of zero, and at their
    smallest and largest values, the fixed-order values replace the screened ones, so
    every sign the check reads, its compass search's starts and its scales are exact."""
    from ratfit.brdf.validity import SCREEN_EXTREMES, SCREEN_MARGIN, _grid_values
    from ratfit.core.arnoldi import ArnoldiBasis

    space = PolynomialSpace("legendre", [[-1.0, 1.0]] * 3, "total")
    rng = np.random.default_rng(3)
    t = rng.uniform(-1, 1, (3000, 3))
    basis, Q = ArnoldiBasis.build(space, t, np.ones(len(t)), 35)
    # q = (t0 - 0.3)^2 + 1e-9 (its smallest values 1e-9 of max), p = t1 (both signs)
    q = Q.T @ ((t[:, 0] - 0.3) ** 2 + 1e-9)
    p = Q.T @ t[:, 1]
    rf = RationalFunction(space, p, q, p_basis=basis, q_basis=basis)
    c = rng.uniform(-1, 1, (100_000, 3))
    c[:2000, 0] = 0.3 + rng.uniform(-1e-6, 1e-6, 2000)  # where q is within 1e-6 of 0
    qg, pg = _grid_values(rf, rf.numerator, rf.numerator, c)
    qe, pe = rf.denominator(c), rf.numerator(c)
    assert np.array_equal(np.sign(qg), np.sign(qe)) and np.array_equal(np.sign(pg), np.sign(pe))
    near = (np.abs(qe) <= SCREEN_MARGIN / 2 * np.abs(qe).max()) | (
        np.abs(pe) <= 2 * SCREEN_MARGIN * np.abs(pe).max())
    assert near.sum() > 2000  # the q dip, and p's zero line t1 = 0
    assert np.array_equal(qg[near], qe[near]) and np.array_equal(pg[near], pe[near])
    # where the compass search starts and the scales come from: the exact numbers too
    order = np.argsort(qe)
    ends = np.concatenate([order[:SCREEN_EXTREMES // 2], order[-SCREEN_EXTREMES // 2:]])
    assert np.array_equal(qg[ends], qe[ends])
    ends = np.argsort(pe)[-SCREEN_EXTREMES // 2:]
    assert np.array_equal(pg[ends], pe[ends])
    # elsewhere the screened values are the same numbers but for the order of the sums
    assert np.max(np.abs(qg - qe)) <= 1e-12 * np.abs(qe).max()
    assert not np.array_equal(qg, qe)  # (the screen is what computed them)


def test_the_screened_check_finds_what_the_exact_one_finds(monkeypatch) -> None:
    """check_validity of a candidate in data-orthonormal bases with a pole between the
    samples: the same verdict, bad points (in the same order), minima and count as the
    check with every grid value in the fixed order (a search then takes the same path)."""
    from ratfit.core.arnoldi import ArnoldiBasis

    a = 75 * DEG
    x = _samples()
    space = PolynomialSpace("legendre", np.stack([x.min(0), x.max(0)], 1), "total")
    X = configurations(P, space.domain, 4000)
    basis, Q = ArnoldiBasis.build(space, space.to_window(X), np.ones(len(X)), 20)
    q = Q.T @ ((X[:, 0] - a) ** 2 + (X[:, 1] - a) ** 2 - 0.01)
    p = Q.T @ (1.0 + X[:, 2])
    rf = RationalFunction(space, p, q, p_basis=basis, q_basis=basis)
    screened = check_validity(rf, P)
    monkeypatch.setattr(ArnoldiBasis, "evaluate_blas", ArnoldiBasis.evaluate)
    exact = check_validity(rf, P)
    assert screened is not None and exact is not None and not screened.valid
    assert len(screened.bad_points) > 10
    assert np.array_equal(screened.bad_points, exact.bad_points)
    assert (screened.min_q, screened.min_r, screened.checked) == (
        exact.min_q, exact.min_r, exact.checked)


def test_a_refuted_proofs_pocket_becomes_rows_where_q_is_negative() -> None:
    """dips_around reads a fine grid around the points a proof refuted at: it returns
    those points (once each) and every grid point where q <= 0, all valid configurations
    inside the domain, so one repair round constrains the whole pocket, not a corner."""
    from ratfit.brdf.validity import _valid_or_limits, dips_around
    from ratfit.core.arnoldi import ArnoldiBasis

    fold = "RUSIN_TH_TD_FOLD"
    dom = np.array([[0.0124, 1.536], [0.0, 1.5359], [-0.9758, 0.9994]])
    space = PolynomialSpace("legendre", dom, "total")
    X = configurations(fold, dom, 6000)
    centre = np.array([0.65, 1.2, 0.13])
    radius = 0.03  # a pocket narrower than the validity grid's spacing (~0.04 rad)
    basis, Q = ArnoldiBasis.build(space, space.to_window(X), np.ones(len(X)), 10)
    q = Q.T @ (np.sum((X - centre) ** 2, axis=1) - radius**2)
    p = Q.T @ np.ones(len(X))
    rf = RationalFunction(space, p, q, p_basis=basis, q_basis=basis)
    assert rf.denominator(X).min() > 0  # the grid alone does not see it
    corner = centre + np.array([0.02, 0.0, 0.0])
    rows = dips_around(rf, np.repeat(corner[None], 8, axis=0), fold)
    assert np.sum(np.all(rows == corner, axis=1)) == 1
    inside = rows[~np.all(rows == corner, axis=1)]
    assert len(inside) > 100
    assert np.all(rf.denominator(inside) <= 0)
    assert np.all(np.linalg.norm(inside - centre, axis=1) <= radius * 1.0001)
    assert np.all((inside >= dom[:, 0]) & (inside <= dom[:, 1]))
    assert np.all(_valid_or_limits(get_parametrization(fold), inside, dom))
    # the pocket's centre is among the rows' reach: the nearest row lies within a step
    step = 2 * 0.04 * (dom[:, 1] - dom[:, 0]) / 16
    assert np.min(np.max(np.abs(inside - centre) / step, axis=1)) <= 0.5 + 1e-9
    # where q is positive all around, the points alone come back
    far = np.array([[0.3, 0.5, 0.5]])
    assert np.array_equal(dips_around(rf, far, fold), far)
    # with a second function (p here), its negative points join too
    rf2 = RationalFunction(space, Q.T @ X[:, 2], Q.T @ np.ones(len(X)),
                           p_basis=basis, q_basis=basis)
    got = dips_around(rf2, np.array([[0.33, 0.41, 0.01]]), fold)
    assert len(got) > 50 and np.sum(got[:, 2] > 0) == 1
    # a pocket across the edge of the valid pairs (40 % of its grid valid there): exactly
    # the grid's valid points where q <= 0, as read on the whole grid
    edge = np.array([0.7, 1.1, 0.4])
    rf3 = RationalFunction(space, p, Q.T @ (np.sum((X - edge) ** 2, axis=1) - radius**2),
                           p_basis=basis, q_basis=basis)
    steps = np.linspace(-0.04, 0.04, 33)
    ext = dom[:, 1] - dom[:, 0]
    grid = np.clip(edge + np.stack(np.meshgrid(steps, steps, steps, indexing="ij"),
                                   axis=-1).reshape(-1, 3) * ext, dom[:, 0], dom[:, 1])
    valid = _valid_or_limits(get_parametrization(fold), grid, dom)
    assert 0.2 < valid.mean() < 0.8
    want = grid[valid & (rf3.denominator(grid) <= 0)]
    got3 = dips_around(rf3, edge[None], fold)
    assert len(want) > 100
    assert np.array_equal(got3, np.unique(np.concatenate([edge[None], want]), axis=0))
    # the grid's size: per (33) an axis, at most about points_each a centre in any dimension
    everywhere = RationalFunction(space, p, -(q + 1e3 * (Q.T @ np.ones(len(X)))),
                                  p_basis=basis, q_basis=basis)
    assert everywhere.denominator(X).max() < 0
    box = dips_around(everywhere, centre[None], fold, keep=[0, 1, 2])  # (no validity filter)
    assert 33**3 <= len(box) <= 33**3 + 1
    assert len(dips_around(everywhere, centre[None], fold, keep=[0, 1, 2],
                           points_each=4000)) in (16**3, 16**3 + 1)
