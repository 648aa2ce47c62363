"""The evaluations of a polynomial at many points: the exact Arnoldi recurrence (the
values verdicts and exports use), its BLAS form for weights, and a space's chunked
evaluation, against plain reference computations."""

from __future__ import annotations

import numpy as np
import pytest

import ratfit.core.arnoldi as arnoldi
from ratfit.core.arnoldi import ArnoldiBasis
from ratfit.core.bases import PolynomialSpace


def _basis(k: int, seed: int = 0) -> tuple[ArnoldiBasis, np.ndarray]:
    rng = np.random.default_rng(seed)
    space = PolynomialSpace("legendre", np.array([[-1.0, 1.0]] * 3), "total")
    t = rng.uniform(-1, 1, (3000, 3))
    basis, _ = ArnoldiBasis.build(space, t, rng.uniform(0.5, 1.0, 3000), k)
    return basis, rng.uniform(-1, 1, (40_000, 3))


def _reference(basis: ArnoldiBasis, t: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The recurrence of ArnoldiBasis._sum_block's docstring, one point at a time in
    Python floats (IEEE double, the same operations in the same order)."""
    H, out = basis.H, np.empty(len(t))
    for p, x in enumerate(t.tolist()):
        f = [1.0 / float(H[0, 0])]
        s = float(c[0]) * f[0]
        for i in range(1, c.size):
            v = x[basis.dims[i]] * f[basis.parents[i]]
            for j in range(i):
                v = v - float(H[j, i]) * f[j]
            f.append(v / float(H[i, i]))
            s = s + float(c[i]) * f[i]
        out[p] = s
    return out


@pytest.mark.parametrize("k", [7, 22])
def test_exact_evaluation_is_the_documented_recurrence_bit_for_bit(k: int) -> None:
    basis, t = _basis(k)
    c = np.random.default_rng(k).normal(size=k)
    pts = t[:2500]
    got = basis.evaluate(pts, c, window=True)
    np.testing.assert_array_equal(got, _reference(basis, pts, c))
    # the same values whatever the block size (one block, or two blocks of 1 000
    # points and a short last one)
    saved = arnoldi._SUM_BLOCK
    try:
        arnoldi._SUM_BLOCK = 1000
        np.testing.assert_array_equal(basis.evaluate(pts, c, window=True), got)
    finally:
        arnoldi._SUM_BLOCK = saved


def test_blas_evaluation_agrees_with_the_exact_one() -> None:
    basis, t = _basis(22)
    c = np.random.default_rng(3).normal(size=22)
    exact = basis.evaluate(t, c, window=True)
    fast = basis.evaluate_blas(t, c, window=True)
    assert fast.shape == exact.shape
    assert np.max(np.abs(fast - exact)) <= 1e-12 * np.max(np.abs(exact))


def test_a_space_evaluates_in_chunks_with_the_values_of_one_product() -> None:
    space = PolynomialSpace("chebyshev", np.array([[0.0, 2.0], [-1.0, 3.0], [1.0, 5.0]]),
                            "total")
    rng = np.random.default_rng(1)
    x = rng.uniform([0, -1, 1], [2, 3, 5], (50_000, 3))
    c = rng.normal(size=20)
    whole = space.design(x, 20) @ c  # one product over every point
    np.testing.assert_array_equal(space.evaluate(x, c), whole)
    assert space.evaluate(x[:0], c).shape == (0,)


@pytest.mark.parametrize("index_set", ["total", "tensor"])
def test_a_space_builds_its_design_in_chunks_with_the_same_entries(index_set: str) -> None:
    """An n-D design is built by chunks of points (bounded temporaries): each entry
    is the product of the same one-variable values as the whole-matrix form."""
    from ratfit.core.bases import _EVAL_CHUNK

    space = PolynomialSpace("legendre", np.array([[0.0, 2.0], [-1.0, 3.0], [1.0, 5.0]]),
                            index_set)
    rng = np.random.default_rng(2)
    x = rng.uniform([0, -1, 1], [2, 3, 5], (2 * _EVAL_CHUNK + 77, 3))
    count = 30
    t = space.to_window(x)
    idx = space.indices(count)
    deg = int(idx.max())
    ref = space.family.vander(t[:, 0], deg)[:, idx[:, 0]].copy()
    for k in (1, 2):
        ref *= space.family.vander(t[:, k], deg)[:, idx[:, k]]
    got = space.design(x, count)
    assert got.shape == (x.shape[0], count)
    np.testing.assert_array_equal(got, ref)


def test_seed_form_row_norms_without_a_stored_cumulative_sum() -> None:
    """The seed's form computes |A(n, m)|'s row norms from B by chunks, the running
    sum of B^2 along each row (no second N x k array): the numbers a stored
    cumulative sum gave, bit for bit, and the norms of the rows themselves."""
    from ratfit.core.qp import _CHUNK, ConstraintSystem
    from ratfit.core.segments import Segments
    from ratfit.fitting.search import RationalFitter

    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, 10.0, (_CHUNK + 5000, 2))  # two chunks
    y = np.exp(-x[:, 0] / 3.0) + x[:, 1]
    seg = Segments.from_widths(x, y, dt=0.1)
    system = ConstraintSystem(RationalFitter(jobs=1).prepare(seg), seg, 0)
    system.prepare(12, 12)
    cum = np.cumsum(system.B ** 2, axis=1)
    for n, m in [(1, 1), (5, 3), (3, 11), (12, 12)]:
        sp, sq = cum[:, n - 1], cum[:, m - 1]
        stored = np.sqrt(np.concatenate([sp + system.lo**2 * sq, sp + system.hi**2 * sq]))
        got = system.row_norms(n, m)
        assert np.array_equal(got, stored)
        assert np.allclose(got, np.linalg.norm(system.rows(n, m), axis=1), rtol=1e-13)
