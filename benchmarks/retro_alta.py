"""ALTA's retro-3M-jaune.dat at ALTA's tutorial width (absolute +-0.5), in the file's own
parametrization: what fits and what is proved not to.

Prints, for a total T (default 23), every split (n, T - n): whether ratfit's exact
certificate proves that no rational with n numerator and T - n denominator
coefficients passes strictly inside every segment. A split whose certificate is
not conclusive is covered by a proved split that contains it ((n, m) fits inside
(n', m') when n <= n' and m <= m'), searched at totals T + 1, T + 2. When every
split of T is covered, no rational with at most T coefficients fits.

Then an independent check with another tool: the smallest max-error of a
polynomial (constant denominator) of each total degree, by HiGHS's LP. A
polynomial fits +-0.5 only if that error is below 0.5.

    python benchmarks/retro_alta.py [--total 23] [--width 0.5]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py
from numpy.polynomial import legendre
from scipy.optimize import linprog

from ratfit.brdf.fitter import brdf_segments, nonnegative_segments
from ratfit.brdf.io import brdf_dataset
from ratfit.core.bases import PolynomialSpace
from ratfit.core.columns import axis_degree_caps
from ratfit.fitting.certificate import certify

REPO = Path(__file__).resolve().parents[1]


def proved(space, seg, n: int, m: int) -> tuple[bool, str]:
    for form in ("arnoldi", "basis"):
        c = certify(space, seg, 0, n, m, formulation=form, exact=True)
        if c.exact:
            return True, form
    return False, ""


def polynomial_minimax(x: np.ndarray, y: np.ndarray, degree: int, caps) -> tuple[int, float]:
    lo, hi = x.min(0), x.max(0)
    t = 2 * (x - lo) / (hi - lo) - 1
    V = [legendre.legvander(t[:, k], degree) for k in range(x.shape[1])]
    idx = [a for a in itertools.product(range(degree + 1), repeat=x.shape[1])
           if sum(a) <= degree and all(ai <= ci for ai, ci in zip(a, caps, strict=True))]
    A = np.stack([np.prod([V[k][:, a[k]] for k in range(x.shape[1])], axis=0) for a in idx], 1)
    k = A.shape[1]
    ones = np.ones((len(y), 1))
    res = linprog(np.r_[np.zeros(k), 1.0], A_ub=np.block([[A, -ones], [-A, -ones]]),
                  b_ub=np.r_[y, -y], bounds=[(None, None)] * k + [(0, None)], method="highs")
    return k, float(res.fun)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--total", type=int, default=23)
    ap.add_argument("--width", type=float, default=0.5)
    add_markdown_option(ap)
    a = ap.parse_args()
    rep = report(a, __file__)
    ds = brdf_dataset(a.data / "alta" / "retro-3M-jaune.dat", None)
    seg = nonnegative_segments(brdf_segments(ds, abs_width=a.width))
    caps = axis_degree_caps(seg.x)
    space = PolynomialSpace("legendre", seg.bounds(), "total", caps)
    title = (f"{ds.meta['param_in']}, {seg.n_points} samples, segments y +- {a.width}, "
             f"degree caps per axis {caps} (distinct values - 1): every split of "
             f"{a.total} coefficients")
    rows = []
    covered_all = True
    for n in range(1, a.total):
        m = a.total - n
        t0 = time.perf_counter()
        ok, form = proved(space, seg, n, m)
        how = f"exact ({form} rows)" if ok else ""
        if not ok:  # a proved larger split contains this one
            for dn, dm in ((0, 1), (1, 0), (1, 1), (0, 2), (2, 0)):
                ok2, form2 = proved(space, seg, n + dn, m + dm)
                if ok2:
                    ok, how = True, f"inside ({n + dn}, {m + dm}), exact ({form2})"
                    break
        covered_all &= ok
        rows.append([str(n), str(m), how or "NOT PROVED", f"{time.perf_counter() - t0:.1f}"])
        print(f"{n} + {m}: {how or 'NOT PROVED'}", file=sys.stderr, flush=True)
    rep.table(title, ["n", "m", "proof", "s"], rows,
              note=f"No rational with at most {a.total} coefficients fits: "
                   f"{'PROVED (exact arithmetic, every split)' if covered_all else 'not proved'}.")
    poly = []
    for d in range(2, 7):
        k, err = polynomial_minimax(seg.x, seg.center[:, 0], d, caps)
        poly.append([str(d), str(k), f"{err:.4f}"])
    rep.table(f"polynomials (m = 1), smallest max |p - y| by HiGHS LP (fits only if < "
              f"{a.width})", ["degree", "terms", "max error"], poly)
    rep.write()


if __name__ == "__main__":
    main()
