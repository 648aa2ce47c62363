"""Core engine timings on the seed's example (1000 points, +-10 %).

Prints three tables:
1. the minimal-total search (all totals from 2 up): staircase walk with 1 and
   2 threads against ALTA's exhaustive strategy (every split of every total),
   measured in the same run: the ratio column is time / exhaustive time;
2. one 20 + 20 QP, active set on and off, per solver, ratio against quadprog
   on the full matrix;
3. the solver comparison behind the default: each solver on the three bases
   at 20 + 20, without the cross-check, verified or not.

Run:  python benchmarks/bench_core.py [--repeat 5]
"""

from __future__ import annotations

import argparse

from _bench import best_of, table  # benchmarks/_bench.py

from ratfit import RationalFitter
from ratfit.core.bases import PolynomialSpace
from ratfit.core.qp import ConstraintSystem, solve_fixed
from ratfit.core.solvers import available_solvers
from ratfit.demos.addendum import PAPER_TABLE, addendum_segments


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    seg = addendum_segments()

    # 1. search
    rows = []
    base, res = best_of(
        lambda: RationalFitter(strategy="exhaustive", jobs=1).fit(seg).result_, 1
    )
    results = {"exhaustive (ALTA), 1 thread": (base, res)}
    for jobs in (1, 2):
        results[f"staircase, {jobs} thread(s)"] = best_of(
            lambda j=jobs: RationalFitter(jobs=j).fit(seg).result_, args.repeat
        )
    for name, (secs, r) in results.items():
        rows.append([name, f"{r.n}+{r.m}={r.total}", str(r.success), str(len(r.history)),
                     f"{secs:.3f}", f"{secs / base:.3f}"])
    table("minimal-total search, Legendre, totals from 2 up (target < 0.5 s on 2 cores)",
          ["strategy", "n+m", "verified", "splits tested", "seconds", "ratio"], rows)

    # 2. single QP
    space = PolynomialSpace("legendre", seg.bounds())
    system = ConstraintSystem(space, seg)
    system.prepare(20, 20)
    rows = []
    ref, _ = best_of(lambda: solve_fixed(system, 20, 20, active_set=False), args.repeat)
    for solver in available_solvers():
        for active in (True, False):
            secs, att = best_of(
                lambda s=solver, a=active: solve_fixed(system, 20, 20, solver=s, active_set=a),
                args.repeat,
            )
            rows.append([solver, "on" if active else "off", att.status, att.decided_by,
                         str(att.qp_solves), f"{secs * 1e3:.1f}", f"{secs / ref:.2f}"])
    table("one 20+20 QP, Legendre, the seed's matrix (target < 50 ms); "
          "ratio vs quadprog on all rows",
          ["solver", "active set", "status", "decided by", "QP solves", "ms", "ratio"], rows)

    # 3. solver comparison without cross-check
    # in the seed's matrix and in the weighted data-orthonormal (Arnoldi) form
    rows = []
    for form in ("basis", "arnoldi"):
        for solver in available_solvers():
            for basis in PAPER_TABLE:
                secs, r = best_of(
                    lambda s=solver, b=basis, f=form: RationalFitter(
                        basis=b, n=20, m=20, solver=s, cross_check="none", formulation=f
                    ).fit(seg).result_,
                    1,
                )
                v = r.verification
                rows.append([form, solver, basis, str(r.success),
                             "-" if v is None else f"{v.max_violation:.3g}",
                             "-" if v is None else str(v.poles_in_domain),
                             f"{secs * 1e3:.0f}"])
    table("solvers alone (no cross-check), 20+20, +-10 %: does the answer verify?",
          ["formulation", "solver", "basis", "verified", "max violation", "poles", "ms"], rows)
    print(f"\ntimes: best of {args.repeat} runs (the exhaustive baseline and table 3: 1 run)")


if __name__ == "__main__":
    main()
