"""Property-based tests (hypothesis) of the engine's invariants."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.polynomial import Polynomial

import ratfit
from ratfit.core.bases import PolynomialSpace
from ratfit.core.monomial import horner, to_monomial
from ratfit.core.rational import RationalFunction
from ratfit.io.fitfile import fit_document, load_fit, parse_fit, save_fit

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow])
finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@st.composite
def smooth_data(draw):
    """Random 1-D data: a positive-denominator rational plus a wiggle, random widths."""
    n = draw(st.integers(20, 150))
    a = draw(st.floats(-5, 5))
    w = draw(st.floats(0.5, 10))
    x = np.linspace(a, a + w, n)
    c = draw(st.lists(st.floats(-2, 2), min_size=2, max_size=4))
    d = draw(st.floats(0.1, 2))
    k = draw(st.floats(0, 3))
    t = (x - a) / w
    y = np.polyval(c, t) / (1 + d * t**2) + 0.2 * np.sin(k * 6 * t) + 3
    dt = draw(st.floats(0.005, 0.3))
    basis = draw(st.sampled_from(["legendre", "chebyshev", "monomial"]))
    return x, y, dt, basis


@settings(max_examples=25, **SETTINGS)
@given(smooth_data())
def test_every_success_satisfies_every_segment(data):
    x, y, dt, basis = data
    seg = ratfit.Segments.from_relative(x, y, dt)
    r = ratfit.fit(seg, basis=basis, max_total=16)
    if r.success:
        # independent evaluation: numpy's own series classes on the mapped variable
        kind = {"legendre": np.polynomial.Legendre, "chebyshev": np.polynomial.Chebyshev,
                "monomial": np.polynomial.Polynomial}[basis]
        dom = [x.min(), x.max()]
        fam = r.rational.to_family()  # from data-orthonormal coefficients, if any
        vals = kind(fam.p, domain=dom)(x) / kind(fam.q, domain=dom)(x)
        assert np.all(np.isfinite(vals))
        assert np.all(vals >= seg.lo[:, 0]) and np.all(vals <= seg.hi[:, 0])
        assert r.verification.poles_in_domain == 0
        assert r.max_violation == 0.0
    else:
        assert r.status in (1, 2)


@st.composite
def rationals(draw):
    dim = draw(st.integers(1, 3))
    family = draw(st.sampled_from(["legendre", "chebyshev", "monomial"]))
    index_set = draw(st.sampled_from(["total", "tensor"]))
    lo = np.array(draw(st.lists(st.floats(-100, 100), min_size=dim, max_size=dim)))
    width = np.array(draw(st.lists(st.floats(1e-3, 1e3), min_size=dim, max_size=dim)))
    space = PolynomialSpace(family, np.stack([lo, lo + width], axis=1), index_set)
    n = draw(st.integers(1, 10))
    m = draw(st.integers(1, 10))
    p = draw(st.lists(finite, min_size=n, max_size=n))
    q = draw(st.lists(finite, min_size=m, max_size=m))
    return RationalFunction(space, p, q)


@settings(max_examples=60, **SETTINGS)
@given(rationals())
def test_fit_json_round_trip_is_exact(rf):
    from ratfit.core.results import FitResult

    # A fit file holds a pole-free function (load refuses a denominator that vanishes
    # or changes sign): |phi_k| <= 1 on the window, so this q0 keeps q > 0.
    rf = RationalFunction(rf.space, rf.p, [float(np.abs(rf.q).sum()) + 1.0, *rf.q[1:]])

    res = FitResult(
        success=True, status=0, message="ok", n=rf.n, m=rf.m, basis=rf.space.family.name,
        index_set=rf.space.index_set, rational=rf, verification=None, delta=1e-5,
        sigma_min=0.1, sigma_max=1e4, active_set_size=0, qp_solves=1, seconds=0.0,
        solver="quadprog", decided_by="quadprog",
    )
    doc = fit_document([res])
    back = parse_fit(json.loads(json.dumps(doc, allow_nan=False)))
    rf2 = back.channels[0].rational
    assert rf2 == rf
    assert np.array_equal(rf2.p, rf.p) and np.array_equal(rf2.q, rf.q)
    assert np.array_equal(back.space.domain, rf.space.domain)


def test_saved_fit_round_trip_on_disk(tmp_path):
    x = np.linspace(0, 3, 60)
    seg = ratfit.Segments.from_relative(x, np.exp(-x) + 1, 0.01)
    r = ratfit.fit(seg)
    path = tmp_path / "sub" / "fit.json"
    save_fit(path, fit_document([r]))
    saved = load_fit(path)
    assert saved.channels[0].rational == r.rational
    assert np.array_equal(saved(x)[:, 0], r.rational(x))
    assert [p.name for p in tmp_path.joinpath("sub").iterdir()] == ["fit.json"]


def test_unverified_fit_is_not_saved(tmp_path):
    x = np.linspace(0, 10, 300)
    seg = ratfit.Segments.from_relative(x, np.sin(5 * x) + 1.5, 0.01)
    r = ratfit.fit(seg, max_total=4)
    assert not r.success
    with pytest.raises(ratfit.InputError, match="unverified"):
        fit_document([r])


# ---------------------------------------------------------------------------- monomial form
def test_monomial_conversion_known_example():
    # Legendre P2 on [0, 2]: t = x - 1, P2 = (3 t^2 - 1) / 2 = 1.5 x^2 - 3 x + 1
    space = PolynomialSpace("legendre", [[0.0, 2.0]])
    rf = RationalFunction(space, [0, 0, 1], [1])
    mf = to_monomial(rf, np.linspace(0, 2, 11))
    assert np.allclose(mf.p, [1.0, -3.0, 1.5], atol=1e-14)
    assert np.allclose(mf.q, [1.0], atol=1e-14)


@settings(max_examples=40, **SETTINGS)
@given(
    st.integers(1, 3),
    st.sampled_from(["legendre", "chebyshev", "monomial"]),
    st.sampled_from(["total", "tensor"]),
    st.integers(0, 2**32 - 1),
)
def test_monomial_form_agrees_with_orthogonal_form(dim, family, index_set, seed):
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-2, 2, dim)
    dom = np.stack([lo, lo + rng.uniform(0.5, 3, dim)], axis=1)
    space = PolynomialSpace(family, dom, index_set)
    n, m = rng.integers(1, 9, size=2)
    q = np.zeros(m)
    q[0] = 10.0  # dominant constant: q stays away from 0 on the domain
    q[1:] = rng.uniform(-1, 1, m - 1)
    rf = RationalFunction(space, rng.uniform(-1, 1, n), q)
    x = rng.uniform(dom[:, 0], dom[:, 1], size=(200, dim))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mf = to_monomial(rf, x)
    xe = x[:, 0] if dim == 1 else x
    ref = rf(x)
    # Horner's forward error bound: eps * sum |P_a| |x|^a (the monomial form's own
    # conditioning on a domain away from 0), carried through the division.
    eps = np.finfo(float).eps
    dp = eps * horner(np.abs(xe), np.abs(mf.p))
    dq = eps * horner(np.abs(xe), np.abs(mf.q))
    qx = np.abs(rf.denominator(x))
    bound = np.max((dp + np.abs(ref) * dq) / qx) / np.max(np.abs(ref))
    assert mf.max_rel_diff <= 100 * bound + 1e-14
    assert np.allclose(horner(xe, mf.p) / horner(xe, mf.q), ref, rtol=0,
                       atol=(100 * bound + 1e-14) * np.max(np.abs(ref)))
    # same count of coefficients: no degree grows
    assert np.count_nonzero(np.abs(mf.p) > 0) <= space.tensor_coef(rf.p).size


def test_fft_route_matches_numpy_route_in_1d():
    space = PolynomialSpace("chebyshev", [[-1.0, 4.0]])
    rng = np.random.default_rng(7)
    rf = RationalFunction(space, rng.normal(size=8), [3.0, 0.5, 0.1])
    mf = to_monomial(rf, np.linspace(-1, 4, 50))
    assert set(mf.errors) == {"numpy", "fft"}
    for err in mf.errors.values():
        assert err < 1e-12
    # compare with numpy's own conversion of the numerator
    ref = np.polynomial.Chebyshev(rf.p, domain=[-1, 4]).convert(kind=Polynomial, domain=[-1, 1])
    assert np.allclose(mf.p, ref.coef, rtol=1e-9, atol=1e-12)


def test_lossy_conversion_warns():
    seg = ratfit.Segments.from_relative(
        np.linspace(100, 110, 200), np.exp(np.linspace(0, 3, 200)), 1e-4
    )
    r = ratfit.fit(seg, n=14, m=2)
    assert r.rational is not None
    with pytest.warns(ratfit.errors.AccuracyWarning, match="loses accuracy"):
        to_monomial(r.rational, seg.x)
