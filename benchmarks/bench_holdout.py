"""Held-out errors of the default rational BRDF fit against analytic models, per channel.

For each Cornell material: K-fold cross-validation (``ratfit.brdf.holdout``, the folds
``ratfit brdf fit --holdout K`` uses) of the default fit (`ratfit brdf fit DATA`: the
same frames, widths and options), and lambert+ggx and lambert+ggx*2 fitted
(``ratfit.brdf.analytic_models.fit_model``, 6 starts) on the same training folds.
Every sample is predicted by a fit that never saw it. Per channel it prints the
held-out RMSE, cos-weighted RMSE and relative RMSE (RMS of log((f + e)/(y + e)),
e = 1e-3 1/sr) of the rational fit and of the better model for each metric, the
fold fits' coefficient counts, and whether the rational fit wins all three.

    python benchmarks/bench_holdout.py [--data DIR] [--only NAME] [--k 5] [--time-limit S]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _bench import ModelComparison, add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.analytic_models import Model, fit_model
from ratfit.brdf.fitter import candidate_parametrizations
from ratfit.brdf.holdout import cross_validate, fold_indices, holdout_metrics
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--only", help="run the materials whose name contains this")
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--time-limit", type=float, default=None,
                    help="per-channel search limit of each fold fit (default: ratfit's)")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    cmp = ModelComparison(METRICS, {"rmse": "RMSE", "cos_rmse": "cos RMSE",
                                    "rel_rmse": "rel. RMSE"})
    for name in MATERIALS:
        if args.only and args.only not in name:
            continue
        samples = read_brdf(args.data / "cornell" / f"{name}.brdf")
        frames = [samples_dataset(samples, p) for p in candidate_parametrizations(OWN)]
        kw = {} if args.time_limit is None else {"time_limit": args.time_limit}
        t0 = time.perf_counter()
        res = cross_validate(frames, args.k, seed=args.seed, **kw)
        secs = time.perf_counter() - t0
        print(f"{name}: {res.folds_verified} of {args.k} fold fits verified, {secs:.0f} s",
              file=sys.stderr, flush=True)
        models = models_held_out(frames[-1], args.k, args.seed)
        sizes = [f["coefficients"] for f in res.folds if f["coefficients"] is not None]
        coefs = f"{min(sizes)}-{max(sizes)}" if sizes else "none"
        for ch in frames[0].output_names:
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
