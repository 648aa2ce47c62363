"""The row-system protocol of P(n, m) and the denominator-positivity rows.

Every constraint system (the seed's matrix, the weighted Arnoldi form, the
monotone CDF rows, a shared denominator, q > 0 rows) is a :class:`RowSystem`:
:func:`ratfit.core.qp.solve_fixed` reads nothing else. Systems that extend
another one hold it (composition) and append rows after its rows.

Pole-freedom is a constraint, not a verdict: the data rows force q > 0 at the
samples (``(hi - lo) q >= margin``), so r has a pole in the domain exactly when
q changes sign between samples. :class:`PositiveDenominator` adds rows
``q(z) / ||psi(z)|| >= delta`` at points z of the domain; :func:`denominator_cuts`
picks the z where a candidate's q is not positive (a dense check of the
domain, the real roots of q and the midpoints between them). Solving,
cutting and re-solving until q is positive (or the augmented QP is
infeasible, which proves that no pole-free solution of that size exists: the
augmented feasible set contains every pole-free one) is constraint generation.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction

__all__ = ["AppendedRows", "LazyRows", "PositiveDenominator", "RowSystem", "denominator_cuts",
           "domain_grid", "smallest", "spread_indices"]

Array = NDArray[np.float64]

# Upper limit on the dense grid of the domain box (n-D pole checks and cuts).
GRID_POINTS = 200_000
# At most this many new q > 0 rows per round.
_MAX_CUTS = 64


@runtime_checkable
class RowSystem(Protocol):
    """What :func:`ratfit.core.qp.solve_fixed` needs of P(n, m): A(n, m) by rows.

    Rows are indexed 0 .. n_rows - 1; ``rows``, ``row_norms`` and
    ``residuals`` agree on that order. The feasible set is
    ``{c : A(n, m) c > 0}``; the QP asks ``A_j c >= delta ||A_j||``.
    """

    space: PolynomialSpace
    n_points: int  # data points (rows come in groups over them)
    t: Array  # the data points in the window [-1, 1]^d, (n_points, d)

    @property
    def n_rows(self) -> int: ...

    def prepare(self, n_max: int, m_max: int) -> None:
        """Make (n_max, m_max) available; called before threads use the system."""

    def conditioning(self, n: int, m: int) -> tuple[float, float, float]:
        """(delta, sigma_min, sigma_max) of A(n, m)."""
        ...

    def rows(self, n: int, m: int, ridx: NDArray[np.int64] | None = None) -> Array: ...

    def row_norms(self, n: int, m: int) -> Array: ...

    def residuals(self, n: int, m: int, c: Array) -> Array: ...

    def initial_rows(self, size: int) -> NDArray[np.int64]: ...

    def to_rational(self, n: int, m: int, c: Array) -> RationalFunction: ...

    def q_design(self, t: Array, m: int) -> Array:
        """Values (len(t), m) of q's basis at window points t: q(t) = q_design @ c[n:]."""
        ...


class LazyRows:
    """``count`` rows (unit norm) that ``make()`` computes when first needed."""

    def __init__(self, make, count: int) -> None:
        self.make, self.count = make, int(count)

    def __len__(self) -> int:
        return self.count

    def build(self) -> Array:
        out = self.make()
        if out.shape[0] != self.count:
            raise ValueError(f"lazy rows: expected {self.count}, got {out.shape[0]}")
        return out


