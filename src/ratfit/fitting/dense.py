"""Between the samples: dense-grid checks and constraint generation.

A fit is verified at its data points, which is all the data can promise. When
the function behind the data is known (a demo, a test, a model), users also
want the fit inside its band *between* samples. :func:`dense_check` measures
that on a grid ``factor`` times denser than the data, and :func:`fit_dense`
makes it true by constraint generation: the worst violations on the dense grid
become extra segments and the search runs again (from the previous total,
since more segments never make a smaller fit feasible), until the dense grid
is clean.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.rational import RationalFunction
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter

__all__ = ["DenseCheck", "DenseFit", "dense_check", "dense_grid", "fit_dense"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DenseCheck:
    """How a fit behaves on a dense grid against the known function."""

    points: int
    max_rel_error: float  # max |r - f| / |f| (inf if r is not finite somewhere)
    max_violation: float  # max distance outside the band, absolute (0 when inside)
    n_violations: int
    worst_x: list[float]
    finite: bool

    @property
    def inside(self) -> bool:
        return self.finite and self.n_violations == 0

    @property
    def success(self) -> bool:
        """The result vocabulary's name for ``inside``."""
        return self.inside

    @property
    def message(self) -> str:
        if self.inside:
            return f"inside the band at all {self.points} dense points"
        if not self.finite:
            return "not finite somewhere on the dense grid (a pole)"
        return (f"{self.n_violations} of {self.points} dense points outside the band, by up "
                f"to {self.max_violation:.3g}")

    def summary(self) -> dict:
        return {
            "dense_points": self.points, "dense_max_rel_error": self.max_rel_error,
            "dense_max_violation": self.max_violation,
            "dense_n_violations": self.n_violations, "dense_inside": self.inside,
        }


def dense_grid(x: ArrayLike, factor: int = 10) -> Array:
    """1-D: ``factor`` times as many equispaced points over the data's range."""
    xa = np.asarray(x, dtype=float).ravel()
    if xa.size < 2:
        raise InputError("a dense grid needs at least two data points")
    if factor < 1:
        raise InputError(f"dense factor must be >= 1, got {factor}")
    return np.linspace(xa.min(), xa.max(), factor * xa.size)


def _band(f: Array, dt: float | None, abs_width: float | None) -> tuple[Array, Array]:
    half = np.zeros_like(f)
    if dt is not None:
        half = np.maximum(half, dt * np.abs(f))
    if abs_width is not None:
        half = np.maximum(half, abs_width)
    return f - half, f + half


def dense_check(rf: RationalFunction, fn: Callable[[Array], Array], x_dense: ArrayLike, *,
                dt: float | None = None, abs_width: float | None = None) -> DenseCheck:
    """Evaluate ``rf`` and the known ``fn`` on ``x_dense``; band as in the fit."""
    if dt is None and abs_width is None:
        raise InputError("give dt and/or abs_width: the band the fit should stay in")
    xd = np.asarray(x_dense, dtype=float)
    f = np.asarray(fn(xd), dtype=float)
    if not np.all(np.isfinite(f)):
        raise InputError("the known function is not finite on the dense grid")
    r = rf(xd)
    finite = bool(np.all(np.isfinite(r)))
    lo, hi = _band(f, dt, abs_width)
    with np.errstate(invalid="ignore", divide="ignore"):
        viol = np.where(np.isfinite(r), np.maximum(lo - r, r - hi), np.inf)
        rel = np.where(np.isfinite(r), np.abs(r - f) / np.abs(f), np.inf)
    bad = viol > 0
    order = np.argsort(-viol)[: min(5, int(bad.sum()))]
    return DenseCheck(
        points=int(xd.shape[0]),
        max_rel_error=float(np.max(rel)),
        max_violation=float(max(0.0, float(np.max(viol)))),
        n_violations=int(bad.sum()),
        worst_x=[float(v) for v in np.atleast_1d(xd[order].ravel())],
        finite=finite,
    )


@dataclass(frozen=True)
class DenseFit:
    """The outcome of :func:`fit_dense`: the final fit, its dense check, history."""

    result: FitResult
    check: DenseCheck
    added_points: int
    rounds: int
    seconds: float
    history: list[dict] = field(default_factory=list)

    @property
    def success(self) -> bool:
        return self.result.success and self.check.inside

    @property
    def message(self) -> str:
        """One line: the fit's message, then the dense check's."""
        return f"{self.result.message}; {self.check.message} after {self.rounds} round(s)"


def fit_dense(fn: Callable[[Array], Array], x: ArrayLike, *, dt: float | None = None,
              abs_width: float | None = None, factor: int = 10, rounds: int = 8,
              per_round: int = 20, fitter: RationalFitter | None = None) -> DenseFit:
    """Fit ``fn`` sampled at ``x`` (1-D) so that the fit stays in its band on a
    grid ``factor`` times denser, by adding the worst dense points as segments."""
    t0 = time.perf_counter()
    xa = np.asarray(x, dtype=float).ravel()
    xd = dense_grid(xa, factor)
    fitter = fitter or RationalFitter()
    domain = [[float(xa.min()), float(xa.max())]]
    pts = np.unique(xa)
    history: list[dict] = []
    min_total = int(fitter.min_total)
    result = check = None
    for k in range(1, rounds + 1):
        y = np.asarray(fn(pts), dtype=float)
        lo, hi = _band(y, dt, abs_width)
        seg = Segments(pts[:, None], lo[:, None], hi[:, None], y=y[:, None])
        params = fitter.get_params()
        # the segments are this loop's (dt/abs_width above), not the fitter's widths
        params.update(domain=domain, min_total=min_total, dt=None, abs_width=None)
        if params.get("max_total") is not None and params["max_total"] < min_total:
            params["max_total"] = min_total
        result = RationalFitter(**params).fit(seg).result_
        if result.rational is None:  # nothing computed at all: more points cannot help
            check = None
            history.append({"round": k, "points": int(pts.size), "total": result.total,
                            "success": False})
            break
        check = dense_check(result.rational, fn, xd, dt=dt, abs_width=abs_width)
        history.append({"round": k, "points": int(pts.size), "total": result.total,
                        "success": result.success, **check.summary()})
        if result.success and check.inside:
            break
        # A candidate with a pole between samples (sparse data) or outside the band
        # there: its dense violations become segments too.
        min_total = result.total if result.success else min_total
        r = result.rational(xd)
        f = np.asarray(fn(xd), dtype=float)
        blo, bhi = _band(f, dt, abs_width)
        with np.errstate(invalid="ignore"):
            viol = np.where(np.isfinite(r), np.maximum(blo - r, r - bhi), np.inf)
        # the worst point of each run of violations (one per excursion), then the worst overall
        bad = viol > 0
        starts = np.flatnonzero(bad & ~np.r_[False, bad[:-1]])
        ends = np.flatnonzero(bad & ~np.r_[bad[1:], False])
        picks = [s + int(np.argmax(viol[s:e + 1])) for s, e in zip(starts, ends, strict=True)]
        picks = sorted(picks, key=lambda i: -viol[i])[:per_round]
        pts = np.unique(np.concatenate([pts, xd[picks]]))
    assert result is not None
    if check is None:
        check = DenseCheck(xd.size, float("inf"), float("inf"), xd.size, [], False)
    return DenseFit(result, check, int(pts.size - np.unique(xa).size), len(history),
                    time.perf_counter() - t0, history)
