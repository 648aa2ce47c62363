"""Is every reported total the smallest pole-free one? Held-out-style data sets.

For each data set and width: ratfit's reported total T (default search, one
thread), then an exhaustive LP over the neighbouring totals T-3..T-1: every
split (n, m) of those totals gets

    max s  s.t.  rows_i(c) >= s  (every segment, both sides, rows scaled to 1),
                 q(t_k) >= s     (a grid of 2001 domain points: no pole),
                 -1 <= c <= 1

(HiGHS through SciPy) in the weighted data-orthonormal form of the split (the
well-conditioned one), and a positive margin's c is verified like any fit (every
segment, no pole in the domain, ratfit.core.verify). The LP's vertex sits on
the boundary, so at margins near its tolerance (1e-8) it finds directions that
do not verify: every split is also fitted alone (``RationalFitter(n=, m=)``,
both formulations), which is what catches a walk that ruled a split out by a
wrong "infeasible". "minimal" is yes when neither finds a fit below T.
Data: ../shared/data (NIST StRD sets, the NIST ITS-90 type K table).

Run:  python benchmarks/bench_minimal_suite.py [--below 3]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit import RationalFitter
from ratfit.core.qp import ArnoldiSystem, sk_denominator
from ratfit.core.verify import verify
from ratfit.io.data import read_data

DATA = Path(os.environ.get("RATFIT_SHARED_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
# (name, file, dt, abs_width)
CASES = [
    ("Kirby2 dt 1e-2", "nist/Kirby2.dat", 1e-2, None),
    ("Kirby2 dt 1e-3", "nist/Kirby2.dat", 1e-3, None),
    ("MGH09 dt 1e-2", "nist/MGH09.dat", 1e-2, None),
    ("Rat42 dt 1e-3", "nist/Rat42.dat", 1e-3, None),
    ("Rat43 dt 1e-3", "nist/Rat43.dat", 1e-3, None),
    ("Thurber dt 1e-3", "nist/Thurber.dat", 1e-3, None),
    ("ENSO dt 0.5", "nist/ENSO.dat", 0.5, None),
    ("thermocouple K abs 5e-4", "tables/thermocouple-type-k.csv", None, 5e-4),
]


def lp_pole_free(space, seg, n: int, m: int):
    """A verified pole-free fit of split (n, m) from the LP, or None."""
    from scipy.optimize import linprog

    try:
        q0 = sk_denominator(space, seg, 0, n, m, as_function=True)
        system = ArnoldiSystem(space, seg, 0, n, m, q0)
    except Exception:  # too few points for the split
        return None
    A = system.rows(n, m)
    A = A / np.linalg.norm(A, axis=1)[:, None]
    grid = np.linspace(-1.0, 1.0, 2001)[:, None]
    Q = system.q_design(grid, m)
    Q = np.hstack([np.zeros((Q.shape[0], n)), Q / np.linalg.norm(Q, axis=1)[:, None]])
    G = np.vstack([A, Q])
    k = n + m
    cost = np.zeros(k + 1)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=np.hstack([-G, np.ones((G.shape[0], 1))]),
                  b_ub=np.zeros(G.shape[0]), bounds=[(-1, 1)] * k + [(None, 1)],
                  method="highs")
    if res.status != 0 or res.x[-1] <= 1e-12:
        return None
    rf = system.to_rational(n, m, res.x[:k])
    ver = verify(rf, seg, channel=0)
    return rf if ver.verified else None


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--below", type=int, default=3, help="totals T-below..T-1 checked")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    rows = []
    for name, rel, dt, aw in CASES:
        path = DATA / rel
        if not path.exists():
            rows.append([name, "-", "-", "-", "-", "-", "missing", "-"])
            continue
        seg = read_data(path).segments(dt=dt, abs_width=aw)
        t0 = time.perf_counter()
        fitter = RationalFitter(jobs=1)
        r = fitter.fit(seg).result_
        secs = time.perf_counter() - t0
        if not r.success:
            rows.append([name, "none", "-", "-", "-", f"{secs:.2f}", "-", "-"])
            continue
        T = r.n + r.m
        t1 = time.perf_counter()
        found, alone = [], []
        for total in range(max(2, T - args.below), T):
            for m in range(1, total):
                if lp_pole_free(fitter.space_, seg, total - m, m) is not None:
                    found.append((total - m, m))
                if RationalFitter(jobs=1, n=total - m, m=m).fit(seg).result_.success:
                    alone.append((total - m, m))
        lp_secs = time.perf_counter() - t1
        smallest = min((sum(s) for s in found + alone), default=None)
        rows.append([name, f"{r.n}+{r.m}={T}",
                     ", ".join(f"{a}+{b}" for a, b in found[:4]) or "none",
                     ", ".join(f"{a}+{b}" for a, b in alone[:4]) or "none",
                     "-" if smallest is None else str(smallest), f"{secs:.2f}",
                     "yes" if smallest is None else "NO", f"{lp_secs:.1f}"])
    rep.table(f"reported total T vs every split of totals T-{args.below}..T-1 (LP; fitted alone)",
              ["data, width", "ratfit n+m", "LP fits below T", "alone fits below T", "smallest",
               "ratfit s", "minimal", "check s"], rows)
    rep.write()


if __name__ == "__main__":
    main()
