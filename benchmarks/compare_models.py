"""Default rational BRDF fits against the best analytic model, per channel, on real data.

For each Cornell material: `ratfit brdf fit DATA` with no options (what
`ratfit.brdf.fitter.fit_brdf_auto` does without widths: the half-vector frame, log
values at each channel's noise level, each channel within 72 coefficients or widened
alone; ISOTROPIC_TV_TL_DPHI only if that fails; the validity proof, the least-squares
polish), evaluated as `ratfit brdf eval` evaluates the saved fit, and
least-squares fits of lambert+ggx and lambert+beckmann
(`ratfit.brdf.analytic_models`, 6 random starts). Per channel it prints the
coefficients, RMSE, log RMSE and cos RMSE of the rational fit, the same errors of
the better analytic model for each metric, their ratio (model / rational: above 1
means the rational fit is better), and whether the rational fit wins all three.

    python benchmarks/compare_models.py [--data DIR] [--only NAME] [--jobs 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _bench import ModelComparison, add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.analytic_models import Model, fit_model
from ratfit.brdf.fitter import (
    brdf_fit_of,
    brdf_metrics,
    candidate_parametrizations,
    fit_brdf_auto,
    fitted_frame,
)
from ratfit.brdf.io import brdf_dataset
from ratfit.brdf.parametrizations import get_parametrization

REPO = Path(__file__).resolve().parents[1]
MODELS = ("lambert+ggx", "lambert+beckmann")
MATERIALS = ("garnet_red", "acryl_blue", "cayman", "krylon_blue", "mystique")
METRICS = ("rmse", "log_rmse", "cos_rmse")
PARAM = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` picks for Cornell's CARTESIAN


def run(path: Path, jobs: int | None):
    ds = brdf_dataset(path, PARAM)
    L, V = get_parametrization(PARAM).to_dirs(ds.x)
    others = [brdf_dataset(path, p) for p in candidate_parametrizations(PARAM) if p != PARAM]
    t0 = time.perf_counter()
    fitter, _seg, meta = fit_brdf_auto([*others, ds], jobs=jobs)
    secs = time.perf_counter() - t0
    # the same samples in the same order in every parametrization
    assert all(np.array_equal(o.y, ds.y) for o in others)
    print(f"{path.stem}: " + "; ".join(
        f"{c['parametrization']} floor {c['floor'] or 0:g} "
        + (c.get("skipped") or str(c["coefficients"] or "no fit"))
        for c in meta["candidates"]))
    if not fitter.success_:
        return ds, None, {}, secs
    # the value a user gets (exp(p / q) for a fit of log values), not the stored ratio
    frame = fitted_frame([*others, ds], meta)
    pred = np.asarray(brdf_fit_of(fitter.results_, meta).eval_coords(frame.x), dtype=float)
    rat = brdf_metrics(pred, ds.y, L[:, 2], ds.output_names)
    for name, r in zip(ds.output_names, fitter.results_, strict=True):
        rat[name]["coefs"] = r.total
        rat[name]["nm"] = f"{r.n}+{r.m}"
    models = {}
    for spec in MODELS:
        mf = fit_model(Model(spec), L, V, ds.y, channel_names=ds.output_names, starts=6)
        models[spec] = brdf_metrics(mf.eval_dirs(L, V), ds.y, L[:, 2], ds.output_names)
    return ds, rat, models, secs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--only", help="run the materials whose name contains this")
    ap.add_argument("--jobs", type=int, default=None)
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    cmp = ModelComparison(METRICS, {"rmse": "RMSE", "log_rmse": "log RMSE",
                                    "cos_rmse": "cos RMSE"})
    for name in MATERIALS:
        if args.only and args.only not in name:
            continue
        ds, rat, models, secs = run(args.data / "cornell" / f"{name}.brdf", args.jobs)
        if rat is None:
            for ch in ds.output_names:
                cmp.add_missing(name, ch, "-", "no verified default fit", secs)
            continue
        for ch in ds.output_names:
            cmp.add(name, ch, rat[ch]["nm"], rat[ch], models, secs)
    cmp.write_to(rep, title=f"default rational fit against the better of {', '.join(MODELS)}, "
                 "per channel", size="n+m", seconds="fit s",
                 what="The default rational fit",
                 legend="fit s: the material's three channels.",
                 plot="compare_models", caption="better analytic model's error / rational "
                 "fit's, per channel (above 1: the rational fit is better)")
    rep.write()


if __name__ == "__main__":
    main()
