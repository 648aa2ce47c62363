"""Held-out errors of the default rational BRDF fit against analytic models, per channel.

For each Cornell material: K-fold cross-validation (``ratfit.brdf.holdout``, the folds
``ratfit brdf fit --holdout K`` uses) of the default fit (`ratfit brdf fit DATA`: the
same frames, widths and options), and lambert+ggx and lambert+ggx*2 fitted
(``ratfit.brdf.analytic_models.fit_model``, 6 starts) on the same training folds.
Every sample is predicted by a fit that never saw it. Per channel it prints the
held-out RMSE, cos-weighted RMSE and relative RMSE (RMS of log((f + e)/(y + e)),
e = 1e-3 1/sr) of the rational fit and of the better model for each metric, the
fold fits' coefficient counts, and whether the rational fit wins all three.

    python benchmarks/bench_holdout.py [--data DIR] [--only NAME ...] [--k 5] [--workers W]

``--workers W`` fits the folds (of every material at once) and the models in W
processes; every fold fit is bounded by counted work, so the table is the same for
any W (seconds aside: with W > 1 a material's "s" is the sum of its fold fits' own
times, not the wall time).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from _bench import ModelComparison, add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.analytic_models import Model, fit_model
from ratfit.brdf.fitter import candidate_parametrizations
from ratfit.brdf.holdout import fit_fold, fold_indices, holdout_metrics, pooled_result
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization

REPO = Path(__file__).resolve().parents[1]
MODELS = ("lambert+ggx", "lambert+ggx*2")
MATERIALS = ("garnet_red", "acryl_blue", "cayman", "krylon_blue", "mystique")
METRICS = ("rmse", "cos_rmse", "rel_rmse")
OWN = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` reads Cornell's Cartesian pairs as


def models_held_out(ds, k: int, seed: int) -> dict[str, dict[str, dict[str, float]]]:
    """Each model fitted on the training folds, evaluated on the held-out one."""
    L, V = get_parametrization(OWN).to_dirs(ds.x)
    y = np.asarray(ds.y)
    out = {}
    for spec in MODELS:
        pred = np.full(y.shape, np.nan)
        for test in fold_indices(ds.n_points, k, seed):
            train = np.setdiff1d(np.arange(ds.n_points), test)
            mf = fit_model(Model(spec), L[train], V[train], y[train],
                           channel_names=ds.output_names, starts=6)
            pred[test] = mf.eval_dirs(L[test], V[test])
        out[spec] = holdout_metrics(pred, y, L[:, 2], ds.output_names)
    return out


def _timed_fold(frames, test, jobs: int | None):
    t0 = time.perf_counter()
    out = fit_fold(frames, test, **({} if jobs is None else {"jobs": jobs}))
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--only", nargs="+", metavar="NAME",
                    help="run the materials whose name contains one of these")
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1,
                    help="processes for the fold fits and models (default 1)")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    cmp = ModelComparison(METRICS, {"rmse": "RMSE", "cos_rmse": "cos RMSE",
                                    "rel_rmse": "rel. RMSE"})
    names = [m for m in MATERIALS if not args.only or any(o in m for o in args.only)]
    frames = {}
    for name in names:
        samples = read_brdf(args.data / "cornell" / f"{name}.brdf")
        frames[name] = [samples_dataset(samples, p) for p in candidate_parametrizations(OWN)]
    jobs = 1 if args.workers > 1 else None  # processes, not threads, when several
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        folds = {name: [pool.submit(_timed_fold, frames[name], t, jobs)
                        for t in fold_indices(frames[name][0].n_points, args.k, args.seed)]
                 for name in names}
        model_runs = {name: pool.submit(models_held_out, frames[name][-1], args.k, args.seed)
                      for name in names}
        for name in names:
            done = [f.result() for f in folds[name]]
            secs = sum(t for _o, t in done)
            res = pooled_result(frames[name], args.k, args.seed, [o for o, _t in done])
            print(f"{name}: {res.folds_verified} of {args.k} fold fits verified, {secs:.0f} s",
                  file=sys.stderr, flush=True)
            models = model_runs[name].result()
            sizes = [f["coefficients"] for f in res.folds if f["coefficients"] is not None]
            coefs = f"{min(sizes)}-{max(sizes)}" if sizes else "none"
            for ch in frames[name][0].output_names:
                if ch not in res.metrics or res.folds_verified < args.k:
                    cmp.add_missing(name, ch, coefs, f"{res.folds_verified} of {args.k} fold "
                                    "fits verified: not compared", secs)
                    continue
                cmp.add(name, ch, coefs, res.metrics[ch], models, secs)
    cmp.write_to(rep, title=f"held out ({args.k}-fold, seed {args.seed}): the default rational "
                 f"fit against the better of {', '.join(MODELS)}, per channel",
                 size="coefs", seconds="s", what="Held out, the default rational fit",
                 legend="coefs: the fold fits' totals over the three channels; s: the "
                        "material's K fold fits.",
                 plot="bench_holdout", caption="held out: better analytic model's error / "
                 "rational fit's, per channel (above 1: the rational fit is better)")
    rep.write()


if __name__ == "__main__":
    main()
