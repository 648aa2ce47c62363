"""scikit-learn conventions of the four estimators: params, clone, repr, fit returns self."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ratfit import RationalFitter, Segments
from ratfit.brdf import BRDFFitter
from ratfit.cdf import MonotoneFitter, cdf_from_table
from ratfit.errors import InputError
from ratfit.fitting import SharedDenominatorFitter
from ratfit.io import load_fit, save_fit

sklearn_base = pytest.importorskip("sklearn.base")

ESTIMATORS = [
    RationalFitter(basis="chebyshev", max_total=30, domain=[[-1.0, 1.0]], jobs=1),
    MonotoneFitter(form="max", grid=20, max_total=12),
    BRDFFitter(parametrization="STARK_2D", positive_q=True, n=3, m=2),
    SharedDenominatorFitter(max_n=8, max_m=4, solver="quadprog"),
]


def _segments_1d(channels: int = 1) -> Segments:
    x = np.linspace(-1, 1, 40)
    ys = [1 / (2 + x), x / (2 + x), np.exp(x)][:channels]
    return Segments.from_relative(x, np.stack(ys, axis=1), 0.01)


@pytest.mark.parametrize("est", ESTIMATORS, ids=lambda e: type(e).__name__)
def test_clone_gives_equal_params_and_a_fresh_object(est) -> None:
    twin = sklearn_base.clone(est)
    assert twin is not est and type(twin) is type(est)
    a, b = est.get_params(deep=True), twin.get_params(deep=True)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(np.asarray(a[k], dtype=object), np.asarray(b[k], dtype=object)), k
    assert repr(twin) == repr(est)


@pytest.mark.parametrize("est", ESTIMATORS, ids=lambda e: type(e).__name__)
def test_every_init_parameter_is_a_param(est) -> None:
    import inspect

    params = est.get_params(deep=False)
    for klass in type(est).__mro__:
        init = klass.__dict__.get("__init__")
        if init is None or klass is object:
            continue
        for p in inspect.signature(init).parameters.values():
            if p.name != "self" and p.kind is not p.VAR_KEYWORD:
                assert p.name in params, f"{klass.__name__}.{p.name}"


def test_repr_shows_exactly_the_non_default_params() -> None:
    assert repr(RationalFitter()) == "RationalFitter()"
    assert repr(RationalFitter(basis="chebyshev", max_total=30)) == (
        "RationalFitter(basis='chebyshev', max_total=30)"
    )
    # MonotoneFitter's own default formulation is "basis": not shown; "auto" is.
    assert repr(MonotoneFitter(grid=5)) == "MonotoneFitter(grid=5)"
    assert repr(MonotoneFitter(formulation="auto")) == "MonotoneFitter(formulation='auto')"
    assert "positive_q=True" in repr(BRDFFitter(positive_q=True))


def test_set_params_round_trip_and_unknown_names() -> None:
    f = RationalFitter()
    assert f.set_params(basis="monomial", n=3, m=2) is f
    assert (f.basis, f.n, f.m) == ("monomial", 3, 2)
    with pytest.raises(InputError, match="unknown parameter 'degree'"):
        f.set_params(degree=3)
    g = MonotoneFitter().set_params(form="max", max_total=9)
    assert g.get_params()["form"] == "max" and g.get_params()["max_total"] == 9


def test_monotone_fit_leaves_active_set_alone() -> None:
    x = np.linspace(0, 1, 40)
    f = MonotoneFitter(form="max", grid=30)
    before = f.get_params()
    assert f.fit(cdf_from_table(x, x**2, abs_width=1e-3)) is f
    assert f.result_.success
    assert f.get_params() == before and f.active_set is None


@pytest.mark.parametrize("est", [RationalFitter(max_total=12), MonotoneFitter(max_total=12)],
                         ids=lambda e: type(e).__name__)
def test_fit_returns_self_and_never_changes_params(est) -> None:
    x = np.linspace(0, 1, 30)
    seg = cdf_from_table(x, x**2, abs_width=1e-3)
    before = repr(est), est.get_params()
    assert est.fit(seg) is est
    assert (repr(est), est.get_params()) == before


def test_shared_denominator_fit_returns_self() -> None:
    seg = _segments_1d(2)
    f = SharedDenominatorFitter(max_n=8, max_m=4)
    assert f.fit(seg) is f
    assert f.success_ and f.result_.success and f.result_.m == 2
    assert [r.channel for r in f.results_] == list(seg.names)
    assert "m = 2" in f.result_.message


def test_several_channels_never_pass_for_one() -> None:
    seg = _segments_1d(2)
    f = RationalFitter(max_total=12).fit(seg)
    assert len(f.results_) == 2 and f.success_
    with pytest.raises(InputError, match=r"fitted 2 channels .*results_\[j\]"):
        _ = f.result_
    with pytest.raises(InputError, match="fitted 2 channels"):
        _ = f.rational_
    # one channel: result_ is that channel
    g = RationalFitter(max_total=12).fit(_segments_1d(1))
    assert g.result_ is g.results_[0] and g.rational_ is g.results_[0].rational


def test_save_fit_takes_a_result_a_fitter_or_a_list(tmp_path) -> None:
    f = RationalFitter(max_total=12).fit(_segments_1d(2))
    for what, name in ((f, "fitter"), (f.results_, "list"), (f.results_[1], "one")):
        path = tmp_path / f"{name}.json"
        save_fit(path, what)
        saved = load_fit(path)
        want = f.results_ if name != "one" else [f.results_[1]]
        assert [c.name for c in saved.channels] == [r.channel for r in want]
        for c, r in zip(saved.channels, want, strict=True):
            assert np.array_equal(c.rational.p, r.rational.p)
    shared = SharedDenominatorFitter(max_n=8, max_m=4).fit(_segments_1d(2))
    save_fit(tmp_path / "shared.json", shared)
    assert len(load_fit(tmp_path / "shared.json").channels) == 2
    with pytest.raises(InputError, match="not fitted"):
        save_fit(tmp_path / "x.json", RationalFitter())
    assert not (tmp_path / "x.json").exists()
    with pytest.raises(TypeError, match="save_fit takes"):
        save_fit(tmp_path / "y.json", 3.0)
    json.loads((tmp_path / "one.json").read_text())  # a plain JSON document


def test_ratfit_imports_without_sklearn() -> None:
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['sklearn'] = None\n"
        "import ratfit, ratfit.cdf, ratfit.brdf, ratfit.fitting, ratfit.cli\n"
        "print(repr(ratfit.RationalFitter(n=2, m=1)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "RationalFitter(n=2, m=1)"


def test_shared_denominator_takes_x_and_y_like_a_regressor() -> None:
    """fit(X, y) builds the segments from dt as RationalFitter does; predict and score
    make it a scikit-learn regressor (cross_val_score runs)."""
    from sklearn.model_selection import KFold, cross_val_score

    x = np.linspace(-1, 1, 40)
    y = np.stack([1 / (2 + x), x / (2 + x)], axis=1)
    f = SharedDenominatorFitter(dt=0.01, max_n=8, max_m=4)
    assert f.fit(x, y) is f and f.success_
    g = SharedDenominatorFitter(max_n=8, max_m=4).fit(Segments.from_widths(x, y, dt=0.01))
    assert (f.result_.n, f.result_.m) == (g.result_.n, g.result_.m)
    for a, b in zip(f.results_, g.results_, strict=True):
        assert np.allclose(a.rational(x), b.rational(x))
    pred = f.predict(x)
    assert pred.shape == (40, 2)
    # verified: inside the segments at every sample, [(1 - dt) y, (1 + dt) y]
    assert np.all(np.abs(pred - y) <= 0.01 * np.abs(y) + 1e-12)
    r2 = 1 - ((y - pred) ** 2).sum(0) / ((y - y.mean(0)) ** 2).sum(0)
    assert f.score(x, y) == pytest.approx(r2.mean()) and f.score(x, y) > 0.999
    assert f.predict(x[:5])[:, 1] == pytest.approx(f.results_[1].rational(x[:5]))
    scores = cross_val_score(SharedDenominatorFitter(dt=0.01, max_n=8, max_m=4), x, y,
                             cv=KFold(4, shuffle=True, random_state=0))
    assert scores.shape == (4,) and np.all(scores > 0.99)
    with pytest.raises(InputError, match="without y"):
        SharedDenominatorFitter(dt=0.01).fit(x)
    with pytest.raises(InputError, match="builds segments around y"):
        SharedDenominatorFitter().fit(x, y)
    with pytest.raises(InputError, match="bounds of their own"):
        SharedDenominatorFitter(dt=0.01).fit(Segments.from_widths(x, y, dt=0.01))
    with pytest.raises(InputError, match="dt"):
        SharedDenominatorFitter(dt=-1.0).fit(x, y)
