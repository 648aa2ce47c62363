"""The values memo of RationalFunction: the same numbers, computed once per array."""

from __future__ import annotations

import numpy as np

import ratfit.core.rational as rational
from ratfit.core.arnoldi import ArnoldiBasis
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction


def _fit_and_counter(monkeypatch):
    rng = np.random.default_rng(3)
    space = PolynomialSpace("legendre", [[0.0, 1.0], [0.0, 2.0]])
    t = rng.uniform(-1, 1, (500, 2))
    pb, _ = ArnoldiBasis.build(space, t, np.ones(500), 6)
    qb, _ = ArnoldiBasis.build(space, t, np.exp(t[:, 0]), 3)
    rf = RationalFunction(space, rng.normal(size=6), [3.0, 0.1, 0.2], p_basis=pb, q_basis=qb)
    calls = []
    real = ArnoldiBasis.evaluate

    def counted(self, x, coef, *, window=False):
        calls.append(np.shape(x)[0])
        return real(self, x, coef, window=window)

    monkeypatch.setattr(ArnoldiBasis, "evaluate", counted)
    monkeypatch.setattr(rational, "MEMO_MIN_POINTS", 100)
    return rf, calls


def test_a_frozen_array_is_evaluated_once_and_gives_the_same_numbers(monkeypatch) -> None:
    rf, calls = _fit_and_counter(monkeypatch)
    x = np.random.default_rng(4).uniform([0, 0], [1, 2], (300, 2))
    fresh = rf(x)  # writeable: computed every time
    assert len(calls) == 2
    rf(x)
    assert len(calls) == 4
    x.setflags(write=False)
    first = rf(x)
    again = rf(x)
    assert len(calls) == 6  # the second call took p and q from the memo
    assert np.array_equal(first, fresh) and np.array_equal(again, fresh)
    again[:] = 0.0  # a copy: the memo's numbers are the caller's to change
    assert np.array_equal(rf(x), fresh) and len(calls) == 6
    # another function, or the same numbers in another array: computed
    other = RationalFunction(rf.space, rf.p * 2, rf.q, p_basis=rf.p_basis,
                             q_basis=rf.q_basis)
    assert np.allclose(other(x), 2 * fresh)
    y = x.copy()
    y.setflags(write=False)
    rf(y)
    assert len(calls) == 10


def test_a_read_only_view_of_a_writeable_array_is_not_kept(monkeypatch) -> None:
    rf, calls = _fit_and_counter(monkeypatch)
    base = np.random.default_rng(5).uniform([0, 0], [1, 2], (300, 2))
    view = base[:]
    view.setflags(write=False)
    before = rf(view)
    base[:, 0] = 0.5  # the view's numbers change under it
    after = rf(view)
    assert len(calls) == 4
    assert not np.array_equal(before, after)
    # small arrays are not kept either
    monkeypatch.setattr(rational, "MEMO_MIN_POINTS", 1000)
    frozen = base.copy()
    frozen.setflags(write=False)
    rf(frozen)
    rf(frozen)
    assert len(calls) == 8
