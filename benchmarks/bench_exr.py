"""The EXR slice of issue 12 with the default widths (what `ratfit brdf fit EXR -o F`
does with no option: dt 0.22, floor 0.2 % of each channel's largest value): per
channel seconds, QPs, (n, m) and whether the fit is verified on every one of the
262 144 samples.

Rows, all measured in this run, each in a fresh process (its own peak memory):

- ``all``: the fit on every sample (what ``ratfit brdf fit EXR -o F`` does);
- ``subset K``: the same fit on a random subset of K samples (``--max-points K``,
  the old way to make it fast), then checked on every sample;
- ``cold`` (with --cold, slow): every sample with the speedups of issue 12 switched
  off (no warm starts, no subset bases), the baseline of the speedup itself.

Ratios are against the ``all`` row's seconds.

    nice python benchmarks/bench_exr.py [--dt D] [--subset 20000] [--cold] [--timeout 1200]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _bench import add_markdown_option, report

DATA = Path(os.environ.get("RATFIT_SHARED_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data"))


def one(path: str, dt: float | None, subset: int, cold: bool) -> dict:
    """Fit and check on every sample; runs in a child process."""
    import resource

    import numpy as np

    from ratfit.brdf.fitter import brdf_segments, fit_brdf, nonnegative_segments, resolve_widths
    from ratfit.brdf.io import brdf_dataset

    if cold:
        import ratfit.core.qp as qp

        qp.BASIS_POINTS = 10**12
    full = brdf_dataset(path, None)
    ds = brdf_dataset(path, None, max_points=subset or None)
    # the widths of the whole file, for every row (a subset would pick its own)
    dt, abs_width, floor_rel, _ = resolve_widths(full, dt, None, None)
    t0 = time.perf_counter()
    fitter, seg, _ = fit_brdf(ds, dt=dt, abs_width=abs_width, floor_rel=floor_rel,
                              warm_start=not cold)
    secs = time.perf_counter() - t0
    every = nonnegative_segments(brdf_segments(full, dt=dt, abs_width=abs_width,
                                               floor_rel=floor_rel))
    rows = []
    for j, r in enumerate(fitter.results_):
        miss = None
        if r.rational is not None:
            with np.errstate(all="ignore"):
                v = r.rational(every.x)
            ok = (every.lo[:, j] <= v) & (v <= every.hi[:, j])
            miss = int(np.sum(~ok))
        rows.append({"channel": r.channel, "n": r.n, "m": r.m, "s": r.seconds,
                     "qps": r.qp_solves, "success": r.success, "missed_all": miss,
                     "message": r.message})
    return {"samples": seg.n_points, "of": every.n_points, "secs": secs, "channels": rows,
            "widths": f"dt {dt:g}, floor {floor_rel}",
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA / "alta" / "data-example-01.exr"))
    ap.add_argument("--dt", type=float, default=None,
                    help="relative width (default: the CLI's default widths)")
    ap.add_argument("--subset", type=int, default=20_000)
    ap.add_argument("--cold", action="store_true", help="also the fit with speedups off")
    ap.add_argument("--timeout", type=float, default=1200.0)
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    add_markdown_option(ap)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(one(a.data, a.dt, int(a.child[0]), a.child[1] == "cold")))
        return
    rep = report(a, __file__)
    runs = [("all", 0, "warm"), (f"subset {a.subset}", a.subset, "warm")]
    if a.cold:
        runs.append(("cold", 0, "cold"))
    out = {}
    for name, size, mode in runs:
        cmd = [sys.executable, __file__, "--data", a.data,
               *(["--dt", str(a.dt)] if a.dt is not None else []), "--child", str(size), mode]
        t0 = time.perf_counter()
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, check=True,
                                 timeout=a.timeout)
            out[name] = json.loads(res.stdout.strip().splitlines()[-1])
        except subprocess.TimeoutExpired:
            out[name] = None
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    base = out["all"]
    rows = []
    for name, _, _ in runs:
        r = out[name]
        if r is None:
            rows.append([name, "-", "-", f"> {a.timeout:.0f}", "-", "-", "-", "-", "-", "-"])
            continue
        for c in r["channels"]:
            bs = next((b["s"] for b in base["channels"] if b["channel"] == c["channel"]),
                      None) if base else None
            on_all = ("yes" if c["success"] and c["missed_all"] == 0 else
                      f"NO ({c['missed_all']} missed)" if c["missed_all"] else "NO")
            minimal = "no (time limit)" if "may not be minimal" in c["message"] else (
                "yes" if c["success"] else "-")
            rows.append([name, c["channel"], f"{r['samples']}", f"{c['s']:.1f}",
                         f"{c['s'] / bs:.2f}" if bs else "-", str(c["qps"]),
                         f"({c['n']}, {c['m']})", minimal, on_all, f"{r['peak_mb']:.0f}"])
        rows.append([name, "all", f"{r['samples']}", f"{r['secs']:.1f}",
                     f"{r['secs'] / base['secs']:.2f}" if base else "-",
                     str(sum(c["qps"] for c in r["channels"])), "", "", "", ""])
    widths = base["widths"] if base else f"dt {a.dt}"
    rep.table(f"{Path(a.data).name} at {widths}, {os.cpu_count()} cores "
              "(x all: seconds / the 'all' row's, same run)",
              ["fit", "channel", "samples", "s", "x all", "QPs", "(n, m)", "minimal",
               "verified on all samples", "peak MB"], rows)
    rep.write()


if __name__ == "__main__":
    main()