class _BuiltOnRead:
    """An attribute that may be set to :class:`LazyRows` and reads as their array,
    built on the first read (stored in ``_<name>``)."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = "_" + name

    def __get__(self, obj: object, owner: type | None = None) -> Array:
        if obj is None:
            return self  # type: ignore[return-value]
        value = getattr(obj, self.slot)
        if isinstance(value, LazyRows):
            value = value.build()
            setattr(obj, self.slot, value)
        return value

    def __set__(self, obj: object, value: Array | LazyRows) -> None:
        setattr(obj, self.slot, value)


class AppendedRows:
    """``base`` plus unit rows: ``q(z) / ||psi(z)|| >= delta`` (rows of ``psi``, acting on
    c[n:]), ``p(z) / ||phi(z)|| >= delta`` (``phi``, on c[:n]) and rows ``chi`` on the whole
    of c (a bound on p / q, such as C q(z) - p(z) >= 0 for a fit of log values).

    Rows ``0 .. base.n_rows - 1`` are the base's, then the q rows, the p rows, the chi rows.
    ``start_active``: the active set of :func:`~ratfit.core.qp.solve_fixed` starts
    with every appended row (rows that exist because a candidate needed them) or
    with the base's rows only (a dense grid, mostly slack, joins where violated).
    ``extra_points`` count toward ``n_points``, so a large grid makes
    ``solve_fixed`` work on an active set rather than on every row at once.
    """

    def __init__(self, base: RowSystem, n: int, m: int, psi: Array | LazyRows | None = None,
                 phi: Array | LazyRows | None = None, *, chi: Array | LazyRows | None = None,
                 start_active: bool = True, extra_points: int = 0) -> None:
        self.base = base
        self.n, self.m = int(n), int(m)
        self.space = base.space
        self.n_points = base.n_points + int(extra_points)
        self.t = base.t
        self.psi = np.zeros((0, self.m)) if psi is None else psi
        self.phi = np.zeros((0, self.n)) if phi is None else phi
        self.chi = np.zeros((0, self.n + self.m)) if chi is None else chi
        self.start_active = start_active

    # psi and phi may be LazyRows: built on first use (a split decided on the data's
    # rows alone, as every infeasible one is, never evaluates a large grid)
    psi = _BuiltOnRead()
    phi = _BuiltOnRead()
    chi = _BuiltOnRead()
    _psi: Array | LazyRows  # what psi, phi and chi hold until first read
    _phi: Array | LazyRows
    _chi: Array | LazyRows

    def _counts(self) -> tuple[int, int, int]:
        return len(self._psi), len(self._phi), len(self._chi)

    @property
    def n_rows(self) -> int:
        return self.base.n_rows + sum(self._counts())

    def prepare(self, n_max: int, m_max: int) -> None:
        self.base.prepare(n_max, m_max)

    def release(self) -> None:
        """What the base kept for a solve's rounds (see ``solve_fixed``)."""
        release = getattr(self.base, "release", None)
        if release is not None:
            release()

    def conditioning(self, n: int, m: int) -> tuple[float, float, float]:
        return self.base.conditioning(n, m)

    def rows(self, n: int, m: int, ridx: NDArray[np.int64] | None = None) -> Array:
        nb, (nq, n_p, _nc) = self.base.n_rows, self._counts()
        if ridx is None:
            ridx = np.arange(self.n_rows)
        out = np.zeros((ridx.size, n + m))
        data = ridx < nb
        if data.any():
            out[data] = self.base.rows(n, m, ridx[data])
        qrow = (ridx >= nb) & (ridx < nb + nq)
        if qrow.any():
            out[qrow, n:] = self.psi[ridx[qrow] - nb]
        prow = (ridx >= nb + nq) & (ridx < nb + nq + n_p)
        if prow.any():
            out[prow, :n] = self.phi[ridx[prow] - nb - nq]
        crow = ridx >= nb + nq + n_p
        if crow.any():
            out[crow] = self.chi[ridx[crow] - nb - nq - n_p]
        return out

    def row_norms(self, n: int, m: int) -> Array:
        return np.concatenate([self.base.row_norms(n, m), np.ones(sum(self._counts()))])

    def residuals(self, n: int, m: int, c: Array) -> Array:
        return np.concatenate([self.base.residuals(n, m, c), self._appended(n, c)])

    def _appended(self, n: int, c: Array) -> Array:
        """The appended rows' values at c: q rows, p rows, chi rows."""
        return np.concatenate([self.psi @ c[n:], self.phi @ c[:n], self.chi @ c])

    def screen(self, n: int, m: int, c: Array) -> Iterator[tuple[NDArray[np.int64], Array, Array]]:
        """Stages of rows to check before a full pass (see solve_fixed): the base's
        (its cheap subset; for a base without one, all its rows), then the appended
        rows, which a candidate meets only once it meets the data."""
        scr = getattr(self.base, "screen", None)
        staged = False
        if scr is not None:
            for stage in scr(n, m, c):
                staged = True
                yield stage
        if not staged:
            nb = self.base.n_rows
            yield np.arange(nb), self.base.residuals(n, m, c), self.base.row_norms(n, m)
        nb, extra = self.base.n_rows, sum(self._counts())
        if extra:
            yield nb + np.arange(extra), self._appended(n, c), np.ones(extra)

    def initial_rows(self, size: int) -> NDArray[np.int64]:
        first = self.base.initial_rows(size)
        if not self.start_active:
            return first
        nb = self.base.n_rows
        return np.concatenate([first, nb + np.arange(self.n_rows - nb)])

    def to_rational(self, n: int, m: int, c: Array) -> RationalFunction:
        return self.base.to_rational(n, m, c)

    def q_design(self, t: Array, m: int) -> Array:
        return self.base.q_design(t, m)


