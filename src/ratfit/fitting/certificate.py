"""Infeasibility certificates: evidence that no rational of a size fits the segments.

P(n, m) asks for c with A c > 0 (rows ``p(x_i) - lo_i q(x_i)`` and
``hi_i q(x_i) - p(x_i)``). By Gordan's theorem exactly one of two things holds:

* some c has A c > 0 (a rational strictly inside every segment), or
* some y >= 0, y != 0 has A^T y = 0.

So a vector y >= 0 with sum y = 1 and A^T y = 0 proves that no rational with
n numerator and m denominator coefficients (whatever the basis: the condition
says a weighted sum of point evaluations annihilates every polynomial of the
two spaces) passes strictly inside these segments, and by monotonicity none
with fewer coefficients either. Numerically, with the rows normalised
(``An = A / ||A_j||``), any y in the simplex bounds the best margin:

    min_j (An c)_j  <=  y^T An c  =  (An^T y)^T c  <=  ||c||_2 ||An^T y||_2,

so ``residual = ||An^T y||_2`` says "no c with ||c|| = 1 has a normalised
margin above residual". y comes from the LP  min ||An^T y||_inf  over the
simplex (HiGHS through :func:`scipy.optimize.linprog`), computed on the
matrix of the formulation that decided infeasibility (Arnoldi or the seed's
basis), then polished on its support, mapped back to the seed's rows (a
positive rescaling of each row) and, on small supports, confirmed in exact
rational arithmetic on the data as stored (floats are exact rationals).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from ratfit.core.bases import PolynomialSpace
from ratfit.core.qp import ArnoldiSystem, ConstraintSystem
from ratfit.core.segments import Segments

__all__ = ["Certificate", "certify", "exact_check", "farkas_certificate"]

Array = NDArray[np.float64]

# A certificate is "numerical" when no unit-norm c can have a normalised margin above
# this in floating point. That is evidence, not a proof: data whose segments have a
# relative width of 1e-10 have true margins of that size (a feasible size looks
# infeasible at this tolerance). Only the exact check makes a certificate ``checked``.
DEFAULT_TOL = 1e-9


@dataclass(frozen=True)
class Certificate:
    """A Farkas (Gordan) vector for P(n, m) and how well it was checked.

    ``points``/``sides`` name the seed's rows carrying weight (side 0: the
    lo-row ``p - lo q``, side 1: the hi-row ``hi q - p``); ``weights`` are
    the weights on the seed's *normalised* rows (sum 1). ``residual`` is
    ||An^T y||_2 in the formulation that decided, ``residual_seed`` the same
    on the seed's normalised rows in the family basis (larger: that matrix is
    ill-conditioned). ``exact`` is True when a nonnegative y on the same
    support annihilates both polynomial spaces exactly (rational arithmetic,
    monomial basis of the original variable), False when that failed, None
    when not attempted. ``checked`` (the certificate is a proof) is ``exact``;
    ``numerical`` says only that the float residual is below the tolerance.
    """

    n: int
    m: int
    formulation: str
    n_rows: int
    points: tuple[int, ...]
    sides: tuple[int, ...]
    weights: tuple[float, ...]
    residual: float
    residual_seed: float
    checked: bool
    exact: bool | None
    exact_note: str
    lp_status: str
    seconds: float
    numerical: bool = False

    @property
    def success(self) -> bool:
        """The result vocabulary's name for ``checked``: the certificate holds."""
        return bool(self.checked)

    @property
    def message(self) -> str:
        what = f"no rational with n={self.n}, m={self.m} fits these segments"
        if not self.checked:
            return f"candidate certificate for ({self.n}, {self.m}) did not check out"
        exact = " (checked in exact arithmetic)" if self.exact else ""
        return f"{what}: Farkas weights on {len(self.points)} segment(s){exact}"

    @property
    def margin_bound(self) -> float:
        """No c with ||c||_2 = 1 has min_j (An c)_j above this (0 when exact)."""
        return 0.0 if self.exact else self.residual

    def summary(self) -> dict:
        """JSON-ready (the ``infeasible_proof`` of ``ratfit fit --json``)."""
        return {
            "kind": "gordan-farkas",
            "n": self.n,
            "m": self.m,
            "formulation": self.formulation,
            "checked": self.checked,
            "proved": self.checked,
            "numerical": self.numerical,
            "exact": self.exact,
            "exact_note": self.exact_note,
            "residual": _finite(self.residual),
            "residual_seed": _finite(self.residual_seed),
            "margin_bound": _finite(self.margin_bound),
            "support_size": len(self.points),
            "points": list(self.points),
            "sides": ["hi" if s else "lo" for s in self.sides],
            "weights": list(self.weights),
            "n_rows": self.n_rows,
            "lp_status": self.lp_status,
            "seconds": round(self.seconds, 6),
            "statement": self.statement(),
        }

    def statement(self) -> str:
        if self.exact:
            return (
                f"no rational with n <= {self.n}, m <= {self.m} coefficients passes strictly "
                "inside every segment (proved in exact rational arithmetic on the data as "
                f"stored; {len(self.points)} segments carry the proof)"
            )
        if self.numerical:
            return (
                f"numerically infeasible, not proved: in floating point no rational with "
                f"n <= {self.n}, m <= {self.m} coefficients has a normalised margin above "
                f"{self.residual:.1e} (exact check: {self.exact_note})"
            )
        return (
            f"not conclusive: the Farkas residual for n <= {self.n}, m <= {self.m} is "
            f"{self.residual:.1e}"
        )


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def farkas_lp(An: Array, time_limit: float = 60.0) -> tuple[Array | None, str]:
    """y >= 0, sum y = 1 minimising ||An^T y||_inf (HiGHS). (None, status) on failure."""
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix, hstack, vstack

    rows, k = An.shape
    At = csr_matrix(An.T)
    ones = csr_matrix(np.ones((k, 1)))
    a_ub = vstack([hstack([At, -ones]), hstack([-At, -ones])]).tocsr()
    a_eq = csr_matrix(np.r_[np.ones(rows), 0.0][None, :])
    cost = np.zeros(rows + 1)
    cost[-1] = 1.0
    res = linprog(cost, A_ub=a_ub, b_ub=np.zeros(2 * k), A_eq=a_eq, b_eq=[1.0],
                  bounds=[(0, None)] * (rows + 1), method="highs",
                  options={"time_limit": max(float(time_limit), 0.1)})
    if res.status != 0 or res.x is None:
        return None, str(res.message)
    y = np.clip(np.asarray(res.x[:rows]), 0.0, None)
    s = y.sum()
    return (y / s if s > 0 else None), "optimal"


