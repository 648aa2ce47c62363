"""A BRDF fit along the mirror direction, where every highlight is, against its samples.

A Cornell file has one sample per incidence angle within 0.02 rad of the mirror
direction (theta_h) and none at the mirror itself below 40 degrees, so a fit's highlight
between them is what the fit makes of a handful of samples. For each fit: its value
(each channel) at the exact mirror pair for incidence angles from 5 to 85 degrees, and
at each sample within 0.02 rad of the mirror direction the sample's value, the fit's and
their ratio per channel (the highlight's colour is the ratio of the channels).

    python benchmarks/mirror_line.py FIT.json [FIT.json ...] [--data DIR] [--markdown [PATH]]

Each fit's material is its file name's stem (``mystique.json`` -> cornell/mystique.brdf).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.fitter import load_brdf_fit
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization

REPO = Path(__file__).resolve().parents[1]
OWN = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` reads Cornell's Cartesian pairs as
MIRROR = 0.02  # rad of theta_h
DEGREES = (5, 10, 20, 30, 40, 50, 60, 65, 70, 75, 77, 79, 80, 85)


def _fmt(values: np.ndarray) -> str:
    return " / ".join(f"{v:.3g}" for v in values)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fits", type=Path, nargs="+", metavar="FIT")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    t = np.radians(np.asarray(DEGREES, dtype=float))
    L = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=1)
    V = L * np.array([-1.0, 1.0, 1.0])
    line_rows, sample_rows = [], []
    for path in args.fits:
        fit = load_brdf_fit(path)
        f = fit.eval_dirs(L, V)
        line_rows += [[path.stem, str(d), _fmt(row)] for d, row in zip(DEGREES, f, strict=True)]
        data = args.data / "cornell" / f"{path.stem}.brdf"
        if not data.exists():
            continue
        ds = samples_dataset(read_brdf(data), OWN)
        Ls, Vs = get_parametrization(OWN).to_dirs(ds.x)
        H = Ls + Vs
        H /= np.linalg.norm(H, axis=1, keepdims=True)
        theta_h = np.arccos(np.clip(H[:, 2], -1.0, 1.0))
        near = np.flatnonzero(theta_h < MIRROR)
        near = near[np.argsort(np.arccos(np.clip(Ls[near, 2], -1.0, 1.0)))]
        y = np.asarray(ds.y)[near]
        g = fit.eval_dirs(Ls[near], Vs[near])
        for i, k in enumerate(near):
            sample_rows.append([path.stem, f"{np.degrees(np.arccos(Ls[k, 2])):.1f}",
                                f"{theta_h[k]:.4f}", _fmt(y[i]), _fmt(g[i]),
                                _fmt(g[i] / np.where(y[i] > 0, y[i], np.nan))])
    rep.table("each fit at the mirror pair (theta_h = 0) of each incidence angle "
              "(1/sr, channels in the fit's order)",
              ["fit", "incidence (deg)", "fit"], line_rows)
    if sample_rows:
        rep.table(f"the samples within {MIRROR} rad of the mirror direction: value, fit, "
                  "fit / value per channel",
                  ["fit", "theta_l (deg)", "theta_h", "y", "fit", "fit / y"], sample_rows)
    rep.write()


if __name__ == "__main__":
    main()
