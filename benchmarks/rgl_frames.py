"""Which frame a rational fit of an RGL table needs: how many cells the best rational of a
given size in each frame leaves outside their segments.

For random cells of one network's MERL table (cells of 0 left out), log values with
segments log((1 -+ w) y + e), e = 1e-3 1/sr, and p and q of one size in Legendre
polynomials of total degree (ratfit's basis) on the frame's box, an LP (HiGHS) minimises
the sum of the amounts by which the cells miss their segments, with q >= 1 at every cell
and every coefficient in [-1e3, 1e3]. The cells it leaves outside are an upper bound on
how many a rational of that size must leave out; 0 means it holds every cell (a witness,
found without ratfit's verification). Among the cells left out, the share whose segment
misses the segment of its mirror cell (phi_d -> pi - phi_d): what no mirror-symmetric
function can hold. Frames:

- half-vector: (theta_h, theta_d, sin^2(theta_h) cos(2 phi_d)), ratfit's default for a
  MERL table (reciprocal, mirror-symmetric, no phi_d at theta_h = 0);
- cos 2phi_d: (theta_h, theta_d, cos(2 phi_d)) (reciprocal, mirror-symmetric);
- reciprocal 4-D: (theta_h, theta_d, sin^2(theta_h) cos(2 phi_d), sin^2(theta_h)
  sin(2 phi_d)) (reciprocal, no phi_d at theta_h = 0, not mirror-symmetric);
- MERL's axes: (theta_h, theta_d, phi_d), phi_d in [0, pi) as the table stores it
  (reciprocal by the fold; neither of the other two);
- fold: ratfit's RUSIN_TH_TD_FOLD, (theta_h, theta_d, sin(theta_h) cos(phi_d)), phi_d
  folded as the table folds it (reciprocal, no phi_d at theta_h = 0, not
  mirror-symmetric; 3-D).

    python benchmarks/rgl_frames.py [--material satin_rosaline] [--channel G]
        [--cells 5000] [--width 0.22] [--degrees 5 6 7] [--markdown [PATH]]
"""

from __future__ import annotations

import argparse
import time
from math import comb
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py
from bench_rgl import DEFAULT_DATA, FLOOR
from rgl_symmetry import disjoint_from_mirror
from scipy import sparse
from scipy.optimize import linprog

from ratfit.brdf.io import merl_coords, merl_from_function
from ratfit.brdf.nbrdf import load_nbrdf
from ratfit.brdf.parametrizations import fold_phi_d
from ratfit.core.bases import PolynomialSpace

BOUND = 1e3  # |coefficient| bound: keeps the LP bounded and its solver in range


def frames(c: np.ndarray) -> dict[str, np.ndarray]:
    """Each frame's coordinates of MERL cells ``c`` (theta_h, theta_d, phi_d)."""
    th, td, pd = c[:, 0], c[:, 1], c[:, 2]
    s2 = np.sin(th) ** 2
    return {
        "half-vector": np.stack([th, td, s2 * np.cos(2 * pd)], axis=1),
        "cos 2phi_d": np.stack([th, td, np.cos(2 * pd)], axis=1),
        "reciprocal 4-D": np.stack([th, td, s2 * np.cos(2 * pd), s2 * np.sin(2 * pd)], axis=1),
        "MERL's axes": np.stack([th, td, pd], axis=1),
        "fold": np.stack([th, td, np.sin(th) * np.cos(fold_phi_d(pd, th, td))], axis=1),
    }


def least_miss(x: np.ndarray, domain: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               count: int) -> tuple[np.ndarray, float]:
    """Per cell, by how much the LP's rational (p, q of ``count`` coefficients each)
    misses [lo, hi]; and the LP's seconds."""
    space = PolynomialSpace("legendre", domain)
    P = space.design(x, count)
    n = len(x)
    eye = sparse.identity(n, format="csr")
    zero = sparse.csr_matrix((n, count))
    # p - lo q + s >= 0, hi q - p + s >= 0, q >= 1; minimise the sum of s
    A = sparse.vstack([
        sparse.hstack([-sparse.csr_matrix(P), sparse.csr_matrix(lo[:, None] * P), -eye]),
        sparse.hstack([sparse.csr_matrix(P), -sparse.csr_matrix(hi[:, None] * P), -eye]),
        sparse.hstack([zero, -sparse.csr_matrix(P), sparse.csr_matrix((n, n))]),
    ], format="csr")
    b = np.concatenate([np.zeros(2 * n), -np.ones(n)])
    cost = np.concatenate([np.zeros(2 * count), np.ones(n)])
    bounds = [(-BOUND, BOUND)] * (2 * count) + [(0.0, None)] * n
    t = time.perf_counter()
    res = linprog(cost, A_ub=A, b_ub=b, bounds=bounds, method="highs-ipm")
    seconds = time.perf_counter() - t
    if res.x is None:
        raise RuntimeError(f"LP failed: {res.message}")
    p, q = P @ res.x[:count], P @ res.x[count:2 * count]
    r = p / q
    return np.maximum(np.maximum(lo - r, r - hi), 0.0), seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", default="satin_rosaline")
    ap.add_argument("--channel", default="G", choices=list("RGB"))
    ap.add_argument("--cells", type=int, default=5000)
    ap.add_argument("--width", type=float, default=0.22)
    ap.add_argument("--degrees", type=int, nargs="+", default=[5, 6, 7],
                    help="total degrees of p and q")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    j = "RGB".index(args.channel)
    table = merl_from_function(load_nbrdf(args.data / "nbrdf-rgl" / f"{args.material}_rgb.npz"))
    g = table[..., j]
    w = args.width
    asym = disjoint_from_mirror(g, w).ravel()
    y_all = g.ravel()
    valid = np.isfinite(y_all)
    cells = np.flatnonzero(valid & (y_all > 0))
    rng = np.random.default_rng(0)
    pick = np.sort(rng.choice(cells, size=min(args.cells, cells.size), replace=False))
    y = y_all[pick]
    lo, hi = np.log((1 - w) * y + FLOOR), np.log((1 + w) * y + FLOOR)
    coords = merl_coords()
    rows = []
    for name, x_all in frames(coords).items():
        domain = np.stack([x_all[valid].min(axis=0), x_all[valid].max(axis=0)], axis=1)
        for d in args.degrees:
            count = comb(d + x_all.shape[1], d)
            miss, seconds = least_miss(x_all[pick], domain, lo, hi, count)
            out = miss > 1e-7
            rows.append([name, f"{x_all.shape[1]}", f"{d}", f"{2 * count}",
                         f"{int(out.sum())}", f"{100.0 * out.mean():.2f}",
                         f"{100.0 * asym[pick][out].mean():.0f}" if out.any() else "-",
                         f"{seconds:.0f}"])
            print(*rows[-1], flush=True)
    rep.table(f"{args.material} {args.channel}: {len(pick)} random cells (cells of 0 left out), "
              f"log values at +-{w:.0%} (floor {FLOOR:g} 1/sr); the cells the least-miss LP's "
              "rational of n + m coefficients leaves outside their segments, and the % of "
              "those whose segment misses its mirror cell's",
              ["frame", "dims", "degree", "n + m", "cells out", "% out", "% mirror-asym.",
               "LP s"], rows)
    rep.write()


if __name__ == "__main__":
    main()
