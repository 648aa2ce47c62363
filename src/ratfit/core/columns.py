"""The column space the data can see: rank-revealing reductions of a basis.

Measured data (BRDFs above all) comes on grids with few distinct values per
axis: a goniometer fixes three light elevations and sweeps the viewer. On such
data a polynomial of degree >= k in an axis with k distinct values is a
combination of lower degrees, so the columns of any graded basis become
linearly dependent: the seed's delta = 1 / cond(A) is 1e-17 and the QP's
constraints are empty of meaning, and the Arnoldi recurrence stops.

Two reductions, both computed from the data only:

- per axis: degrees capped by that axis's distinct values minus one
  (:func:`axis_degree_caps`), applied through the index set of
  :class:`~ratfit.core.bases.PolynomialSpace` (``max_degree``), so every
  coefficient counted is one the data can determine, and fit files, exports
  and the Arnoldi recurrence all see the same index set;
- for what remains (dependencies that are not axis-aligned): singular values
  below a rank tolerance are zeros, not a condition number
  (:func:`nonzero_singular_values`), and pivoted QR picks independent columns
  (:func:`independent_columns`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "MAX_DEGREE_CAP",
    "axis_degree_caps",
    "constant_axes",
    "distinct_per_axis",
    "independent_columns",
    "nonzero_singular_values",
    "rank_tolerance",
]

Array = NDArray[np.float64]


def distinct_per_axis(t: ArrayLike, rtol: float = 1e-9) -> NDArray[np.int64]:
    """How many distinct values each column of ``t`` (N, d) takes.

    Values closer than ``rtol`` times the axis's span are one value (grids
    written with 17 digits after a trigonometric conversion jitter in the last bits).
    """
    a = np.asarray(t, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    out = np.empty(a.shape[1], dtype=np.int64)
    for k in range(a.shape[1]):
        v = np.sort(a[:, k])
        if v.size == 0:
            out[k] = 0
            continue
        span = float(v[-1] - v[0])
        gaps = np.diff(v)
        out[k] = 1 + int(np.count_nonzero(gaps > rtol * max(span, 1e-300)))
    return out


# The largest cap written: a fit file accepts no more (ratfit.io.fitfile), and a cap
# this high never binds, since the k-th index of a graded order has degree < k: it
# would take more than 10 000 coefficients. Dense scattered data has more distinct
# values per axis (retro-gray-tape-dense in the half-vector frame: 53 300), and its
# verified fits were written with caps the loader refused.
MAX_DEGREE_CAP = 10_000


def axis_degree_caps(t: ArrayLike, rtol: float = 1e-9) -> tuple[int, ...]:
    """Largest degree per axis that the points can carry: distinct values - 1, at
    most :data:`MAX_DEGREE_CAP` (which never binds below 10 001 coefficients)."""
    return tuple(int(min(max(c - 1, 0), MAX_DEGREE_CAP)) for c in distinct_per_axis(t, rtol))


def constant_axes(x: ArrayLike) -> NDArray[np.int64]:
    """Axes on which every point has the same value (nothing to fit there)."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    return np.flatnonzero(np.ptp(a, axis=0) == 0) if a.shape[0] else np.arange(0)


def rank_tolerance(shape: tuple[int, int], smax: float) -> float:
    """Singular values at or below this are numerically zero (LAPACK's rule)."""
    return float(max(shape) * np.finfo(float).eps * smax)


def nonzero_singular_values(s: ArrayLike, shape: tuple[int, int] | None = None,
                            rtol: float | None = None) -> Array:
    """The singular values of a matrix that are not numerically zero.

    ``s`` in any order; returned descending. A matrix with dependent columns
    has cond = inf, yet the QP only ever moves in its row space: its margin
    delta is the ratio of the extreme *nonzero* singular values.
    """
    v = np.sort(np.abs(np.asarray(s, dtype=float)))[::-1]
    if v.size == 0 or v[0] <= 0:
        return v[:0]
    if rtol is not None:
        tol = rtol * v[0]
    else:
        tol = rank_tolerance(shape or (v.size, v.size), float(v[0]))
    return v[v > tol]


def independent_columns(M: ArrayLike, rtol: float = 1e-10) -> NDArray[np.int64]:
    """Indices (ascending) of a maximal set of independent columns of ``M``.

    Pivoted QR: the pivot order picks, at each step, the column with the most
    left after projecting out those already taken; columns whose remainder is
    below ``rtol`` times the largest pivot are dependent.
    """
    from scipy.linalg import qr

    A = np.asarray(M, dtype=float)
    if A.size == 0:
        return np.arange(0)
    norms = np.linalg.norm(A, axis=0)
    scaled = A / np.where(norms > 0, norms, 1.0)
    _, R, piv = qr(scaled, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    if d.size == 0 or d[0] == 0:
        return np.arange(0)
    rank = int(np.count_nonzero(d > rtol * d[0]))
    return np.sort(piv[:rank]).astype(np.int64)
