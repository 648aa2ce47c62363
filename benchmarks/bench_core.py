"""Core engine timings on the seed's example (1000 points, +-10 %).

Prints four tables:
0. the seed search against its references, measured in one run: a plain
   first-feasible loop over every split of every total (quadprog on the full
   seed matrix, delta from np.linalg.svd, no active set), one such QP at the
   answer's size, ratfit in-process and ratfit through the CLI (the search time
   the CLI reports and the whole process, with a bytecode cache as installed
   packages have), and the interpreter importing numpy alone (no fit: the floor
   under any whole process); targets: ratfit >= 6x faster than the loop, within
   5x of the one QP;
1. the minimal-total search (all totals from 2 up): staircase walk with 1 and
   2 threads against ALTA's exhaustive strategy (every split of every total),
   measured in the same run: the ratio column is time / exhaustive time;
2. one 20 + 20 QP, active set on and off, per solver, ratio against quadprog
   on the full matrix;
3. the solver comparison behind the default: each solver on the three bases
   at 20 + 20, without the cross-check, verified or not.

Run:  python benchmarks/bench_core.py [--repeat 5] [--only-seed]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _bench import Report, add_markdown_option, best_of, report  # benchmarks/_bench.py

from ratfit import RationalFitter
from ratfit.core.bases import PolynomialSpace
from ratfit.core.qp import ConstraintSystem, solve_fixed
from ratfit.core.solvers import available_solvers
from ratfit.demos.addendum import PAPER_TABLE, addendum_segments


def _full_qp(system: ConstraintSystem, n: int, m: int):
    """quadprog on every row of the seed's A(n, m), delta = 1 / cond(A) from an SVD of
    A itself; the solution or None (infeasible)."""
    import quadprog

    A = system.rows(n, m)
    s = np.linalg.svd(A, compute_uv=False)
    b = (s[-1] / s[0]) * np.linalg.norm(A, axis=1)
    try:
        return quadprog.solve_qp(np.eye(n + m), np.zeros(n + m), A.T, b, 0)[0]
    except ValueError:
        return None


def _brute_force(seg) -> tuple[int, int]:
    """Every split of totals 2, 3, ... up to the first feasible one."""
    space = PolynomialSpace("legendre", seg.bounds())
    system = ConstraintSystem(space, seg)
    system.prepare(40, 40)
    for total in range(2, 81):
        for m in range(1, total):
            if _full_qp(system, total - m, m) is not None:
                return total - m, m
    raise RuntimeError("no split up to 80")


def seed_table(rep: Report, seg, repeat: int) -> None:
    from ratfit.core.threads import one_blas_thread

    with one_blas_thread():  # as ratfit's search: BLAS threads only spin on these sizes
        brute, (bn, bm) = best_of(lambda: _brute_force(seg), max(1, repeat // 2))
    ours, r = best_of(lambda: RationalFitter(jobs=1).fit(seg).result_, repeat)
    space = PolynomialSpace("legendre", seg.bounds())
    system = ConstraintSystem(space, seg)
    system.prepare(r.n, r.m)
    with one_blas_thread():
        one, _ = best_of(lambda: _full_qp(system, r.n, r.m), repeat)
    # the CLI on the same segments (CSV, --dt 0.1), its reported search time and the
    # whole process; the environment's PYTHONPATH decides which ratfit runs. As an
    # installed package runs: with its bytecode cache (written by one untimed run into
    # a temporary folder, PYTHONPYCACHEPREFIX), also where the environment sets
    # PYTHONDONTWRITEBYTECODE (then every process compiled ratfit's modules again,
    # those the search imports on first use inside its reported time)
    x = seg.x[:, 0]
    y = 0.5 * (seg.lo[:, 0] + seg.hi[:, 0])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "seed.csv"
        path.write_text("x,y\n" + "".join(f"{float(a)!r},{float(b)!r}\n"
                                           for a, b in zip(x, y, strict=True)))
        cmd = [sys.executable, "-m", "ratfit", "fit", str(path), "--dt", "0.1", "--jobs", "1",
               "--json"]
        env = os.environ.copy()
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pycache")
        subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
        runs = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            out = subprocess.run(cmd, capture_output=True, text=True, env=env)
            wall = time.perf_counter() - t0
            doc = json.loads(out.stdout)
            runs.append((doc["seconds"], wall, doc["n"], doc["m"]))
        # the floor under any Python CLI's whole process: the interpreter importing numpy
        floor_runs = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", "import numpy"], check=True, env=env)
            floor_runs.append(time.perf_counter() - t0)
    numpy_floor = min(floor_runs)
    cli_search = min(v[0] for v in runs)
    cli_wall = min(v[1] for v in runs)
    cn, cm = runs[0][2], runs[0][3]
    rows = [
        ["first-feasible loop, quadprog, full matrix", f"{bn}+{bm}", f"{brute:.3f}", "1.00",
         f"{brute / one:.1f}"],
        [f"one QP at the answer's size ({r.n}+{r.m}), full matrix", "-", f"{one:.4f}",
         f"{brute / one:.1f}", "1.0"],
        ["ratfit, in-process (jobs 1)", f"{r.n}+{r.m}", f"{ours:.3f}", f"{brute / ours:.2f}",
         f"{ours / one:.1f}"],
        ["ratfit CLI, reported search time", f"{cn}+{cm}", f"{cli_search:.3f}",
         f"{brute / cli_search:.2f}", f"{cli_search / one:.1f}"],
        ["ratfit CLI, whole process", f"{cn}+{cm}", f"{cli_wall:.3f}", f"{brute / cli_wall:.2f}",
         f"{cli_wall / one:.1f}"],
        ["python -c 'import numpy' (no fit: the floor of any whole process)", "-",
         f"{numpy_floor:.3f}", f"{brute / numpy_floor:.2f}", f"{numpy_floor / one:.1f}"],
    ]
    rep.table("seed search (1000 points, +-10 %, Legendre, totals from 2), one run; targets: "
              "'x faster' >= 6, 'x one QP' <= 5",
              ["what", "n+m", "seconds", "x faster than loop", "x one QP"], rows)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--only-seed", action="store_true", help="table 0 only")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__, name="bench_core_seed" if args.only_seed else None)
    seg = addendum_segments()
    seed_table(rep, seg, args.repeat)
    if args.only_seed:
        rep.write()
        return

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
    rep.table("minimal-total search, Legendre, totals from 2 up (target < 0.5 s on 2 cores)",
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
    rep.table("one 20+20 QP, Legendre, the seed's matrix (target < 50 ms); "
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
    rep.table("solvers alone (no cross-check), 20+20, +-10 %: does the answer verify?",
              ["formulation", "solver", "basis", "verified", "max violation", "poles", "ms"], rows)
    rep.note(f"Times: best of {args.repeat} runs (the exhaustive baseline and the last "
             "table: 1 run).")
    rep.write()


if __name__ == "__main__":
    main()
