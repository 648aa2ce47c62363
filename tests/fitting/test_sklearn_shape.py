"""Issue 27: the estimators in scikit-learn's shape (fit(X, y) from width options,
predict, score = R^2, cross_val_score), a fitted rational takes scalars, and p/q are
named alike on a fit and on its monomial form."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from ratfit import PolynomialSpace, RationalFitter, RationalFunction, Segments
from ratfit.cdf import MonotoneFitter
from ratfit.core.estimator import r2_score
from ratfit.core.monomial import to_monomial
from ratfit.errors import InputError
from ratfit.io.data import read_data

sklearn = pytest.importorskip("sklearn")
from sklearn.base import clone, is_regressor  # noqa: E402
from sklearn.metrics import r2_score as sk_r2  # noqa: E402
from sklearn.model_selection import KFold, cross_val_score  # noqa: E402
from sklearn.pipeline import make_pipeline  # noqa: E402
from sklearn.preprocessing import FunctionTransformer  # noqa: E402


@pytest.fixture(scope="module")
def kirby2(shared_data: Path) -> tuple[np.ndarray, np.ndarray]:
    data = read_data(shared_data / "nist" / "Kirby2.dat")
    return data.x, data.y[:, 0]


def test_cross_val_score_on_kirby2(kirby2) -> None:
    X, y = kirby2
    cv = KFold(5, shuffle=True, random_state=0)
    scores = cross_val_score(RationalFitter(dt=0.01), X, y, cv=cv, error_score="raise")
    assert scores.shape == (5,)
    # Each score is R^2 of a fit on the other folds, computed here by hand.
    for score, (train, test) in zip(scores, cv.split(X), strict=True):
        f = RationalFitter(dt=0.01).fit(X[train], y[train])
        assert f.success_
        pred = f.predict(X[test])
        assert pred.shape == (test.size,)
        by_hand = 1 - np.sum((y[test] - pred) ** 2) / np.sum((y[test] - y[test].mean()) ** 2)
        assert score == pytest.approx(by_hand, rel=1e-12)
        # every training segment is met, so the training residual is within 1 %
        assert np.all(np.abs(f.predict(X[train]) - y[train]) <= 0.01 * np.abs(y[train]) * 1.000001)
    # interpolating in Kirby2 (151 points, smooth) is accurate: R^2 > 0.999 on each fold
    assert scores.min() > 0.999
    assert is_regressor(RationalFitter())


def test_fit_xy_is_fit_of_the_segments_it_builds(kirby2) -> None:
    X, y = kirby2
    a = RationalFitter(dt=0.01).fit(X, y)
    b = RationalFitter().fit(Segments.from_relative(X, y, 0.01))
    assert (a.result_.n, a.result_.m) == (b.result_.n, b.result_.m) == (9, 5)
    assert np.array_equal(a.rational_.p, b.rational_.p)
    assert np.array_equal(a.rational_.q, b.rational_.q)
    assert a.score(X, y) == pytest.approx(sk_r2(y, a.predict(X)), rel=1e-14)
    # both widths: each segment is the union of the two intervals (as Segments.from_widths)
    c = RationalFitter(dt=0.001, abs_width=2.0).fit(X, y)
    seg = Segments.from_widths(X, y, dt=0.001, abs_width=2.0)
    assert np.array_equal(c.segments_.lo, seg.lo) and np.array_equal(c.segments_.hi, seg.hi)


def test_width_options_are_params_and_reach_a_pipeline(kirby2) -> None:
    X, y = kirby2
    est = RationalFitter(dt=0.01, max_total=30)
    assert est.get_params()["dt"] == 0.01 and est.get_params()["abs_width"] is None
    assert repr(est) == "RationalFitter(dt=0.01, max_total=30)"
    twin = clone(est).set_params(dt=0.05, abs_width=0.5)
    assert (twin.dt, twin.abs_width, est.dt) == (0.05, 0.5, 0.01)
    pipe = make_pipeline(FunctionTransformer(np.log), RationalFitter(dt=0.01))
    pipe.set_params(rationalfitter__dt=0.02)
    pipe.fit(X, y)
    fitted = pipe[-1]
    assert fitted.dt == 0.02 and fitted.success_
    assert fitted.segments_.x[:, 0] == pytest.approx(np.log(X[:, 0]))
    assert pipe.score(X, y) > 0.999


def test_multi_channel_predict_and_score() -> None:
    x = np.linspace(-1, 1, 40)
    Y = np.stack([1 / (2 + x), np.exp(x)], axis=1)
    f = RationalFitter(dt=1e-3).fit(x, Y)
    pred = f.predict(x)
    assert pred.shape == (40, 2)
    assert np.all(np.abs(pred - Y) <= 1e-3 * np.abs(Y) * (1 + 1e-9))
    assert f.score(x, Y) == pytest.approx(sk_r2(Y, pred), rel=1e-14)


def test_r2_score_matches_scikit_learn() -> None:
    rng = np.random.default_rng(3)
    y = rng.normal(size=(30, 3))
    p = y + rng.normal(scale=0.3, size=y.shape)
    assert r2_score(y, p) == pytest.approx(sk_r2(y, p), rel=1e-14)
    assert r2_score(y[:, 0], p[:, 0]) == pytest.approx(sk_r2(y[:, 0], p[:, 0]), rel=1e-14)
    const = np.ones(5)
    assert r2_score(const, const) == sk_r2(const, const) == 1.0
    assert r2_score(const, const + 1) == sk_r2(const, const + 1) == 0.0


def test_combinations_that_cannot_mean_anything_are_refused() -> None:
    x = np.linspace(0, 1, 20)
    seg = Segments.from_relative(x, np.exp(x), 0.01)
    with pytest.raises(InputError, match=r"give RationalFitter\(dt=...\)"):
        RationalFitter().fit(x, np.exp(x))
    with pytest.raises(InputError, match="Segments with bounds of their own"):
        RationalFitter(dt=0.01).fit(seg)
    with pytest.raises(InputError, match="Segments carry their own bounds"):
        RationalFitter().fit(seg, np.exp(x))
    with pytest.raises(InputError, match="without y"):
        RationalFitter(dt=0.01).fit(x)
    with pytest.raises(InputError, match="dt must be"):
        RationalFitter(dt=-1.0).fit(x, np.exp(x))
    with pytest.raises(AttributeError, match="not fitted yet"):
        RationalFitter(dt=0.01).predict(x)
    failed = RationalFitter(dt=1e-6, max_total=3).fit(x, np.exp(3 * x))
    assert not failed.success_
    with pytest.raises(InputError, match="no verified fit for channel"):
        failed.predict(x)


def test_monotone_fitter_takes_x_y_too() -> None:
    x = np.linspace(0, 1, 40)
    f = MonotoneFitter(grid=50, abs_width=1e-3).fit(x, x**2)
    assert f.success_ and f.score(x, x**2) > 0.9999


def test_a_fitted_rational_takes_scalars() -> None:
    x = np.linspace(0, 3, 50)
    r = RationalFitter(dt=0.01).fit(x, 1 / (2 + x)).rational_
    v = r(2.5)  # raised "points must have shape (N, 1), got ()"
    assert type(v) is float and v == r([2.5])[0] == r(np.float64(2.5))
    assert v == pytest.approx(1 / 4.5, rel=0.011)
    # n-D: one point as a vector of length d
    space = PolynomialSpace("monomial", [[-1.0, 1.0], [-1.0, 1.0]])
    r2 = RationalFunction(space, [1.0, 1.0], [2.0])  # (1 + t1) / 2
    w = r2([0.5, -0.25])
    assert type(w) is float and w == pytest.approx(0.75)
    assert r2(np.array([[0.5, -0.25], [0.0, 0.0]])).tolist() == [0.75, 0.5]
    # the monomial form too
    mf = to_monomial(r, x)
    assert type(mf(2.5)) is float and mf(2.5) == pytest.approx(v, rel=1e-12)


def test_monomial_form_names_p_and_q_like_a_fit() -> None:
    space = PolynomialSpace("legendre", [[0.0, 2.0]])
    rf = RationalFunction(space, [1.0, 0.5], [2.0, 0.0, 0.25])
    mf = to_monomial(rf, np.linspace(0, 2, 11))
    assert mf.p.shape == (2,) and mf.q.shape == (3,)
    x = np.linspace(0, 2, 7)
    assert np.allclose(np.polynomial.polynomial.polyval(x, mf.p)
                       / np.polynomial.polynomial.polyval(x, mf.q), rf(x), rtol=1e-13)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert mf.P is mf.p and mf.Q is mf.q
    assert [w.category for w in caught] == [DeprecationWarning, DeprecationWarning]
    assert "use .p" in str(caught[0].message)
