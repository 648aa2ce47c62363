"""MERL-size benchmark on a material that needs tens of coefficients.

A synthetic isotropic material (Lambert + two GGX lobes, each with Schlick
Fresnel and a Smith-style shadowing term; colour differs per lobe) is tabulated
at MERL's 90x90x180 resolution, written as a MERL .binary, read back, and fitted
on R, G, B in COS_TH_TD_PD with relative segments (default 5 %, the order of a
gonioreflectometer's noise) and a floor of 0.2 % of each channel's maximum.
Subsets grow from 1e4 samples to every valid cell (~1.1e6). Each size runs in
a fresh process so its peak memory (ru_maxrss) is its own; ratios are against
the smallest size in the same run.

    nice python benchmarks/bench_merl.py [--sizes 10000 30000 100000 300000 0] [--dt 0.05]
        [--timeout 900]

Size 0 means every valid cell. A size that runs past --timeout is reported as such.
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
from _bench import add_markdown_option, report  # benchmarks/_bench.py

KD = np.array([0.10, 0.06, 0.03])
LOBES = (  # (alpha, specular colour F0)
    (0.18, np.array([0.90, 0.75, 0.45])),
    (0.50, np.array([0.10, 0.12, 0.16])),
)


def material(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Lambert + two GGX lobes with Schlick Fresnel and separable Smith G (N, 3)."""
    h = L + V
    h = h / np.linalg.norm(h, axis=1)[:, None]
    nh = h[:, 2]
    nl = np.clip(L[:, 2], 1e-4, 1.0)
    nv = np.clip(V[:, 2], 1e-4, 1.0)
    vh = np.clip(np.sum(V * h, axis=1), 0.0, 1.0)
    out = np.repeat(KD[None, :] / np.pi, len(L), axis=0)
    for alpha, f0 in LOBES:
        a2 = alpha * alpha
        d = a2 / (np.pi * ((a2 - 1.0) * nh * nh + 1.0) ** 2)

        def g1(c: np.ndarray, a2: float = a2) -> np.ndarray:
            return 2.0 * c / (c + np.sqrt(a2 + (1.0 - a2) * c * c))

        fres = f0[None, :] + (1.0 - f0[None, :]) * ((1.0 - vh) ** 5)[:, None]
        out += fres * (d * g1(nl) * g1(nv) / (4.0 * nl * nv))[:, None]
    return out


def one(path: str, size: int, dt: float, floor_rel: float, jobs: int, param: str,
        max_total: int) -> dict:
    """Read the MERL file and fit it; runs in a child process."""
    import resource

    from ratfit.brdf.fitter import fit_brdf
    from ratfit.brdf.io import brdf_dataset

    t0 = time.perf_counter()
    ds = brdf_dataset(path, param, max_points=size or None)
    t_read = time.perf_counter() - t0
    fitter, seg, _ = fit_brdf(ds, dt=dt, floor_rel=floor_rel, jobs=jobs, max_total=max_total)
    t_fit = time.perf_counter() - t0 - t_read
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {
        "samples": seg.n_points, "read_s": t_read, "fit_s": t_fit, "peak_mb": rss,
        "verified": fitter.success_,
        # "*": the channel's search stopped at the time limit (total not shown minimal)
        "nm": [f"({r.n}, {r.m}){'*' if r.time_limited else ''}" for r in fitter.results_],
        "coefs": sum(r.n + r.m for r in fitter.results_),
        "qps": sum(r.qp_solves for r in fitter.results_),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 30_000, 100_000, 300_000, 0])
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--floor-rel", type=float, default=0.002)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--max-total", type=int, default=80)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--param", default="COS_TH_TD_PD")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    add_markdown_option(ap)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(one(a.child[0], int(a.child[1]), a.dt, a.floor_rel, a.jobs, a.param,
                             a.max_total)))
        return
    from ratfit.brdf.io import merl_from_function, read_merl, write_merl

    rep = report(a, __file__)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "synthetic.binary")
        t0 = time.perf_counter()
        write_merl(path, merl_from_function(material))
        t_write = time.perf_counter() - t0
        m = read_merl(path)
        print(f"wrote the MERL file in {t_write:.2f} s; {int(m.valid.sum())} valid cells of "
              f"{m.valid.size}", flush=True)
        for size in a.sizes:
            cmd = [sys.executable, __file__, "--child", path, str(size), "--dt", str(a.dt),
                   "--floor-rel", str(a.floor_rel), "--jobs", str(a.jobs), "--param", a.param,
                   "--max-total", str(a.max_total)]
            t0 = time.perf_counter()
            try:
                out = subprocess.run(cmd, capture_output=True, text=True, check=True,
                                     timeout=a.timeout)
                rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            except subprocess.TimeoutExpired:
                rows.append({"samples": size or int(m.valid.sum()), "timeout": a.timeout})
            print(f"size {size or 'all'}: {time.perf_counter() - t0:.1f} s", file=sys.stderr,
                  flush=True)
    base = next((r for r in rows if "fit_s" in r), None)
    cells = []
    for r in rows:
        if "timeout" in r:
            cells.append([str(r["samples"]), "-", f"> {r['timeout']:.0f}", "-", "-", "-",
                          "did not finish", "-", "-", "-"])
            continue
        assert base is not None
        cells.append([str(r["samples"]), f"{r['read_s']:.2f}", f"{r['fit_s']:.2f}",
                      f"{r['fit_s'] / base['fit_s']:.1f}", f"{r['samples'] / base['samples']:.1f}",
                      f"{r['peak_mb']:.0f}", str(r["verified"]), str(r["coefs"]), str(r["qps"]),
                      " ".join(r["nm"])])
    starred = any("*" in nm for r in rows for nm in r.get("nm", []))
    rep.table(f"param {a.param}, dt {a.dt}, floor {a.floor_rel} x max, jobs {a.jobs} "
              "(x fit, x samples: against the first row, same run)",
              ["samples", "read s", "fit s", "x fit", "x samples", "peak MB", "verified",
               "coefs", "QPs", "(n, m) per channel"], cells,
              note="(*: that channel's search stopped at the time limit; its total may not "
                   "be minimal)" if starred else "")
    rep.write()

if __name__ == "__main__":
    main()
