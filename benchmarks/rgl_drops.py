"""Where RGL's encoded materials, written as MERL tables, drop between neighbouring cells.

A default ``ratfit brdf fit`` of these tables finds no verified fit (bench_rgl.py). This
script measures the cells that no smooth function of few coefficients follows: cells of
0 (the network's negative outputs, clipped) and cells below a tenth of one of their six
grid neighbours (theta_h, theta_d and phi_d indices +- 1; phi_d wraps at pi). Per material
and channel: how many there are, the elevation of the lower of L and V at their sample
points (median, 95th percentile, largest, in degrees), and the share of seeded random
direction pairs (L and V uniform on the hemisphere, as in bench_rgl.py) whose MERL cell is
one of them: above 5 %, such cells alone decide a 95th percentile of relative errors.

    python benchmarks/rgl_drops.py [--only NAME ...] [--pairs 100000] [--data DIR]
        [--markdown [PATH]]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py
from bench_rgl import DEFAULT_DATA, seeded_pairs  # the pairs bench_rgl.py scores

from ratfit.brdf.io import MERL_SHAPE, merl_coords, merl_from_function, merl_indices
from ratfit.brdf.nbrdf import load_nbrdf
from ratfit.brdf.parametrizations import _from_half_diff, get_parametrization

DROP = 0.1  # a cell below this fraction of a grid neighbour's value


def neighbour_max(g: np.ndarray) -> np.ndarray:
    """The largest of each cell's six grid neighbours (NaN cells skipped; phi_d wraps)."""
    out = np.full(g.shape, -np.inf)
    for axis in range(3):
        for step in (1, -1):
            nb = np.roll(g, step, axis=axis)
            if axis < 2:  # theta_h and theta_d do not wrap
                edge = [slice(None)] * 3
                edge[axis] = 0 if step == 1 else -1
                nb[tuple(edge)] = np.nan
            out = np.where(np.isfinite(nb), np.maximum(out, nb), out)
    return out


def lower_elevation() -> np.ndarray:
    """Degrees above the horizon of the lower of L and V at each cell's sample point."""
    c = merl_coords()
    L, V = _from_half_diff(c[:, 0], np.zeros(len(c)), c[:, 1], c[:, 2])
    z = np.clip(np.minimum(L[:, 2], V[:, 2]), -1.0, 1.0)
    return np.degrees(np.arcsin(z)).reshape(MERL_SHAPE)


def pair_cells(n_pairs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MERL cell indices of ``n_pairs`` seeded pairs, L and V uniform on the hemisphere."""
    L, V = seeded_pairs(n_pairs)
    th, td, pd = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V).T
    return merl_indices(th, td, pd)


def material_options(description: str) -> tuple[argparse.Namespace, list[Path]]:
    """The options of a script that measures the RGL tables (``--only``, ``--pairs``,
    ``--data``, ``--markdown``) and the networks they select."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--only", nargs="*", default=None, help="material name prefixes")
    ap.add_argument("--pairs", type=int, default=100_000)
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    add_markdown_option(ap)
    args = ap.parse_args()
    nets = sorted((args.data / "nbrdf-rgl").glob("*.npz"))
    if args.only:
        nets = [p for p in nets if any(p.stem.startswith(o) for o in args.only)]
    return args, nets


def main() -> None:
    args, nets = material_options(__doc__.splitlines()[0])
    rep = report(args, __file__)
    elevation = lower_elevation()
    cells = pair_cells(args.pairs)
    rows = []
    over = 0
    for path in nets:
        table = merl_from_function(load_nbrdf(path))
        worst = 0.0
        for j, ch in enumerate("RGB"):
            g = table[..., j]
            ok = np.isfinite(g)
            zero = ok & (g <= 0.0)
            drop = ok & (g < DROP * neighbour_max(g))
            share = float(drop[cells].mean())
            worst = max(worst, share)
            el = (" / ".join(f"{v:.1f}" for v in np.percentile(elevation[drop], [50, 95, 100]))
                  if drop.any() else "-")
            rows.append([path.stem, ch, f"{int(ok.sum())}", f"{int(zero.sum())}",
                         f"{int(drop.sum())}", el, f"{100.0 * share:.2f}"])
        over += worst > 0.05
    rep.table(f"cells of each RGL table (valid cells, cells of 0, cells below {DROP:g} of a "
              "grid neighbour); elevation of the lower of L and V at the latter (median / "
              f"95th percentile / largest, degrees); % of {args.pairs} seeded random pairs "
              "whose cell is one of them",
              ["material", "ch", "valid", "zero", "drops", "elevation deg", "% of pairs"],
              rows)
    rep.note(f"{over} of {len(nets)} materials have a channel whose drops hold more than 5 % "
             "of the random pairs.")
    rep.write()


if __name__ == "__main__":
    main()
