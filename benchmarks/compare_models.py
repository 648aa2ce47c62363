"""Rational BRDF fits against the best analytic model on real data (Cornell, ALTA retro).

For each data set: one verified rational fit per channel (ratfit.brdf.fitter.fit_brdf) and
least-squares fits of several analytic models (ratfit.brdf.analytic_models); every row reports
the coefficients used, RMSE and relative RMSE on all samples (ratfit.brdf.fitter.brdf_metrics),
and the ratio of each RMSE to the rational fit's (the baseline, same run).

    python benchmarks/compare_models.py [--data DIR] [--only NAME]

Segment settings per data set are those under which the rational fit verifies
(measured): Cornell dt 0.2 with a floor of 0.5 % of each channel's max and q > 0
on the valid grid; retro dt 0.5, floor 1 %, q > 0 on the valid grid, at the split
(23, 79) the search reached (its full search takes over 10 minutes).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ratfit.brdf.fitter import BRDFFit, brdf_metrics, fit_brdf
from ratfit.brdf.io import brdf_dataset
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.viz.report import cos_factor, model_fit_for

REPO = Path(__file__).resolve().parents[1]
MODELS = ("lambert+blinn", "lambert+ward", "lambert+beckmann", "lambert+ggx",
          "lambert+lafortune*2")
CASES = [
    ("cornell/garnet_red.brdf", "ISOTROPIC_TV_TL_DPHI",
     {"dt": 0.2, "floor_rel": 0.005, "positive_q": True}),
    ("cornell/acryl_blue.brdf", "ISOTROPIC_TV_TL_DPHI",
     {"dt": 0.2, "floor_rel": 0.005, "positive_q": True}),
    ("alta/retro-3M-jaune.dat", "RETRO_TV_TVL_PROJ_DPHI",
     {"dt": 0.5, "floor_rel": 0.01, "positive_q": True, "n": 23, "m": 79}),
]


def run_case(path: Path, param: str | None, settings: dict, max_total: int):
    ds = brdf_dataset(path, param)
    pname = str(ds.meta["param_in"])
    L, V = get_parametrization(pname).to_dirs(ds.x)
    rows = []
    t0 = time.perf_counter()
    if "n" not in settings:
        settings = {**settings, "max_total": max_total}
    fitter, _, meta = fit_brdf(ds, **settings)
    secs = time.perf_counter() - t0
    ok = all(r.success for r in fitter.results_)
    if ok:
        from ratfit.io.fitfile import fit_document, parse_fit

        saved = parse_fit(fit_document(fitter.results_, extra={"brdf": meta}))
        pred = BRDFFit(saved, pname).eval_coords(ds.x)
        met = brdf_metrics(pred, ds.y, L[:, 2], ds.output_names)
        coefs = "+".join(f"{r.n}/{r.m}" for r in fitter.results_)
        rows.append(("rational", coefs, sum(r.total for r in fitter.results_), met, secs))
    else:
        print(f"  rational fit not verified on every channel (max_total={max_total})")
    for spec in MODELS:
        t0 = time.perf_counter()
        mf = model_fit_for(pname, ds, spec, starts=6)
        pred = mf.eval_dirs(L, V)
        if cos_factor(ds):
            pred = pred * L[:, 2:3]
        met = brdf_metrics(pred, ds.y, L[:, 2], ds.output_names)
        rows.append((spec, f"{mf.model.n_params} x {mf.n_channels}",
                     mf.model.n_params * mf.n_channels, met, time.perf_counter() - t0))
    return ds, pname, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--max-total", type=int, default=80)
    ap.add_argument("--only", help="run the data sets whose path contains this")
    args = ap.parse_args()
    for rel, param, settings in CASES:
        if args.only and args.only not in rel:
            continue
        ds, pname, rows = run_case(args.data / rel, param, settings, args.max_total)
        print(f"\n{rel}: {ds.n_points} samples, {pname}, channels {', '.join(ds.output_names)}"
              f" (rational fit settings {settings})")
        base = None
        if rows and rows[0][0] == "rational":
            base = np.mean([m["rmse"] for m in rows[0][3].values()])
        print(f"{'fit':22s} {'coefs (n/m per ch.)':>20s} {'total':>6s} {'RMSE':>10s} "
              f"{'rel.RMSE':>9s} {'RMSE/rat.':>9s} {'s':>7s}")
        for name, coefs, total, met, secs in rows:
            rmse = float(np.mean([m["rmse"] for m in met.values()]))
            rel = float(np.mean([m["rel_rmse"] for m in met.values()]))
            ratio = f"{rmse / base:9.2f}" if base else f"{'-':>9s}"
            print(f"{name:22s} {coefs:>20s} {total:6d} {rmse:10.4g} {rel:9.3g} {ratio} "
                  f"{secs:7.1f}")
        print("(RMSE and rel. RMSE averaged over channels; rel. RMSE = RMS of (f - y)/y "
              "over y != 0)")


if __name__ == "__main__":
    main()
