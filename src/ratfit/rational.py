"""The rational function r = p / q in a :class:`~ratfit.bases.PolynomialSpace`.

Immutable and independent of how it was computed (QP, search, file): it only
evaluates, finds poles and converts.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .bases import PolynomialSpace

__all__ = ["RationalFunction"]

Array = NDArray[np.float64]


class RationalFunction:
    """r(x) = p(x) / q(x), with ``p``, ``q`` coefficient vectors in graded order.

    ``n = len(p)`` and ``m = len(q)`` count coefficients (degree n - 1 in 1-D).
    """

    def __init__(self, space: PolynomialSpace, p: ArrayLike, q: ArrayLike) -> None:
        self.space = space
        self.p = np.array(p, dtype=float).ravel()
        self.q = np.array(q, dtype=float).ravel()
        if self.p.size < 1 or self.q.size < 1:
            raise ValueError("p and q need at least one coefficient each")
        self.p.setflags(write=False)
        self.q.setflags(write=False)

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
        return self.space.evaluate(x, self.p, window=window)

    def denominator(self, x: ArrayLike, *, window: bool = False) -> Array:
        return self.space.evaluate(x, self.q, window=window)

    def __call__(self, x: ArrayLike, *, window: bool = False) -> Array:
        """Values at points x (N, d) or (N,) in 1-D; inf/NaN where q vanishes."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.numerator(x, window=window) / self.denominator(x, window=window)

    def poles(self) -> NDArray:
        """All (complex) roots of q in the original variable (1-D only)."""
        if self.space.dim != 1:
            raise NotImplementedError("poles() is defined for 1-D functions; use verify() in n-D")
        q = np.trim_zeros(self.q, "b")
        if q.size <= 1:
            return np.array([], dtype=complex)
        t = np.asarray(self.space.family.roots(q), dtype=complex)
        a, b = self.space._scale
        return (t - b[0]) / a[0]

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

    def to_dict(self) -> dict:
        return {
            "space": self.space.to_dict(),
            "p": self.p.tolist(),
            "q": self.q.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> RationalFunction:
        return cls(PolynomialSpace.from_dict(d["space"]), d["p"], d["q"])

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, RationalFunction)
            and self.space == other.space
            and np.array_equal(self.p, other.p)
            and np.array_equal(self.q, other.q)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (
            f"RationalFunction({self.space.family.name}, dim={self.space.dim}, "
            f"n={self.n}, m={self.m})"
        )
