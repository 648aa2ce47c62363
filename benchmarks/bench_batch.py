"""Throughput of `ratfit.batch` on a 24-fit batch: 1 and 2 Dask worker processes.

The batch: 6 synthetic CSV files x 2 channels x 2 tolerances (dt = 1e-3, 1e-4),
1000 points each, ALTA's exhaustive search (about 0.5 s a fit), no monomial
form, written to a temporary folder. Baseline, measured in the same
run: the same 24 fits one after another in this process (RationalFitter, no
Dask, one BLAS thread like the workers). For each worker count a LocalCluster
(processes, 1 thread each) is started, the batch runs into a fresh folder (so
nothing is resumed), and the cluster is stopped; "batch s" excludes the cluster
start, "with start s" includes it. The ratio column is the speed-up over the
1-worker batch.

Run:  python benchmarks/bench_batch.py [--repeat 3] [--workers 1 2]
(The speed-up is bounded by the cores: 2 on the reference machine.)
"""

from __future__ import annotations

import os

# One BLAS thread, as in Dask's worker processes (their nanny sets the same
# variables): the serial baseline then does the same arithmetic per fit.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import logging  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _bench import add_markdown_option, report  # noqa: E402  (benchmarks/_bench.py)

from ratfit.batch import runner as batch  # noqa: E402
from ratfit.core.segments import Segments  # noqa: E402
from ratfit.fitting.search import RationalFitter  # noqa: E402
from ratfit.io.data import read_data, write_csv  # noqa: E402

FUNCS = (
    lambda x: np.exp(np.sin(3 * x)) + 0.5,
    lambda x: np.arctan(8 * x) + 2.0,
    lambda x: 1.0 / (1.0 + 4 * (x - 0.3) ** 2),
    lambda x: np.cosh(x) + np.sin(5 * x) / 4,
    lambda x: np.log(x + 2.5) + 1.0,
    lambda x: np.sqrt(x + 1.5) * (1.2 + np.cos(2 * x)),
)


def write_inputs(folder: Path) -> dict:
    x = np.linspace(-1.0, 2.0, 1000)
    for i in range(6):
        f, g = FUNCS[i], FUNCS[(i + 1) % 6]
        y = np.stack([f(x), g(x) * (1 + 0.1 * i)], axis=1)
        write_csv(folder / f"material{i}.csv", x[:, None], y, output_names=("r", "g"))
    # ALTA's exhaustive search: about 0.5 s a fit, so that per-task overhead is small
    return {"defaults": {"max_total": 60, "strategy": "exhaustive", "monomial": False},
            "settings": [{"dt": 1e-3}, {"dt": 1e-4}], "inputs": ["material*.csv"]}


def serial(manifest: dict, folder: Path) -> float:
    tasks, _ = batch.plan(manifest, folder)
    t0 = time.perf_counter()
    for t in tasks:
        s = t.settings
        seg = read_data(t.path).segments(dt=s["dt"])
        j = t.channel_index
        one = Segments(seg.x, seg.lo[:, [j]], seg.hi[:, [j]], seg.y[:, [j]], (t.channel,))
        RationalFitter(**{k: s[k] for k in batch.FIT_PARAMS}).fit(one)
    return time.perf_counter() - t0


def on_cluster(manifest: dict, folder: Path, workers: int, out: Path) -> tuple[float, float, int]:
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, processes=True, threads_per_worker=1,
                           dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    t1 = time.perf_counter()
    try:
        summary = batch.run(manifest, client, outdir=out, base_dir=folder)
        t2 = time.perf_counter()
    finally:
        client.close()
        cluster.close()
    assert summary.fitted == len(summary.rows) == 24, summary.counts
    return t2 - t1, t2 - t0, summary.counts["ok"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3, help="rounds; best round per configuration")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        manifest = write_inputs(folder)
        # Rounds interleave the configurations, so that load from other processes
        # hits them alike; each keeps its best round.
        base = float("inf")
        results: dict[int, tuple[float, float, int]] = {}
        for k in range(args.repeat):
            base = min(base, serial(manifest, folder))
            for w in args.workers:
                res = on_cluster(manifest, folder, w, folder / f"out-{w}-{k}")
                results[w] = min(results.get(w, res), res)
        ref = results[args.workers[0]][0]
        rows = [["serial (no Dask)", "-", f"{base:.2f}", "-", f"{24 / base:.2f}",
                 f"{ref / base:.2f}"]]
        for w, (secs, with_start, ok) in results.items():
            rows.append([f"{w} worker(s)", str(ok), f"{secs:.2f}", f"{with_start:.2f}",
                         f"{24 / secs:.2f}", f"{ref / secs:.2f}"])
        load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
        rep.table(f"24-fit batch ({os.cpu_count()} cores, load average {load}), "
                  f"best of {args.repeat}",
                  ["run", "verified", "batch s", "with start s", "fits/s",
                   f"speed-up vs {args.workers[0]} worker"], rows)
    rep.write()


if __name__ == "__main__":
    main()