class PositiveDenominator(AppendedRows):
    """``base`` plus one row ``q(z) / ||psi(z)|| >= delta`` per point z added.

    The rows come in the order the points were added, and the active set starts
    with all of them (they exist because a candidate needed them).
    """

    def __init__(self, base: RowSystem, n: int, m: int) -> None:
        super().__init__(base, n, m)
        self.z = np.zeros((0, base.t.shape[1]))

    @property
    def n_cuts(self) -> int:
        return int(self.z.shape[0])

    def add(self, z: Array) -> int:
        """Add rows at window points ``z`` (k, d) not already present; returns how many."""
        z = np.asarray(z, dtype=float).reshape(-1, self.z.shape[1])
        if self.n_cuts:
            z = z[~(np.abs(z[:, None, :] - self.z[None, :, :]).max(axis=2) == 0).any(axis=1)]
        psi = self.base.q_design(z, self.m)
        nrm = np.linalg.norm(psi, axis=1)
        keep = np.isfinite(nrm) & (nrm > 0)
        if not keep.any():
            return 0
        self.z = np.vstack([self.z, z[keep]])
        self.psi = np.vstack([self.psi, psi[keep] / nrm[keep, None]])
        return int(keep.sum())


def smallest(values: Array, count: int) -> NDArray[np.int64]:
    """Indices of the ``count`` smallest entries of ``values``, in no particular order
    (NaN counts as largest): an active set needs which rows, not their order, and a
    partial sort of 2.2 million residuals is several times cheaper than a full one."""
    count = max(int(count), 0)
    if count >= values.size:
        return np.arange(values.size)
    if count == 0:
        return np.zeros(0, dtype=np.int64)
    return np.argpartition(values, count - 1)[:count]


def spread_indices(n: int, count: int) -> NDArray[np.int64]:
    """``count`` indices of 0 .. n - 1 evenly spaced from the first to the last (all
    of them when ``count >= n``): a subset that covers a sorted list end to end."""
    if count >= n:
        return np.arange(n)
    return np.linspace(0, n - 1, count).round().astype(np.int64)


def domain_grid(dim: int, n_data: int) -> Array:
    """The dense grid (window coordinates) on which q's sign is checked.

    1-D: max(4001, 4 N + 1) equispaced points of [-1, 1]; n-D: a tensor grid
    of about :data:`GRID_POINTS` points of the box [-1, 1]^d.
    """
    if dim == 1:
        return np.linspace(-1.0, 1.0, max(4001, 4 * n_data + 1))[:, None]
    per_dim = max(3, int(GRID_POINTS ** (1.0 / dim)))
    axes = [np.linspace(-1.0, 1.0, per_dim)] * dim
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)


def denominator_cuts(rf: RationalFunction, grid: Array | None = None,
                     max_cuts: int = _MAX_CUTS) -> Array:
    """Window points where q is not safely positive: the new q > 0 rows.

    1-D: in every run of grid points with q <= 0 its minimum and both ends,
    plus the real roots of q in the domain and the midpoints between
    consecutive roots (a pair of roots between two grid points leaves no
    trace on the grid). n-D: grid points with q <= 0, spread over the run of
    them (sorted by grid index) and the most negative one. Empty when q is
    positive on the grid and (1-D) has no real root in the domain.
    """
    space = rf.space
    if grid is None:
        grid = domain_grid(space.dim, 0)
    with np.errstate(all="ignore"):
        qg = rf.denominator(grid, window=True)
    bad = ~(qg > 0)  # NaN counts
    picks: list[Array] = []
    if space.dim == 1:
        roots = space.to_window(rf.real_poles_in_domain()[:, None]) if rf.m > 1 else None
        if roots is not None and roots.size:
            r = np.clip(np.sort(roots[:, 0]), -1.0, 1.0)
            picks.append(r[:, None])
            if r.size > 1:
                picks.append((0.5 * (r[1:] + r[:-1]))[:, None])
        if bad.any():
            starts = np.flatnonzero(bad & ~np.r_[False, bad[:-1]])
            ends = np.flatnonzero(bad & ~np.r_[bad[1:], False])
            for s, e in zip(starts, ends, strict=True):
                seg = np.nan_to_num(qg[s:e + 1], nan=-np.inf)
                idx = {s, e, s + int(np.argmin(seg))}
                picks.append(grid[sorted(idx)])
    elif bad.any():
        where = np.flatnonzero(bad)
        spread = where[spread_indices(where.size, max_cuts - 1)]
        worst = where[int(np.argmin(np.nan_to_num(qg[where], nan=-np.inf)))]
        picks.append(grid[np.unique(np.r_[spread, worst])])
    if not picks:
        return np.zeros((0, space.dim))
    z = np.unique(np.vstack(picks), axis=0)
    if z.shape[0] > max_cuts:
        z = z[spread_indices(z.shape[0], max_cuts)]
    return z
