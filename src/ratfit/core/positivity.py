"""Proofs that a polynomial keeps its sign on a box: Bernstein bounds with subdivision.

A polynomial of degree n_k in each window variable t_k in [-1, 1] is a
combination of tensor Bernstein polynomials, which are non-negative and sum to
one on the box; so its smallest Bernstein coefficient is a lower bound of its
minimum there, and the coefficients at the box's corners are its values there.
Where the bound is not yet positive, the box is halved (de Casteljau at the
midpoint: the halves' coefficients converge to the polynomial's values) until
every piece is proved, a corner is provably negative (a counterexample), or the
work budget is spent.

The bound is rigorous for the polynomial whose coefficients are the given
float64 numbers: the change of basis is exact in rational arithmetic and then
rounded once, and every floating-point operation after it carries a running
bound of its rounding error (standard model, |fl(a op b) - a op b| <= u |.|),
which is subtracted before a coefficient counts as positive.

:func:`prove_positive` is the entry point; ``ratfit.brdf`` uses it to prove q > 0
and p >= 0 (so r = p / q >= 0 with no pole) wherever a BRDF fit is evaluated.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["SignProof", "bernstein_matrix", "prove_below", "prove_positive"]

Array = NDArray[np.float64]
_U = 2.0**-53  # unit roundoff of float64
_SAFETY = 1.0 + 1e-9  # covers the rounding of the error bound's own arithmetic


@dataclass(frozen=True)
class SignProof:
    """What the Bernstein subdivision established about a polynomial on a box.

    ``proved``: the polynomial is > 0 (``strict``) or >= 0 on the whole box.
    ``lower``: a rigorous lower bound of its minimum over the box (the smallest
    over the proved and unproved pieces; the value itself at a counterexample).
    ``scale``: the largest |Bernstein coefficient| on the box (an upper bound of
    max |f|), so ``lower / scale`` is the relative margin. ``points``: window
    coordinates where the polynomial is, or may be, lowest: the counterexample
    corners, else the centres of the unproved pieces with the lowest bounds
    (where a fitter should add constraint rows). ``boxes``: pieces examined.
    """

    proved: bool
    lower: float
    scale: float
    counterexample: bool
    points: Array
    boxes: int
    method: str

    @property
    def margin(self) -> float:
        """``lower / scale``: the proved relative margin (negative when unproved)."""
        return self.lower / self.scale if self.scale > 0 else self.lower

    def summary(self) -> str:
        if self.proved:
            return (f"proved by {self.method} on {self.boxes} boxes, "
                    f"min >= {self.margin:.3g} of max")
        what = "negative at a corner" if self.counterexample else "not proved"
        return f"{what} ({self.method}, {self.boxes} boxes, lower bound {self.margin:.3g} of max)"


# --------------------------------------------------------------------------- exact bases
def _family_powers(family: str, deg: int) -> list[list[Fraction]]:
    """Exact coefficients in powers of t of the family's polynomials 0..deg."""
    one, zero = Fraction(1), Fraction(0)
    rows: list[list[Fraction]] = [[one] + [zero] * deg]
    if deg == 0:
        return rows
    rows.append([zero, one] + [zero] * (deg - 1))
    for k in range(1, deg):
        prev, cur = rows[k - 1], rows[k]
        shifted = [zero] + cur[:-1]  # t * cur
        if family == "legendre":  # (k+1) P_{k+1} = (2k+1) t P_k - k P_{k-1}
            a, b = Fraction(2 * k + 1, k + 1), Fraction(k, k + 1)
        elif family == "chebyshev":  # T_{k+1} = 2 t T_k - T_{k-1}
            a, b = Fraction(2), Fraction(1)
        elif family == "monomial":  # t^{k+1}
            a, b = Fraction(1), Fraction(0)
        else:
            raise ValueError(f"no Bernstein conversion for basis {family!r}")
        rows.append([a * s - b * p for s, p in zip(shifted, prev, strict=True)])
    return rows


