"""K-fold held-out errors of a BRDF fit: what a fit predicts at samples it never saw.

A fit verified at its samples says nothing about the directions between them, and
those are the ones a renderer asks for. :func:`cross_validate` splits the samples
into K folds (a seeded permutation: the same folds on every run), fits the other
K - 1 folds exactly as the full fit is made (the same frames, widths and options)
and evaluates each fold's fit where a renderer would, through
:class:`~ratfit.brdf.fitter.BRDFFit`. The errors are pooled over every held-out
sample of the folds that verified.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.options import NOISE_FLOOR
from ratfit.errors import InputError
from ratfit.io.data import Dataset

__all__ = ["REL_FLOOR", "WORST_SHARE", "HoldoutResult", "cross_validate", "fit_fold",
           "fold_indices", "holdout_metrics", "pooled_result"]

Array = NDArray[np.float64]
#: e (1/sr) of the relative error log((f + e)/(y + e)): values far below it (the noise
#: of a measured diffuse tail, exact zeros of a colour conversion) do not dominate it.
#: The same noise level the relative polish divides by (:data:`~ratfit.brdf.options.NOISE_FLOOR`).
REL_FLOOR = NOISE_FLOOR
#: A single held-out sample carrying at least this share of a channel's squared error is
#: named in :meth:`HoldoutResult.lines`: the RMSE then says more about that sample (often
#: outside the box the other folds sampled) than about the fit.
WORST_SHARE = 0.25


def fold_indices(n: int, k: int, seed: int = 0) -> list[NDArray[np.intp]]:
    """The held-out rows of each of ``k`` folds of ``n`` samples: a permutation drawn
    from ``seed``, cut into ``k`` parts whose sizes differ by at most one."""
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k < 2:
        raise InputError(f"holdout needs K >= 2 folds, got {k!r}")
    if n < k:
        raise InputError(f"{k} folds need at least {k} samples, got {n}")
    order = np.random.default_rng(seed).permutation(n)
    return [np.sort(part) for part in np.array_split(order, int(k))]


def holdout_metrics(pred: ArrayLike, ref: ArrayLike, cos_l: ArrayLike | None,
                    names: Sequence[str]) -> dict[str, dict[str, float]]:
    """Per channel: ``rmse``, ``cos_rmse`` (error x cos theta_l, when known) and
    ``rel_rmse``, the RMS of log((f + e)/(y + e)) with e = :data:`REL_FLOOR`."""
    p = np.asarray(pred, dtype=float)
    y = np.asarray(ref, dtype=float)
    out: dict[str, dict[str, float]] = {}
    for j, name in enumerate(names):
        e = p[:, j] - y[:, j]
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.log(np.maximum(p[:, j] + REL_FLOOR, 1e-300) / (y[:, j] + REL_FLOOR))
        m = {"rmse": float(np.sqrt(np.mean(e**2))),
             "rel_rmse": float(np.sqrt(np.mean(rel**2)))}
        if cos_l is not None:
            m["cos_rmse"] = float(np.sqrt(np.mean((e * np.asarray(cos_l, dtype=float)) ** 2)))
        out[str(name)] = m
    return out


@dataclass
class HoldoutResult:
    """The held-out errors of K fits, each made without one fold.

    ``metrics`` are pooled over the samples of the folds whose fit verified
    (``held_out`` of them); ``folds`` records each fold's size, parametrization and
    coefficients (None where nothing verified). ``predictions`` (N, k) holds each
    sample's held-out prediction (NaN in folds without a fit); it is not saved.
    """

    k: int
    seed: int
    metrics: dict[str, dict[str, float]]
    folds: list[dict[str, Any]]
    held_out: int
    n_points: int
    predictions: Array = field(repr=False, default_factory=lambda: np.zeros((0, 0)))
    values: Array = field(repr=False, default_factory=lambda: np.zeros((0, 0)))

    def worst(self) -> dict[str, dict[str, float]]:
        """Per channel, the held-out sample with the largest squared error: its row,
        value, prediction and share of the channel's summed squared error. A pooled
        RMSE is often one unseen sample (garnet_red, 5-fold: the file's largest value, at
        theta_d 1.388 rad outside the other folds' box, over 99 % of R's squared error)."""
        p, y = self.predictions, self.values
        out: dict[str, dict[str, float]] = {}
        if p.size == 0 or p.shape != y.shape:
            return out
        for j, name in enumerate(self.metrics):
            e2 = (p[:, j] - y[:, j]) ** 2
            ok = np.isfinite(e2)
            if not ok.any() or not e2[ok].sum() > 0:
                continue
            i = int(np.flatnonzero(ok)[np.argmax(e2[ok])])
            out[name] = {"row": i, "y": float(y[i, j]), "predicted": float(p[i, j]),
                         "share": float(e2[i] / e2[ok].sum())}
        return out

    @property
    def folds_verified(self) -> int:
        return sum(f["coefficients"] is not None for f in self.folds)

    def to_dict(self) -> dict[str, Any]:
        """The fit file's ``brdf.holdout`` block."""
        return {"k": self.k, "seed": self.seed, "folds_verified": self.folds_verified,
                "held_out": self.held_out, "n_points": self.n_points,
                "rel_floor": REL_FLOOR, "metrics": self.metrics, "folds": self.folds}

    def lines(self) -> list[str]:
        """What a user reads: one line for the folds, one per channel."""
        sizes = [f["coefficients"] for f in self.folds if f["coefficients"] is not None]
        head = (f"held-out ({self.k}-fold, seed {self.seed}): {self.folds_verified} of "
                f"{self.k} fold fits verified, {self.held_out} of {self.n_points} samples "
                "predicted by a fit that never saw them")
        if sizes:
            head += f"; coefficients per fold {min(sizes)}..{max(sizes)}"
        out = [head]
        for name, m in self.metrics.items():
            out.append(f"{name}: held-out " + ", ".join(
                f"{k} {v:.4g}" for k, v in m.items())
                + f" (rel_rmse: RMS of log((f + {REL_FLOOR:g})/(y + {REL_FLOOR:g})))")
        for name, w in self.worst().items():
            if w["share"] >= WORST_SHARE:
                out.append(f"{name}: {100 * w['share']:.0f} % of the held-out squared error is "
                           f"one sample (row {w['row'] + 1}: data {w['y']:.4g}, predicted "
                           f"{w['predicted']:.4g})")
        return out


