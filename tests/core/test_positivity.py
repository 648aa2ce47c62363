"""Bernstein-bound sign proofs (ratfit.core.positivity): sound on random polynomials,
tight enough to prove small margins, and they find the point where a sign fails."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import chebyshev as C
from numpy.polynomial import legendre as L
from numpy.polynomial import polynomial as P

from ratfit.core.positivity import bernstein_matrix, prove_positive


@pytest.mark.parametrize("family,val", [("legendre", L.legval), ("chebyshev", C.chebval),
                                         ("monomial", P.polyval)])
def test_bernstein_coefficients_bound_the_polynomial(family, val):
    rng = np.random.default_rng(3)
    for deg in (0, 1, 4, 9, 17):
        M, A = bernstein_matrix(family, deg)
        c = rng.normal(size=deg + 1)
        b = M @ c
        t = np.linspace(-1, 1, 2001)
        v = val(t, c)
        # end coefficients are the end values; all lie between the extremes' hull
        assert b[0] == pytest.approx(val(-1.0, c), abs=1e-12 * np.abs(c).sum())
        assert b[-1] == pytest.approx(val(1.0, c), abs=1e-12 * np.abs(c).sum())
        assert b.min() <= v.min() + 1e-12 and b.max() >= v.max() - 1e-12
        np.testing.assert_array_equal(A, np.abs(M))


@pytest.mark.parametrize("eps,proved,counter", [(1e-3, True, False), (1e-8, True, False),
                                                (0.0, False, False), (-1e-6, False, True)])
def test_double_root_margin(eps, proved, counter):
    """(t - 0.3)^2 + eps: proved down to a margin of 1e-8, a double root is not proved,
    and a dip below zero is found with its point."""
    c = L.poly2leg([0.09 + eps, -0.6, 1.0])
    pr = prove_positive(c, "legendre")
    assert pr.proved is proved and pr.counterexample is counter
    if proved:
        assert 0 < pr.lower <= eps * (1 + 1e-9)
    else:
        assert pr.points.shape[1] == 1
        assert np.min(np.abs(pr.points[:, 0] - 0.3)) < 0.01
    if counter:
        assert np.all(L.legval(pr.points[:, 0], c) < 0)


def test_never_proves_a_negative_polynomial():
    """Random 2-D and 3-D polynomials shifted to touch zero from either side: a proof is
    never given where a dense sample finds a value <= 0, and a counterexample is a point
    where the value is < 0."""
    rng = np.random.default_rng(7)
    proved = counters = 0
    for trial in range(60):
        d = 2 + trial % 2
        shape = tuple(rng.integers(2, 7, size=d))
        T = rng.normal(size=shape) / (1 + np.indices(shape).sum(axis=0)) ** 2
        g = rng.uniform(-1, 1, size=(4000, d))
        vals = L.legval2d(g[:, 0], g[:, 1], T) if d == 2 else L.legval3d(*g.T, T)
        shift = -vals.min() + rng.choice([-1e-2, -1e-5, 1e-5, 0.05]) * np.abs(vals).max()
        T = T.copy()
        T[(0,) * d] += shift
        vals = vals + shift
        pr = prove_positive(T, "legendre", max_boxes=20_000)
        if pr.proved:
            proved += 1
            assert vals.min() > 0
        if pr.counterexample:
            counters += 1
            pv = (L.legval2d(*pr.points.T, T) if d == 2 else L.legval3d(*pr.points.T, T))
            assert np.all(pv <= 0)
    assert proved >= 8 and counters >= 8, (proved, counters)  # both outcomes exercised


def test_excluded_pieces_are_not_part_of_the_region():
    """1 - 2 t^2 is negative near the ends; excluding |t| > 0.6 leaves a region where it
    is positive, and the proof says so; without the exclusion it finds the negative end."""
    c = L.poly2leg([1.0, 0.0, -2.0])  # 1 - 2 t^2 > 0 on |t| < 0.7
    assert prove_positive(c, "legendre").counterexample
    pr = prove_positive(c, "legendre", exclude=lambda lo, hi: (lo[:, 0] >= 0.6)
                        | (hi[:, 0] <= -0.6))
    assert pr.proved
