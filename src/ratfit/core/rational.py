"""The rational function r = p / q in a :class:`~ratfit.core.bases.PolynomialSpace`.

Immutable and independent of how it was computed (QP, search, file): it only
evaluates, finds poles and converts. p and q are coefficient vectors either
in the space's family (Legendre, ...) or, when ``p_basis``/``q_basis`` are
given, in polynomial bases orthonormal on the data
(:class:`~ratfit.core.arnoldi.ArnoldiBasis`), which represent denominators of
large dynamic range that the family's coefficients cannot carry in double
precision. :meth:`RationalFunction.to_family` converts to the family.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.bases import PolynomialSpace

if TYPE_CHECKING:
    from ratfit.core.arnoldi import ArnoldiBasis

__all__ = ["VALUE_FORMS", "RationalFunction", "ratio_values"]

Array = NDArray[np.float64]

#: What a fit's p / q gives: the values themselves ("linear") or their logarithms
#: ("log": the value is exp(p / q), positive by construction).
VALUE_FORMS = ("linear", "log")


def ratio_values(ratio: ArrayLike, values: str = "linear") -> Array:
    """A fit's values from its p / q (:data:`VALUE_FORMS`): the ratio itself, or exp of it
    for a fit of log values; non-finite stays non-finite. The one definition every
    evaluator and every check of a fit's values uses."""
    r = np.asarray(ratio, dtype=np.float64)
    if values == "log":
        with np.errstate(over="ignore"):
            return np.exp(r)
    return r


def _single_point(x: ArrayLike, dim: int) -> Array | None:
    """``x`` as a (1, dim) array when it is one point (a number in 1-D, a vector of
    length ``dim`` > 1 in n-D), else None: evaluations of one point return a float."""
    if isinstance(x, np.ndarray) and x.dtype == object:
        return None
    shape = np.shape(x)
    if shape == () or (dim > 1 and shape == (dim,)):
        return np.asarray(x, dtype=float).reshape(1, dim)
    return None


# Values of p and q at a large, read-only point array are kept for the next
# evaluation of the same function at the same array (the polish scores the candidate
# its verification has just evaluated; the metrics evaluate the fits the final proof
# has just verified): each is a pass over every sample (~1 s per million points and
# 50 coefficients). At most MEMO_ENTRIES values, from MEMO_MIN_POINTS points up.
MEMO_ENTRIES = 8
MEMO_MIN_POINTS = 65_536


def _frozen(x: object) -> bool:
    """``x`` is a large ndarray that nothing can write to: read-only, and so is every
    array it is a view of (a read-only view of a writeable array may still change)."""
    if not isinstance(x, np.ndarray) or x.ndim == 0 or x.shape[0] < MEMO_MIN_POINTS:
        return False
    a: object = x
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


class _ValuesMemo:
    """The last :data:`MEMO_ENTRIES` evaluations (function, p or q, points, window)
    -> values, keyed by the identity of the function and of the point array (both
    held weakly, so an entry dies with either); a hit returns a copy of the same
    numbers the evaluation would compute again."""

    def __init__(self, entries: int) -> None:
        self.entries = entries
        self._items: list[tuple[weakref.ref, weakref.ref, str, bool, Array]] = []
        self._lock = threading.Lock()

    def get(self, rf: RationalFunction, which: str, x: ArrayLike, window: bool,
            compute: Callable[[], Array]) -> Array:
        if not _frozen(x):
            return compute()
        with self._lock:
            for i, (fr, xr, w, win, vals) in enumerate(self._items):
                if fr() is rf and xr() is x and w == which and win == window:
                    self._items.append(self._items.pop(i))  # most recent last
                    return vals.copy()
        vals = compute()
        with self._lock:
            self._items = [e for e in self._items if e[0]() is not None and e[1]() is not None]
            self._items.append((weakref.ref(rf), weakref.ref(x), which, window, vals.copy()))
            del self._items[:-self.entries]
        return vals


_MEMO = _ValuesMemo(MEMO_ENTRIES)