@lru_cache(maxsize=64)
def bernstein_matrix(family: str, deg: int) -> tuple[Array, Array]:
    """(M, |M|) with b = M c: Bernstein coefficients on [-1, 1] of sum_i c_i phi_i.

    Built in exact rational arithmetic (t = 2 s - 1, then powers of s to
    Bernstein form), rounded once to float64.
    """
    powers_t = _family_powers(family, deg)
    # t^j = sum_i C(j, i) 2^i (-1)^(j-i) s^i
    t_to_s = [[Fraction(math.comb(j, i) * 2**i * (-1) ** (j - i)) if i <= j else Fraction(0)
               for i in range(deg + 1)] for j in range(deg + 1)]
    # s^i = sum_{k>=i} C(k, i) / C(deg, i) B_k
    s_to_b = [[Fraction(math.comb(k, i), math.comb(deg, i)) if k >= i else Fraction(0)
               for k in range(deg + 1)] for i in range(deg + 1)]
    M = np.empty((deg + 1, deg + 1))
    for col, pt in enumerate(powers_t):
        ps = [sum((pt[j] * t_to_s[j][i] for j in range(deg + 1)), Fraction(0))
              for i in range(deg + 1)]
        for k in range(deg + 1):
            M[k, col] = float(sum((ps[i] * s_to_b[i][k] for i in range(deg + 1)), Fraction(0)))
    M.setflags(write=False)
    A = np.abs(M)
    A.setflags(write=False)
    return M, A


def _apply_axis(M: Array, A: Array, C: Array, E: Array, axis: int) -> tuple[Array, Array]:
    """M along ``axis`` of C (and the error bound E carried along)."""
    n = M.shape[1]
    Cm = np.moveaxis(C, axis, -1)
    Em = np.moveaxis(E, axis, -1)
    out = Cm @ M.T
    # |fl(M^ x^) - M x| <= |M| E + (gamma_n + u) |M| |x^|  (M^ = M rounded once)
    gam = (n + 1) * _U / (1 - (n + 1) * _U)
    err = (Em @ A.T) + gam * (np.abs(Cm) @ A.T)
    return np.moveaxis(out, -1, axis), np.moveaxis(err * _SAFETY, -1, axis)


def _to_bernstein(family: str, coef: Array) -> tuple[Array, Array]:
    C = np.asarray(coef, dtype=float)
    E = np.zeros_like(C)
    for ax in range(C.ndim):
        M, A = bernstein_matrix(family, C.shape[ax] - 1)
        C, E = _apply_axis(M, A, C, E, ax)
    return C, E


def _split(B: Array, E: Array, axis: int) -> tuple[Array, Array, Array, Array]:
    """de Casteljau at the midpoint along ``axis`` (axis >= 1; axis 0 counts boxes)."""
    Bm = np.moveaxis(B, axis, -1)
    Em = np.moveaxis(E, axis, -1)
    n = Bm.shape[-1]
    left_b, left_e = [Bm[..., 0]], [Em[..., 0]]
    right_b, right_e = [Bm[..., -1]], [Em[..., -1]]
    cb, ce = Bm, Em
    for _ in range(1, n):
        cb = 0.5 * (cb[..., :-1] + cb[..., 1:])  # the halving is exact; the sum rounds once
        ce = (0.5 * (ce[..., :-1] + ce[..., 1:]) + _U * np.abs(cb)) * _SAFETY
        left_b.append(cb[..., 0])
        left_e.append(ce[..., 0])
        right_b.append(cb[..., -1])
        right_e.append(ce[..., -1])
    L = np.moveaxis(np.stack(left_b, axis=-1), -1, axis)
    LE = np.moveaxis(np.stack(left_e, axis=-1), -1, axis)
    R = np.moveaxis(np.stack(right_b[::-1], axis=-1), -1, axis)
    RE = np.moveaxis(np.stack(right_e[::-1], axis=-1), -1, axis)
    return L, LE, R, RE


def _corners(B: Array) -> Array:
    """Coefficients at the 2^d corners of each box (the polynomial's values there)."""
    d = B.ndim - 1
    idx = np.array(np.meshgrid(*([[0, -1]] * d), indexing="ij")).reshape(d, -1)
    return B[(slice(None), *idx)]  # (boxes, 2^d)


def prove_positive(coef: ArrayLike, family: str, *, strict: bool = True,
                   exclude: Callable[[Array, Array], NDArray[np.bool_]] | None = None,
                   max_boxes: int = 40_000,
                   min_width: float = 1e-7, report: int = 64) -> SignProof:
    """Prove that the tensor polynomial ``coef`` is > 0 (``strict``) or >= 0 on [-1, 1]^d.

    ``coef`` is the dense d-way array C[a_1, ..., a_d] of coefficients in the
    ``family`` (legendre, chebyshev, monomial) of the window variables.
    ``exclude(lo, hi)`` (window corners of pieces, (k, d) each) marks pieces where
    the polynomial is never evaluated (e.g. no pair of directions maps there): they
    are dropped from the region instead of being proved. The work is
    bounded by ``max_boxes`` pieces and by pieces narrower than ``min_width``;
    an unproved answer lists up to ``report`` points to constrain.
    """
    C = np.asarray(coef, dtype=float)
    if C.ndim == 0:
        C = C.reshape(1)

    def same(lo: Array, hi: Array, B: list[Array], E: list[Array]
             ) -> tuple[Array, Array, NDArray[np.bool_]]:
        return B[0], E[0], np.ones(len(lo), dtype=bool)

    return _subdivide([C], family, same, strict, exclude, max_boxes, min_width, report)


