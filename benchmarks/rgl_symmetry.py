"""How far RGL's encoded materials are from the symmetries an isotropic fit is built with.

The default frame for a MERL table (RUSIN_TH_TD_SYM: theta_h, theta_d,
sin^2(theta_h) cos(2 phi_d)) makes a fit reciprocal, isotropic at the mirror direction and
mirror-symmetric: f(theta_h, theta_d, phi_d) = f(theta_h, theta_d, pi - phi_d), the
same BRDF after reflecting L and V in a vertical plane. The networks that stand in for
RGL's measurements are reciprocal (a MERL table folds phi_d into [0, pi)) but are neither
mirror-symmetric nor free of phi_d at theta_h = 0. This script measures by how much, per
material and channel, on the network written as a MERL table and at seeded random pairs:

- cells: % of valid cells whose +-22 % segment (widened by the noise floor, 1e-3 1/sr)
  shares no value with the segment of the mirror cell (phi_d -> pi - phi_d). No
  mirror-symmetric function meets both; the second figure counts only cells whose
  lower direction is more than 10 degrees above the horizon.
- mirror spread: the largest ratio over phi_d of the cells at theta_h = 0 (h at the normal,
  where an isotropic BRDF cannot depend on phi_d), over theta_d with both directions
  more than 10 degrees up.
- p95 bound: a lower bound on the 95th percentile of relative errors (as bench_rgl.py
  scores them, |f - y| / max(y, 1e-3)) of any mirror-symmetric fit at L, V uniform on the
  hemisphere. For a pair P with value y and its mirror image P' with y', one value f
  has max(err(P), err(P')) >= b = |y - y'| / (max(y, e) + max(y', e)); P and P' are
  equally likely, so err >= t on at least half the share of pairs with b >= t, and
  the 95th percentile is at least the 90th percentile of b.

    python benchmarks/rgl_symmetry.py [--only NAME ...] [--pairs 100000] [--data DIR]
        [--markdown [PATH]]
"""

from __future__ import annotations

import numpy as np
from _bench import report  # benchmarks/_bench.py
from bench_rgl import FLOOR, seeded_pairs  # bench_rgl.py's pairs and errors
from rgl_drops import lower_elevation, material_options

from ratfit.brdf.io import merl_from_function
from ratfit.brdf.nbrdf import load_nbrdf

WIDTH = 0.22  # the default relative width of a MERL table's segments
UP = 10.0  # degrees: cells and pairs this far above the horizon count as "up"
MIRROR_K = (180 - np.arange(180)) % 180  # phi_d index k -> pi - phi_d


def disjoint_from_mirror(g: np.ndarray, width: float = WIDTH) -> np.ndarray:
    """Cells whose segment [(1 - w) y - e, (1 + w) y + e] misses their mirror cell's."""
    lo, hi = (1.0 - width) * g - FLOOR, (1.0 + width) * g + FLOOR
    lo_m, hi_m = lo[:, :, MIRROR_K], hi[:, :, MIRROR_K]
    with np.errstate(invalid="ignore"):
        return (lo > hi_m) | (lo_m > hi)  # NaN (no cell) compares False


def mirror_spread(g: np.ndarray, elevation: np.ndarray) -> float:
    """Largest max/min over phi_d of (y + e) at theta_h = 0, theta_d rows > UP degrees up."""
    worst = 1.0
    for j in range(g.shape[1]):
        row = g[0, j]
        if elevation[0, j].min() > UP and np.isfinite(row).all():
            worst = max(worst, float((row.max() + FLOOR) / (row.min() + FLOOR)))
    return worst


def mirror_pairs(n_pairs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """bench_rgl.py's seeded pairs (all of the hemisphere) and their mirror images in
    the x-z plane."""
    L, V = seeded_pairs(n_pairs)
    flip = np.array([1.0, -1.0, 1.0])
    return L, V, L * flip, V * flip


def main() -> None:
    args, nets = material_options(__doc__.splitlines()[0])
    rep = report(args, __file__)
    elevation = lower_elevation()
    up = elevation > UP
    L, V, Lm, Vm = mirror_pairs(args.pairs)
    rows = []
    bounds = []
    for path in nets:
        net = load_nbrdf(path)
        table = merl_from_function(net)
        y, ym = net.eval_dirs(L, V), net.eval_dirs(Lm, Vm)
        b = np.abs(y - ym) / (np.maximum(y, FLOOR) + np.maximum(ym, FLOOR))
        bound = np.percentile(b, 90, axis=0)
        bounds.append(bound)
        for j, ch in enumerate("RGB"):
            g = table[..., j]
            valid = np.isfinite(g) & np.isfinite(g[:, :, MIRROR_K])
            dis = disjoint_from_mirror(g) & valid
            rows.append([path.stem, ch,
                         f"{100.0 * dis.sum() / valid.sum():.1f}",
                         f"{100.0 * (dis & up).sum() / (valid & up).sum():.1f}",
                         f"{mirror_spread(g, elevation):.2f}",
                         f"{100.0 * bound[j]:.1f}"])
    rep.table(f"each RGL network as a MERL table: % of valid cells whose +-{WIDTH:.0%} segment "
              f"misses its mirror cell's (all; both directions > {UP:g} deg up), the "
              f"largest max/min over phi_d at theta_h = 0 ({UP:g} deg up), and the least 95th "
              f"percentile of relative error (%) any mirror-symmetric fit can have at "
              f"{args.pairs} seeded random pairs",
              ["material", "ch", "% cells", f"% cells > {UP:g} deg", "mirror spread",
               "p95 bound %"], rows)
    worst = np.max(np.array(bounds), axis=1) if bounds else np.zeros(0)
    rep.note(f"{int((worst >= 0.25).sum())} of {len(nets)} materials have a channel in "
             "which no mirror-symmetric fit can have a 95th percentile of relative errors "
             "below 25 %; "
             f"{int((worst >= 0.05).sum())} have one in which it cannot be below 5 %.")
    rep.write()


if __name__ == "__main__":
    main()
