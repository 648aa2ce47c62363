"""Polynomial bases on the scaled domain [-1, 1]^d, 1-D and n-D.

Every basis operation is delegated to ``numpy.polynomial``: a 1-D
:class:`Family` only plugs in numpy's module functions (vander, val, der,
roots, conversion to power series), as ``numpy.polynomial``'s own classes do.
:class:`PolynomialSpace` adds what numpy lacks: graded multi-index sets of any
dimension and the affine map from the data ``domain`` to the ``window``.

Coefficient counts, not degrees: ``n`` basis functions means the first ``n``
multi-indices of the graded order (degree ``n - 1`` in 1-D).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.polynomial import chebyshev as _cheb
from numpy.polynomial import legendre as _leg
from numpy.polynomial import polynomial as _poly
from numpy.typing import ArrayLike, NDArray

from ratfit.errors import InputError

__all__ = [
    "FAMILIES",
    "INDEX_SETS",
    "Family",
    "PolynomialSpace",
    "get_family",
    "multi_indices",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Family:
    """A 1-D polynomial family on the window [-1, 1], by numpy module functions.

    (numpy types these functions as overloaded callables over every dtype; here
    they are called on float arrays and give float arrays.)
    """

    name: str
    vander: Callable[..., Any]
    val: Callable[..., Any]
    der: Callable[..., Any]
    roots: Callable[..., NDArray[Any]]
    to_power: Callable[..., Any]
    from_power: Callable[..., Any]


def _identity(c: ArrayLike) -> Array:
    return np.array(c, dtype=float)


FAMILIES: dict[str, Family] = {
    "legendre": Family(
        "legendre", _leg.legvander, _leg.legval, _leg.legder, _leg.legroots,
        _leg.leg2poly, _leg.poly2leg,
    ),
    "chebyshev": Family(
        "chebyshev", _cheb.chebvander, _cheb.chebval, _cheb.chebder, _cheb.chebroots,
        _cheb.cheb2poly, _cheb.poly2cheb,
    ),
    # The seed's "centered monomials": powers of the scaled variable t in [-1, 1].
    "monomial": Family(
        "monomial", _poly.polyvander, _poly.polyval, _poly.polyder, _poly.polyroots,
        _identity, _identity,
    ),
}

INDEX_SETS = ("total", "tensor")
# points per chunk of an n-D evaluation (PolynomialSpace.evaluate)
_EVAL_CHUNK = 16_384
VARIABLES = ("x", "log")


def get_family(name: str) -> Family:
    try:
        return FAMILIES[name]
    except KeyError:
        raise InputError(
            f"unknown basis {name!r}; choose one of {', '.join(FAMILIES)}"
        ) from None


def multi_indices(dim: int, count: int, index_set: str = "total",
                  max_degree: tuple[int, ...] | None = None) -> NDArray[np.int64]:
    """The first ``count`` multi-indices of ``dim`` variables in graded order.

    ``max_degree`` (one cap per axis) leaves out every index above its cap:
    what data with few distinct values per axis can determine
    (:mod:`ratfit.core.columns`). The capped set stays downward closed.

    ``total``: by total degree |a|_1, then by descending power of x0 inside a
    shell, e.g. (1,0) before (0,1). ``tensor``: by max degree |a|_inf, then by
    total degree, then the same tie order, e.g. (1,0), (0,1), (1,1). Any prefix
    of either order is a downward-closed set only at complete shells; neither the
    QP nor the monomial conversion needs that (degrees never grow under a change
    of basis).
    """
    if index_set not in INDEX_SETS:
        raise InputError(f"unknown index set {index_set!r}; choose one of {', '.join(INDEX_SETS)}")
    if dim < 1:
        raise InputError(f"dimension must be >= 1, got {dim}")
    if count < 0:
        raise InputError(f"number of coefficients must be >= 0, got {count}")
    caps = None if max_degree is None else tuple(int(v) for v in max_degree)
    if caps is not None:
        if len(caps) != dim or min(caps) < 0:
            raise InputError(f"max_degree needs {dim} caps >= 0, got {max_degree!r}")
        room = _capped_size(caps, index_set)
        if count > room:
            raise InputError(
                f"{count} coefficients asked for, but the degree caps {list(caps)} (the "
                f"data's distinct values per axis, minus one) allow only {room}"
            )
    out: list[tuple[int, ...]] = []
    shell = 0
    while len(out) < count:
        # Shells are generated lazily: a full shell has (s+1)^dim candidates, so
        # enumerating it whole is exponential in the dimension.
        for a in _shell(dim, shell, index_set):
            if caps is not None and not all(v <= c for v, c in zip(a, caps, strict=True)):
                continue
            out.append(a)
            if len(out) == count:
                break
        shell += 1
    return np.array(out[:count], dtype=np.int64).reshape(count, dim)


def _capped_size(caps: tuple[int, ...], index_set: str) -> int:
    """Number of multi-indices under per-axis caps (both index sets reach the box)."""
    return int(np.prod([c + 1 for c in caps], dtype=float)) if caps else 0


def _shell(dim: int, s: int, index_set: str) -> Iterator[tuple[int, ...]]:
    """Multi-indices of shell s: lower total degree first, then x0's power descending."""
    if dim == 1:
        yield (s,)
        return
    if index_set == "total":
        yield from _compositions(s, dim, s)
        return
    for t in range(s, s * dim + 1):  # tensor: max(a) == s, by total degree t
        for a in _compositions(t, dim, s):
            if max(a) == s:
                yield a


