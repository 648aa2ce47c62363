"""Where the held-out errors of bench_holdout.py lie: which samples decide each RMSE.

Reads the predictions ``bench_holdout.py --save DIR`` keeps (every sample predicted by
the fold fit that never saw it, and by each analytic model fitted on the same folds) and
prints, per material and channel:

- the share of the rational fit's and of the better model's summed squared error that
  its single worst sample carries, with that sample's angles, value and predictions;
- the share of the rational fit's squared error within 0.02 rad of the mirror direction
  (theta_h), where a Cornell file has one sample per incidence angle;
- RMSE, cos-weighted RMSE and relative RMSE (RMS of log((f + e)/(y + e)), e = 1e-3 1/sr)
  of the rational fit and the better model over every sample but the file's largest value
  (at the most grazing incidence, outside the box its training folds span when held out),
  and whether the rational fit wins all three there. This is a diagnosis, not the
  benchmark's score: bench_holdout.py's table (every sample) is.

    python benchmarks/holdout_where.py DIR [--markdown [PATH]]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.holdout import holdout_metrics
from ratfit.brdf.parametrizations import get_parametrization

MIRROR = 0.02  # rad of theta_h: "at the mirror direction"
METRICS = ("rmse", "cos_rmse", "rel_rmse")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="the folder bench_holdout.py --save wrote")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    files = sorted(args.dir.glob("*.npz"))
    if not files:
        raise SystemExit(f"error: no .npz files in {args.dir}")
    worst_rows, rest_rows = [], []
    wins = total = 0
    for path in files:
        z = np.load(path)
        L, V, y, rat = z["L"], z["V"], z["y"], z["rational"]
        models = {k.removeprefix("model_"): z[k] for k in z.files if k.startswith("model_")}
        theta_h, theta_d = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V)[:, :2].T
        names = [str(c) for c in z["channels"]]
        top = int(np.argmax(np.max(y, axis=1)))
        rest = np.arange(len(y)) != top
        # the three held-out errors of each predictor over every sample but the largest
        rest_errors = {name: holdout_metrics(p[rest], y[rest], L[rest, 2], names)
                       for name, p in {"rational": rat, **models}.items()}
        for j, ch in enumerate(names):
            e2 = (rat[:, j] - y[:, j]) ** 2
            i = int(np.argmax(e2))
            best = min(models, key=lambda k: float(np.mean((models[k][:, j] - y[:, j]) ** 2)))
            m2 = (models[best][:, j] - y[:, j]) ** 2
            k = int(np.argmax(m2))
            near = e2[theta_h < MIRROR].sum() / e2.sum()
            worst_rows.append([
                path.stem, ch, f"{e2[i] / e2.sum():.2f}",
                f"{theta_h[i]:.3f} / {theta_d[i]:.3f}", f"{y[i, j]:.3g}",
                f"{rat[i, j]:.3g}", f"{models[best][i, j]:.3g}", f"{near:.2f}",
                f"{m2[k] / m2.sum():.2f}"])
            r = [rest_errors["rational"][ch][q] for q in METRICS]
            b = [min(rest_errors[m][ch][q] for m in models) for q in METRICS]
            won = all(r[q] < b[q] for q in range(3))
            wins += won
            total += 1
            rest_rows.append([path.stem, ch] + [
                f"{r[q]:.4g} / {b[q]:.4g} ({b[q] / r[q]:.2f}x)" for q in range(3)]
                + ["yes" if won else "no"])
    rep.table("the rational fit's worst held-out sample, per channel (share: of the channel's "
              "summed squared error; model: the better model by RMSE, at the same sample; "
              f"near mirror: share within {MIRROR} rad of theta_h)",
              ["material", "ch", "worst share", "theta_h / theta_d", "y", "rational",
               "model", "near-mirror share", "model's worst share"], worst_rows)
    rep.table("held out, every sample but the file's largest value: rational / better model "
              "(model / rational)",
              ["material", "ch", "RMSE", "cos RMSE", "rel. RMSE", "wins all"], rest_rows)
    rep.note(f"Without the file's largest value the rational fit wins all three errors in "
             f"{wins} of {total} channels.")
    rep.write()


if __name__ == "__main__":
    main()
