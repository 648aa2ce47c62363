"""MERL-size benchmark: a synthetic 90x90x180 material written as a MERL .binary from
an analytic BRDF (Lambert + GGX lobe), read back, and fitted on R, G, B in 3-D
(COS_TH_TD_PD, relative segments). Each size runs in a fresh process so its peak
memory (ru_maxrss) is its own; ratios are against the smallest size, same run.

    python benchmarks/bench_merl.py [--sizes 10000 100000 0] [--dt 0.05] [--jobs 2]

Size 0 means every valid cell of the table (about 1.1e6 of the 1.46e6 cells;
the rest put L or V below the horizon and are stored as missing, as in MERL).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

KD = np.array([0.05, 0.08, 0.12])
KS = np.array([0.6, 0.5, 0.4])


def ggx(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    h = L + V
    c = h[:, 2] / np.linalg.norm(h, axis=1)
    a2 = 0.5**2
    d = a2 / (np.pi * ((a2 - 1.0) * c * c + 1.0) ** 2)
    return KD[None, :] + KS[None, :] * d[:, None]


def one(path: str, size: int, dt: float, jobs: int, param: str) -> dict:
    """Read the MERL file and fit it; runs in a child process."""
    import resource

    from ratfit.brdf.fitter import fit_brdf
    from ratfit.brdf.io import brdf_dataset

    t0 = time.perf_counter()
    ds = brdf_dataset(path, param, max_points=size or None)
    t_read = time.perf_counter() - t0
    fitter, seg, _ = fit_brdf(ds, dt=dt, jobs=jobs, max_total=60)
    t_fit = time.perf_counter() - t0 - t_read
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {
        "samples": seg.n_points, "read_s": t_read, "fit_s": t_fit, "peak_mb": rss,
        "verified": fitter.success_,
        "nm": [(r.n, r.m) for r in fitter.results_],
        "max_rel": [r.verification.max_rel_error if r.verification else None
                    for r in fitter.results_],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 0])
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--param", default="COS_TH_TD_PD")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(one(a.child[0], int(a.child[1]), a.dt, a.jobs, a.param)))
        return
    from ratfit.brdf.io import merl_from_function, read_merl, write_merl

    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "synthetic.binary")
        t0 = time.perf_counter()
        write_merl(path, merl_from_function(ggx))
        t_write = time.perf_counter() - t0
        t0 = time.perf_counter()
        m = read_merl(path)
        t_read = time.perf_counter() - t0
        print(f"wrote MERL file in {t_write:.2f} s, read back in {t_read:.2f} s; "
              f"{int(m.valid.sum())} valid cells of {m.valid.size}")
        rows = []
        for size in a.sizes:
            out = subprocess.run(
                [sys.executable, __file__, "--child", path, str(size), "--dt", str(a.dt),
                 "--jobs", str(a.jobs), "--param", a.param],
                capture_output=True, text=True, check=True,
            )
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    base = rows[0]
    print(f"\nparam {a.param}, dt {a.dt}, jobs {a.jobs}")
    print(f"{'samples':>9} {'read s':>7} {'fit s':>8} {'x fit':>7} {'x samples':>9} "
          f"{'peak MB':>8} {'verified':>8}  (n, m) per channel, max rel. error")
    for r in rows:
        print(f"{r['samples']:>9} {r['read_s']:>7.2f} {r['fit_s']:>8.2f} "
              f"{r['fit_s'] / base['fit_s']:>7.1f} {r['samples'] / base['samples']:>9.1f} "
              f"{r['peak_mb']:>8.0f} {str(r['verified']):>8}  {r['nm']} "
              f"{[round(v, 4) if v is not None else None for v in r['max_rel']]}")


if __name__ == "__main__":
    main()
