"""ratfit vs scipy.interpolate.AAA on the seed's function, 500 points of [-3, 12].

For each max-relative-error target (1e-1, 1e-2, 1e-3), measured in one run:

* AAA: the smallest ``max_terms`` whose max relative error on the data is below
  the target. ``max_terms = k`` gives type (k-1, k-1): 2k p/q coefficients,
  3k real parameters (support points, values, weights). Real poles inside
  [-3, 12] are counted (AAA does not exclude them).
* ratfit: a verified fit inside segments [(1-e) y, (1+e) y], found by the
  search, in the well-conditioned (Arnoldi) formulation and in the seed's
  formulation; and with constraint generation on a 10x denser grid.
* "dense err": max |r - f| / |f| on 5 000 points, between the samples.

Ratio column: ratfit coefficients / AAA coefficients (target: <= 1).

    python benchmarks/bench_aaa.py [--quick]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py
from scipy.interpolate import AAA

from ratfit.core.segments import Segments
from ratfit.demos.addendum import addendum_function
from ratfit.fitting.dense import fit_dense
from ratfit.fitting.search import RationalFitter

X = np.linspace(-3.0, 12.0, 500)
Y = addendum_function(X)
XD = np.linspace(-3.0, 12.0, 5000)
YD = addendum_function(XD)


def aaa_for(target: float) -> dict:
    t0 = time.perf_counter()
    with_poles = 0
    for k in range(2, 80):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = AAA(X, Y, max_terms=k, rtol=0.0)
        real_in = _real_poles(r)
        with_poles += real_in > 0
        err = float(np.max(np.abs(r(X) - Y) / np.abs(Y)))
        if err < target:
            break
    secs = time.perf_counter() - t0
    print(f"AAA, target {target:.0e}: {with_poles} of the {k - 1} degrees tried "
          f"(k = 2..{k}) leave real poles in [-3, 12]")
    dense = float(np.max(np.abs(r(XD) - YD) / np.abs(YD)))
    return {"coef": 2 * k, "reals": 3 * k, "type": f"({k - 1},{k - 1})", "err": err,
            "dense": dense, "poles": real_in, "s": secs,
            "path": f"{with_poles} of the {k - 1} degrees tried (k = 2..{k})"}


def _real_poles(r) -> int:
    z = r.poles()
    return int(np.sum((np.abs(z.imag) < 1e-9 * (1 + np.abs(z.real)))
                      & (z.real >= -3) & (z.real <= 12)))


def ratfit_for(target: float, formulation: str) -> dict:
    seg = Segments.from_relative(X, Y, target)
    t0 = time.perf_counter()
    r = RationalFitter(formulation=formulation, max_total=150).fit(seg).result_
    secs = time.perf_counter() - t0
    if not r.success:
        return {"coef": None, "type": "-", "err": None, "dense": None, "poles": None, "s": secs}
    with np.errstate(all="ignore"):
        dense = float(np.max(np.abs(r.rational(XD) - YD) / np.abs(YD)))
    return {"coef": r.total, "type": f"({r.n},{r.m})", "err": r.verification.max_rel_error,
            "dense": dense, "poles": r.verification.poles_in_domain, "s": secs}


def dense_for(target: float) -> dict:
    t0 = time.perf_counter()
    out = fit_dense(addendum_function, X, dt=target, factor=10)
    r = out.result
    with np.errstate(all="ignore"):
        dense = float(np.max(np.abs(r.rational(XD) - YD) / np.abs(YD)))
    return {"coef": r.total if out.success else None, "type": f"({r.n},{r.m})",
            "err": r.verification.max_rel_error if r.verification else None,
            "dense": dense, "poles": r.verification.poles_in_domain if r.verification else None,
            "s": time.perf_counter() - t0}


def figure(rows) -> object:
    """p/q coefficients against the target, per method (log x)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    for method in dict.fromkeys(name for _, name, _, _ in rows):
        pts = [(t, d["coef"]) for t, name, d, _ in rows if name == method and d["coef"]]
        if pts:
            ax.plot(*zip(*pts, strict=True), marker="o", label=method)
    ax.set_xscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("max relative error target")
    ax.set_ylabel("p/q coefficients")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip the seed's formulation")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    rows = []
    for target in (1e-1, 1e-2, 1e-3):
        base = aaa_for(target)
        rows.append((target, "AAA (baseline)", base, base["coef"]))
        rows.append((target, "ratfit arnoldi", ratfit_for(target, "arnoldi"), base["coef"]))
        rows.append((target, "ratfit + dense grid", dense_for(target), base["coef"]))
        if not args.quick:
            rows.append((target, "ratfit seed form", ratfit_for(target, "basis"), base["coef"]))

    def cell(v, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    cells = [[f"{target:.0e}", name, d["type"], cell(d["coef"], "d"),
              "-" if d["coef"] is None else f"{d['coef'] / ref:.2f}", cell(d["err"], ".2e"),
              cell(d["dense"], ".2e"), cell(d["poles"], "d"), f"{d['s']:.2f}"]
             for target, name, d, ref in rows]
    rep.table("ratfit vs AAA on the seed's function, 500 points of [-3, 12] (ratio: "
              "coefficients / AAA's, same run)",
              ["target", "method", "type", "p/q coef", "ratio", "data err", "dense err",
               "poles", "s"], cells,
              note="AAA: max_terms k gives type (k-1, k-1) = 2k p/q coefficients (3k reals); "
                   "ratfit: n + m, every segment verified, no pole in [-3, 12]. \"dense "
                   "err\": max relative error on 5 000 points between the samples; poles: "
                   "real poles inside [-3, 12].")
    rep.note("On its way to each target AAA passes through fits with real poles in "
             "[-3, 12]: " + "; ".join(f"{t:.0e}: {d['path']}" for t, name, d, _ in rows
                                       if name.startswith("AAA")) + ".")
    rep.figure(figure(rows), "bench_aaa", "p/q coefficients needed for each max relative "
               "error target, per method")
    rep.write()


if __name__ == "__main__":
    main()
