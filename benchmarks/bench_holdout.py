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
        [--fit KEY=VALUE ...] [--save DIR]

``--workers W`` fits the folds (of every material at once) and the models in W
processes; every fold fit is bounded by counted work, so the table is the same for
any W (seconds aside: with W > 1 a material's "s" is the sum of its fold fits' own
times, not the wall time). ``--fit KEY=VALUE`` (repeatable) fits every fold with a
non-default option (a keyword of ``fit_brdf_auto``), to choose defaults by held-out
error. ``--save DIR`` keeps every held-out prediction (``DIR/<material>.npz``: the
directions, values, the rational fit's and each model's predictions).
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


def models_held_out(ds, k: int, seed: int
                    ) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, np.ndarray]]:
    """Each model fitted on the training folds, evaluated on the held-out one: the
    metrics per model and the held-out predictions per model."""
    L, V = get_parametrization(OWN).to_dirs(ds.x)
    y = np.asarray(ds.y)
    out, preds = {}, {}
    for spec in MODELS:
        pred = np.full(y.shape, np.nan)
        for test in fold_indices(ds.n_points, k, seed):
            train = np.setdiff1d(np.arange(ds.n_points), test)
            mf = fit_model(Model(spec), L[train], V[train], y[train],
                           channel_names=ds.output_names, starts=6)
            pred[test] = mf.eval_dirs(L[test], V[test])
        out[spec] = holdout_metrics(pred, y, L[:, 2], ds.output_names)
        preds[spec] = pred
    return out, preds


def save_predictions(path: Path, ds, res, model_preds: dict[str, np.ndarray]) -> None:
    """Every sample's held-out prediction (the rational fit's and each model's), its
    value and directions, for a closer look at where the errors lie."""
    L, V = get_parametrization(OWN).to_dirs(ds.x)
    np.savez_compressed(path, L=L, V=V, y=np.asarray(ds.y), rational=res.predictions,
                        channels=np.asarray(ds.output_names),
                        **{f"model_{spec}": p for spec, p in model_preds.items()})


def _timed_fold(frames, test, options: dict):
    t0 = time.perf_counter()
    out = fit_fold(frames, test, **options)
    return out, time.perf_counter() - t0


def _option(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise SystemExit(f"error: --fit needs KEY=VALUE, got {text!r}")
    for kind in (int, float):
        try:
            return key, kind(value)
        except ValueError:
            pass
    return key, {"true": True, "false": False, "none": None}.get(value.lower(), value)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--only", nargs="+", metavar="NAME",
                    help="run the materials whose name contains one of these")
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1,
                    help="processes for the fold fits and models (default 1)")
    ap.add_argument("--fit", action="append", default=[], metavar="KEY=VALUE",
                    help="a fit option other than the default, e.g. polish_error=relative "
                         "(repeatable; keyword of ratfit.brdf.fitter.fit_brdf_auto)")
    ap.add_argument("--save", type=Path, metavar="DIR",
                    help="also write each material's held-out predictions to "
                         "DIR/<material>.npz (rational fit and models)")
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
    options = dict(_option(o) for o in args.fit)
    if args.workers > 1:
        options.setdefault("jobs", 1)  # processes, not threads, when several
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        folds = {name: [pool.submit(_timed_fold, frames[name], t, options)
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
            models, model_preds = model_runs[name].result()
            if args.save is not None:
                args.save.mkdir(parents=True, exist_ok=True)
                save_predictions(args.save / f"{name}.npz", frames[name][-1], res, model_preds)
            sizes = [f["coefficients"] for f in res.folds if f["coefficients"] is not None]
            coefs = f"{min(sizes)}-{max(sizes)}" if sizes else "none"
            for ch in frames[name][0].output_names:
                if ch not in res.metrics or res.folds_verified < args.k:
                    cmp.add_missing(name, ch, coefs, f"{res.folds_verified} of {args.k} fold "
                                    "fits verified: not compared", secs)
                    continue
                cmp.add(name, ch, coefs, res.metrics[ch], models, secs)
            # each material's rows as soon as they are known: a run stopped later keeps them
            print("\n".join("  " + " | ".join(str(c) for c in row)
                            for row in cmp.rows[-len(frames[name][0].output_names):]),
                  file=sys.stderr, flush=True)
    what = "the default rational fit" if not args.fit else \
        "the rational fit with " + ", ".join(args.fit)
    cmp.write_to(rep, title=f"held out ({args.k}-fold, seed {args.seed}): {what} "
                 f"against the better of {', '.join(MODELS)}, per channel",
                 size="coefs", seconds="s", what=f"Held out, {what}",
                 legend="coefs: the fold fits' totals over the three channels; s: the "
                        "material's K fold fits.",
                 plot=rep.stem("bench_holdout"),
                 caption="held out: better analytic model's error / "
                 "rational fit's, per channel (above 1: the rational fit is better)")
    rep.write()


if __name__ == "__main__":
    main()