class RationalFunction:
    """r(x) = p(x) / q(x), with ``p``, ``q`` coefficient vectors in graded order.

    ``n = len(p)`` and ``m = len(q)`` count coefficients (degree n - 1 in 1-D).

    Parameters
    ----------
    space : PolynomialSpace
        Basis family, domain and index set of p and q.
    p, q : array-like
        Coefficients in the space's basis (or in ``p_basis`` / ``q_basis``).
    p_basis, q_basis : ArnoldiBasis, optional
        Data-orthonormal bases (the well-conditioned formulation's fits).

    Examples
    --------
    >>> from ratfit import PolynomialSpace, RationalFunction
    >>> r = RationalFunction(PolynomialSpace("monomial", [[-1.0, 1.0]]), [1.0], [2.0, 1.0])
    >>> r([0.0, 1.0]).tolist()   # 1 / (2 + t)
    [0.5, 0.3333333333333333]
    """

    def __init__(self, space: PolynomialSpace, p: ArrayLike, q: ArrayLike, *,
                 p_basis: ArnoldiBasis | None = None,
                 q_basis: ArnoldiBasis | None = None) -> None:
        self.space = space
        self.p_basis = p_basis
        self.q_basis = q_basis
        self.p = np.array(p, dtype=float).ravel()
        self.q = np.array(q, dtype=float).ravel()
        if self.p.size < 1 or self.q.size < 1:
            raise ValueError("p and q need at least one coefficient each")
        self.p.setflags(write=False)
        self.q.setflags(write=False)
        for name, b, c in (("p", p_basis, self.p), ("q", q_basis, self.q)):
            if b is not None and (b.space != space or b.size < c.size):
                raise ValueError(f"{name}_basis does not match the space or the coefficients")

    @property
    def orthonormal(self) -> bool:
        """True when p or q is held in a data-orthonormal (Arnoldi) basis."""
        return self.p_basis is not None or self.q_basis is not None

    @property
    def n(self) -> int:
        return int(self.p.size)

    @property
    def m(self) -> int:
        return int(self.q.size)

    @property
    def total(self) -> int:
        return self.n + self.m

    def numerator(self, x: ArrayLike, *, window: bool = False) -> Array:
        return _MEMO.get(self, "p", x, window, lambda: np.asarray(
            (self.p_basis or self.space).evaluate(x, self.p, window=window)))

    def denominator(self, x: ArrayLike, *, window: bool = False) -> Array:
        return _MEMO.get(self, "q", x, window, lambda: np.asarray(
            (self.q_basis or self.space).evaluate(x, self.q, window=window)))

    def to_family(self) -> RationalFunction:
        """The same function with p and q in the space's family (exact up to
        rounding; check the values when q has a large dynamic range)."""
        if not self.orthonormal:
            return self
        p = self.p if self.p_basis is None else self.p_basis.to_family(self.p)
        q = self.q if self.q_basis is None else self.q_basis.to_family(self.q)
        return RationalFunction(self.space, p, q)

    @overload
    def __call__(self, x: float, *, window: bool = False) -> float: ...

    @overload
    def __call__(self, x: ArrayLike, *, window: bool = False) -> Array: ...

    def __call__(self, x: ArrayLike, *, window: bool = False) -> Array | float:
        """Values at points x (N, d), or (N,) in 1-D; inf/NaN where q vanishes.

        One point gives a float: a scalar in 1-D, a vector of length d in n-D.
        """
        single = _single_point(x, self.space.dim)
        if single is not None:
            return float(self(single, window=window)[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.numerator(x, window=window) / self.denominator(x, window=window)

    def poles(self) -> NDArray:
        """All (complex) roots of q in the original variable (1-D only)."""
        if self.space.dim != 1:
            raise NotImplementedError("poles() is defined for 1-D functions; use verify() in n-D")
        q = np.trim_zeros(self.q, "b")
        if q.size <= 1:
            return np.array([], dtype=complex)
        if self.q_basis is not None:
            t = np.asarray(self.q_basis.roots(q), dtype=complex)
        else:
            t = np.asarray(self.space.family.roots(q), dtype=complex)
        a, b = self.space._scale
        return self.space.from_variable((t - b[0]) / a[0])

    def real_poles_in_domain(self, *, rtol: float = 1e-9) -> Array:
        """Real roots of q inside the domain (closed), from q's basis coefficients."""
        z = self.poles()
        if z.size == 0:
            return np.array([])
        lo, hi = self.space.domain[0]
        width = hi - lo
        real = np.abs(z.imag) <= rtol * width + 1e-300
        r = z.real[real]
        pad = rtol * width
        return np.sort(r[(r >= lo - pad) & (r <= hi + pad)])

    def bases_dict(self) -> dict:
        """The orthonormal bases (if any), keyed p_basis / q_basis."""
        out = {}
        if self.p_basis is not None:
            out["p_basis"] = self.p_basis.to_dict()
        if self.q_basis is not None:
            out["q_basis"] = self.q_basis.to_dict()
        return out

    def to_dict(self) -> dict:
        return {
            "space": self.space.to_dict(),
            "p": self.p.tolist(),
            "q": self.q.tolist(),
            **self.bases_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict, space: PolynomialSpace | None = None) -> RationalFunction:
        from ratfit.core.arnoldi import ArnoldiBasis

        space = PolynomialSpace.from_dict(d["space"]) if space is None else space
        bases = {
            key: ArnoldiBasis.from_dict(d[key], space)
            for key in ("p_basis", "q_basis") if d.get(key) is not None
        }
        return cls(space, d["p"], d["q"], **bases)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, RationalFunction)
            and self.space == other.space
            and np.array_equal(self.p, other.p)
            and np.array_equal(self.q, other.q)
            and self.p_basis == other.p_basis
            and self.q_basis == other.q_basis
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (
            f"RationalFunction({self.space.family.name}, dim={self.space.dim}, "
            f"n={self.n}, m={self.m}{', orthonormal' if self.orthonormal else ''})"
        )
