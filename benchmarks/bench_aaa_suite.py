"""ratfit vs scipy.interpolate.AAA over a suite of test functions (run by hand).

The functions are modelled on the kinds SciPy's own AAA tests use: smooth
(exp, Runge, log), with poles inside or just outside the interval (tan),
non-smooth (|x|), over many decades (sqrt on logspace(-15, 0)), gamma. For each
relative width e in 1e-1, 1e-2, 1e-3, measured in one run:

* ratfit: the search's verified fit inside [(1-e) y, (1+e) y] (default options,
  time limit per fit below): total n + m, the variable (x, or log x for data
  over many decades), real poles in the interval of the verified fit (always 0
  when verified), seconds.
* AAA: the smallest ``max_terms = k`` whose max relative error at the data is
  at most e: 2k p/q coefficients (type (k-1, k-1)), its real poles inside the
  interval (AAA does not exclude them), seconds (the scan over k).
* flag ``MISS``: ratfit found nothing while AAA has a pole-free fit.

    python benchmarks/bench_aaa_suite.py [--quick] [--time-limit S]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py
from scipy.interpolate import AAA
from scipy.special import gamma

from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter

LIN = np.linspace(-1.0, 1.0, 500)
# name, x, f(x); x avoids zeros of f (relative widths) and poles of f.
SUITE: list[tuple[str, np.ndarray, np.ndarray]] = [
    ("exp(x)", LIN, np.exp(LIN)),
    ("runge 1/(1+25x^2)", LIN, 1.0 / (1.0 + 25.0 * LIN**2)),
    ("log(1.1+x)+3", LIN, np.log(1.1 + LIN) + 3.0),
    ("1/(1.1+x)", LIN, 1.0 / (1.1 + LIN)),
    ("tan(pi x/2), |x|<=0.99", 0.99 * LIN, np.tan(np.pi * 0.99 * LIN / 2) + 70.0),
    ("tan(pi x)+20 (poles in)", LIN, np.tan(np.pi * LIN) + 20.0),
    ("|x|+0.01", LIN, np.abs(LIN) + 0.01),
    ("sqrt(x), logspace(-15,0)", np.logspace(-15, 0, 300), np.sqrt(np.logspace(-15, 0, 300))),
    ("gamma(x), [0.1,4]", np.linspace(0.1, 4.0, 300), gamma(np.linspace(0.1, 4.0, 300))),
    ("2+sin(10x)", LIN, 2.0 + np.sin(10.0 * LIN)),
]
WIDTHS = (1e-1, 1e-2, 1e-3)


def aaa_fit(x: np.ndarray, y: np.ndarray, target: float, kmax: int = 100) -> dict:
    t0 = time.perf_counter()
    best = None
    for k in range(1, kmax + 1):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                r = AAA(x, y, rtol=0.0, max_terms=k, clean_up=False)
            except Exception:  # noqa: BLE001 - AAA breaks down at some sizes: try the next
                continue
            with np.errstate(all="ignore"):
                err = float(np.max(np.abs(r(x) - y) / np.abs(y)))
        if err <= target:
            poles = np.asarray(r.poles())
            real = poles[np.abs(poles.imag) <= 1e-9 * (x.max() - x.min())].real
            inside = int(np.sum((real >= x.min()) & (real <= x.max())))
            best = {"coef": 2 * len(r.support_points), "poles": inside, "err": err}
            break
    secs = time.perf_counter() - t0
    return {"coef": None, "poles": None, "err": None, "seconds": secs} if best is None else {
        **best, "seconds": secs}


def ratfit_fit(x: np.ndarray, y: np.ndarray, target: float, limit: float) -> dict:
    seg = Segments.from_relative(x, y, target)
    t0 = time.perf_counter()
    res = RationalFitter(time_limit=limit).fit(seg).result_
    secs = time.perf_counter() - t0
    ok = res.success
    return {"total": res.n + res.m if ok else None,
            "variable": res.rational.space.variable if ok else "-",
            "poles": res.verification.poles_in_domain if ok else None,
            "seconds": secs, "message": res.message}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="widths 1e-1 and 1e-2 only")
    ap.add_argument("--time-limit", type=float, default=60.0, help="ratfit seconds per fit")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    widths = WIDTHS[:2] if args.quick else WIDTHS
    rows, misses = [], 0
    for name, x, y in SUITE:
        for e in widths:
            a = aaa_fit(x, y, e)
            r = ratfit_fit(x, y, e, args.time_limit)
            miss = r["total"] is None and a["coef"] is not None and a["poles"] == 0
            misses += miss
            rows.append([
                name, f"{e:.0e}", "-" if r["total"] is None else str(r["total"]), r["variable"],
                "-" if r["poles"] is None else str(r["poles"]), f"{r['seconds']:.2f}",
                "-" if a["coef"] is None else str(a["coef"]),
                "-" if a["poles"] is None else str(a["poles"]), f"{a['seconds']:.2f}",
                "MISS" if miss else "",
            ])
            print(f"{name} {e:.0e}: ratfit {rows[-1][2]} ({r['seconds']:.1f} s), "
                  f"AAA {rows[-1][6]}", flush=True)
    rep.table("ratfit vs AAA, relative widths (coefficients: ratfit n+m, AAA 2k)",
              ["function", "width", "ratfit n+m", "var", "poles", "s", "AAA 2k", "AAA poles",
               "AAA s", ""], rows)
    print(f"\nrows where ratfit finds nothing while AAA has a pole-free fit: {misses}")
    rep.write()


if __name__ == "__main__":
    main()