def prove_below(q_coef: ArrayLike, p_coef: ArrayLike, family: str,
                bound: Callable[[Array, Array], tuple[Array, NDArray[np.bool_]]], *,
                exclude: Callable[[Array, Array], NDArray[np.bool_]] | None = None,
                max_boxes: int = 40_000, min_width: float = 1e-7,
                report: int = 64) -> SignProof:
    """Prove C(x) q - p > 0 on [-1, 1]^d for a bound C that varies over the box (so
    p / q < C(x) wherever q > 0): ``bound(lo, hi)`` gives each piece (window corners)
    a number c at most C's smallest value on it, and whether C equals c all over the
    piece. A piece is proved when c q - p is; a corner where c q - p <= 0 is a
    counterexample only on a piece where C is c throughout (elsewhere the piece is
    halved again). ``q_coef`` and ``p_coef``: dense tensors of one shape, as
    :func:`prove_positive` takes. A step bound (the samples' envelope over theta_h and
    theta_d) makes C q - p no polynomial, so no single Bernstein form proves it."""
    Q = np.asarray(q_coef, dtype=float)
    P = np.asarray(p_coef, dtype=float)
    if Q.shape != P.shape:
        raise ValueError(f"q and p tensors differ in shape: {Q.shape} and {P.shape}")

    def combined(lo: Array, hi: Array, B: list[Array], E: list[Array]
                 ) -> tuple[Array, Array, NDArray[np.bool_]]:
        c, exact = bound(lo, hi)
        c = np.asarray(c, dtype=float).reshape((-1,) + (1,) * (B[0].ndim - 1))
        cq = c * B[0]  # one rounding each: the product, then the difference
        out = cq - B[1]
        err = (np.abs(c) * E[0] + E[1] + _U * (np.abs(cq) + np.abs(out))) * _SAFETY
        return out, err, np.asarray(exact, dtype=bool)

    return _subdivide([Q, P], family, combined, True, exclude, max_boxes, min_width,
                      report)