def _polish(An: Array, y: Array) -> Array:
    """Refine y on its support: the null vector of An[S]^T, if it keeps y >= 0."""
    S = np.flatnonzero(y > 1e-12 * y.max())
    if S.size < 2:
        return y
    _, _, vt = np.linalg.svd(An[S].T, full_matrices=True)
    z = vt[-1]
    if z.sum() < 0:
        z = -z
    if np.any(z < -1e-12 * np.abs(z).max()):
        return y
    z = np.clip(z, 0.0, None)
    if z.sum() <= 0:
        return y
    out = np.zeros_like(y)
    out[S] = z / z.sum()
    return out if np.linalg.norm(An.T @ out) <= np.linalg.norm(An.T @ y) else y


def farkas_certificate(
    system: ConstraintSystem | ArnoldiSystem,
    n: int,
    m: int,
    *,
    seg: Segments | None = None,
    channel: int = 0,
    tol: float = DEFAULT_TOL,
    exact: bool | None = None,
    max_exact: int = 24,
    time_limit: float = 60.0,
) -> Certificate:
    """A Gordan certificate for P(n, m) on ``system`` (ArnoldiSystem or the seed's
    ConstraintSystem). ``seg``/``channel`` give the raw data for the seed-row
    check and the exact confirmation (attempted when ``exact`` is True, or None
    and n + m <= ``max_exact``). ``time_limit`` bounds the LP (seconds)."""
    t0 = time.perf_counter()
    system.prepare(n, m)
    A = system.rows(n, m)
    norms = np.linalg.norm(A, axis=1)
    norms = np.where(norms > 0, norms, 1.0)
    An = A / norms[:, None]
    npts = system.n_points
    y, lp_status = farkas_lp(An, time_limit)
    form = "arnoldi" if isinstance(system, ArnoldiSystem) else "basis"
    if y is None:
        return Certificate(n, m, form, An.shape[0], (), (), (), float("inf"), float("inf"),
                           False, None, "", lp_status, time.perf_counter() - t0)
    y = _polish(An, y)
    residual = float(np.linalg.norm(An.T @ y))
    # Back to the seed's rows: row_j = d_j * seed_row_j (in another basis), so the
    # weight on the seed's normalised row is y_j d_j ||seed_row_j|| / ||row_j||.
    seed = ConstraintSystem(system.space, seg, channel) if seg is not None else None
    if isinstance(system, ArnoldiSystem):
        d = np.tile(system.v / system.scale, 2)
    else:
        d = np.ones(An.shape[0])
    residual_seed = residual
    w = y.copy()
    if seed is not None and seed is not system:
        seed.prepare(n, m)
        seed_norms = seed.row_norms(n, m)
        w = y * d * seed_norms / norms
        w /= w.sum()
        S = np.flatnonzero(w > 0)
        As = seed.rows(n, m, S) / seed_norms[S, None]
        residual_seed = float(np.linalg.norm(As.T @ w[S]))
    S = np.flatnonzero(w > 1e-15)
    points = tuple(int(v) for v in S % npts)
    sides = tuple(int(v) for v in S // npts)
    numerical = residual <= tol
    ex: bool | None = None
    note = "not attempted"
    if seg is not None and numerical and (exact or (exact is None and n + m <= max_exact)):
        ex, note = exact_check(system.space, seg, channel, n, m, points, sides, w[S])
    return Certificate(
        n, m, form, An.shape[0], points, sides, tuple(float(v) for v in w[S]), residual,
        residual_seed, bool(ex), ex, note, lp_status, time.perf_counter() - t0,
        numerical=numerical,
    )


def certify(space: PolynomialSpace, seg: Segments, channel: int, n: int, m: int, *,
            formulation: str = "arnoldi", **kw) -> Certificate:
    """Build the system of ``formulation`` for (n, m) and certify it."""
    from ratfit.core.qp import sk_denominator

    if formulation == "arnoldi":
        system: ConstraintSystem | ArnoldiSystem = ArnoldiSystem(
            space, seg, channel, n, m, sk_denominator(space, seg, channel, n, m)
        )
    else:
        system = ConstraintSystem(space, seg, channel)
    return farkas_certificate(system, n, m, seg=seg, channel=channel, **kw)


# -- exact confirmation ------------------------------------------------------------------
def exact_check(space: PolynomialSpace, seg: Segments, channel: int, n: int, m: int,
                points: tuple[int, ...], sides: tuple[int, ...],
                weights: Array) -> tuple[bool, str]:
    """Is there z >= 0, z != 0 on these rows with sum_j z_j row_j = 0 exactly?

    Rows are written in monomials of the original variables with the data's
    floats as exact rationals, so the answer is about the data as stored, in
    any basis of the same polynomial spaces (the index set must be downward
    closed, which every total-degree prefix is).
    """
    idx_p = space.indices(n)
    idx_q = space.indices(m)
    for idx in (idx_p, idx_q):
        have = {tuple(a) for a in idx.tolist()}
        for a in have:
            for d in range(len(a)):
                if a[d] > 0 and tuple(a[:d] + (a[d] - 1,) + a[d + 1:]) not in have:
                    return False, "index set not downward closed: not attempted"
    x = seg.x
    lo, hi = seg.lo[:, channel], seg.hi[:, channel]
    cols = []
    for i, side in zip(points, sides, strict=True):
        xi = [Fraction(float(v)) for v in x[i]]
        mono_p = [_mono(xi, a) for a in idx_p.tolist()]
        mono_q = [_mono(xi, a) for a in idx_q.tolist()]
        if side == 0:
            b = Fraction(float(lo[i]))
            cols.append([v for v in mono_p] + [-b * v for v in mono_q])
        else:
            b = Fraction(float(hi[i]))
            cols.append([-v for v in mono_p] + [b * v for v in mono_q])
    # M z = 0 with M (k x s): columns are the rows of A on the support.
    M = [list(r) for r in zip(*cols, strict=True)]
    basis = _nullspace(M, len(cols))
    if not basis:
        return False, "the support's rows are linearly independent in exact arithmetic"
    if len(basis) == 1:
        z = basis[0]
    else:
        # Several null vectors: take the one nearest the float weights.
        B = np.array([[float(v) for v in b] for b in basis]).T
        alpha, *_ = np.linalg.lstsq(B, np.asarray(weights, float), rcond=None)
        coef = [Fraction(float(a)) for a in alpha]
        z = [sum((c * b[j] for c, b in zip(coef, basis, strict=True)), Fraction(0))
             for j in range(len(cols))]
    if sum(z) < 0:
        z = [-v for v in z]
    if all(v >= 0 for v in z) and any(v > 0 for v in z):
        return True, f"exact null vector >= 0 on {len(cols)} rows"
    neg = sum(1 for v in z if v < 0)
    return False, f"exact null vector has {neg} negative weight(s)"


def _mono(xi: list[Fraction], a: list[int]) -> Fraction:
    out = Fraction(1)
    for v, e in zip(xi, a, strict=True):
        out *= v**e
    return out


def _nullspace(M: list[list[Fraction]], ncols: int) -> list[list[Fraction]]:
    """Exact null-space basis of M (rows x ncols) by Gauss-Jordan over Q."""
    rows = [r[:] for r in M]
    pivots: list[int] = []
    r = 0
    for c in range(ncols):
        piv = next((i for i in range(r, len(rows)) if rows[i][c] != 0), None)
        if piv is None:
            continue
        rows[r], rows[piv] = rows[piv], rows[r]
        inv = 1 / rows[r][c]
        rows[r] = [v * inv for v in rows[r]]
        for i in range(len(rows)):
            if i != r and rows[i][c] != 0:
                f = rows[i][c]
                rows[i] = [a - f * b for a, b in zip(rows[i], rows[r], strict=True)]
        pivots.append(c)
        r += 1
        if r == len(rows):
            break
    free = [c for c in range(ncols) if c not in pivots]
    basis = []
    for fcol in free:
        z = [Fraction(0)] * ncols
        z[fcol] = Fraction(1)
        for i, pc in enumerate(pivots):
            z[pc] = -rows[i][fcol]
        basis.append(z)
    return basis


# Above this many rows the LP is no longer cheap enough to run after every failed search.
_SEARCH_MAX_ROWS = 60_000
# Above this total the exact check is not attempted, so no search certificate is made.
_SEARCH_MAX_EXACT = 24


def search_proof(run, time_limit: float = 60.0) -> dict | None:
    """The certificate summary for the largest infeasible split a search tried
    (``run`` is a ``ratfit.fitting.search.SearchEngine``), or None when there is none or the
    system is not one of the two standard formulations. When the decisive formulation
    gives no exact proof, the seed's basis form is tried too (its Farkas LP often
    resolves what HiGHS cannot in the weighted form at widths of 1e-12). The LPs
    share ``time_limit`` seconds."""
    if not run.infeasible:
        return None
    t0 = time.perf_counter()
    n, m = max(run.infeasible, key=lambda s: (s[0] + s[1], s[1]))
    if n + m > _SEARCH_MAX_EXACT:
        return None  # no exact check at this size: the LP could not end in a proof
    att = run.cache[(n, m)][0]
    systems = []
    if att.formulation == "arnoldi":
        systems.append(run.split_system(n, m))
    systems.append(run.system)
    best = None
    for system in systems:
        left = time_limit - (time.perf_counter() - t0)
        if system is None or left <= 0:
            continue
        if type(system) not in (ConstraintSystem, ArnoldiSystem) or \
                system.n_rows > _SEARCH_MAX_ROWS:
            continue
        try:
            cert = farkas_certificate(system, n, m, seg=run.seg, channel=run.channel,
                                      time_limit=left)
        except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - LP or SVD breakdown
            continue
        if best is None or (cert.checked, cert.numerical) > (best.checked, best.numerical):
            best = cert
        if cert.checked:
            break
    return None if best is None else best.summary()
