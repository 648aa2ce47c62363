"""CDF fitting and sampling timings, with a tabulated inverse CDF as the baseline.

Two lobes, each a 1000-point tabulated pdf: Beckmann (cos theta_h, alpha 0.3)
and GGX (theta_h, alpha 0.1, heavy tail). Per lobe:

1. build: the monotone rational CDF fit (staircase search, +-5e-4 segments,
   with and without 200 extra constraint points) against building the
   baseline table (cumulative trapezoid + normalisation); ratio = time / baseline;
2. draw 1e6 samples: rational inverse CDF (safeguarded Newton) against
   ``numpy.interp`` on the tabulated inverse CDF; ratio = time / baseline;
   both with their sup-error against the true CDF and the KS statistic of the
   draws against the true CDF (what the extra time buys: a smooth,
   compact, verified CDF and a pdf that is the exact derivative).

Run:  python benchmarks/bench_cdf.py [--repeat 3] [--samples 1000000]
"""

from __future__ import annotations

import argparse

import numpy as np
from _bench import add_markdown_option, best_of, report  # benchmarks/_bench.py
from scipy.integrate import cumulative_trapezoid

from ratfit.cdf.monotone import MonotoneFitter, cdf_from_pdf
from ratfit.cdf.sampling import (
    RationalCDF,
    beckmann_cos_cdf,
    beckmann_cos_pdf,
    ggx_theta_cdf,
    ggx_theta_pdf,
    ks_statistic,
)

LOBES = {
    "beckmann a=0.3 (cos th)": (0.0, 1.0, lambda v: beckmann_cos_pdf(v, 0.3),
                                lambda v: beckmann_cos_cdf(v, 0.3)),
    "ggx a=0.1 (theta)": (0.0, np.pi / 2, lambda v: ggx_theta_pdf(v, 0.1),
                          lambda v: ggx_theta_cdf(v, 0.1)),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--samples", type=int, default=1_000_000)
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    build_rows, draw_rows = [], []
    for name, (a, b, pdf, cdf) in LOBES.items():
        x = np.linspace(a, b, 1000)
        f = pdf(x)
        z = np.linspace(a, b, 20_001)

        def baseline_table(x=x, f=f):
            F = cumulative_trapezoid(f, x, initial=0.0)
            return F / F[-1]

        t_base, F_tab = best_of(baseline_table, args.repeat)
        build_rows.append([name, "table (baseline)", "-", f"{t_base * 1e3:.3f}", "1",
                           f"{np.abs(np.interp(z, x, F_tab) - cdf(z)).max():.2e}"])
        models = {}
        for grid in (0, 200):
            def fit(grid=grid, x=x, f=f):
                seg = cdf_from_pdf(x, f, abs_width=5e-4)
                return MonotoneFitter(grid=grid).fit(seg).result_

            t, res = best_of(fit, args.repeat)
            ok = "yes" if res.success else "NO"
            build_rows.append([name, f"rational, grid {grid}", f"{res.n}+{res.m} ({ok})",
                               f"{t * 1e3:.1f}", f"{t / t_base:.0f}",
                               f"{np.abs(RationalCDF(res.rational).cdf(z) - cdf(z)).max():.2e}"
                               if res.success else "-"])
            if res.success:
                models[grid] = RationalCDF(res.rational)
        model = models.get(200) or models.get(0)
        if model is None:
            continue
        u = np.random.default_rng(0).random(args.samples)
        t_interp, xs_tab = best_of(lambda u=u, F_tab=F_tab, x=x: np.interp(u, F_tab, x),
                                   args.repeat)
        t_rat, xs_rat = best_of(lambda u=u, model=model: model.ppf(u), args.repeat)
        draw_rows.append([name, "np.interp inverse table (baseline)",
                          f"{t_interp * 1e3:.1f}", "1", f"{ks_statistic(xs_tab, cdf):.2e}"])
        draw_rows.append([name, f"rational ppf ({model.rational.n}+{model.rational.m})",
                          f"{t_rat * 1e3:.1f}", f"{t_rat / t_interp:.1f}",
                          f"{ks_statistic(xs_rat, cdf):.2e}"])
    rep.table("Build a CDF from a 1000-point pdf table (ratio vs the baseline table)",
              ["lobe", "method", "n+m (verified)", "ms", "ratio", "sup|F - F_true|"], build_rows)
    rep.table(f"Draw {args.samples:.0e} samples (ratio vs np.interp)",
              ["lobe", "method", "ms", "ratio", "KS vs true"], draw_rows)
    rep.write()


if __name__ == "__main__":
    main()