def _compositions(total: int, parts: int, cap: int) -> Iterator[tuple[int, ...]]:
    """Tuples of ``parts`` integers in [0, cap] summing to ``total``, first entry descending."""
    if parts == 1:
        if total <= cap:
            yield (total,)
        return
    for a in range(min(total, cap), max(-1, total - cap * (parts - 1) - 1), -1):
        for rest in _compositions(total - a, parts - 1, cap):
            yield (a, *rest)


class PolynomialSpace:
    """A polynomial family on ``domain`` (d intervals), mapped affinely to [-1,1]^d.

    Working on [-1, 1]^d keeps the basis well conditioned whatever the data's units.

    Parameters
    ----------
    family : {"legendre", "chebyshev", "monomial"}
        Basis family (:data:`FAMILIES`).
    domain : array-like of shape (d, 2)
        [min, max] per input dimension.
    index_set : {"total", "tensor"}, default "total"
        Graded by total degree or by max degree (n-D).
    max_degree : sequence of int, optional
        Per-axis degree caps (see :func:`multi_indices`); an axis capped at 0
        is one the function does not depend on.
    variable : {"x", "log"}, default "x"
        "log" (1-D, positive domain): the window is the affine image of log x,
        so p and q are polynomials in log x. Data spanning many decades (sqrt on
        1e-15..1) is then smooth and small in t, where polynomials in x would
        need a denominator whose values span 1e180.

    Attributes
    ----------
    family : Family
    domain : ndarray of shape (d, 2)
    index_set : str

    Examples
    --------
    >>> from ratfit import PolynomialSpace
    >>> s = PolynomialSpace("chebyshev", [[0.0, 10.0]])
    >>> s.dim, s.to_window([0.0, 5.0, 10.0]).ravel().tolist()
    (1, [-1.0, 0.0, 1.0])
    """

    def __init__(self, family: str, domain: ArrayLike, index_set: str = "total",
                 max_degree: tuple[int, ...] | None = None, variable: str = "x") -> None:
        self.family = get_family(family)
        dom = np.array(domain, dtype=float).reshape(-1, 2)
        if not np.all(np.isfinite(dom)):
            raise InputError(f"domain must be finite, got {dom.tolist()}")
        if float(np.max(np.abs(dom), initial=0.0)) > 1e300:
            raise InputError(f"domain bounds beyond 1e300 in magnitude: {dom.tolist()}")
        if np.any(dom[:, 1] <= dom[:, 0]):
            bad = int(np.flatnonzero(dom[:, 1] <= dom[:, 0])[0])
            raise InputError(
                f"domain of dimension {bad} is empty or reversed: {dom[bad].tolist()}"
            )
        if index_set not in INDEX_SETS:
            raise InputError(
                f"unknown index set {index_set!r}; choose one of {', '.join(INDEX_SETS)}"
            )
        self.domain = dom
        self.domain.setflags(write=False)
        self.index_set = index_set
        if max_degree is not None:
            max_degree = tuple(int(v) for v in max_degree)
            if len(max_degree) != dom.shape[0] or min(max_degree) < 0:
                raise InputError(
                    f"max_degree needs {dom.shape[0]} caps >= 0, got {list(max_degree)}"
                )
        self.max_degree = max_degree
        if variable not in VARIABLES:
            raise InputError(f"unknown variable {variable!r}; choose one of {', '.join(VARIABLES)}")
        if variable == "log" and (dom.shape[0] != 1 or dom[0, 0] <= 0):
            raise InputError(f"variable 'log' needs a 1-D domain of positive x, got {dom.tolist()}")
        self.variable = variable

    # -- geometry -------------------------------------------------------------
    @property
    def dim(self) -> int:
        return int(self.domain.shape[0])

    @cached_property
    def _scale(self) -> tuple[Array, Array]:
        """(a, b) of t = a u + b, with u = x (or log x for variable 'log')."""
        lo, hi = self.domain[:, 0], self.domain[:, 1]
        if self.variable == "log":
            lo, hi = np.log(lo), np.log(hi)
        return 2.0 / (hi - lo), -(hi + lo) / (hi - lo)

    def from_variable(self, u: NDArray) -> NDArray:
        """x from u (the affine preimage of t): exp for variable 'log' (complex too)."""
        return np.exp(u) if self.variable == "log" else u

    def to_window(self, x: ArrayLike) -> Array:
        """Map points (N, d) in the domain to t in [-1, 1]^d."""
        xa = np.asarray(x, dtype=float)
        if xa.ndim == 1 and self.dim == 1:
            xa = xa[:, None]
        if xa.ndim != 2 or xa.shape[1] != self.dim:
            raise InputError(
                f"points must have shape (N, {self.dim}), got {np.shape(x)}"
            )
        a, b = self._scale
        if self.variable == "log":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.log(xa) * a + b  # x <= 0 gives NaN/-inf: outside the space
        return xa * a + b

    def from_window(self, t: ArrayLike) -> Array:
        a, b = self._scale
        return self.from_variable((np.asarray(t, dtype=float) - b) / a)

    # -- index sets and matrices ---------------------------------------------
    def indices(self, count: int) -> NDArray[np.int64]:
        return multi_indices(self.dim, count, self.index_set, self.max_degree)

    def capacity(self) -> int | None:
        """How many basis functions the caps allow (None: unbounded)."""
        return None if self.max_degree is None else _capped_size(self.max_degree, self.index_set)

    def design(self, x: ArrayLike, count: int, *, window: bool = False) -> Array:
        """Matrix (N, count) of the first ``count`` basis functions at the points."""
        t = np.asarray(x, dtype=float) if window else self.to_window(x)
        if t.ndim == 1:
            t = t[:, None]
        idx = self.indices(count)
        if count == 0:
            return np.zeros((t.shape[0], 0))
        deg = int(idx.max())
        if self.dim == 1:
            return self.family.vander(t[:, 0], deg)[:, idx[:, 0]]
        # by chunks of points: whole, the factors' temporaries were as large as the
        # result again (1.2 GB beside a 530 MB design at 60 functions on a full MERL
        # table); each entry is the same product either way
        out = np.empty((t.shape[0], idx.shape[0]))
        for s in range(0, t.shape[0], _EVAL_CHUNK):
            tc = t[s:s + _EVAL_CHUNK]
            block = out[s:s + _EVAL_CHUNK]
            block[...] = self.family.vander(tc[:, 0], deg)[:, idx[:, 0]]
            for k in range(1, self.dim):
                block *= self.family.vander(tc[:, k], deg)[:, idx[:, k]]
        return out

    def evaluate(self, x: ArrayLike, coef: ArrayLike, *, window: bool = False) -> Array:
        """Values of the polynomial with coefficients ``coef`` (graded order)."""
        c = np.asarray(coef, dtype=float)
        t = np.asarray(x, dtype=float) if window else self.to_window(x)
        if self.dim == 1:
            return self.family.val(np.ravel(t), c)
        if t.ndim == 1:
            t = t[:, None]
        # in chunks of points: the design of a million points (a MERL table, 22
        # functions: 194 MB, and the Vandermonde matrices beside it) is never formed,
        # and each chunk's stays in cache (1.5 s -> 0.4 s a polynomial; the same values:
        # each row's product with c does not depend on the rows around it)
        out = np.empty(t.shape[0])
        for s in range(0, t.shape[0], _EVAL_CHUNK):
            out[s:s + _EVAL_CHUNK] = self.design(t[s:s + _EVAL_CHUNK], c.size, window=True) @ c
        return out

    def tensor_coef(self, coef: ArrayLike) -> Array:
        """Dense d-way array C[a_1, ..., a_d] holding the graded coefficients."""
        c = np.asarray(coef, dtype=float)
        idx = self.indices(c.size)
        shape = tuple(int(v) + 1 for v in idx.max(axis=0)) if c.size else (1,) * self.dim
        out = np.zeros(shape)
        out[tuple(idx.T)] = c
        return out

    # -- (de)serialisation ------------------------------------------------------
    def to_dict(self) -> dict:
        d = {
            "family": self.family.name,
            "dim": self.dim,
            "index_set": self.index_set,
            "domain": self.domain.tolist(),
        }
        if self.max_degree is not None:
            d["max_degree"] = list(self.max_degree)
        if self.variable != "x":
            d["variable"] = self.variable
        return d

    @classmethod
    def from_dict(cls, d: dict) -> PolynomialSpace:
        md = d.get("max_degree")
        return cls(d["family"], d["domain"], d.get("index_set", "total"),
                   None if md is None else tuple(md), variable=d.get("variable", "x"))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, PolynomialSpace)
            and self.family.name == other.family.name
            and self.index_set == other.index_set
            and np.array_equal(self.domain, other.domain)
            and self.max_degree == other.max_degree
            and self.variable == other.variable
        )

    def __hash__(self) -> int:
        return hash((self.family.name, self.index_set, self.domain.tobytes(), self.max_degree,
                     self.variable))

    def __repr__(self) -> str:
        return (
            f"PolynomialSpace({self.family.name!r}, domain={self.domain.tolist()}, "
            f"index_set={self.index_set!r}"
            + (f", max_degree={list(self.max_degree)}" if self.max_degree is not None else "")
            + (f", variable={self.variable!r}" if self.variable != "x" else "")
            + ")"
        )
