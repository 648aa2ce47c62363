"""Default fits of ALTA's retro-reflection files, as a user runs them
(``ratfit brdf fit FILE -o F.json``, no option), repeated: how often each one
verifies and in how many seconds, with the validity repair at its default number of
rounds and at a baseline number (3, what it was before), all measured in this run.

The dense files' searches meet many candidates that meet every segment but dip
below 0 between the samples; whether the repair turns them into verified fits
decides whether the default fit verifies inside the time limit. Repeats matter:
with two threads the order in which validity points are found varies from run to
run, and so does the search's path.

Each fit runs in a fresh process (its own peak memory). Ratios are the median
seconds of a row against the baseline row's of the same file.

    nice python benchmarks/bench_retro.py [--runs 3] [--rounds 3,10]
        [--files retro-3M-jaune-dense.dat,...] [--timeout 900]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _bench import add_markdown_option, report

DATA = Path(os.environ.get("RATFIT_SHARED_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data"))
FILES = ("retro-3M-jaune-dense.dat",)


def child(rounds: int, args: list[str]) -> None:
    """The CLI with ``REPAIR_ROUNDS`` set, then this process's peak memory on stderr;
    runs in a child process (``--child ROUNDS CLI-ARGS...``)."""
    import resource

    import ratfit.brdf.fitter as fitter
    from ratfit.cli import main

    fitter.REPAIR_ROUNDS = rounds
    code: int | str | None = 0
    try:
        main(args=args, prog_name="ratfit", standalone_mode=True)
    except SystemExit as e:
        code = e.code
    print("PEAK", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, file=sys.stderr)
    sys.exit(code)


def run_one(path: Path, rounds: int, timeout: float) -> dict:
    """One default fit in a child process: exit code, seconds, peak MB, fit summary."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "fit.json"
        cmd = [sys.executable, __file__, "--child", str(rounds),
               "brdf", "fit", str(path), "-o", str(out), "--json"]
        t0 = time.perf_counter()
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"rc": None, "secs": time.perf_counter() - t0}
        secs = time.perf_counter() - t0
        peak = next((float(line.split()[1]) for line in res.stderr.splitlines()
                     if line.startswith("PEAK ")), float("nan"))
        doc = {}
        if res.stdout.strip():
            try:
                doc = json.loads(res.stdout)
            except json.JSONDecodeError:
                doc = {}
        chans = doc.get("channels") or ([doc] if "n" in doc else [])
        dt = json.loads(out.read_text())["brdf"]["segments"]["dt"] if out.exists() else None
        metrics = next(iter((doc.get("metrics") or {}).values()), {})
        tried = "; ".join(
            f"{c['parametrization']} {c['dt']:g}: "
            + (str(c["coefficients"]) if c.get("verified") else
               "no candidate" if c.get("no_candidate") else
               str(c.get("skipped") or "none verified"))
            for c in doc.get("parametrization_candidates") or [])
        return {"tried": tried, "dt": dt, "rmse": metrics.get("rmse"),
                "log_rmse": metrics.get("log_rmse"),
                "rc": res.returncode, "secs": secs, "peak_mb": peak,
                "written": out.exists(), "param": doc.get("parametrization", "-"),
                "sizes": " ".join(f"{c.get('n')}+{c.get('m')}" for c in chans),
                "verified": bool(chans) and all(c.get("verified") for c in chans),
                "time_limited": any(c.get("time_limited") for c in chans)}


def main() -> None:
    if sys.argv[1:2] == ["--child"]:
        child(int(sys.argv[2]), sys.argv[3:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--rounds", default="3,10",
                    help="repair rounds to compare, the first one the baseline")
    ap.add_argument("--files", default=",".join(FILES))
    ap.add_argument("--timeout", type=float, default=900.0)
    add_markdown_option(ap)
    a = ap.parse_args()
    rep = report(a, __file__)
    rounds = [int(r) for r in a.rounds.split(",")]
    rows, summary = [], []
    for name in a.files.split(","):
        path = DATA / "alta" / name
        base = None
        for r in rounds:
            got = []
            for i in range(a.runs):
                res = run_one(path, r, a.timeout)
                got.append(res)
                ok = res["rc"] == 0 and res.get("verified") and res.get("written")
                print(f"{name} rounds {r} run {i + 1}: rc {res['rc']}, {res['secs']:.1f} s"
                      f"{', verified ' + res['sizes'] if ok else ''}; tried {res.get('tried')}",
                      file=sys.stderr,
                      flush=True)
                rows.append([name, str(r), str(i + 1),
                             "timeout" if res["rc"] is None else str(res["rc"]),
                             "yes" + ("*" if res.get("time_limited") else "") if ok else "NO",
                             res.get("param", "-"),
                             f"{res['dt']:g}" if ok and res.get("dt") else "-",
                             res.get("sizes", "-") if ok else "-",
                             f"{res['rmse']:.3g} / {res['log_rmse']:.3g}" if ok and res.get(
                                 "rmse") is not None else "-",
                             f"{res['secs']:.1f}", f"{res.get('peak_mb', float('nan')):.0f}"])
            med = statistics.median(g["secs"] for g in got)
            base = med if base is None else base
            n_ok = sum(1 for g in got if g["rc"] == 0 and g.get("verified"))
            summary.append([name, str(r), f"{n_ok}/{len(got)}", f"{med:.1f}",
                            f"{med / base:.2f}"])
    rep.table("each default fit (yes*: the time limit ended the search after the fit was "
              "found, the total may not be minimal)",
              ["file", "repair rounds", "run", "exit", "verified", "parametrization", "dt",
               "n+m", "RMSE / log RMSE", "s", "peak MB"], rows)
    rep.table(f"per file and setting, {os.cpu_count()} cores (x base: median seconds / the "
              "first setting's, same run)",
              ["file", "repair rounds", "verified", "median s", "x base"], summary)
    rep.write()


if __name__ == "__main__":
    main()
