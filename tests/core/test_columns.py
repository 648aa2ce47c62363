"""Rank-revealing reductions: the column space data on few distinct values per axis can see."""

from __future__ import annotations

import numpy as np
import pytest

import ratfit
from ratfit.core.bases import PolynomialSpace, multi_indices
from ratfit.core.columns import (
    axis_degree_caps,
    constant_axes,
    distinct_per_axis,
    independent_columns,
    nonzero_singular_values,
)
from ratfit.errors import InputError


def test_distinct_values_and_caps_ignore_last_bit_jitter() -> None:
    a = np.repeat([0.1, 0.5, 0.9], 4)
    a[1] += 1e-15  # the same grid value written through a trigonometric round trip
    t = np.stack([a, np.linspace(0, 1, 12), np.full(12, 2.0)], axis=1)
    assert distinct_per_axis(t).tolist() == [3, 12, 1]
    assert axis_degree_caps(t) == (2, 11, 0)
    assert constant_axes(t).tolist() == [2]


def test_capped_indices_skip_what_an_axis_cannot_carry() -> None:
    idx = multi_indices(2, 8, "total", (1, 5))
    assert all(a[0] <= 1 for a in idx.tolist())
    # graded order kept: (0,0), (1,0), (0,1), (1,1), (0,2), (1,2), (0,3), (1,3)
    assert idx.tolist() == [[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2], [0, 3], [1, 3]]
    space = PolynomialSpace("legendre", [[0, 1], [0, 1]], "total", (1, 5))
    assert space.capacity() == 12
    with pytest.raises(InputError, match="allow only 12"):
        space.indices(13)
    back = PolynomialSpace.from_dict(space.to_dict())
    assert back == space and back.max_degree == (1, 5)
    assert PolynomialSpace("legendre", [[0, 1], [0, 1]]) != space


def test_nonzero_singular_values_and_pivoted_columns() -> None:
    rng = np.random.default_rng(0)
    M = rng.standard_normal((50, 4))
    M = np.hstack([M, M[:, :1] + 2 * M[:, 2:3]])  # column 4 depends on 0 and 2
    s = np.linalg.svd(M, compute_uv=False)
    assert s[-1] < 1e-13 * s[0]
    nz = nonzero_singular_values(s, M.shape)
    assert nz.size == 4 and nz[-1] > 0.1
    keep = independent_columns(M)
    assert keep.size == 4 and np.linalg.matrix_rank(M[:, keep]) == 4


def test_grid_with_three_values_on_one_axis_fits_with_a_sane_delta() -> None:
    # Three "light elevations", many "view" angles: degree >= 3 in x0 is invisible.
    x0 = np.repeat([0.2, 0.6, 1.0], 120)
    x1 = np.tile(np.linspace(-1.0, 1.0, 120), 3)
    x = np.stack([x0, x1], axis=1)
    y = (1.0 + x0) / (1.2 + np.cos(2.0 * x1))
    seg = ratfit.Segments.from_relative(x, y, 0.02)
    fitter = ratfit.RationalFitter(n=9, m=6, formulation="basis").fit(seg)
    res = fitter.result_
    assert fitter.space_.max_degree == (2, 119)
    assert res.delta > 1e-8  # the uncapped seed matrix has delta ~ 1e-17 here
    assert res.success, res.message
    idx = fitter.space_.indices(res.n)
    assert idx[:, 0].max() <= 2


def test_caps_of_dense_scattered_data_stay_loadable(tmp_path) -> None:
    """More distinct values per axis than a fit file's cap (retro-gray-tape-dense in
    the half-vector frame has 53 300): the caps are clipped at MAX_DEGREE_CAP, where
    they never bind, and the verified fit saves and loads back."""
    from ratfit.core.columns import MAX_DEGREE_CAP
    from ratfit.io.fitfile import fit_document, load_fit, save_fit

    rng = np.random.default_rng(0)
    x = rng.uniform(-1.0, 1.0, size=(12_500, 2))
    assert distinct_per_axis(x).tolist() == [12_500, 12_500]
    assert axis_degree_caps(x) == (MAX_DEGREE_CAP, MAX_DEGREE_CAP) == (10_000, 10_000)
    y = (2.0 + x[:, 0]) / (1.5 + x[:, 1])
    seg = ratfit.Segments.from_relative(x, y, 0.01)
    fitter = ratfit.RationalFitter(n=3, m=3).fit(seg)
    assert fitter.success_ and fitter.space_.max_degree == (10_000, 10_000)
    path = tmp_path / "fit.json"
    save_fit(path, fit_document(fitter.results_))
    saved = load_fit(path)
    np.testing.assert_allclose(saved(x[:100])[:, 0], fitter.rational_(x[:100]), rtol=1e-12)
