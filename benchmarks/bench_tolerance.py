"""Best relative width at fixed size (ratfit) vs SciPy's AAA at equal real parameters.

The seed's function on 500 equispaced points of [-3, 12]. For each d, ratfit's
smallest relative width at n = m = d + 1 (2d + 1 free real parameters: one
coefficient is the common scale of p and q), found by bisection with
feasibility QPs, against the max relative error of AAA of type (d, d) (also
2d + 1 free parameters) on the same points. The baseline is AAA, measured in
the same run; ``ratio`` = ratfit width / AAA error (< 1: ratfit is better).
ratfit's width is a verified bound (every segment met, no pole in the domain)
with a certificate that no (d+1, d+1) rational fits at width / (1 + rtol).

Run: python benchmarks/bench_tolerance.py [--points 500] [--rtol 1e-2]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit.demos.addendum import addendum_function
from ratfit.fitting.tolerance import aaa_error, best_width


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--rtol", type=float, default=1e-2)
    ap.add_argument("--degrees", type=int, nargs="+", default=[4, 6, 8, 10, 12, 14, 17, 20])
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    x = np.linspace(-3.0, 12.0, args.points)
    y = addendum_function(x)
    rows = []
    for d in args.degrees:
        aaa = aaa_error(x, y, d)
        t0 = time.perf_counter()
        res = best_width(x, y, d + 1, d + 1, rtol=args.rtol)
        secs = time.perf_counter() - t0
        ratio = res.width / aaa["max_rel_error"]
        rows.append([str(d), str(2 * d + 1), f"{aaa['max_rel_error']:.3e}",
                     str(aaa["real_poles_in_domain"]), f"{res.width:.3e}",
                     "yes" if res.lower_certified else "no", f"{ratio:.2e}",
                     str(len(res.steps)), f"{secs:.1f}"])
        print(f"d {d}: {secs:.1f} s", file=sys.stderr, flush=True)
    rep.table(f"seed function, {args.points} points on [-3, 12], rtol {args.rtol}: ratfit's "
              "best width at n = m = d + 1 against AAA's error at type (d, d) (ratio: width / "
              "AAA error, same run)",
              ["d", "params", "AAA max rel", "AAA poles", "ratfit width", "certified",
               "ratio", "QPs", "s"], rows)
    rep.write()


if __name__ == "__main__":
    main()