def _subdivide(coefs: list[Array], family: str,
               combine: Callable[[Array, Array, list[Array], list[Array]],
                                 tuple[Array, Array, NDArray[np.bool_]]],
               strict: bool, exclude: Callable[[Array, Array], NDArray[np.bool_]] | None,
               max_boxes: int, min_width: float, report: int) -> SignProof:
    """The subdivision of :func:`prove_positive` on the Bernstein forms of ``coefs``
    (one shape), halved together; ``combine(lo, hi, Bs, Es)`` gives each piece's
    coefficients and error bounds of the polynomial to prove, and where its corner
    values may count as counterexamples."""
    d = coefs[0].ndim
    if not all(np.all(np.isfinite(C)) for C in coefs):
        return SignProof(False, -math.inf, math.inf, True, np.zeros((1, d)), 0,
                         "Bernstein bounds (non-finite coefficient)")
    forms = [_to_bernstein(family, C) for C in coefs]
    Bs = [f[0][None] for f in forms]
    Es = [f[1][None] for f in forms]
    lo = np.full((1, d), -1.0)
    hi = np.full((1, d), 1.0)
    method = "Bernstein bounds with subdivision"
    B0, _E0, _exact = combine(lo, hi, Bs, Es)
    scale = float(np.max(np.abs(B0)))
    if scale == 0.0:
        return SignProof(not strict, 0.0, 0.0, strict, np.zeros((1, d)), 1, method)
    cap = max(16, int(4e7 // max(1, Bs[0][0].size * 8 * len(Bs))))  # boxes per batch
    boxes = 0
    proved_low = math.inf
    while True:
        if exclude is not None:
            drop = np.asarray(exclude(lo, hi), dtype=bool)
            if drop.any():
                Bs, Es = [b[~drop] for b in Bs], [e[~drop] for e in Es]
                lo, hi = lo[~drop], hi[~drop]
                if len(lo) == 0:
                    return SignProof(True, proved_low, scale, False, np.zeros((0, d)),
                                     boxes, method)
        boxes += len(lo)
        B, E, exact = combine(lo, hi, Bs, Es)
        flat_b = B.reshape(len(B), -1)
        flat_e = E.reshape(len(B), -1)
        low = np.min(flat_b - flat_e, axis=1)
        ok = low > 0 if strict else low >= 0
        if ok.any():
            proved_low = min(proved_low, float(np.min(low[ok])))
        cb = _corners(B)
        ce = _corners(E)
        # a corner coefficient is the value there: provably < 0 (or <= 0 when strict)
        neg = (cb + ce <= 0) if strict else (cb + ce < 0)
        neg &= exact[:, None]
        if exclude is not None and neg.any():  # a corner outside the region proves nothing
            rows, cols = np.nonzero(neg)
            pts = _corner_points(lo[rows], hi[rows], np.ones((len(rows), neg.shape[1]), bool))
            pts = pts.reshape(len(rows), neg.shape[1], d)[np.arange(len(rows)), cols]
            outside = np.asarray(exclude(pts, pts), dtype=bool)
            neg[rows[outside], cols[outside]] = False
        bad = neg.any(axis=1)
        if bad.any():
            pts = _corner_points(lo[bad], hi[bad], neg[bad])[:report]
            return SignProof(False, float(np.min(cb[bad])), scale, True, pts, boxes, method)
        keep = ~ok
        Bs, Es = [b[keep] for b in Bs], [e[keep] for e in Es]
        lo, hi, low = lo[keep], hi[keep], low[keep]
        if len(lo) == 0:
            return SignProof(True, proved_low, scale, False, np.zeros((0, d)), boxes, method)
        width = hi - lo
        if boxes >= max_boxes or float(np.max(width)) < min_width:
            # half the points at the lowest bounds, half spread over every unproved piece
            # (they often line a whole surface, e.g. the edge of the evaluated region)
            order = np.argsort(low)
            pick = np.unique(np.concatenate([
                order[: report // 2],
                order[np.linspace(0, len(order) - 1, report - report // 2).astype(np.int64)],
            ]))
            pts = 0.5 * (lo[pick] + hi[pick])
            return SignProof(False, float(np.min(low)), scale, False, pts, boxes, method)
        if len(lo) > cap:  # the lowest bounds first; the rest wait
            order = np.argsort(low)
            rest = order[cap:]
            wait = ([b[rest] for b in Bs], [e[rest] for e in Es], lo[rest], hi[rest])
            now = order[:cap]
            Bs, Es, lo, hi = [b[now] for b in Bs], [e[now] for e in Es], lo[now], hi[now]
        else:
            wait = None
        # each piece is halved along its widest side
        axis_of = np.argmax(hi - lo, axis=1)
        nbs: list[list[Array]] = [[] for _ in Bs]
        nes: list[list[Array]] = [[] for _ in Bs]
        nlo, nhi = [], []
        for ax in np.unique(axis_of):
            sel = axis_of == ax
            for k in range(len(Bs)):
                L, LE, R, RE = _split(Bs[k][sel], Es[k][sel], int(ax) + 1)
                nbs[k] += [L, R]
                nes[k] += [LE, RE]
            mid = 0.5 * (lo[sel, ax] + hi[sel, ax])
            llo, lhi = lo[sel].copy(), hi[sel].copy()
            lhi[:, ax] = mid
            rlo, rhi = lo[sel].copy(), hi[sel].copy()
            rlo[:, ax] = mid
            nlo += [llo, rlo]
            nhi += [lhi, rhi]
        if wait is not None:
            for k in range(len(Bs)):
                nbs[k].append(wait[0][k])
                nes[k].append(wait[1][k])
            nlo.append(wait[2])
            nhi.append(wait[3])
        Bs = [np.concatenate(b) for b in nbs]
        Es = [np.concatenate(e) for e in nes]
        lo, hi = np.concatenate(nlo), np.concatenate(nhi)


def _corner_points(lo: Array, hi: Array, neg: NDArray[np.bool_]) -> Array:
    """Window coordinates of the flagged corners (same order as :func:`_corners`)."""
    d = lo.shape[1]
    bits = np.array(np.meshgrid(*([[0, 1]] * d), indexing="ij")).reshape(d, -1).T  # (2^d, d)
    pts = lo[:, None, :] + bits[None, :, :] * (hi - lo)[:, None, :]
    return pts[neg]