def _rows(ds: Dataset, rows: NDArray[np.intp]) -> Dataset:
    """The samples ``rows`` of ``ds``; default widths are resolved again from them."""
    meta = {k: v for k, v in ds.meta.items() if not str(k).startswith("default_widths")}
    return replace(ds, x=ds.x[rows], y=None if ds.y is None else ds.y[rows],
                   lo=None if ds.lo is None else ds.lo[rows],
                   hi=None if ds.hi is None else ds.hi[rows], meta=meta)


def _cos_l(datasets: Sequence[Dataset]) -> Array | None:
    """cos(theta_l) of the samples, from the first frame that determines it."""
    from ratfit.brdf.fitter import cos_theta_l

    for ds in datasets:
        try:
            return cos_theta_l(ds.x, str(ds.meta.get("param_in")))
        except InputError:
            continue
    return None


def fit_fold(datasets: Sequence[Dataset], test: NDArray[np.intp],
             **fit_kw: Any) -> tuple[Array | None, dict[str, Any]]:
    """One fold: :func:`~ratfit.brdf.fitter.fit_brdf_auto` with ``fit_kw`` on every
    sample but ``test``; returns its predictions at ``test`` (None without a verified
    fit) and the fold's entry (size, parametrization, coefficients). A function of
    its arguments alone, so folds may run in separate processes."""
    from ratfit.brdf.fitter import brdf_fit_of, fit_brdf_auto, fit_coefficients, fitted_frame

    n = datasets[0].n_points
    train = np.setdiff1d(np.arange(n), test)
    fitter, _seg, meta = fit_brdf_auto([_rows(ds, train) for ds in datasets], **fit_kw)
    entry: dict[str, Any] = {"held_out": int(test.size), "parametrization": None,
                             "coefficients": None}
    if not fitter.success_:
        return None, entry
    fit = brdf_fit_of(fitter.results_, meta)
    frame = fitted_frame(datasets, meta)
    entry.update(parametrization=meta["parametrization"],
                 coefficients=fit_coefficients(fitter))
    return np.asarray(fit.eval_coords(frame.x[test]), dtype=float), entry


def _check_frames(datasets: Sequence[Dataset]) -> None:
    if not datasets:
        raise InputError("cross_validate needs at least one dataset")
    n = datasets[0].n_points
    if any(ds.n_points != n or ds.y is None for ds in datasets):
        raise InputError("every frame must hold the same samples, with values")


def pooled_result(datasets: Sequence[Dataset], k: int, seed: int,
                  outcomes: Sequence[tuple[Array | None, dict[str, Any]]]) -> HoldoutResult:
    """The :class:`HoldoutResult` of the ``k`` folds' :func:`fit_fold` outcomes, in
    :func:`fold_indices` order."""
    _check_frames(datasets)
    n = datasets[0].n_points
    y = np.asarray(datasets[0].y, dtype=float)
    names = datasets[0].output_names or tuple(f"y{j}" for j in range(y.shape[1]))
    pred = np.full(y.shape, np.nan)
    seen = np.zeros(n, dtype=bool)  # predicted by a verified fold fit (non-finite stays in)
    for test, (p, _entry) in zip(fold_indices(n, k, seed), outcomes, strict=True):
        if p is not None:
            pred[test] = p
            seen[test] = True
    cl = _cos_l(datasets)
    metrics = holdout_metrics(pred[seen], y[seen], None if cl is None else cl[seen], names) \
        if seen.any() else {}
    return HoldoutResult(int(k), int(seed), metrics, [e for _p, e in outcomes],
                         int(seen.sum()), n, pred, y)


def cross_validate(datasets: Sequence[Dataset], k: int, *, seed: int = 0,
                   workers: int = 1, **fit_kw: Any) -> HoldoutResult:
    """K-fold held-out errors of :func:`~ratfit.brdf.fitter.fit_brdf_auto` with
    ``fit_kw`` on ``datasets`` (the same samples in each frame to try).

    ``workers`` > 1 fits folds in that many processes; each fold's fit is bounded by
    counted work, not a clock, so the result is the same for any ``workers``."""
    _check_frames(datasets)
    tests = fold_indices(datasets[0].n_points, k, seed)
    if workers <= 1:
        outcomes = [fit_fold(datasets, t, **fit_kw) for t in tests]
    else:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=min(int(workers), len(tests))) as pool:
            futures = [pool.submit(fit_fold, datasets, t, **fit_kw) for t in tests]
            outcomes = [f.result() for f in futures]
    return pooled_result(datasets, k, seed, outcomes)
