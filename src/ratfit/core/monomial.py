"""Monomial form of a fit in the ORIGINAL (unscaled) variables, for Horner evaluation.

Two routes (seed sections 1 and 4), and the more accurate one on the data wins:

* ``numpy``: numpy's basis conversion (``Legendre(...).convert(kind=Polynomial)``)
  applied per dimension, composed with the affine map to the domain.
* ``fft``: evaluate p and q at the roots of unity scaled to a circle of radius
  R_k enclosing the domain (one grid per dimension), and invert that Vandermonde
  matrix, which is unitary up to scaling: an inverse FFT.

Neither changes the number of coefficients: degrees are preserved.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
from numpy.polynomial import Polynomial
from numpy.polynomial import polynomial as _poly
from numpy.typing import ArrayLike, NDArray

from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.errors import AccuracyWarning, InputError

__all__ = ["MonomialForm", "horner", "to_monomial"]

Array = NDArray[np.float64]
_NUMPY_KIND: dict[str, Any] = {
    "legendre": np.polynomial.Legendre,
    "chebyshev": np.polynomial.Chebyshev,
    "monomial": np.polynomial.Polynomial,
}


@dataclass(frozen=True)
class MonomialForm:
    """p and q as dense tensors p[a_1..a_d] of x_1^a_1 ... x_d^a_d coefficients.

    Named ``p`` and ``q`` like the coefficients of
    :class:`~ratfit.core.rational.RationalFunction` (``P`` and ``Q`` are
    deprecated aliases).
    """

    p: Array
    q: Array
    method: str  # "numpy" or "fft"
    max_rel_diff: float  # max |r_mono - r| / max |r| on the data points
    errors: dict[str, float]  # the same for every method tried

    @property
    def P(self) -> Array:  # noqa: N802 -- the deprecated name
        """Deprecated: use ``p``."""
        warnings.warn("MonomialForm.P is deprecated; use .p (as on a fit)",
                      DeprecationWarning, stacklevel=2)
        return self.p

    @property
    def Q(self) -> Array:  # noqa: N802 -- the deprecated name
        """Deprecated: use ``q``."""
        warnings.warn("MonomialForm.Q is deprecated; use .q (as on a fit)",
                      DeprecationWarning, stacklevel=2)
        return self.q

    @overload
    def __call__(self, x: float) -> float: ...

    @overload
    def __call__(self, x: ArrayLike) -> Array: ...

    def __call__(self, x: ArrayLike) -> Array | float:
        """Values at points x (N, d), or (N,) in 1-D; one point gives a float."""
        dim = max(self.p.ndim, 1)
        shape = np.shape(x)
        if shape == () or (dim > 1 and shape == (dim,)):
            pt = np.asarray(x, dtype=float).reshape(1, dim)
            return float(self(pt[:, 0] if dim == 1 else pt)[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            return horner(x, self.p) / horner(x, self.q)

    def terms(self, which: str = "p") -> tuple[list[list[int]], list[float]]:
        """Nonzero coefficients as (exponents, values)."""
        T = self.p if which == "p" else self.q
        idx = np.argwhere(T != 0)
        return idx.tolist(), [float(T[tuple(i)]) for i in idx]

    def to_dict(self) -> dict:
        pe, pc = self.terms("p")
        qe, qc = self.terms("q")
        return {
            "method": self.method,
            "max_rel_diff": self.max_rel_diff,
            "p_exponents": pe, "p": pc, "q_exponents": qe, "q": qc,
        }


def horner(x: ArrayLike, C: ArrayLike) -> Array:
    """Evaluate sum C[a] x^a by nested Horner, one dimension at a time."""
    C = np.asarray(C)
    xa = np.asarray(x, dtype=float)
    if C.ndim == 1:
        return _poly.polyval(np.ravel(xa), C)
    if xa.ndim != 2 or xa.shape[1] != C.ndim:
        raise ValueError(f"points must have shape (N, {C.ndim}), got {xa.shape}")
    c = _poly.polyval(xa[:, 0], C)  # shape C.shape[1:] + (N,)
    for k in range(1, C.ndim):
        c = _poly.polyval(xa[:, k], c, tensor=False)
    return c


def _axis_matrix_numpy(space: PolynomialSpace, k: int, deg: int) -> Array:
    """M[j, a]: coefficient of x_k^j in basis function a of dimension k."""
    kind = _NUMPY_KIND[space.family.name]
    dom = space.domain[k]
    M = np.zeros((deg + 1, deg + 1))
    for a in range(deg + 1):
        e = np.zeros(a + 1)
        e[a] = 1.0
        conv = kind(e, domain=dom).convert(kind=Polynomial, domain=[-1, 1], window=[-1, 1])
        M[: conv.coef.size, a] = conv.coef
    return M


def _apply_axes(T: Array, mats: list[Array]) -> Array:
    for k, M in enumerate(mats):
        T = np.moveaxis(np.tensordot(M, T, axes=([1], [k])), 0, k)
    return T


def _via_numpy(space: PolynomialSpace, T: Array) -> Array:
    mats = [_axis_matrix_numpy(space, k, T.shape[k] - 1) for k in range(space.dim)]
    return _apply_axes(T, mats)


def _via_fft(space: PolynomialSpace, T: Array) -> Array:
    a, b = space._scale
    evals, radii = [], []
    for k in range(space.dim):
        K = T.shape[k]
        R = float(np.max(np.abs(space.domain[k])))
        z = R * np.exp(2j * np.pi * np.arange(K) / K)
        t = a[k] * z + b[k]
        evals.append(space.family.vander(t, K - 1))  # E[j, a] = b_a(t_j), complex t
        radii.append(R)
    vals = _apply_axes(T.astype(complex), evals)
    coef = np.fft.fftn(vals) / vals.size
    for k, R in enumerate(radii):
        shape = [1] * space.dim
        shape[k] = T.shape[k]
        coef = coef / (R ** np.arange(T.shape[k], dtype=float)).reshape(shape)
    return coef.real


def to_monomial(rf: RationalFunction, x: ArrayLike, *, warn_rtol: float = 1e-8) -> MonomialForm:
    """Convert ``rf`` to monomials of the original variables; pick the best route.

    ``x`` are points (the data) where the routes are compared with the
    orthogonal form. An :class:`AccuracyWarning` is issued when even the best
    route differs from it by more than ``warn_rtol`` relative to max |r|.
    """
    space = rf.space
    if getattr(space, "variable", "x") != "x":
        raise InputError("a fit in log x has no monomial form in x")
    xa = np.asarray(x, dtype=float)
    if xa.ndim == 1:
        xa = xa[:, None]
    ref = rf(xa)
    fam = rf.to_family()
    Tp, Tq = space.tensor_coef(fam.p), space.tensor_coef(fam.q)
    scale = float(np.max(np.abs(ref[np.isfinite(ref)]), initial=0.0)) or 1.0
    errors: dict[str, float] = {}
    forms = {}
    for method, fn in (("numpy", _via_numpy), ("fft", _via_fft)):
        P, Q = fn(space, Tp), fn(space, Tq)
        xe = xa[:, 0] if space.dim == 1 else xa
        with np.errstate(all="ignore"):
            val = horner(xe, P) / horner(xe, Q)
        err = float(np.max(np.abs(val - ref))) / scale
        errors[method] = err if np.isfinite(err) else float("inf")
        forms[method] = (P, Q)
    method = min(errors, key=lambda k: errors[k])
    P, Q = forms[method]
    best = MonomialForm(P, Q, method, errors[method], errors)
    if not best.max_rel_diff <= warn_rtol:
        warnings.warn(
            f"monomial conversion loses accuracy: max relative difference "
            f"{best.max_rel_diff:.2e} on the data (best route: {method}); "
            "evaluate the orthogonal form instead",
            AccuracyWarning,
            stacklevel=2,
        )
    return best
