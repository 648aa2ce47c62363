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
import time

import numpy as np

from ratfit.demos.addendum import addendum_function
from ratfit.fitting.tolerance import aaa_error, best_width


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--rtol", type=float, default=1e-2)
    ap.add_argument("--degrees", type=int, nargs="+", default=[4, 6, 8, 10, 12, 14, 17, 20])
    args = ap.parse_args()
    x = np.linspace(-3.0, 12.0, args.points)
    y = addendum_function(x)
    head = (f"{'d':>3} {'params':>6} {'AAA max rel':>12} {'AAA poles':>9} {'ratfit width':>13} "
            f"{'certified':>9} {'ratio':>9} {'QPs':>4} {'s':>6}")
    print(f"seed function, {args.points} points on [-3, 12], rtol {args.rtol}")
    print(head)
    print("-" * len(head))
    for d in args.degrees:
        aaa = aaa_error(x, y, d)
        t0 = time.perf_counter()
        res = best_width(x, y, d + 1, d + 1, rtol=args.rtol)
        secs = time.perf_counter() - t0
        ratio = res.width / aaa["max_rel_error"]
        print(f"{d:>3} {2 * d + 1:>6} {aaa['max_rel_error']:>12.3e} "
              f"{aaa['real_poles_in_domain']:>9} {res.width:>13.3e} "
              f"{'yes' if res.lower_certified else 'no':>9} {ratio:>9.2e} "
              f"{len(res.steps):>4} {secs:>6.1f}", flush=True)


if __name__ == "__main__":
    main()
